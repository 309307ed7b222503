// The tools the test program starts run without LeakSanitizer's exit check in the sanitizer build,
// except inside a ScopedToolLeakCheck (file_util.h says why). This file sets that up when the
// program starts, and checks what a started tool sees.
#include <cstdlib>
#include <string>

#include <gtest/gtest.h>

#include "file_util.h"

#if defined(__SANITIZE_ADDRESS__)
#define LPOE_TESTS_ADDRESS_SANITIZER 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define LPOE_TESTS_ADDRESS_SANITIZER 1
#endif
#endif
#ifndef LPOE_TESTS_ADDRESS_SANITIZER
#define LPOE_TESTS_ADDRESS_SANITIZER 0
#endif

namespace lpoe {
namespace testing {
namespace tool_leak_check {

struct ChildOptions {
  bool had = false;      // ASAN_OPTIONS was set when the program started
  std::string original;  // its value then
  int scopes = 0;        // ScopedToolLeakCheck objects alive
};

ChildOptions& Options() {
  static ChildOptions options;
  return options;
}

// ASAN_OPTIONS for the processes started from now on: the program's own, or those with the leak
// check off. This process parsed its options when it started; changing the variable changes only
// what its children see (the sanitizer's flags are read left to right, the last one counts).
void SetChildLeakCheck(bool on) {
  if (!LPOE_TESTS_ADDRESS_SANITIZER) return;
  const ChildOptions& o = Options();
  if (on) {
    if (o.had) {
      setenv("ASAN_OPTIONS", o.original.c_str(), 1);
    } else {
      unsetenv("ASAN_OPTIONS");
    }
  } else {
    const std::string off = o.had && !o.original.empty() ? o.original + ":detect_leaks=0"
                                                         : std::string("detect_leaks=0");
    setenv("ASAN_OPTIONS", off.c_str(), 1);
  }
}

const bool kChildOptionsSet = [] {
  ChildOptions& o = Options();
  const char* value = std::getenv("ASAN_OPTIONS");
  o.had = value != nullptr;
  if (value != nullptr) o.original = value;
  SetChildLeakCheck(false);
  return true;
}();

// What a shell started now sees in ASAN_OPTIONS ("<unset>" when nothing).
std::string ChildSees() {
  std::string out;
  RunCapture("printf '%s' \"${ASAN_OPTIONS-<unset>}\"", &out);
  return out;
}

std::string Original() { return Options().had ? Options().original : std::string("<unset>"); }

}  // namespace tool_leak_check

using tool_leak_check::Options;
using tool_leak_check::SetChildLeakCheck;

ScopedToolLeakCheck::ScopedToolLeakCheck() {
  if (Options().scopes++ == 0) SetChildLeakCheck(true);
}

ScopedToolLeakCheck::~ScopedToolLeakCheck() {
  if (--Options().scopes == 0) SetChildLeakCheck(false);
}

namespace tool_leak_check {

TEST(ToolLeakCheck, ToolsRunWithoutItOutsideTheScopeAndWithTheProgramsOptionsInside) {
  ASSERT_TRUE(kChildOptionsSet);
  const std::string off = ChildSees();
  if (LPOE_TESTS_ADDRESS_SANITIZER) {
    // The last flag of the list is the one that counts.
    const std::string tail = ":detect_leaks=0";
    EXPECT_TRUE(
        off == "detect_leaks=0" ||
        (off.size() > tail.size() && off.compare(off.size() - tail.size(), tail.size(), tail) == 0))
        << off;
  } else {
    EXPECT_EQ(off, Original());  // no sanitizer, no leak check to turn off: nothing changes
  }
  {
    ScopedToolLeakCheck check;
    EXPECT_EQ(ChildSees(), Original());
    {
      ScopedToolLeakCheck nested;
      EXPECT_EQ(ChildSees(), Original());
    }
    EXPECT_EQ(ChildSees(), Original());  // the outer scope still holds
  }
  EXPECT_EQ(ChildSees(), off);
}

}  // namespace tool_leak_check
}  // namespace testing
}  // namespace lpoe
