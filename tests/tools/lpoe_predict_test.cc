// Runs lpoe_simulate and lpoe_predict: the actual model written by the simulator predicts its own
// noise-free data (compliance, harmonics, payload, tilted gravity), degrees and per-row targets are
// honoured, and bad flags, bad files and unwritable outputs give their exit codes and leave nothing.
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "file_util.h"
#include "lpoe/io/io.h"
#include "lpoe/kinematics/se3.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/io/urdf.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/model/residual_layer.h"

namespace lpoe {
namespace {
namespace lpoe_predict_test {

namespace fs = std::filesystem;

constexpr int kExitOk = 0, kExitUsage = 1, kExitInput = 2;
constexpr double kToleranceMm = 1e-9;

using testing::RunCapture;

class LpoePredict : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("lpoe_predict_test_" + std::to_string(getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Path(const std::string& name) const { return (dir_ / name).string(); }
  int Predict(const std::string& args, std::string* out) const {
    return RunCapture(std::string(LPOE_PREDICT_PATH) + " " + args, out);
  }
  // The simulated data and actual model: a small arm with every term.
  void Simulate(const std::string& extra) {
    std::string out;
    ASSERT_EQ(RunCapture(std::string(LPOE_SIMULATE_PATH) +
                      " --errors=random --joint_errors=compliance,harmonics --count=40 "
                      "--payload_mass=0.7 --payload_com=5,0,25 --gravity_tilt=0.004 --all_tools " +
                      extra + " --output=" + Path("data.csv") + " --actual_out=" + Path("actual.yaml"),
                  &out),
              kExitOk)
        << out;
  }
  std::vector<std::vector<double>> ReadCsv(const std::string& path) const {
    std::ifstream in(path);
    std::string line;
    std::vector<std::vector<double>> rows;
    do {
      std::getline(in, line);
    } while (!line.empty() && line[0] == '#');
    EXPECT_EQ(line, "x,y,z");
    while (std::getline(in, line)) {
      std::vector<double> row;
      std::stringstream ss(line);
      std::string field;
      while (std::getline(ss, field, ',')) row.push_back(std::stod(field));
      rows.push_back(row);
    }
    return rows;
  }
  fs::path dir_;
};

TEST_F(LpoePredict, ActualModelPredictsItsNoiseFreeData) {
  for (const std::string unit : {"rad", "deg"}) {
    Simulate("--angle_unit=" + unit);
    RobotModel actual;
    ASSERT_TRUE(ReadRobotModel(Path("actual.yaml"), &actual).ok());
    ASSERT_FALSE(actual.joint_errors.empty());
    MeasurementSet data;
    ASSERT_TRUE(ReadMeasurements(Path("data.csv"), actual,
                                 unit == "deg" ? AngleUnit::kDegrees : AngleUnit::kRadians, &data)
                    .ok());
    std::string out;
    ASSERT_EQ(Predict("--model=" + Path("actual.yaml") + " --joints=" + Path("data.csv") +
                          " --angle_unit=" + unit + " --output=" + Path("out.csv"),
                      &out),
              kExitOk)
        << out;
    const std::vector<std::vector<double>> rows = ReadCsv(Path("out.csv"));
    ASSERT_EQ(static_cast<int>(rows.size()), data.size());
    for (int r = 0; r < data.size(); ++r) {
      ASSERT_EQ(rows[r].size(), 3u);
      const Eigen::Vector3d p(rows[r][0], rows[r][1], rows[r][2]);
      EXPECT_LT((p - data.position(r)).norm(), kToleranceMm) << "row " << r;
    }
  }
}

// --gravity_tilt_deg tilts the actual robot's gravity by the angles calibration reports (about x
// and y for gravity along -z); with --gravity_tilt, or out of range, it is refused.
TEST_F(LpoePredict, SimulatorGravityTiltInDegrees) {
  std::string out;
  const std::string base = std::string(LPOE_SIMULATE_PATH) + " --count=5 --output=" +
                           Path("tilt.csv") + " --actual_out=" + Path("tilted.yaml");
  ASSERT_EQ(RunCapture(base + " --gravity_tilt_deg=0.3,-0.1", &out), kExitOk) << out;
  RobotModel actual;
  ASSERT_TRUE(ReadRobotModel(Path("tilted.yaml"), &actual).ok());
  const Eigen::Vector3d level(0, 0, -kStandardGravity);
  const Eigen::Vector2d t = GravityTiltBetween(level, actual.gravity);
  EXPECT_NEAR(t(0) * 180 / M_PI, 0.3, 1e-9);
  EXPECT_NEAR(t(1) * 180 / M_PI, -0.1, 1e-9);
  EXPECT_NEAR(actual.gravity.norm(), kStandardGravity, 1e-12);
  for (const std::string bad : {"--gravity_tilt_deg=0.3", "--gravity_tilt_deg=9,0",
                                "--gravity_tilt_deg=0.3,0.1 --gravity_tilt=0.01"}) {
    out.clear();
    EXPECT_EQ(RunCapture(base + " " + bad, &out), kExitUsage) << bad;
    EXPECT_NE(out.find("--gravity_tilt"), std::string::npos) << out;
  }
}

// A model with a residual layer (docs/residual_layer.md): the positions include its correction
// and --predict_std adds its standard deviation per row; a model without one refuses the flag.
TEST_F(LpoePredict, ResidualLayerAndPredictStd) {
  Simulate("");
  RobotModel model;
  ASSERT_TRUE(ReadRobotModel(Path("actual.yaml"), &model).ok());
  MeasurementSet data;
  ASSERT_TRUE(ReadMeasurements(Path("data.csv"), model, AngleUnit::kRadians, &data).ok());
  std::vector<double> q;
  std::vector<int> tools;
  std::vector<Eigen::Vector3d> residuals;
  for (int r = 0; r < data.size(); ++r) {
    q.insert(q.end(), data.q(r), data.q(r) + 6);
    tools.push_back(data.target(r));
    residuals.emplace_back(0.04 * std::sin(data.q(r)[1]), -0.02 * std::cos(data.q(r)[0]), 0.01);
  }
  auto layer = std::make_shared<ResidualLayer>();
  ASSERT_TRUE(FitResidualLayer(q, tools, residuals, 6, model.num_tools(), ResidualLayerOptions(),
                               layer.get())
                  .ok());
  const RobotModel parametric = model;
  model.residual_layer = layer;
  ASSERT_TRUE(WriteRobotModel(Path("layered.yaml"), model).ok());
  std::string out;
  ASSERT_EQ(Predict("--model=" + Path("layered.yaml") + " --joints=" + Path("data.csv") +
                        " --frame=measurement --predict_std --output=" + Path("std.csv"),
                    &out),
            kExitOk)
      << out;
  std::ifstream in(Path("std.csv"));
  std::string line;
  std::getline(in, line);
  EXPECT_NE(line.find("std"), std::string::npos) << line;  // the comment names the column
  std::getline(in, line);
  EXPECT_EQ(line, "x,y,z,std");
  double largest = 0;
  for (int r = 0; r < data.size(); ++r) {
    ASSERT_TRUE(std::getline(in, line)) << r;
    std::vector<double> v;
    std::stringstream ss(line);
    std::string field;
    while (std::getline(ss, field, ',')) v.push_back(std::stod(field));
    ASSERT_EQ(v.size(), 4u);
    const Eigen::Vector3d p(v[0], v[1], v[2]);
    EXPECT_LT((p - PredictToolPosition(model, data.q(r), data.target(r))).norm(), kToleranceMm);
    largest = std::max(largest,
                       (p - PredictToolPosition(parametric, data.q(r), data.target(r))).norm());
    // Near the data the variance is the small difference s_f^2 - k^T W k: a few 1e-9 mm of
    // rounding between two evaluations (Eigen's product kernels), far below any use.
    EXPECT_NEAR(v[3], layer->Std(data.q(r), data.target(r)), 1e-8);
    EXPECT_GT(v[3], 0);
  }
  EXPECT_GT(largest, 0.01);  // the layer's correction is in the positions
  out.clear();
  EXPECT_EQ(Predict("--model=" + Path("actual.yaml") + " --joints=" + Path("data.csv") +
                        " --predict_std --output=" + Path("none.csv"),
                    &out),
            kExitUsage);
  EXPECT_NE(out.find("needs a model with a residual layer"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(Path("none.csv")));
}

TEST_F(LpoePredict, ToolFlagAndTargetColumn) {
  Simulate("");
  std::ofstream(Path("joints.csv")) << "# comment\nextra,Q2,q1,q3,q4,q5,q6,target\n"
                                    << "7,0.1,0.2,0.3,0.4,0.5,0.6,smr1\n";
  std::ofstream(Path("joints_no_target.csv")) << "q1,q2,q3,q4,q5,q6\r\n0.2,0.1,0.3,0.4,0.5,0.6\r\n";
  RobotModel actual;
  ASSERT_TRUE(ReadRobotModel(Path("actual.yaml"), &actual).ok());
  const double q[6] = {0.2, 0.1, 0.3, 0.4, 0.5, 0.6};
  std::string out;
  ASSERT_EQ(Predict("--model=" + Path("actual.yaml") + " --joints=" + Path("joints.csv") +
                        " --output=" + Path("a.csv"),
                    &out),
            kExitOk)
      << out;
  const std::vector<double> a = ReadCsv(Path("a.csv")).at(0);
  EXPECT_LT((Eigen::Vector3d(a[0], a[1], a[2]) - PredictToolPosition(actual, q, 0)).norm(),
            kToleranceMm);
  ASSERT_EQ(Predict("--model=" + Path("actual.yaml") + " --joints=" + Path("joints_no_target.csv") +
                        " --tool=0 --output=" + Path("b.csv"),
                    &out),
            kExitOk)
      << out;
  const std::vector<double> b = ReadCsv(Path("b.csv")).at(0);
  EXPECT_LT((Eigen::Vector3d(b[0], b[1], b[2]) - PredictToolPosition(actual, q, 0)).norm(),
            kToleranceMm);
}

TEST_F(LpoePredict, BadInputsGiveExitCodesAndNoOutput) {
  Simulate("");
  const std::string model = " --model=" + Path("actual.yaml");
  std::ofstream(Path("missing_q6.csv")) << "q1,q2,q3,q4,q5\n0,0,0,0,0\n";
  std::ofstream(Path("bad_value.csv")) << "q1,q2,q3,q4,q5,q6\n0,0,0,0,0,0\n0,0,x,0,0,0\n";
  std::ofstream(Path("bad_target.csv")) << "q1,q2,q3,q4,q5,q6,target\n0,0,0,0,0,0,smr7\n";
  struct Case {
    std::string args;
    int code;
    std::string message;
  } cases[] = {
      {model + " --joints=" + Path("data.csv"), kExitUsage, "--output"},
      {model + " --joints=" + Path("data.csv") + " --angle_unit=grad", kExitUsage, "angle_unit"},
      {model + " --joints=" + Path("data.csv") + " --tool=9", kExitUsage, "--tool '9'"},
      {model + " --joints=" + Path("missing_q6.csv"), kExitInput, "missing_q6.csv:1: no column q6"},
      {model + " --joints=" + Path("bad_value.csv"), kExitInput, "bad_value.csv:3: q3 'x'"},
      {model + " --joints=" + Path("bad_target.csv"), kExitInput, "bad_target.csv:2: target 'smr7'"},
      {" --model=" + Path("none.yaml") + " --joints=" + Path("data.csv"), kExitInput, "none.yaml"},
  };
  for (const Case& c : cases) {
    std::string out;
    const bool has_output = c.args.find("--output") == std::string::npos &&
                            c.message != "--output";
    const std::string args = c.args + (has_output ? " --output=" + Path("out.csv") : "");
    EXPECT_EQ(Predict(args, &out), c.code) << args << "\n" << out;
    EXPECT_NE(out.find(c.message), std::string::npos) << out;
    EXPECT_FALSE(fs::exists(Path("out.csv"))) << args;
  }
  std::string out;
  // A missing output directory is found before any work (tools/common/output_files.h): a usage error.
  EXPECT_EQ(Predict(model + " --joints=" + Path("data.csv") + " --output=" + Path("no/dir/out.csv"),
                    &out),
            kExitUsage)
      << out;
  EXPECT_NE(out.find("does not exist"), std::string::npos) << out;
}

// Positions in the robot's base frame by default, in the calibration's measurement frame on request.
TEST_F(LpoePredict, FrameBaseUndoesTheRecordedRegistration) {
  Simulate("");
  RobotModel model;
  ASSERT_TRUE(ReadRobotModel(Path("actual.yaml"), &model).ok());
  Vector6d xi;
  xi << 0.2, -0.4, 1.0, 2500, -800, 400;
  model.T_measurement_base = ExpSE3(xi);
  model.joints[0].origin = model.T_measurement_base * model.joints[0].origin;
  ASSERT_TRUE(WriteRobotModel(Path("registered.yaml"), model).ok());
  std::ofstream(Path("q.csv")) << "q1,q2,q3,q4,q5,q6\n0.1,-0.5,0.7,0.2,1.1,-0.4\n";
  std::string out;
  for (const char* frame : {"base", "measurement"}) {
    ASSERT_EQ(Predict("--model=" + Path("registered.yaml") + " --joints=" + Path("q.csv") +
                          " --frame=" + frame + " --output=" + Path(std::string(frame) + ".csv"),
                      &out),
              kExitOk)
        << out;
  }
  const auto base = ReadCsv(Path("base.csv")), measurement = ReadCsv(Path("measurement.csv"));
  ASSERT_EQ(base.size(), 1u);
  ASSERT_EQ(measurement.size(), 1u);
  const Eigen::Vector3d pb(base[0][0], base[0][1], base[0][2]);
  const Eigen::Vector3d pm(measurement[0][0], measurement[0][1], measurement[0][2]);
  EXPECT_LT((model.T_measurement_base * pb - pm).norm(), 1e-6);
  EXPECT_GT((pb - pm).norm(), 1000.0);  // not vacuous
  EXPECT_NE(testing::ReadAll(Path("base.csv")).find("model's base frame"), std::string::npos);
  EXPECT_EQ(Predict("--model=" + Path("registered.yaml") + " --joints=" + Path("q.csv") +
                        " --frame=tracker --output=" + Path("x.csv"),
                    &out),
            kExitUsage);
}

// The same chain-selection flags as lpoe_calibrate: a URDF's SMR links as tools.
TEST_F(LpoePredict, UrdfChainFlagsSelectTheToolsAsInEveryTool) {
  const std::string urdf = std::string(LPOE_TEST_DATA_DIR) + "/urdf/ur_like.urdf";
  std::ofstream(Path("q.csv")) << "q1,q2,q3,q4,q5,q6\n0.1,-0.5,0.7,0.2,1.1,-0.4\n";
  RobotModel model;
  UrdfOptions options;
  options.tip_link = "flange";
  options.tool_links = {"flange", "tool_smr"};
  ASSERT_TRUE(ReadRobotModelUrdf(urdf, &model, options).ok());
  const double q[6] = {0.1, -0.5, 0.7, 0.2, 1.1, -0.4};
  std::string out;
  for (int t = 0; t < 2; ++t) {
    const std::string name = options.tool_links[t];
    ASSERT_EQ(Predict("--model=" + urdf + " --tip_link=flange --tool_links=flange,tool_smr " +
                          "--tool=" + name + " --joints=" + Path("q.csv") +
                          " --output=" + Path(name + ".csv"),
                      &out),
              kExitOk)
        << out;
    const auto rows = ReadCsv(Path(name + ".csv"));
    ASSERT_EQ(rows.size(), 1u);
    const Eigen::Vector3d expected = ToolPosition(model, q, t);
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(rows[0][a], expected(a), kToleranceMm) << name;
  }
  EXPECT_GT((ToolPosition(model, q, 0) - ToolPosition(model, q, 1)).norm(), 1.0);  // not vacuous
  // The flags select a URDF chain: with a YAML model they are a usage error.
  Simulate("");
  EXPECT_EQ(Predict("--model=" + Path("actual.yaml") + " --tool_links=smr1 --joints=" +
                        Path("q.csv") + " --output=" + Path("y.csv"),
                    &out),
            kExitUsage)
      << out;
  EXPECT_NE(out.find("is not a URDF"), std::string::npos) << out;
}

}  // namespace lpoe_predict_test
}  // namespace
}  // namespace lpoe
