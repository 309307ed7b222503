// lpoe_simulate --measurement=ballbar|plane and lpoe_calibrate on their files: default
// flags, exit 0, a model that predicts the simulated robot's tool positions to micrometres after the
// rigid (ballbar) or similarity (planes alone) alignment, the report's table per kind, and bad
// input refused with the file and line and nothing written.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <Eigen/Dense>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "file_util.h"
#include "lpoe/io/io.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/model/residual_layer.h"

#ifndef LPOE_CALIBRATE_PATH
#error "LPOE_CALIBRATE_PATH must name the lpoe_calibrate binary"
#endif
#ifndef LPOE_SIMULATE_PATH
#error "LPOE_SIMULATE_PATH must name the lpoe_simulate binary"
#endif

namespace lpoe {
namespace {
namespace contact_tool_test {

using testing::RunInDir;
using testing::ShellQuote;
using testing::ToolOutput;

// The errors of the test: frames about 1 mm and 3 mrad, joint zeros 0.01 rad.
const char kErrors[] =
    " --errors=random --error_rotation=0.003 --error_translation=1 --error_tilt=0 --error_zero=0.01"
    " --error_seed=5";

class ContactTool : public ::testing::Test {
 protected:
  ToolOutput Run(const std::string& binary, const std::string& args) {
    return RunInDir(dir_.path(), ShellQuote(binary) + " " + args);
  }
  std::string P(const std::string& name) const { return ShellQuote(dir_ / name); }
  void Simulate(const std::string& kind, double noise, const std::string& out) {
    const ToolOutput o = Run(LPOE_SIMULATE_PATH, "--measurement=" + kind + kErrors +
                                                     " --count=300 --seed=3 --noise_sigma=" +
                                                     std::to_string(noise) + " --output=" + P(out) +
                                                     " --model_out=" + P("nominal.yaml") +
                                                     " --actual_out=" + P("actual.yaml"));
    ASSERT_EQ(o.exit_code, 0) << o.err;
  }
  // RMS (mm) of the calibrated model's tool positions from the actual robot's at random
  // configurations, after the best rigid (or similarity) alignment; the similarity's scale too.
  double HeldOutRms(const std::string& calibrated, bool similarity, double* scale) {
    RobotModel cal, actual;
    EXPECT_TRUE(ReadRobotModel(dir_ / calibrated, &cal).ok());
    EXPECT_TRUE(ReadRobotModel(dir_ / "actual.yaml", &actual).ok());
    const int m = 200;
    Eigen::Matrix3Xd A(3, m), B(3, m);
    std::vector<double> q(6);
    for (int i = 0; i < m; ++i) {
      // Configurations spread over the part of the workspace the simulations measure in.
      for (int j = 0; j < 6; ++j) q[j] = std::sin(1.7 * i + 2.3 * j) * (j < 3 ? 0.6 : 1.2);
      q[1] += -0.4;
      q[2] += 1.0;
      q[4] += 0.8;
      A.col(i) = PredictToolPosition(cal, q.data(), 0);  // with the models' joint-space terms
      B.col(i) = PredictToolPosition(actual, q.data(), 0);
    }
    const Eigen::Matrix4d T = Eigen::umeyama(A, B, similarity);
    *scale = std::cbrt(T.topLeftCorner<3, 3>().determinant());
    const Eigen::Matrix3Xd moved = (T.topLeftCorner<3, 3>() * A).colwise() + T.topRightCorner<3, 1>();
    return std::sqrt((moved - B).colwise().squaredNorm().mean());
  }
  nlohmann::json Report() {
    std::ifstream in(dir_ / "report.json");
    return nlohmann::json::parse(in);
  }

