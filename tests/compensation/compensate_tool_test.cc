// Runs lpoe_compensate on files written here: a "calibrated" model (a robot with kinematic errors,
// registered to a measurement frame metres away) and its nominal model. Checks targets mode (mixed
// position and pose rows, degrees), the joint-program mode through the registration, the status
// of an unreachable row with and without --strict, the JSON summary, and a bad file's message.
#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "file_util.h"
#include "lpoe/io/io.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/model/residual_layer.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/model/simulation.h"
#include "test_util.h"

namespace lpoe {
namespace {
namespace compensate_tool_test {

constexpr int kExitOk = 0;
constexpr int kExitInput = 2;
constexpr int kExitNotAllOk = 8;
constexpr double kDeg = 3.14159265358979323846 / 180;
constexpr double kReachedMm = 1e-6;

int RunTool(const std::string& args, std::string* out) {
  return testing::RunCapture(std::string(LPOE_COMPENSATE_PATH) + " " + args, out);
}

// Data rows of a CSV (no comments), split by commas; the header into *header.
std::vector<std::vector<std::string>> ReadCsv(const std::string& path,
                                              std::vector<std::string>* header) {
  std::ifstream in(path);
  std::vector<std::vector<std::string>> rows;
  std::string line;
  bool first = true;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::vector<std::string> f;
    std::stringstream ss(line);
    std::string cell;
    while (std::getline(ss, cell, ',')) f.push_back(cell);
    if (!line.empty() && line.back() == ',') f.push_back("");
    if (first) {
      *header = f;
      first = false;
    } else {
      rows.push_back(f);
    }
  }
  return rows;
}

class CompensateTool : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("lpoe_compensate_test_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::create_directories(dir_);
    nominal_ = MakeCobot6();
    calibrated_ = ApplyErrors(nominal_, RandomErrors(nominal_, 2e-3, 1.0, 2e-3, 0, 3));
    // Registered calibration: the model lives in a tracker frame 2 m away, turned.
    calibrated_.T_measurement_base =
        SE3d(ExpSO3(Eigen::Vector3d(0.1, -0.2, 0.7)), Eigen::Vector3d(2000, -1500, 300));
    calibrated_.joints[0].origin = calibrated_.T_measurement_base * calibrated_.joints[0].origin;
    ASSERT_TRUE(WriteRobotModel(Path("cal.yaml"), calibrated_).ok());
    ASSERT_TRUE(WriteRobotModel(Path("nom.yaml"), nominal_).ok());
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  std::string Path(const std::string& name) const { return (dir_ / name).string(); }
  void Write(const std::string& name, const std::string& text) const {
    std::ofstream(Path(name)) << text;
  }

  std::filesystem::path dir_;
  RobotModel nominal_, calibrated_;
};

TEST_F(CompensateTool, RegistrationRoundTripsThroughTheModelFile) {
  RobotModel read;
  ASSERT_TRUE(ReadRobotModel(Path("cal.yaml"), &read).ok());
  EXPECT_LT((read.T_measurement_base.t - calibrated_.T_measurement_base.t).norm(), 1e-9);
  EXPECT_LT((read.T_measurement_base.R - calibrated_.T_measurement_base.R).norm(), 1e-12);
  RobotModel nominal;
  ASSERT_TRUE(ReadRobotModel(Path("nom.yaml"), &nominal).ok());
  EXPECT_TRUE(nominal.T_measurement_base.R.isIdentity(0));
}

// A calibrated model with a residual layer fitted around one region of the workspace: targets
// there are reached as the layered model predicts; a target far from every configuration the layer
// was identified on is compensated too, with a warning (docs/residual_layer.md).
TEST_F(CompensateTool, ResidualLayerTargetsAndTheFarWarning) {
  RobotModel layered = calibrated_;
  std::vector<double> q;
  std::vector<int> tools;
  std::vector<Eigen::Vector3d> residuals;
  // Around a configuration of the program of TargetsModeMixedRowsInDegrees.
  const double centre[6] = {10 * kDeg, -30 * kDeg, 60 * kDeg, 20 * kDeg, 45 * kDeg, -10 * kDeg};
  for (int i = 0; i < 200; ++i) {
    double qr[6];
    for (int j = 0; j < 6; ++j) qr[j] = centre[j] + 0.4 * std::sin(1.7 * i + 2.3 * j);
    q.insert(q.end(), qr, qr + 6);
    tools.push_back(0);
    residuals.emplace_back(0.05 * std::sin(qr[1] + qr[2]), 0.03 * std::cos(qr[0]), -0.02);
  }
  auto layer = std::make_shared<ResidualLayer>();
  ASSERT_TRUE(
      FitResidualLayer(q, tools, residuals, 6, 1, ResidualLayerOptions(), layer.get()).ok());
  layered.residual_layer = layer;
  ASSERT_TRUE(WriteRobotModel(Path("layered.yaml"), layered).ok());
  // Targets in the measurement frame: what the layered model predicts at two configurations, one
  // inside the region, one far outside it: every joint two of the layer's length scales beyond
  // the data, which span +-0.4 rad about the centre (the fit chooses the length scales, so "far"
  // is measured in them, as the warning is).
  std::vector<std::vector<double>> at(2, std::vector<double>(centre, centre + 6));
  at[0][1] += 0.1;
  for (int j = 0; j < 6; ++j) {
    const double beyond = 0.4 + 2.0 * layer->length_scales(j);
    at[1][j] += j % 2 ? -beyond : beyond;
  }
  ASSERT_LT(layer->KernelDistance(at[0].data()), 3.0);
  ASSERT_GT(layer->KernelDistance(at[1].data()), 3.0);
  std::string csv = "q1,q2,q3,q4,q5,q6,x,y,z\n";
  std::vector<Eigen::Vector3d> targets;
  for (const std::vector<double>& c : at) {
    targets.push_back(PredictToolPosition(layered, c.data(), 0));
    std::ostringstream row;
    row.precision(17);
    for (int j = 0; j < 6; ++j) row << c[j] + 0.02 << ",";  // seeds near the configuration
    row << targets.back()(0) << "," << targets.back()(1) << "," << targets.back()(2) << "\n";
    csv += row.str();
  }
  Write("targets.csv", csv);
  std::string out;
  ASSERT_EQ(RunTool("--model=" + Path("layered.yaml") + " --targets=" + Path("targets.csv") +
                        " --frame=measurement --output=" + Path("out.csv"),
                    &out),
            kExitOk)
      << out;
  EXPECT_NE(out.find("1 of 2 row(s) are far from every configuration the residual layer"),
            std::string::npos)
      << out;
  EXPECT_NE(out.find("first on line 3"), std::string::npos) << out;
  std::vector<std::string> header;
  const auto rows = ReadCsv(Path("out.csv"), &header);
  ASSERT_EQ(rows.size(), 2u);
  EXPECT_EQ(rows[0][6], "ok");
  for (size_t k = 0; k < rows.size(); ++k) {
    EXPECT_NE(rows[k][6], "unreachable") << k;
    double solved[6];
    for (int j = 0; j < 6; ++j) solved[j] = std::stod(rows[k][j]);
    EXPECT_LT((PredictToolPosition(layered, solved, 0) - targets[k]).norm(), 1e-6) << k;
  }
  // Inside the region the layer moved the solution: the parametric model is off there.
  double inside[6];
  for (int j = 0; j < 6; ++j) inside[j] = std::stod(rows[0][j]);
  EXPECT_GT((PredictToolPosition(calibrated_, inside, 0) - targets[0]).norm(), 0.01);
}

TEST_F(CompensateTool, TargetsModeMixedRowsInDegrees) {
  const std::vector<std::vector<double>> program = {{10, -30, 60, 20, 45, -10},
                                                    {-40, -50, 80, -30, 60, 30},
                                                    {70, -20, 40, 10, -50, 90}};
  std::string csv = "q1,q2,q3,q4,q5,q6,x,y,z,quat_x,quat_y,quat_z,quat_w\n";
  std::vector<SE3d> wanted;
  for (size_t k = 0; k < program.size(); ++k) {
    std::vector<double> rad(6);
    for (int j = 0; j < 6; ++j) rad[j] = program[k][j] * kDeg;
    // What the program reaches with the true robot, moved a little: the compensation target.
    rad[1] += 0.01;
    const SE3d T = ToolPose(calibrated_, rad.data());
    wanted.push_back(T);
    // Written in the robot's base frame (--frame=base, the default), where programs live.
    const SE3d Tb = calibrated_.T_measurement_base.Inverse() * T;
    std::ostringstream row;
    row.precision(17);
    for (int j = 0; j < 6; ++j) row << program[k][j] << ",";
    row << Tb.t(0) << "," << Tb.t(1) << "," << Tb.t(2);
    if (k == 1) {  // a pose row
      const Eigen::Vector4d q = RotationToQuaternion<double>(Tb.R);
      row << "," << q(0) << "," << q(1) << "," << q(2) << "," << q(3) << "\n";
    } else {
      row << ",,,,\n";
    }
    csv += row.str();
  }
  Write("targets.csv", csv);
  std::string out;
  ASSERT_EQ(RunTool("--model=" + Path("cal.yaml") + " --targets=" + Path("targets.csv") +
                        " --output=" + Path("out.csv") + " --nominal=" + Path("nom.yaml") +
                        " --angle_unit=deg --report=" + Path("report.json"),
                    &out),
            kExitOk)
      << out;
  std::vector<std::string> header;
  const auto rows = ReadCsv(Path("out.csv"), &header);
  ASSERT_EQ(rows.size(), program.size());
  ASSERT_EQ(header[6], "status");
  ASSERT_EQ(header[9], "corrected_x");
  for (size_t k = 0; k < rows.size(); ++k) {
    std::vector<double> q(6);
    for (int j = 0; j < 6; ++j) q[j] = std::stod(rows[k][j]) * kDeg;
    EXPECT_EQ(rows[k][6], "ok") << "row " << k;
    const SE3d T = ToolPose(calibrated_, q.data());
    EXPECT_LT((T.t - wanted[k].t).norm(), kReachedMm) << "row " << k;
    if (k == 1) {
      EXPECT_LT(LogSO3<double>(T.R * wanted[k].R.transpose()).norm(), 1e-8);
    }
    // corrected_*: the nominal model's tool position at the compensated joints.
    const Eigen::Vector3d corrected(std::stod(rows[k][9]), std::stod(rows[k][10]),
                                    std::stod(rows[k][11]));
    EXPECT_LT((corrected - ToolPosition(nominal_, q.data())).norm(), 1e-9);
    // Orientation columns only on the pose row.
    EXPECT_EQ(rows[k][12].empty(), k != 1) << "row " << k;
  }
  std::ifstream in(Path("report.json"));
  const nlohmann::json report = nlohmann::json::parse(in);
  EXPECT_EQ(report["rows"], 3);
  EXPECT_EQ(report["status_counts"]["ok"], 3);
  EXPECT_NEAR(report["largest_correction"]["value"].get<double>(), 0.01, 0.01);
  EXPECT_NE(out.find("ok 3"), std::string::npos) << out;
  EXPECT_EQ(report["frame"], "base");
  // The same targets read in the measurement frame are metres off: an error naming the frame.
  EXPECT_EQ(RunTool("--model=" + Path("cal.yaml") + " --targets=" + Path("targets.csv") +
                        " --output=" + Path("wrong.csv") + " --angle_unit=deg --frame=measurement",
                    &out),
            2)
      << out;
  EXPECT_NE(out.find("were read in the measurement frame (--frame=measurement)"),
            std::string::npos)
      << out;
  EXPECT_FALSE(std::filesystem::exists(Path("wrong.csv")));
}

TEST_F(CompensateTool, JointProgramModeThroughTheRegistration) {
  const std::vector<std::vector<double>> program = {{0.2, -0.5, 1.0, 0.3, 0.8, -0.2},
                                                    {-0.7, -0.9, 1.4, -0.5, 1.1, 0.6}};
  std::string csv = "# planned with the nominal model\nq1,q2,q3,q4,q5,q6,comment\n";
  for (const auto& q : program) {
    std::ostringstream row;
    row.precision(17);
    for (int j = 0; j < 6; ++j) row << q[j] << ",";
    row << "ignored\n";
    csv += row.str();
  }
  Write("program.csv", csv);
  std::string out;
  ASSERT_EQ(RunTool("--model=" + Path("cal.yaml") + " --joints=" + Path("program.csv") +
                        " --nominal=" + Path("nom.yaml") + " --output=" + Path("out.csv"),
                    &out),
            kExitOk)
      << out;
  std::vector<std::string> header;
  const auto rows = ReadCsv(Path("out.csv"), &header);
  ASSERT_EQ(rows.size(), program.size());
  for (size_t k = 0; k < rows.size(); ++k) {
    std::vector<double> q(6);
    for (int j = 0; j < 6; ++j) q[j] = std::stod(rows[k][j]);
    EXPECT_EQ(rows[k][6], "ok");
    // The calibrated robot reaches, in the measurement frame, the nominal pose carried there by
    // the registration.
    const SE3d want = calibrated_.T_measurement_base * ToolPose(nominal_, program[k].data());
    const SE3d got = ToolPose(calibrated_, q.data());
    EXPECT_LT((got.t - want.t).norm(), kReachedMm);
    EXPECT_LT(LogSO3<double>(got.R * want.R.transpose()).norm(), 1e-8);
    // A real correction, but a small one.
    double change = 0;
    for (int j = 0; j < 6; ++j) change = std::max(change, std::abs(q[j] - program[k][j]));
    EXPECT_GT(change, 1e-4);
    EXPECT_LT(change, 0.05);
  }
}

// A TCP that was never measured, given at compensation time by its offset on the flange.
TEST_F(CompensateTool, TcpGivenByItsOffsetIsTheToolReached) {
  RobotModel with_tcp = calibrated_;
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitX()).toRotationMatrix();
  with_tcp.tools.push_back(Tool{"tcp", SE3d(R, Eigen::Vector3d(10, -20, 150))});
  const int tcp = with_tcp.num_tools() - 1;
  const std::vector<std::vector<double>> seeds = {{0.2, -0.5, 1.0, 0.3, 0.8, -0.2},
                                                  {-0.4, -0.9, 1.3, -0.2, 1.0, 0.5}};
  std::string csv = "q1,q2,q3,q4,q5,q6,x,y,z,quat_x,quat_y,quat_z,quat_w\n";
  std::vector<SE3d> wanted;
  for (const auto& seed : seeds) {
    std::vector<double> q = seed;
    q[2] += 0.02;
    const SE3d T = ToolPose(with_tcp, q.data(), tcp);  // measurement frame
    wanted.push_back(T);
    const Eigen::Vector4d quat = RotationToQuaternion<double>(T.R);
    std::ostringstream row;
    row.precision(17);
    for (double v : seed) row << v << ",";
    row << T.t(0) << "," << T.t(1) << "," << T.t(2) << "," << quat(0) << "," << quat(1) << ","
        << quat(2) << "," << quat(3) << "\n";
    csv += row.str();
  }
  Write("targets.csv", csv);
  std::string out;
  ASSERT_EQ(RunTool("--frame=measurement --tcp=10,-20,150,0.3,0,0 --model=" + Path("cal.yaml") +
                        " --targets=" + Path("targets.csv") + " --output=" + Path("out.csv"),
                    &out),
            kExitOk)
      << out;
  std::vector<std::string> header;
  const auto rows = ReadCsv(Path("out.csv"), &header);
  ASSERT_EQ(rows.size(), seeds.size());
  for (size_t k = 0; k < rows.size(); ++k) {
    std::vector<double> q(6);
    for (int j = 0; j < 6; ++j) q[j] = std::stod(rows[k][j]);
    EXPECT_EQ(rows[k][6], "ok");
    const SE3d T = ToolPose(with_tcp, q.data(), tcp);
    EXPECT_LT((T.t - wanted[k].t).norm(), kReachedMm);
    EXPECT_LT(LogSO3<double>(T.R * wanted[k].R.transpose()).norm(), 1e-8);
    // Not vacuous: tool 0 at those joints is elsewhere.
    EXPECT_GT((ToolPosition(with_tcp, q.data(), 0) - wanted[k].t).norm(), 50.0);
  }
  EXPECT_EQ(RunTool("--tcp=10,20 --model=" + Path("cal.yaml") + " --targets=" +
                        Path("targets.csv") + " --output=" + Path("bad.csv"),
                    &out),
            1);
  EXPECT_EQ(RunTool("--tcp=no_such_tool --model=" + Path("cal.yaml") + " --targets=" +
                        Path("targets.csv") + " --output=" + Path("bad.csv"),
                    &out),
            1);
}

TEST_F(CompensateTool, UnreachableRowIsWrittenAndStrictFails) {
  // Half a metre beyond the arm's reach (in the measurement frame of the calibrated model): an
  // unreachable target, not a frame mistake (those are metres off, CompensateTool.
  // TargetsModeMixedRowsInDegrees).
  const Eigen::Vector3d far = calibrated_.T_measurement_base * Eigen::Vector3d(1500, 0, 400);
  std::ostringstream row;
  row.precision(17);
  row << "q1,q2,q3,q4,q5,q6,x,y,z\n0.2,-0.5,1.0,0.3,0.8,-0.2," << far(0) << "," << far(1) << ","
      << far(2) << "\n";
  Write("targets.csv", row.str());
  const std::string args = "--frame=measurement --model=" + Path("cal.yaml") +
                           " --targets=" + Path("targets.csv") +
                           " --output=" + Path("out.csv");
  std::string out;
  EXPECT_EQ(RunTool(args, &out), kExitOk) << out;
  std::vector<std::string> header;
  auto rows = ReadCsv(Path("out.csv"), &header);
  ASSERT_EQ(rows.size(), 1u);
  EXPECT_EQ(rows[0][6], "unreachable");
  EXPECT_GT(std::stod(rows[0][7]), 100.0);  // residual, mm
  out.clear();
  std::filesystem::remove(Path("out.csv"));
  EXPECT_EQ(RunTool(args + " --strict", &out), kExitNotAllOk) << out;
  rows = ReadCsv(Path("out.csv"), &header);
  EXPECT_EQ(rows.size(), 1u);  // written anyway
  EXPECT_NE(out.find("unreachable 1"), std::string::npos) << out;
}

// The file is solved on several threads in blocks; the output is the same, row for row, whatever
// the thread count (and a bad row late in the file leaves no output behind).
TEST_F(CompensateTool, OutputIndependentOfThreadCount) {
  constexpr int kRows = 3000;
  std::string csv = "q1,q2,q3,q4,q5,q6,x,y,z\n";
  testing::TestRandom rng(7);
  for (int k = 0; k < kRows; ++k) {
    std::vector<double> q = rng.Configuration(nominal_);
    const Eigen::Vector3d p = ToolPosition(calibrated_, q.data());
    for (double v : q) csv += std::to_string(v + 0.01) + ",";
    csv += std::to_string(p(0)) + "," + std::to_string(p(1)) + "," + std::to_string(p(2)) + "\n";
  }
  Write("targets.csv", csv);
  std::string first;
  for (int threads : {1, 2, 3}) {
    const std::string output = Path("out" + std::to_string(threads) + ".csv");
    std::string out;
    ASSERT_EQ(RunTool("--frame=measurement --model=" + Path("cal.yaml") + " --targets=" +
                          Path("targets.csv") +
                          " --output=" + output + " --threads=" + std::to_string(threads),
                      &out),
              kExitOk)
        << out;
    std::vector<std::string> header;
    const auto rows = ReadCsv(output, &header);
    ASSERT_EQ(rows.size(), static_cast<size_t>(kRows));
    std::ifstream in(output);
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    text.erase(0, text.find('\n') + 1);  // the comment names the input, same for all
    if (first.empty()) {
      first = text;
    } else {
      EXPECT_EQ(text, first) << threads << " threads";
    }
  }
  Write("bad.csv", csv + "0,0,0,0,0,0,1,2,oops\n");
  std::string out;
  EXPECT_EQ(RunTool("--model=" + Path("cal.yaml") + " --targets=" + Path("bad.csv") +
                        " --output=" + Path("bad_out.csv") + " --threads=2",
                    &out),
            kExitInput);
  EXPECT_NE(out.find("bad.csv:" + std::to_string(kRows + 2) + ": z 'oops' is not a position"),
            std::string::npos)
      << out;
  EXPECT_FALSE(std::filesystem::exists(Path("bad_out.csv")));
  for (const auto& entry : std::filesystem::directory_iterator(dir_)) {
    EXPECT_EQ(entry.path().filename().string().find(".tmp."), std::string::npos);
  }
}

TEST_F(CompensateTool, BadInputNamesFileAndLine) {
  Write("targets.csv", "q1,q2,q3,q4,q5,q6,x,y,z\n0,0,0,0,0,0,1,2,3\n0,0,zero,0,0,0,1,2,3\n");
  std::string out;
  EXPECT_EQ(RunTool("--model=" + Path("cal.yaml") + " --targets=" + Path("targets.csv") +
                        " --output=" + Path("out.csv"),
                    &out),
            kExitInput);
  EXPECT_NE(out.find("targets.csv:3: q3 'zero' is not a joint value"), std::string::npos) << out;
  EXPECT_FALSE(std::filesystem::exists(Path("out.csv")));
  out.clear();
  EXPECT_EQ(RunTool("--model=" + Path("cal.yaml") + " --joints=" + Path("targets.csv") +
                        " --output=" + Path("out.csv"),
                    &out),
            1)
      << "--joints without --nominal is a usage error: " << out;
}

}  // namespace compensate_tool_test
}  // namespace
}  // namespace lpoe
