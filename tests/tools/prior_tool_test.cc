// lpoe_prior (docs/recalibration.md): the fleet prior of calibrated models of one type,
// run as a tool on model files written by the test: what it writes is the library's FleetPrior of
// the files, is read back as a prior, lies nearer the type than the robots do; models of another
// chain or other tools, too few models, a missing file and an output that is an input are refused
// with their reason and nothing written.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "file_util.h"
#include "lpoe/io/io.h"
#include "lpoe/model/model_covariance.h"
#include "lpoe/model/prior.h"
#include "lpoe/recalibration.h"
#include "lpoe/model/simulation.h"

#ifndef LPOE_PRIOR_PATH
#error "LPOE_PRIOR_PATH must name the lpoe_prior binary"
#endif

namespace lpoe {
namespace {
namespace prior_tool_test {

using testing::ShellQuote;

// A UR5-like type with 3 SMRs and a systematic deviation from its drawing; each robot of it with
// smaller errors of its own (0.2 mm, 0.3 mrad).
RobotModel TypeModel() {
  RobotModel m = MakeUr5Like();
  m.tools.resize(3);
  const Eigen::Vector3d points[3] = {{60, 0, 90}, {-30, 55, 90}, {-30, -55, 90}};
  for (int t = 0; t < 3; ++t) {
    m.tools[t].name = "smr" + std::to_string(t + 1);
    m.tools[t].origin = SE3d(Eigen::Matrix3d::Identity(), points[t]);
  }
  return ApplyErrors(m, RandomErrors(m, 0.003, 2.0, 0.002, 0.0, 99));
}

RobotModel Member(const RobotModel& type, uint64_t seed) {
  return ApplyErrors(type, RandomErrors(type, 0.0003, 0.2, 0.0002, 0.0005, seed));
}

testing::ToolOutput Prior(const testing::TempDir& dir, const std::vector<std::string>& models,
                          const std::string& output) {
  std::string list;
  for (const std::string& m : models) list += (list.empty() ? "" : ",") + m;
  return testing::RunInDir(dir.path(), ShellQuote(LPOE_PRIOR_PATH) + " --models=" +
                                           ShellQuote(list) + " --output=" + ShellQuote(output));
}

// Mean squared |xi| of the joint frames 2..n (frame 1 carries each robot's own registration).
double JointFrameSpread(const RobotModel& reference, const RobotModel& model) {
  double sum = 0;
  for (int f = 1; f < model.num_joints(); ++f) sum += FrameDeviation(reference, model, f).squaredNorm();
  return sum;
}

TEST(PriorTool, WritesTheFleetMeanAndCovarianceReadBackAsAPrior) {
  testing::ScopedToolLeakCheck leak_check;  // lpoe_prior's main path, with the leak check at exit
  testing::TempDir dir("prior_tool_test");
  const RobotModel type = TypeModel();
  std::vector<std::string> paths;
  std::vector<RobotModel> read(8);
  double member_spread = 0;
  for (int k = 0; k < 8; ++k) {
    const RobotModel m = Member(type, 100 + k);
    member_spread += JointFrameSpread(type, m) / 8;
    paths.push_back(dir / ("robot" + std::to_string(k + 1) + ".yaml"));
    ASSERT_TRUE(WriteRobotModel(paths.back(), m).ok());
    ASSERT_TRUE(ReadRobotModel(paths.back(), &read[k]).ok());
  }
  const std::string fleet = dir / "fleet.yaml";
  const testing::ToolOutput o = Prior(dir, paths, fleet);
  ASSERT_EQ(o.exit_code, 0) << o.err;
  EXPECT_NE(o.out.find("fleet prior of 8 robots"), std::string::npos) << o.out;
  EXPECT_EQ(o.err.find("rank at most"), std::string::npos) << o.err;  // 8 >= 7: full rank
  // These robots' SMRs differ in orientation too (6 directions, not the 3 of position data): the
  // predictive covariance of such a block needs 9 robots, and the tool says so; the joint frames'
  // (4 directions) need 7 and are not named.
  EXPECT_NE(o.err.find("smr1 (6 directions: 9)"), std::string::npos) << o.err;
  EXPECT_EQ(o.err.find("joint"), std::string::npos) << o.err;
  // Read back as lpoe_calibrate --prior reads it.
  RobotModel mean;
  ParameterPrior prior;
  ASSERT_TRUE(ReadPrior(fleet, PriorScales(), &mean, &prior).ok());
  EXPECT_TRUE(prior.informative);
  ModelCovariance covariance;
  ASSERT_TRUE(ReadModelCovariance(fleet, mean, &covariance).ok());
  EXPECT_EQ(covariance.models, 8);
  // The library's fleet prior of the same files.
  RobotModel expected_mean;
  ModelCovariance expected;
  ASSERT_TRUE(FleetPrior(read, &expected_mean, &expected).ok());
  ASSERT_EQ(covariance.frames.size(), expected.frames.size());
  for (size_t f = 0; f < expected.frames.size(); ++f) {
    ASSERT_EQ(covariance.frames[f].size(), 36);
    EXPECT_LE((covariance.frames[f] - expected.frames[f]).cwiseAbs().maxCoeff(),
              1e-9 * expected.frames[f].cwiseAbs().maxCoeff())
        << "frame " << f;
    EXPECT_LE(FrameDeviation(expected_mean, mean, static_cast<int>(f)).norm(), 1e-9) << "frame " << f;
  }
  // The mean of 8 robots lies nearer the type than the robots themselves (by about sqrt(8)).
  EXPECT_LT(JointFrameSpread(type, mean), 0.5 * member_spread);
}

TEST(PriorTool, SaysHowManyRobotsACovarianceNeeds) {
  testing::TempDir dir("prior_tool_test");
  const RobotModel type = TypeModel();
  std::vector<std::string> paths;
  for (int k = 0; k < 3; ++k) {
    paths.push_back(dir / ("robot" + std::to_string(k + 1) + ".yaml"));
    ASSERT_TRUE(WriteRobotModel(paths.back(), Member(type, 200 + k)).ok());
  }
  // Three: written, with the warning that a frame's covariance has rank 2 of 6.
  const testing::ToolOutput three = Prior(dir, paths, dir / "three.yaml");
  ASSERT_EQ(three.exit_code, 0) << three.err;
  EXPECT_NE(three.err.find("rank at most 2"), std::string::npos) << three.err;
  EXPECT_NE(three.err.find("needs 7 robots"), std::string::npos) << three.err;
  EXPECT_NE(three.err.find("tolerances"), std::string::npos) << three.err;
  // One: refused as a usage error, nothing written.
  const testing::ToolOutput one = Prior(dir, {paths[0]}, dir / "one.yaml");
  EXPECT_EQ(one.exit_code, 1);
  EXPECT_NE(one.err.find("at least 2"), std::string::npos) << one.err;
  EXPECT_FALSE(testing::Exists(dir / "one.yaml"));
  // A robot listed twice would count twice.
  const testing::ToolOutput twice = Prior(dir, {paths[0], paths[1], paths[0]}, dir / "twice.yaml");
  EXPECT_EQ(twice.exit_code, 1);
  EXPECT_NE(twice.err.find("listed twice"), std::string::npos) << twice.err;
  EXPECT_FALSE(testing::Exists(dir / "twice.yaml"));
}

TEST(PriorTool, RefusesModelsOfAnotherChainOrOtherTools) {
  testing::TempDir dir("prior_tool_test");
  const RobotModel type = TypeModel();
  const std::string a = dir / "a.yaml", b = dir / "b.yaml";
  ASSERT_TRUE(WriteRobotModel(a, Member(type, 1)).ok());
  ASSERT_TRUE(WriteRobotModel(b, Member(type, 2)).ok());
  RobotModel fewer_tools = Member(type, 3);
  fewer_tools.tools.pop_back();
  const std::string c = dir / "two_smrs.yaml";
  ASSERT_TRUE(WriteRobotModel(c, fewer_tools).ok());
  const testing::ToolOutput tools = Prior(dir, {a, b, c}, dir / "fleet.yaml");
  EXPECT_EQ(tools.exit_code, 2);
  EXPECT_NE(tools.err.find(c + " has 2 tools"), std::string::npos) << tools.err;
  EXPECT_NE(tools.err.find("same tools"), std::string::npos) << tools.err;
  RobotModel five = MakeUr5Like();
  five.joints.pop_back();
  const std::string d = dir / "five_joints.yaml";
  ASSERT_TRUE(WriteRobotModel(d, five).ok());
  const testing::ToolOutput chain = Prior(dir, {a, d}, dir / "fleet.yaml");
  EXPECT_EQ(chain.exit_code, 2);
  EXPECT_NE(chain.err.find(d + " has 5 joints"), std::string::npos) << chain.err;
  EXPECT_NE(chain.err.find("one chain"), std::string::npos) << chain.err;
  // A missing file is named; an output that is an input is refused before any work.
  const testing::ToolOutput missing = Prior(dir, {a, dir / "none.yaml"}, dir / "fleet.yaml");
  EXPECT_EQ(missing.exit_code, 2);
  EXPECT_NE(missing.err.find(dir / "none.yaml"), std::string::npos) << missing.err;
  // --model is not its input (a user who meant --models is told).
  const testing::ToolOutput model = testing::RunInDir(
      dir.path(), ShellQuote(LPOE_PRIOR_PATH) + " --model=" + ShellQuote(a) + " --models=" +
                      ShellQuote(a + "," + b) + " --output=" + ShellQuote(dir / "fleet.yaml"));
  EXPECT_EQ(model.exit_code, 1);
  EXPECT_NE(model.err.find("not --model"), std::string::npos) << model.err;
  const testing::ToolOutput onto = Prior(dir, {a, b}, b);
  EXPECT_EQ(onto.exit_code, 1);
  EXPECT_FALSE(testing::Exists(dir / "fleet.yaml"));
}

}  // namespace prior_tool_test
}  // namespace
}  // namespace lpoe
