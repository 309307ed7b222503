// libFuzzer target: the --targets_only filter (TargetNameFilter, RE2) on an arbitrary
// pattern and name (the input split at its first NUL byte). Checks: no crash, no recursion on long
// names and no exponential time (libFuzzer's timeout); a refused pattern says so with the pattern;
// a pattern of plain letters and digits matches exactly the name equal to it; a filter matches the
// same names as the same pattern compiled again.
#include <cstddef>
#include <cstdint>
#include <string>

#include "fuzz_common.h"
#include "lpoe/program.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string input(reinterpret_cast<const char*>(data), size);
  const size_t nul = input.find('\0');
  const std::string pattern = input.substr(0, nul);
  const std::string name = nul == std::string::npos ? std::string() : input.substr(nul + 1);
  lpoe::TargetNameFilter filter;
  const lpoe::Status s = filter.Compile(pattern);
  if (!s.ok()) {
    if (s.message().compare(0, 14, "targets_only '") != 0) {
      lpoe::fuzz::Fail("a refused pattern without its message", s.message());
    }
    return 0;
  }
  const bool match = filter.Matches(name);
  lpoe::TargetNameFilter again;
  if (!again.Compile(pattern).ok() || again.Matches(name) != match) {
    lpoe::fuzz::Fail("the same pattern matches differently", pattern);
  }
  bool plain = !pattern.empty();
  for (char c : pattern) {
    plain = plain && ((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
                      c == '_');
  }
  if (plain && match != (name == pattern)) {
    lpoe::fuzz::Fail("a plain pattern does not match exactly its own text", pattern + " / " + name);
  }
  // The empty pattern selects every name.
  if (!lpoe::TargetNameFilter().Matches(name)) lpoe::fuzz::Fail("empty filter refused a name", name);
  return 0;
}
