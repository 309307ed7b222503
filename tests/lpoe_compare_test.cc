// Runs the lpoe_compare tool on the shipped data: the two solvers must agree (exit 0), and a
// tolerance no calibration can meet must be reported as a disagreement (exit 7).
#include <sys/wait.h>

#include <array>
#include <cstdio>
#include <string>

#include <gtest/gtest.h>

namespace {

constexpr int kExitOk = 0;
constexpr int kExitDisagree = 7;

// Runs the command, returns its exit status and captures stdout.
int RunTool(const std::string& args, std::string* out) {
  const std::string command = std::string(LPOE_COMPARE_BINARY) + " " + args + " 2>&1";
  FILE* pipe = popen(command.c_str(), "r");
  if (pipe == nullptr) return -1;
  std::array<char, 4096> buffer;
  size_t n;
  while ((n = fread(buffer.data(), 1, buffer.size(), pipe)) > 0) out->append(buffer.data(), n);
  const int status = pclose(pipe);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
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

}  // namespace
