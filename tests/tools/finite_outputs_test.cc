// Property test: every tool run on random valid models writes only finite numbers. The
// models are the test robots with tilted, offset joint axes (test_util.h); each is simulated with
// random kinematic errors, calibrated, and then predicted, compensated (targets, joints and a
// program), planned and compared; every number of every file written (CSV, JSON, YAML, HTML,
// program text) must be finite, and no "nan" or "inf" word may appear.
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "file_util.h"
#include "lpoe/io/io.h"
#include "test_util.h"

namespace lpoe {
namespace {
namespace finite_outputs_test {

using testing::ListDir;
using testing::ReadAll;
using testing::RunInDir;
using testing::TempDir;
using testing::ToolOutput;
using testing::WriteAll;

// The first non-finite number or nan/inf word of `text`, or "" when there is none. In a YAML model
// `.inf` / `-.inf` are the open sides of joint limits and allowed.
std::string FirstNonFinite(const std::string& text, bool yaml) {
  auto word_char = [](char c) { return std::isalnum(static_cast<unsigned char>(c)) || c == '_'; };
  for (size_t i = 0; i < text.size();) {
    if (!word_char(text[i])) {
      ++i;
      continue;
    }
    size_t e = i;
    while (e < text.size() && word_char(text[e])) ++e;
    std::string word = text.substr(i, e - i);
    for (char& c : word) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    const bool yaml_inf = yaml && word == "inf" && i > 0 && text[i - 1] == '.';
    if ((word == "nan" || word == "inf" || word == "infinity") && !yaml_inf) {
      return text.substr(i > 20 ? i - 20 : 0, 60);
    }
    if (std::isdigit(static_cast<unsigned char>(text[i])) && (i == 0 || !word_char(text[i - 1]))) {
      const double v = std::strtod(text.c_str() + i, nullptr);
      if (!std::isfinite(v)) return text.substr(i, 40);
    }
    i = e;
  }
  return "";
}

std::string Tool(const char* path) { return std::string(path) + " "; }

TEST(FiniteOutputs, EveryToolWritesOnlyFiniteNumbersOnRandomModels) {
  testing::ScopedToolLeakCheck leak_check;  // every tool's main path, with the leak check at exit
  const std::vector<testing::NamedRobot> robots = testing::TestRobotsWithTiltedVariants(40);
  // Three of the tilted variants: a 6R, the 7-joint arm and the arm with a prismatic joint.
  for (const char* want : {"cobot6_tilted", "arm7_tilted", "arm_prismatic_tilted"}) {
    const RobotModel* model = nullptr;
    for (const auto& r : robots) {
      if (r.name == want) model = &r.model;
    }
    ASSERT_NE(model, nullptr) << want;
    SCOPED_TRACE(want);
    // Planning samples the joints within their limits: a prismatic joint needs some.
    RobotModel nominal = *model;
    for (Joint& j : nominal.joints) {
      if (j.type == JointType::kPrismatic && !std::isfinite(j.lower)) {
        j.lower = -100;
        j.upper = 100;
      }
    }
    model = &nominal;
    TempDir d;
    ASSERT_TRUE(WriteRobotModel(d / "nominal.yaml", *model).ok());
    const std::string flange = "--flange=" + model->tools[0].name + " ";
    ToolOutput r = RunInDir(d.path(), Tool(LPOE_SIMULATE_PATH) +
                                          "--model=nominal.yaml --errors=random --count=60 "
                                          "--noise_sigma=0.01 --seed=3 --output=m.csv "
                                          "--actual_out=actual.yaml");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    r = RunInDir(d.path(), Tool(LPOE_CALIBRATE_PATH) +
                               "--model=nominal.yaml --measurements=m.csv --output=cal.yaml "
                               "--report=cal.json --html_report=cal.html --plots_dir= --quiet "
                               "--force");
    ASSERT_TRUE(r.exit_code == 0 || r.exit_code == 8) << r.out << r.err;
    r = RunInDir(d.path(), Tool(LPOE_PREDICT_PATH) + "--model=cal.yaml --joints=m.csv "
                                                     "--output=predicted.csv --frame=measurement");
    EXPECT_EQ(r.exit_code, 0) << r.err;
    r = RunInDir(d.path(), Tool(LPOE_COMPENSATE_PATH) +
                               "--model=cal.yaml --nominal=nominal.yaml --joints=m.csv "
                               "--output=joints.csv --report=joints.json --threads=1");
    EXPECT_TRUE(r.exit_code == 0 || r.exit_code == 8) << r.err;
    // The measured positions as targets (in the calibration's frame), seeded by their joints.
    r = RunInDir(d.path(), Tool(LPOE_COMPENSATE_PATH) +
                               "--model=cal.yaml --targets=m.csv --frame=measurement "
                               "--output=targets.csv --report=targets.json --threads=1");
    EXPECT_TRUE(r.exit_code == 0 || r.exit_code == 8) << r.err;
    // A joint program of the robot's own joint count.
    std::string program = "def p():\n";
    for (int k = 0; k < 3; ++k) {
      program += "  movej([";
      for (int j = 0; j < model->num_joints(); ++j) {
        program += (j ? ", " : "") + std::to_string(0.1 * (k + 1) * (j % 2 ? -1 : 1));
      }
      program += "])\n";
    }
    ASSERT_TRUE(WriteAll(d / "in.script", program + "end\n"));
    r = RunInDir(d.path(), Tool(LPOE_COMPENSATE_PATH) + flange +
                               "--model=cal.yaml --nominal=nominal.yaml --program=in.script "
                               "--output=out.script --report=program.json");
    EXPECT_EQ(r.exit_code, 0) << r.err;
    // (Every candidate counts: the arms with tilted axes are near a singularity by the default
    // measure; what matters here is that the plan's numbers are finite.)
    r = RunInDir(d.path(), Tool(LPOE_PLAN_PATH) +
                               "--model=cal.yaml --count=12 --candidate_count=300 "
                               "--workspace_count=50 --random_draws=2 --min_singularity=0 "
                               "--output=plan.csv");
    EXPECT_EQ(r.exit_code, 0) << r.err;
    r = RunInDir(d.path(), Tool(LPOE_COMPARE_PATH) +
                               "--model=nominal.yaml --measurements=m.csv --output=compare.json "
                               "--quiet --force");
    EXPECT_TRUE(r.exit_code == 0 || r.exit_code == 7 || r.exit_code == 8) << r.err;
    int files = 0;
    for (const std::string& name : ListDir(d.path())) {
      const std::string text = ReadAll(d / name);
      const bool yaml = name.size() > 5 && name.compare(name.size() - 5, 5, ".yaml") == 0;
      EXPECT_EQ(FirstNonFinite(text, yaml), "") << name;
      ++files;
    }
    // The inputs and the 13 outputs of the runs above.
    EXPECT_GE(files, 15) << ::testing::PrintToString(ListDir(d.path()));
  }
}

// The checker itself finds what it must.
TEST(FiniteOutputs, CheckerFindsNanAndInfinity) {
  EXPECT_EQ(FirstNonFinite("x,y,z\n1.5,2e3,-4\n", false), "");
  EXPECT_NE(FirstNonFinite("x,y,z\n1.5,nan,-4\n", false), "");
  EXPECT_NE(FirstNonFinite("{\"a\": -Infinity}", false), "");
  EXPECT_NE(FirstNonFinite("q1\n1e999\n", false), "");
  EXPECT_EQ(FirstNonFinite("limits: [-.inf, .inf]\n", true), "");
  EXPECT_NE(FirstNonFinite("limits: [-.inf, .inf]\n", false), "");
  EXPECT_EQ(FirstNonFinite("data:image/png;base64,iVBORnanAAinfA==", false), "");
}

}  // namespace finite_outputs_test
}  // namespace
}  // namespace lpoe