  testing::TempDir dir_{"lpoe_contact_tool"};
};

TEST_F(ContactTool, BallbarWithDefaultFlags) {
  Simulate("ballbar", 0.002, "bar.csv");
  const ToolOutput o = Run(LPOE_CALIBRATE_PATH, "--model=" + P("nominal.yaml") +
                                                    " --measurements=" + P("bar.csv") +
                                                    " --output=" + P("cal.yaml") +
                                                    " --report=" + P("report.json"));
  ASSERT_EQ(o.exit_code, 0) << o.err << o.out;
  EXPECT_NE(o.out.find("do not see the robot's base relative to the pivots"), std::string::npos)
      << o.out;
  double scale = 0;
  double nominal_scale = 0;
  const double e = HeldOutRms("cal.yaml", false, &scale);
  const double e0 = HeldOutRms("nominal.yaml", false, &nominal_scale);
  EXPECT_LT(e, 0.01) << "mm; the nominal model: " << e0;
  EXPECT_GT(e0, 0.5);
  const nlohmann::json r = Report();
  ASSERT_EQ(r["measurement_kinds"].size(), 1u);
  EXPECT_EQ(r["measurement_kinds"][0]["kind"], "distance");
  EXPECT_EQ(r["measurement_kinds"][0]["verdict"], "pass");
  EXPECT_EQ(r["base"]["directions_left_out"], 6);
  EXPECT_EQ(r["scale"]["held"], false);
  EXPECT_EQ(r["features"]["pivots"].size(), 3u);
}

TEST_F(ContactTool, PlanesAloneHoldTheScale) {
  Simulate("plane", 0.003, "cube.csv");
  const ToolOutput o = Run(LPOE_CALIBRATE_PATH, "--model=" + P("nominal.yaml") +
                                                    " --measurements=" + P("cube.csv") +
                                                    " --solver=ceres --output=" + P("cal.yaml") +
                                                    " --report=" + P("report.json"));
  ASSERT_EQ(o.exit_code, 0) << o.err << o.out;
  EXPECT_NE(o.out.find("no row measures a length"), std::string::npos) << o.out;
  double scale = 0;
  const double e = HeldOutRms("cal.yaml", true, &scale);
  EXPECT_LT(e, 0.02);
  EXPECT_NEAR(scale, 1.0, 0.03);
  const nlohmann::json r = Report();
  EXPECT_EQ(r["scale"]["held"], true);
  EXPECT_EQ(r["measurement_kinds"][0]["kind"], "plane");
  EXPECT_EQ(r["features"]["planes"].size(), 3u);
}

TEST_F(ContactTool, BallbarAndPlanesEachWithItsNoise) {
  Simulate("ballbar", 0.002, "bar.csv");
  Simulate("plane", 0.003, "cube.csv");
  // The files' sigma columns dropped: the noise per file from --sigmas.
  for (const char* name : {"bar.csv", "cube.csv"}) {
    std::ifstream in(dir_ / name);
    std::string text, line;
    while (std::getline(in, line)) {
      if (!line.empty() && line[0] != '#') line = line.substr(0, line.rfind(','));
      text += line + "\n";
    }
    std::ofstream(dir_ / (std::string("plain_") + name)) << text;
  }
  const ToolOutput bad = Run(LPOE_CALIBRATE_PATH, "--model=" + P("nominal.yaml") +
                                                      " --measurements=" + P("plain_bar.csv") + "," +
                                                      P("plain_cube.csv") + " --output=" + P("cal.yaml"));
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_NE(bad.err.find("plain_bar.csv:3: no 'sigma' column and no noise given"), std::string::npos)
      << bad.err;
  EXPECT_FALSE(std::ifstream(dir_ / "cal.yaml").good());
  const ToolOutput o = Run(LPOE_CALIBRATE_PATH,
                           "--model=" + P("nominal.yaml") + " --measurements=" + P("plain_bar.csv") +
                               "," + P("plain_cube.csv") + " --sigmas=0.002,0.003 --output=" +
                               P("cal.yaml") + " --report=" + P("report.json") + " --holdout=0.2");
  ASSERT_EQ(o.exit_code, 0) << o.err << o.out;
  double scale = 0;
  EXPECT_LT(HeldOutRms("cal.yaml", false, &scale), 0.01);
  const nlohmann::json r = Report();
  ASSERT_EQ(r["measurement_kinds"].size(), 2u);
  for (const nlohmann::json& k : r["measurement_kinds"]) {
    EXPECT_EQ(k["verdict"], "pass") << k.dump();
    EXPECT_GT(k["held_out_rows"].get<int>(), 0);
    EXPECT_LT(k["held_out_rms_mm"].get<double>(), 3 * k["expected_noise_mm"].get<double>());
  }
  EXPECT_EQ(r["scale"]["held"], false);
}

// Tracker positions and ballbar distances together: the tracker sees the base, so nothing is left
// out, and the pivots are estimated in the tracker's frame.
TEST_F(ContactTool, TrackerAndBallbar) {
  testing::ScopedToolLeakCheck leak_check;  // the contact kinds' paths, with the leak check at exit
  Simulate("ballbar", 0.002, "bar.csv");
  Simulate("position", 0.03, "track.csv");
  const ToolOutput o = Run(LPOE_CALIBRATE_PATH, "--model=" + P("nominal.yaml") + " --measurements=" +
                                                    P("track.csv") + "," + P("bar.csv") +
                                                    " --sigmas=0.03,0.002 --output=" + P("cal.yaml") +
                                                    " --report=" + P("report.json"));
  ASSERT_EQ(o.exit_code, 0) << o.err << o.out;
  double scale = 0;
  EXPECT_LT(HeldOutRms("cal.yaml", false, &scale), 0.01);
  const nlohmann::json r = Report();
  EXPECT_EQ(r["base"]["directions_left_out"], 0);
  EXPECT_EQ(r["measurement_kinds"].size(), 2u);
  EXPECT_EQ(r["measurement_kinds"][0]["kind"], "position");
}

#ifdef LPOE_COMPARE_PATH
// lpoe_compare: the two solvers agree on ballbar and probe data together.
TEST_F(ContactTool, CompareAgrees) {
  Simulate("ballbar", 0.002, "bar.csv");
  Simulate("plane", 0.003, "cube.csv");
  const ToolOutput o = Run(LPOE_COMPARE_PATH, "--model=" + P("nominal.yaml") + " --measurements=" +
                                                  P("bar.csv") + "," + P("cube.csv") +
                                                  " --tolerance_mm=1e-4");
  EXPECT_EQ(o.exit_code, 0) << o.err << o.out;
  EXPECT_NE(o.out.find("largest difference of the predicted tool points"), std::string::npos) << o.out;
}
#endif

// --joint_errors=harmonics with ballbar data: the calibrated YAML carries the term (its
// joint_errors section), the report names its values and the combinations left out, lpoe_compare
// with the same term finds both solvers agreeing.
TEST_F(ContactTool, BallbarWithJointErrors) {
  Simulate("ballbar", 0.002, "bar.csv");
  const ToolOutput o = Run(LPOE_CALIBRATE_PATH,
                           "--model=" + P("nominal.yaml") + " --measurements=" + P("bar.csv") +
                               " --joint_errors=harmonics --output=" + P("cal.yaml") +
                               " --report=" + P("report.json") + " --html_report=" + P("r.html"));
  ASSERT_EQ(o.exit_code, 0) << o.err << o.out;
  {
    std::ifstream html(dir_ / "r.html");
    const std::string page((std::istreambuf_iterator<char>(html)), std::istreambuf_iterator<char>());
    EXPECT_NE(page.find("Joint-space term harmonics: joint1.sin1 = "), std::string::npos);
  }
  EXPECT_NE(o.out.find("joint-space term harmonics: "), std::string::npos) << o.out;
  RobotModel cal;
  ASSERT_TRUE(ReadRobotModel(dir_ / "cal.yaml", &cal).ok());
  EXPECT_EQ(cal.joint_errors.Values("harmonics").size(),
            static_cast<size_t>(NumHarmonicsParameters(6)));
  std::ifstream in(dir_ / "report.json");
  const nlohmann::json r = nlohmann::json::parse(in);
  ASSERT_EQ(r["joint_errors"].size(), 1u) << r.dump();
  EXPECT_EQ(r["joint_errors"][0]["term"], "harmonics");
  EXPECT_EQ(r["joint_errors"][0]["values"].size(), static_cast<size_t>(NumHarmonicsParameters(6)));
  // The distances are fitted to their noise (the verdict per kind).
  EXPECT_EQ(r["measurement_kinds"][0]["verdict"], "pass") << r.dump();
  const ToolOutput u = Run(LPOE_CALIBRATE_PATH, "--model=" + P("nominal.yaml") +
                                                    " --measurements=" + P("bar.csv") +
                                                    " --joint_errors=harmonics --urdf_output=" +
                                                    P("cal.urdf"));
  EXPECT_EQ(u.exit_code, 1) << u.err;
  EXPECT_NE(u.err.find("cannot hold the joint-space terms"), std::string::npos) << u.err;
#ifdef LPOE_COMPARE_PATH
  // Both terms: both solvers converge and agree (the linear solver stops at the minimum to
  // round-off, where its Gauss-Newton step's promise can be round-off too).
  const ToolOutput c = Run(LPOE_COMPARE_PATH,
                           "--model=" + P("nominal.yaml") + " --measurements=" + P("bar.csv") +
                               " --joint_errors=compliance,harmonics --tolerance_mm=1e-4");
  EXPECT_EQ(c.exit_code, 0) << c.err << c.out;
#endif
}

// lpoe_simulate --measurement=ballbar --joint_errors=harmonics: the actual robot carries the
// simulator's harmonics (5-30 arcsec each) and the distances are read at its effective joints.
// lpoe_calibrate --joint_errors=harmonics on that file recovers the term: the calibrated model's
// tool positions (with its term) match the actual robot's to micrometres after the rigid
// alignment, several times better than the geometric calibration of the same file. (The term's
// values themselves are not compared: the combinations the rows cannot tell from the geometry are
// left out, and others trade with the frames.)
TEST_F(ContactTool, SimulatedJointErrorsRecovered) {
  const ToolOutput s = Run(LPOE_SIMULATE_PATH, std::string("--measurement=ballbar") + kErrors +
                                                   " --joint_errors=harmonics --count=300 --seed=3"
                                                   " --noise_sigma=0.002 --output=" + P("bar.csv") +
                                                   " --model_out=" + P("nominal.yaml") +
                                                   " --actual_out=" + P("actual.yaml"));
  ASSERT_EQ(s.exit_code, 0) << s.err;
  RobotModel actual;
  ASSERT_TRUE(ReadRobotModel(dir_ / "actual.yaml", &actual).ok());
  ASSERT_TRUE(actual.joint_errors.Has("harmonics"));
  for (const char* terms : {"harmonics", "none"}) {
    const ToolOutput o = Run(LPOE_CALIBRATE_PATH,
                             "--model=" + P("nominal.yaml") + " --measurements=" + P("bar.csv") +
                                 " --joint_errors=" + terms + " --output=" +
                                 P(std::string(terms) + ".yaml"));
    ASSERT_EQ(o.exit_code, 0) << o.err << o.out;
  }
  double scale = 0;
  const double e_term = HeldOutRms("harmonics.yaml", false, &scale);
  const double e_geometric = HeldOutRms("none.yaml", false, &scale);
  ::testing::Test::RecordProperty("held_out_rms_nm", static_cast<int>(1e6 * e_term));
  ::testing::Test::RecordProperty("geometric_rms_nm", static_cast<int>(1e6 * e_geometric));
  EXPECT_LT(e_term, 0.01) << "mm";
  EXPECT_LT(3 * e_term, e_geometric) << "with the term " << e_term << " mm, without " << e_geometric;
  // --joint_errors=auto on the same file: the cross-validation's table on stderr, the choice in
  // the report, and the true term among the chosen.
  const ToolOutput a = Run(LPOE_CALIBRATE_PATH,
                           "--model=" + P("nominal.yaml") + " --measurements=" + P("bar.csv") +
                               " --joint_errors=auto --output=" + P("auto.yaml") +
                               " --report=" + P("report.json"));
  ASSERT_EQ(a.exit_code, 0) << a.err << a.out;
  EXPECT_NE(a.err.find("joint errors (auto): 5-fold cross-validation"), std::string::npos) << a.err;
  const nlohmann::json r = Report();
  const std::string chosen = r["joint_error_selection"]["chosen"];
  ::testing::Test::RecordProperty("auto_chosen", chosen);
  EXPECT_NE(chosen.find("harmonics"), std::string::npos) << a.err;
  EXPECT_EQ(r["joint_error_selection"]["candidates"].size(), size_t{1} << JointTermNames().size());
  EXPECT_LT(HeldOutRms("auto.yaml", false, &scale), 0.01) << "mm";
}

// --verify with a ballbar file of the same pivots (another seed, the same robot): its table per
// kind in the report, fitting to the noise; --kfold's cross-validated RMS per kind; a pivot the
// calibration does not estimate refused, naming it, nothing written.
TEST_F(ContactTool, VerifyAndKfold) {
  Simulate("ballbar", 0.002, "bar.csv");
  Simulate("plane", 0.003, "cube.csv");
  ToolOutput o = Run(LPOE_SIMULATE_PATH, std::string("--measurement=ballbar") + kErrors +
                                             " --count=100 --seed=9 --noise_sigma=0.002 --output=" +
                                             P("verify.csv"));
  ASSERT_EQ(o.exit_code, 0) << o.err;
  o = Run(LPOE_CALIBRATE_PATH, "--model=" + P("nominal.yaml") + " --measurements=" + P("bar.csv") +
                                   "," + P("cube.csv") + " --verify=" + P("verify.csv") +
                                   " --kfold=4 --output=" + P("cal.yaml") + " --report=" +
                                   P("report.json"));
  ASSERT_EQ(o.exit_code, 0) << o.err << o.out;
  EXPECT_NE(o.out.find("verify RMS"), std::string::npos) << o.out;
  const nlohmann::json r = Report();
  ASSERT_EQ(r["measurement_kinds"].size(), 2u);
  const nlohmann::json& bar = r["measurement_kinds"][0];
  const nlohmann::json& cube = r["measurement_kinds"][1];
  ASSERT_EQ(bar["kind"], "distance");
  ASSERT_TRUE(bar.contains("verification")) << bar.dump();
  EXPECT_EQ(bar["verification"]["source"], "verify");
  EXPECT_EQ(bar["verification"]["rows"], 100);
  EXPECT_EQ(bar["verification"]["verdict"], "pass");
  // The calibrated robot predicts new distances to their noise (the nominal one: to millimetres).
  EXPECT_LT(bar["verification"]["rms_mm"].get<double>(), 1.5 * 0.002);
  EXPECT_FALSE(cube.contains("verification"));  // no plane rows verified
  for (const nlohmann::json* k : {&bar, &cube}) {
    ASSERT_TRUE(k->contains("kfold")) << k->dump();
    EXPECT_EQ((*k)["kfold"]["folds"], 4);
    EXPECT_EQ((*k)["kfold"]["rows"], (*k)["rows"]);
    // Each fold's rows predicted by the others' calibration: near the noise, not below half of it.
    const double cv = (*k)["kfold"]["rms_mm"].get<double>();
    const double sigma = (*k)["expected_noise_mm"].get<double>();
    EXPECT_LT(cv, 1.5 * sigma) << k->dump();
    EXPECT_GT(cv, 0.5 * sigma) << k->dump();
  }
  // A pivot the calibration does not estimate.
  std::ofstream(dir_ / "other.csv") << "q1,q2,q3,q4,q5,q6,distance,pivot,sigma\n"
                                       "0,0,0,0,0,0,150,elsewhere,0.002\n";
  o = Run(LPOE_CALIBRATE_PATH, "--model=" + P("nominal.yaml") + " --measurements=" + P("bar.csv") +
                                   " --verify=" + P("other.csv") + " --output=" + P("cal2.yaml"));
  EXPECT_EQ(o.exit_code, 2);
  EXPECT_NE(o.err.find("--verify names a pivot or plane that --measurements does not"),
            std::string::npos)
      << o.err;
  EXPECT_NE(o.err.find("elsewhere"), std::string::npos) << o.err;
  EXPECT_FALSE(std::ifstream(dir_ / "cal2.yaml").good());
  o = Run(LPOE_CALIBRATE_PATH, "--model=" + P("nominal.yaml") + " --measurements=" + P("bar.csv") +
                                   " --verify=" + P("verify.csv") + " --holdout=0.2");
  EXPECT_EQ(o.exit_code, 1);
  EXPECT_NE(o.err.find("either --verify or --holdout"), std::string::npos) << o.err;
}

// --residual_model=gp with ballbar rows: the layer is fitted on the rows' projections, written in
// the YAML (read back as any layer), and the report gives the held-out figures without and with it
// (the simulated arm is geometric: the layer must not make the held-out rows worse).
TEST_F(ContactTool, ResidualLayerFromBallbar) {
  Simulate("ballbar", 0.002, "bar.csv");
  const ToolOutput o = Run(LPOE_CALIBRATE_PATH, "--model=" + P("nominal.yaml") +
                                                    " --measurements=" + P("bar.csv") +
                                                    " --residual_model=gp --holdout=0.3"
                                                    " --output=" + P("cal.yaml") + " --report=" +
                                                    P("report.json"));
  ASSERT_EQ(o.exit_code, 0) << o.err << o.out;
  EXPECT_NE(o.out.find("residual layer: Gaussian process on projected rows"), std::string::npos)
      << o.out;
  EXPECT_NE(o.out.find("held-out RMS"), std::string::npos) << o.out;
  const nlohmann::json r = Report();
  const nlohmann::json& layer = r["residual_layer"];
  ASSERT_TRUE(layer["fitted"].get<bool>()) << layer.dump();
  EXPECT_EQ(layer["layer"]["observations"], "projected");
  ASSERT_EQ(layer["kinds"].size(), 1u);
  const nlohmann::json& bar = layer["kinds"][0];
  EXPECT_EQ(bar["kind"], "distance");
  const double without = bar["held_out_rms_mm_without_layer"].get<double>();
  const double with = bar["held_out_rms_mm_with_layer"].get<double>();
  EXPECT_EQ(with, r["measurement_kinds"][0]["held_out_rms_mm"].get<double>());
  EXPECT_LE(with, 1.01 * without) << bar.dump();
  RobotModel cal;
  ASSERT_TRUE(ReadRobotModel(dir_ / "cal.yaml", &cal).ok());
  ASSERT_TRUE(cal.residual_layer);
  EXPECT_EQ(cal.residual_layer->num_inducing(), layer["layer"]["inducing"].get<int>());
  EXPECT_TRUE(layer["selection"].is_null());
  // auto: the cross-validation's table; on a geometric arm the simpler candidate, none.
  const ToolOutput a = Run(LPOE_CALIBRATE_PATH, "--model=" + P("nominal.yaml") +
                                                    " --measurements=" + P("bar.csv") +
                                                    " --residual_model=auto --report=" +
                                                    P("auto.json"));
  ASSERT_EQ(a.exit_code, 0) << a.err << a.out;
  EXPECT_NE(a.out.find("residual model (auto): 5-fold cross-validation"), std::string::npos)
      << a.out;
  std::ifstream in(dir_ / "auto.json");
  const nlohmann::json ra = nlohmann::json::parse(in);
  const nlohmann::json& sel = ra["residual_layer"]["selection"];
  ASSERT_EQ(sel["candidates"].size(), 2u) << sel.dump();
  EXPECT_EQ(sel["candidates"][sel["chosen"].get<int>()]["model"], "none") << sel.dump();
  EXPECT_FALSE(ra["residual_layer"]["fitted"].get<bool>());
}

// The URDF output of a ballbar calibration predicts what the calibrated YAML does.
TEST_F(ContactTool, UrdfOutputIsTheCalibratedModel) {
  Simulate("ballbar", 0.002, "bar.csv");
  const ToolOutput o = Run(LPOE_CALIBRATE_PATH, "--model=" + P("nominal.yaml") +
                                                    " --measurements=" + P("bar.csv") +
                                                    " --output=" + P("cal.yaml") +
                                                    " --urdf_output=" + P("cal.urdf"));
  ASSERT_EQ(o.exit_code, 0) << o.err << o.out;
  RobotModel yaml, urdf, nominal;
  ASSERT_TRUE(ReadRobotModel(dir_ / "cal.yaml", &yaml).ok());
  ASSERT_TRUE(ReadRobotModelFile(dir_ / "cal.urdf", &urdf).ok());
  ASSERT_TRUE(ReadRobotModel(dir_ / "nominal.yaml", &nominal).ok());
  double worst = 0, moved = 0;
  for (int i = 0; i < 20; ++i) {
    std::vector<double> q(6);
    for (int j = 0; j < 6; ++j) q[j] = std::sin(0.9 * i + 1.3 * j);
    worst = std::max(worst, (ToolPosition(yaml, q.data()) - ToolPosition(urdf, q.data())).norm());
    moved = std::max(moved, (ToolPosition(yaml, q.data()) - ToolPosition(nominal, q.data())).norm());
  }
  EXPECT_LT(worst, 1e-6);  // mm
  EXPECT_GT(moved, 0.1);   // the calibration changed the model
}

#ifdef LPOE_PLAN_PATH
// lpoe_plan --measurement=ballbar: 40 poses on the pivots' spheres within the stroke; the distances
// measured there (on the simulated robot, noise 0.002 mm) calibrate it with lpoe_calibrate to
// micrometres. Refusals with their reasons, nothing written.
TEST_F(ContactTool, PlanBallbarThenCalibrate) {
  Simulate("ballbar", 0.002, "bar.csv");
  // The simulation's pivots, from its comment line: "... pivots (x y z) (x y z) (x y z)".
  std::vector<Eigen::Vector3d> pivots;
  {
    std::ifstream in(dir_ / "bar.csv");
    for (std::string line; std::getline(in, line);) {
      const size_t at = line.find("pivots (");
      if (at == std::string::npos) continue;
      std::stringstream ss(line.substr(at + 7));
      char open, close;
      Eigen::Vector3d c;
      while (ss >> open >> c(0) >> c(1) >> c(2) >> close) pivots.push_back(c);
    }
  }
  ASSERT_EQ(pivots.size(), 3u);
  std::string flag;
  for (const Eigen::Vector3d& c : pivots) {
    // As set up: a couple of millimetres off.
    flag += (flag.empty() ? "" : ";") + std::to_string(c(0) + 2) + "," + std::to_string(c(1) - 1) +
            "," + std::to_string(c(2) + 1.5);
  }
  ToolOutput o = Run(LPOE_PLAN_PATH, "--model=" + P("nominal.yaml") +
                                         " --measurement=ballbar --pivots='" + flag +
                                         "' --count=40 --output=" + P("plan.csv"));
  ASSERT_EQ(o.exit_code, 0) << o.err;
  RobotModel nominal, actual;
  ASSERT_TRUE(ReadRobotModel(dir_ / "nominal.yaml", &nominal).ok());
  ASSERT_TRUE(ReadRobotModel(dir_ / "actual.yaml", &actual).ok());
  std::ifstream plan(dir_ / "plan.csv");
  std::ofstream measured(dir_ / "measured.csv");
  measured << "q1,q2,q3,q4,q5,q6,pivot,distance,sigma\n";
  int rows = 0;
  for (std::string line; std::getline(plan, line);) {
    if (line.empty() || line[0] == '#' || line[0] == 'q') continue;
    std::vector<std::string> cells;
    std::stringstream ss(line);
    for (std::string c; std::getline(ss, c, ',');) cells.push_back(c);
    ASSERT_EQ(cells.size(), 7u) << line;
    std::vector<double> q(6);
    for (int j = 0; j < 6; ++j) q[j] = std::stod(cells[j]);
    const int k = cells[6].back() - '1';
    ASSERT_TRUE(k >= 0 && k < 3) << cells[6];
    // On the nominal robot the ball sits on the sphere around the pivot given, within the stroke.
    const Eigen::Vector3d given = pivots[k] + Eigen::Vector3d(2, -1, 1.5);
    EXPECT_LE(std::abs((ToolPosition(nominal, q.data()) - given).norm() - 150), 1.0) << line;
    // What the bar reads on the robot as it is: +-0.002 mm in turn for the noise.
    const double d = (ToolPosition(actual, q.data()) - pivots[k]).norm() + (rows % 2 ? 0.002 : -0.002);
    char text[64];
    std::snprintf(text, sizeof(text), "%.6f", d);
    measured << line << "," << text << ",0.002\n";
    ++rows;
  }
  measured.close();
  EXPECT_EQ(rows, 40);
  o = Run(LPOE_CALIBRATE_PATH, "--model=" + P("nominal.yaml") + " --measurements=" +
                                   P("measured.csv") + " --output=" + P("cal.yaml"));
  ASSERT_EQ(o.exit_code, 0) << o.err << o.out;
  double scale = 0;
  const double e = HeldOutRms("cal.yaml", false, &scale);
  const double e0 = HeldOutRms("nominal.yaml", false, &scale);
  EXPECT_LT(e, 0.01) << "mm; the nominal model: " << e0;
  EXPECT_GT(e0, 0.5);
  RecordProperty("held_out_rms_um", std::to_string(1000 * e));

  // Refusals: no pivots (exit 1), fewer poses than parameters (exit 3); nothing written.
  o = Run(LPOE_PLAN_PATH, "--model=" + P("nominal.yaml") + " --measurement=ballbar --count=40 " +
                              "--output=" + P("plan2.csv"));
  EXPECT_EQ(o.exit_code, 1);
  EXPECT_NE(o.err.find("--measurement=ballbar needs --pivots"), std::string::npos) << o.err;
  o = Run(LPOE_PLAN_PATH, "--model=" + P("nominal.yaml") + " --measurement=ballbar --pivots='" +
                              flag + "' --count=10 --output=" + P("plan2.csv"));
  EXPECT_EQ(o.exit_code, 3);
  EXPECT_NE(o.err.find("plan more poses than parameters"), std::string::npos) << o.err;
  o = Run(LPOE_PLAN_PATH, "--model=" + P("nominal.yaml") + " --measurement=ballbar --pivots='" +
                              flag + "' --count=40 --criterion=A --output=" + P("plan2.csv"));
  EXPECT_EQ(o.exit_code, 1);
  EXPECT_NE(o.err.find("--criterion is for tracker plans"), std::string::npos) << o.err;
  EXPECT_FALSE(std::ifstream(dir_ / "plan2.csv").good());
  EXPECT_FALSE(std::ifstream(dir_ / "plan2.json").good());
}

// lpoe_plan --measurement=plane: 40 probe contacts on the simulated cube's three faces (the
// planes as lpoe_simulate placed them), every tip one probe radius off its face and within the
// face's circle, every face touched, more information than random plans of as many.
TEST_F(ContactTool, PlanProbeOnTheCubeFaces) {
  Simulate("plane", 0.003, "cube.csv");
  // "... planes n.x = d: (nx ny nz d) (nx ny nz d) (nx ny nz d)".
  std::vector<Eigen::Vector4d> planes;
  {
    std::ifstream in(dir_ / "cube.csv");
    for (std::string line; std::getline(in, line);) {
      const size_t at = line.find("n.x = d: (");
      if (at == std::string::npos) continue;
      std::stringstream ss(line.substr(at + 9));
      char open, close;
      Eigen::Vector4d pl;
      while (ss >> open >> pl(0) >> pl(1) >> pl(2) >> pl(3) >> close) planes.push_back(pl);
    }
  }
  ASSERT_EQ(planes.size(), 3u);
  // The cube of 100 mm behind its +x, +y, +z faces: each face's centre.
  const Eigen::Vector3d corner(planes[0](3), planes[1](3), planes[2](3));
  std::string plane_flag, centre_flag;
  std::vector<Eigen::Vector3d> centres;
  for (int k = 0; k < 3; ++k) {
    Eigen::Vector3d c = corner - Eigen::Vector3d(50, 50, 50);
    c(k) = corner(k);
    centres.push_back(c);
    plane_flag += (k ? ";" : "") + std::to_string(planes[k](0)) + "," +
                  std::to_string(planes[k](1)) + "," + std::to_string(planes[k](2)) + "," +
                  std::to_string(planes[k](3));
    centre_flag += (k ? ";" : "") + std::to_string(c(0)) + "," + std::to_string(c(1)) + "," +
                   std::to_string(c(2));
  }
  const ToolOutput o = Run(LPOE_PLAN_PATH, "--model=" + P("nominal.yaml") +
                                               " --measurement=plane --planes='" + plane_flag +
                                               "' --face_centres='" + centre_flag +
                                               "' --count=40 --output=" + P("probe.csv"));
  ASSERT_EQ(o.exit_code, 0) << o.err;
  RobotModel nominal;
  ASSERT_TRUE(ReadRobotModel(dir_ / "nominal.yaml", &nominal).ok());
  std::ifstream plan(dir_ / "probe.csv");
  int rows = 0;
  for (std::string line; std::getline(plan, line);) {
    if (line.empty() || line[0] == '#' || line[0] == 'q') continue;
    std::vector<std::string> cells;
    std::stringstream ss(line);
    for (std::string c; std::getline(ss, c, ',');) cells.push_back(c);
    ASSERT_EQ(cells.size(), 8u) << line;
    std::vector<double> q(6);
    for (int j = 0; j < 6; ++j) q[j] = std::stod(cells[j]);
    const int k = cells[6] == "face_x" ? 0 : cells[6] == "face_y" ? 1 : cells[6] == "face_z" ? 2 : -1;
    ASSERT_GE(k, 0) << cells[6];
    EXPECT_EQ(std::stod(cells[7]), 3.0);
    const Eigen::Vector3d p = ToolPosition(nominal, q.data());
    EXPECT_NEAR(planes[k].head<3>().dot(p) - planes[k](3), 3.0, 1e-4) << line;
    const Eigen::Vector3d on_face = p - 3.0 * planes[k].head<3>();
    EXPECT_LE((on_face - centres[k]).norm(), 40.0 + 1e-4) << line;
    ++rows;
  }
  EXPECT_EQ(rows, 40);
  std::ifstream in(dir_ / "probe.json");
  const nlohmann::json r = nlohmann::json::parse(in);
  EXPECT_EQ(r["poses_per_feature"].size(), 3u) << r.dump();
  EXPECT_GT(r["plan"]["D_log_det"].get<double>(), r["random_plans"]["best_D_log_det"].get<double>());
}
#endif

TEST_F(ContactTool, BadRowsNameFileAndLine) {
  Simulate("ballbar", 0.002, "bar.csv");
  std::ofstream(dir_ / "broken.csv") << "q1,q2,q3,q4,q5,q6,distance,sigma\n0,0,0,0,0,0,150,0.002\n"
                                        "0,0,0,0,0,0,-3,0.002\n";
  const ToolOutput o = Run(LPOE_CALIBRATE_PATH, "--model=" + P("nominal.yaml") +
                                                    " --measurements=" + P("broken.csv") +
                                                    " --output=" + P("cal.yaml"));
  EXPECT_EQ(o.exit_code, 2);
  EXPECT_NE(o.err.find("broken.csv:3: column 'distance'"), std::string::npos) << o.err;
  EXPECT_FALSE(std::ifstream(dir_ / "cal.yaml").good());
  // The gravity tilt: refused with its reason, nothing written.
  for (const char* flag : {"--joint_errors=compliance,tilt"}) {
    const ToolOutput u = Run(LPOE_CALIBRATE_PATH, "--model=" + P("nominal.yaml") +
                                                      " --measurements=" + P("bar.csv") + " " +
                                                      flag + " --output=" + P("cal.yaml"));
    EXPECT_EQ(u.exit_code, 1) << flag;
    EXPECT_NE(u.err.find("not available with distance or plane data: "), std::string::npos)
        << u.err;
    EXPECT_GT(u.err.size(), 150u) << u.err;
    EXPECT_FALSE(std::ifstream(dir_ / "cal.yaml").good());
  }
  // Every refused flag says why.
  for (const char* flag : {"--loss=huber", "--fixed_tools=tool0", "--parameterization=full"}) {
    const ToolOutput v = Run(LPOE_CALIBRATE_PATH, "--model=" + P("nominal.yaml") +
                                                      " --measurements=" + P("bar.csv") + " " +
                                                      flag + " --output=" + P("cal.yaml"));
    EXPECT_EQ(v.exit_code, 1) << flag;
    const std::string name = std::string(flag).substr(0, std::string(flag).find('='));
    EXPECT_NE(v.err.find(name + " is not available with distance or plane data: "),
              std::string::npos)
        << v.err;
    // The reason: more than the reference to the docs.
    EXPECT_GT(v.err.size(), name.size() + 120) << v.err;
    EXPECT_FALSE(std::ifstream(dir_ / "cal.yaml").good());
  }
}


// The report's error table per pivot and per plane and its plot: one pivot's rows disturbed by
// +-0.02 mm (ten times the bar's noise) stand out in its own figures while the other pivots and the
// planes stay at their noise; the figures per feature add up to the kind's; the HTML carries the
// table and the picture.
TEST_F(ContactTool, ReportTablesPerPivotAndPlane) {
  Simulate("ballbar", 0.002, "bar.csv");
  Simulate("plane", 0.003, "cube.csv");
  {
    std::ifstream in(dir_ / "bar.csv");
    std::string text, line;
    int disturbed = 0;
    while (std::getline(in, line)) {
      // q1..q6,distance,pivot,target,sigma: pivot2's distances moved by +-0.02 mm in turn.
      std::vector<std::string> cells;
      std::stringstream ss(line);
      for (std::string c; std::getline(ss, c, ',');) cells.push_back(c);
      if (line[0] != '#' && cells.size() == 10 && cells[7] == "pivot2") {
        cells[6] = std::to_string(std::stod(cells[6]) + (disturbed++ % 2 ? 0.02 : -0.02));
        line.clear();
        for (size_t i = 0; i < cells.size(); ++i) line += (i ? "," : "") + cells[i];
      }
      text += line + "\n";
    }
    ASSERT_GT(disturbed, 50);
    std::ofstream(dir_ / "bar.csv") << text;
  }
  const ToolOutput o = Run(LPOE_CALIBRATE_PATH,
                           "--model=" + P("nominal.yaml") + " --measurements=" + P("bar.csv") +
                               "," + P("cube.csv") + " --holdout=0.2 --kfold=3 --output=" +
                               P("cal.yaml") + " --report=" + P("report.json") +
                               " --html_report=" + P("report.html"));
  ASSERT_EQ(o.exit_code, 0) << o.err << o.out;
  const nlohmann::json r = Report();
  ASSERT_EQ(r["measurement_kinds"].size(), 2u);
  std::map<std::string, double> rms;
  for (const nlohmann::json& k : r["measurement_kinds"]) {
    ASSERT_TRUE(k.contains("features")) << k.dump();
    const nlohmann::json& features = k["features"];
    ASSERT_EQ(features.size(), 3u) << k.dump();  // three pivots, three faces of the cube
    int rows = 0, held = 0;
    double sum = 0, held_sum = 0, max_abs = 0;
    for (const nlohmann::json& f : features) {
      rows += f["rows"].get<int>();
      sum += f["rows"].get<int>() * std::pow(f["rms_mm"].get<double>(), 2);
      max_abs = std::max(max_abs, f["max_abs_mm"].get<double>());
      ASSERT_TRUE(f.contains("held_out_rms_mm")) << f.dump();
      ASSERT_TRUE(f.contains("kfold_rms_mm")) << f.dump();
      held += f["held_out_rows"].get<int>();
      held_sum += f["held_out_rows"].get<int>() * std::pow(f["held_out_rms_mm"].get<double>(), 2);
      rms[f["name"].get<std::string>()] = f["rms_mm"].get<double>();
    }
    // The features' rows are the kind's rows, their RMS combine to the kind's.
    EXPECT_EQ(rows, k["rows"].get<int>());
    EXPECT_NEAR(std::sqrt(sum / rows), k["rms_mm"].get<double>(), 1e-9);
    EXPECT_DOUBLE_EQ(max_abs, k["max_abs_mm"].get<double>());
    EXPECT_EQ(held, k["held_out_rows"].get<int>());
    EXPECT_NEAR(std::sqrt(held_sum / held), k["held_out_rms_mm"].get<double>(), 1e-6);
  }
  // The disturbed pivot is the one that stands out (its rows cannot be fitted below their +-0.02).
  EXPECT_GT(rms["pivot2"], 0.01);
  for (const char* name : {"pivot1", "pivot3", "face_x", "face_y", "face_z"}) {
    EXPECT_LT(rms[name], 0.4 * rms["pivot2"]) << name;
  }
  const std::string html = testing::ReadAll(dir_ / "report.html");
  EXPECT_NE(html.find("Errors per pivot and plane"), std::string::npos);
  for (const char* name : {"pivot1", "pivot2", "pivot3", "face_x", "face_y", "face_z"}) {
    EXPECT_NE(html.find("</td><td>" + std::string(name) + "</td>"), std::string::npos) << name;
  }
  const size_t svg = html.find("<svg");
  ASSERT_NE(svg, std::string::npos);
  EXPECT_NE(html.find("</svg>", svg), std::string::npos);
  // A panel per kind, a series per pivot and plane and the held-out rows, named in the picture.
  for (const char* text : {"distance errors (ballbar)", "plane contact errors (touch probe)",
                           "pivot pivot2", "plane face_z", "held out"}) {
    EXPECT_NE(html.find(text, svg), std::string::npos) << text;
  }
}

}  // namespace contact_tool_test
}  // namespace
}  // namespace lpoe
