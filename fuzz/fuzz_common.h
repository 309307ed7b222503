// Shared helpers of the libFuzzer targets (fuzz/*.cc).
#ifndef LPOE_FUZZ_FUZZ_COMMON_H_
#define LPOE_FUZZ_FUZZ_COMMON_H_

#include <cstdio>
#include <cstdlib>
#include <string>

#include "lpoe/status.h"

namespace lpoe {
namespace fuzz {

// A property the readers promise does not hold: print it and abort, which libFuzzer reports as a
// crash with the reproducer.
[[noreturn]] inline void Fail(const std::string& what, const std::string& detail) {
  std::fprintf(stderr, "fuzz property violated: %s\n%s\n", what.c_str(), detail.c_str());
  std::abort();
}

// Every error must name the file and a line: "<source>:<line>: ...".
inline void CheckErrorMessage(const Status& s, const std::string& source) {
  const std::string& m = s.message();
  const std::string prefix = source + ":";
  if (m.compare(0, prefix.size(), prefix) != 0) Fail("error message without the file name", m);
  size_t k = prefix.size();
  const size_t digits_start = k;
  while (k < m.size() && m[k] >= '0' && m[k] <= '9') ++k;
  if (k == digits_start || k >= m.size() || m[k] != ':') {
    Fail("error message without a line number", m);
  }
  if (m[digits_start] == '0') Fail("error message with line 0 or a leading zero", m);
}

}  // namespace fuzz
}  // namespace lpoe

#endif  // LPOE_FUZZ_FUZZ_COMMON_H_
