// Runs the lpoe_compare tool on the shipped data: the two solvers must agree (exit 0), and a
// tolerance no calibration can meet must be reported as a disagreement (exit 7).
#include <string>

#include <gtest/gtest.h>

#include "file_util.h"

namespace {
namespace lpoe_compare_test {

constexpr int kExitOk = 0;
constexpr int kExitDisagree = 7;

// Runs the tool, returns its exit status and captures stdout and stderr.
int RunTool(const std::string& args, std::string* out) {
  return ::lpoe::testing::RunCapture(std::string(LPOE_COMPARE_PATH) + " " + args, out);
}

TEST(LpoeCompare, DefaultDataAgree) {
  std::string out;
  EXPECT_EQ(RunTool("", &out), kExitOk) << out;
  EXPECT_NE(out.find("predicted positions"), std::string::npos) << out;
  EXPECT_NE(out.find("result: agree"), std::string::npos) << out;
}

TEST(LpoeCompare, ImpossibleToleranceDisagrees) {
  std::string out;
  EXPECT_EQ(RunTool("--tolerance_mm=0", &out), kExitDisagree) << out;
  EXPECT_NE(out.find("DISAGREE"), std::string::npos) << out;
}

TEST(LpoeCompare, BadFlagIsUsageError) {
  std::string out;
  EXPECT_EQ(RunTool("--parameterization=bogus", &out), 1) << out;
}

}  // namespace lpoe_compare_test
}  // namespace
