// Real-tracker-data path: registration to an arbitrary measurement frame, several SMRs,
// degrees, lost-beam rows, the identifiability report and outlier listing.
#include <cmath>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "lpoe/analysis.h"
#include "lpoe/io/io.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/linear_solver.h"
#include "lpoe/registration.h"
#include "lpoe/model/simulation.h"
#include "lpoe/model/statistics.h"

namespace lpoe {
namespace {
namespace registration_test {

constexpr int kRows = 240;
constexpr int kHeldOut = 60;
constexpr double kNoiseSigma = 0.02;          // mm
constexpr double kSameErrorTolerance = 1e-6;  // mm
constexpr double kZeroRowFraction = 0.01;

RobotModel ThreeSmrCobot() {
  RobotModel m = MakeCobot6();
  m.tools.push_back(Tool{"smr2", SE3d(Eigen::Matrix3d::Identity(), Eigen::Vector3d(-35, 30, 55))});
  m.tools.push_back(Tool{"smr3", SE3d(Eigen::Matrix3d::Identity(), Eigen::Vector3d(10, -45, 70))});
  return m;
}

// A tracker frame 2.5 m from the base, turned 2 rad about a skew axis.
SE3d TrackerFromBase() {
  SE3d T;
  T.R = ExpSO3(Eigen::Vector3d(Eigen::Vector3d(0.3, -0.5, 0.8).normalized() * 2.0));
  T.t = Eigen::Vector3d(1800, -1500, 900);
  T.t *= 2500.0 / T.t.norm();
  return T;
}

struct Outcome {
  ErrorStatistics held_out;
  int64_t skipped = 0;
};

// Writes `data` (transformed by T) as a degrees CSV with zero rows, reads it back, registers and
// calibrates like lpoe_calibrate does, and returns the held-out statistics.
Outcome CalibrateThroughFiles(const RobotModel& nominal, const MeasurementSet& data, const SE3d& T,
                              bool insert_zero_rows) {
  const int n = nominal.num_joints();
  MeasurementSet moved(n);
  for (int r = 0; r < data.size(); ++r) {
    std::vector<double> q(data.q(r), data.q(r) + n);
    for (double& v : q) v *= 180.0 / M_PI;
    moved.Add(q.data(), T * data.position(r), data.target(r));
  }
  std::string csv = MeasurementsToCsv(nominal, moved);
  if (insert_zero_rows) {
    // Insert lost-beam rows (all-zero positions) at about 1% of the lines.
    std::istringstream in(csv);
    std::ostringstream out;
    std::string line;
    int k = 0;
    const int every = static_cast<int>(1.0 / kZeroRowFraction);
    while (std::getline(in, line)) {
      out << line << "\n";
      if (k > 0 && k % every == 0) out << "10,20,30,40,50,60,0,0,0,smr1\n";
      ++k;
    }
    csv = out.str();
  }
  MeasurementSet all;
  CsvReadReport report;
  const Status s =
      ParseMeasurementsCsv(csv, "tracker.csv", nominal, AngleUnit::kDegrees, &all, &report);
  EXPECT_TRUE(s.ok()) << s.message();
  MeasurementSet identification, verification;
  all.SplitAt(all.size() - kHeldOut, &identification, &verification);

  RobotModel start;
  RegistrationReport reg;
  const Status rs = RegisterToMeasurements(nominal, identification, &start, &reg);
  EXPECT_TRUE(rs.ok()) << rs.message();
  const CalibrationResult result = CalibrateLinear(start, identification);
  EXPECT_TRUE(result.converged()) << result.message;
  return {PositionErrorStatistics(result.model, verification), report.skipped_zero_rows};
}

TEST(Registration, TrackerFrameGivesTheSameHeldOutErrorAsTheBaseFrame) {
  const RobotModel truth_nominal = ThreeSmrCobot();
  const KinematicErrors errors = RandomErrors(truth_nominal, 0.005, 3.0, 0.02, 0.03, 11);
  const RobotModel actual = ApplyErrors(truth_nominal, errors);
  SimulationOptions options;
  options.count = kRows;
  options.noise_sigma = kNoiseSigma;
  options.all_tools = true;
  options.seed = 5;
  const MeasurementSet data = SimulateMeasurements(actual, errors.joint_zero, options);

  // The user's model has rough SMR offsets (tens of mm off).
  RobotModel nominal = truth_nominal;
  nominal.tools[0].origin.t += Eigen::Vector3d(20, -15, 25);
  nominal.tools[1].origin.t += Eigen::Vector3d(-30, 10, 20);
  nominal.tools[2].origin.t += Eigen::Vector3d(15, 25, -20);

  const Outcome base = CalibrateThroughFiles(nominal, data, SE3d(), false);
  const Outcome tracker = CalibrateThroughFiles(nominal, data, TrackerFromBase(), true);
  EXPECT_GT(tracker.skipped, 0);
  EXPECT_EQ(base.held_out.count, tracker.held_out.count);
  EXPECT_NEAR(base.held_out.norm.max_abs, tracker.held_out.norm.max_abs, kSameErrorTolerance);
  EXPECT_NEAR(base.held_out.norm.mean_abs, tracker.held_out.norm.mean_abs, kSameErrorTolerance);
  EXPECT_NEAR(base.held_out.norm.rms, tracker.held_out.norm.rms, kSameErrorTolerance);
  // And the calibration worked: held-out errors at the noise level.
  EXPECT_LT(base.held_out.norm.max_abs, 10 * kNoiseSigma);
}

TEST(Registration, WithoutRegistrationTheTrackerFrameFails) {
  // The reason registration exists: linearizing 2.5 m away does not converge to the right answer.
  const RobotModel nominal = MakeCobot6();
  const KinematicErrors errors = PaperTable2Errors();
  const RobotModel actual = ApplyErrors(nominal, errors);
  SimulationOptions options;
  options.count = 100;
  const MeasurementSet data = SimulateMeasurements(actual, errors.joint_zero, options);
  MeasurementSet moved(6);
  const SE3d T = TrackerFromBase();
  for (int r = 0; r < data.size(); ++r) moved.Add(data.q(r), T * data.position(r));
  LinearSolverOptions o;
  o.max_iterations = 10;
  const CalibrationResult direct = CalibrateLinear(nominal, moved, o);
  const bool good = direct.converged() &&
                    PositionErrorStatistics(direct.model, moved).norm.max_abs < 1e-3;
  RobotModel start;
  ASSERT_TRUE(RegisterToMeasurements(nominal, moved, &start, nullptr).ok());
  const CalibrationResult registered = CalibrateLinear(start, moved);
  ASSERT_TRUE(registered.converged()) << registered.message;
  EXPECT_LT(PositionErrorStatistics(registered.model, moved).norm.max_abs, 1e-6);
  // Registration must not be slower or worse than a lucky direct solve.
  if (good) {
    EXPECT_LE(registered.iterations, direct.iterations + 2);
  }
}

TEST(Registration, RigidFitRecoversAKnownTransform) {
  std::vector<Eigen::Vector3d> a, b;
  const SE3d T = TrackerFromBase();
  for (int k = 0; k < 10; ++k) {
    a.emplace_back(std::sin(k) * 500, std::cos(3 * k) * 400, k * 37.0);
    b.push_back(T * a.back());
  }
  SE3d fit;
  ASSERT_TRUE(FitRigidTransform(a, b, &fit).ok());
  EXPECT_LT((fit.R - T.R).norm(), 1e-12);
  EXPECT_LT((fit.t - T.t).norm(), 1e-9);
  // Collinear points cannot fix a rotation.
  std::vector<Eigen::Vector3d> line, line_b;
  for (int k = 0; k < 5; ++k) {
    line.emplace_back(k, 2.0 * k, 3.0 * k);
    line_b.push_back(T * line.back());
  }
  EXPECT_FALSE(FitRigidTransform(line, line_b, &fit).ok());
}

// Gravity is attached to the robot: registering to a tracker frame expresses it there.
TEST(Registration, GravityTurnsWithTheBase) {
  const RobotModel nominal = MakeCobot6();
  SimulationOptions options;
  options.count = 30;
  MeasurementSet data = SimulateMeasurements(nominal, {}, options);
  const SE3d T = TrackerFromBase();
  for (int r = 0; r < data.size(); ++r) data.mutable_position(r) = T * data.position(r);
  RobotModel registered;
  RegistrationReport report;
  ASSERT_TRUE(RegisterToMeasurements(nominal, data, &registered, &report).ok());
  EXPECT_LT((registered.gravity - T.R * nominal.gravity).norm(), 1e-9);
}

TEST(Analysis, ReportNamesTheFifteenUnidentifiableDirectionsOfCobot6) {
  const RobotModel nominal = MakeCobot6();
  const KinematicErrors errors = PaperTable2Errors();
  SimulationOptions options;
  options.count = 70;
  options.noise_sigma = 0.03;
  const MeasurementSet data =
      SimulateMeasurements(ApplyErrors(nominal, errors), errors.joint_zero, options);
  const CalibrationResult result = CalibrateLinear(nominal, data);
  ASSERT_TRUE(result.converged());
  const IdentifiabilityReport report = AnalyzeIdentifiability(nominal, data, result);
  ASSERT_EQ(report.unidentifiable.size(), 15u);
  for (int j = 1; j <= 6; ++j) {
    int found = 0;
    for (const Direction& d : report.unidentifiable) {
      const std::string prefix = "joint" + std::to_string(j) + ".";
      if (d.name == prefix + "rz" || d.name == prefix + "tz") ++found;
      EXPECT_FALSE(d.reason.empty());
    }
    EXPECT_EQ(found, 2) << "joint " << j;
  }
  int tool = 0;
  for (const Direction& d : report.unidentifiable) tool += d.name.rfind("smr1.r", 0) == 0;
  EXPECT_EQ(tool, 3);
  EXPECT_EQ(report.rank, 27);
  EXPECT_EQ(report.standard_deviation.size(), 27);
  EXPECT_TRUE(report.warnings.empty()) << report.warnings.front();
  EXPECT_FALSE(report.most_correlated.empty());
}

TEST(Analysis, FlagsDataThatBarelyMovesOneJoint) {
  const RobotModel nominal = MakeCobot6();
  const KinematicErrors errors = PaperTable2Errors();
  SimulationOptions options;
  options.count = 100;
  options.noise_sigma = 0.03;
  for (int i = 0; i < 6; ++i) {
    options.lower.push_back(-M_PI);
    options.upper.push_back(M_PI);
  }
  options.lower[3] = 0.40;  // joint 4 moves 0.1 rad (6 degrees)
  options.upper[3] = 0.50;
  const MeasurementSet data =
      SimulateMeasurements(ApplyErrors(nominal, errors), errors.joint_zero, options);
  const CalibrationResult result = CalibrateLinear(nominal, data);
  const IdentifiabilityReport report = AnalyzeIdentifiability(nominal, data, result);
  bool flagged = false;
  for (const std::string& w : report.warnings) flagged |= w.find("joint4") != std::string::npos;
  EXPECT_TRUE(flagged);
}

TEST(Analysis, ListsWildPointsByLine) {
  const RobotModel nominal = MakeCobot6();
  const KinematicErrors errors = PaperTable2Errors();
  SimulationOptions options;
  options.count = 100;
  options.noise_sigma = 0.02;
  MeasurementSet data =
      SimulateMeasurements(ApplyErrors(nominal, errors), errors.joint_zero, options);
  // Re-read through CSV so that rows carry line numbers; then corrupt two rows.
  std::string csv = MeasurementsToCsv(nominal, data);
  MeasurementSet read;
  ASSERT_TRUE(ParseMeasurementsCsv(csv, "m.csv", nominal, AngleUnit::kRadians, &read).ok());
  read.mutable_position(17) += Eigen::Vector3d(4, -3, 2);
  read.mutable_position(63) += Eigen::Vector3d(0, 0, 6);
  const CalibrationResult result = CalibrateLinear(nominal, read);
  ASSERT_TRUE(result.converged());
  const std::vector<Outlier> outliers = FindOutliers(result.model, read);
  ASSERT_GE(outliers.size(), 2u);
  std::vector<int> rows;
  for (const Outlier& o : outliers) rows.push_back(o.row);
  EXPECT_NE(std::find(rows.begin(), rows.end(), 17), rows.end());
  EXPECT_NE(std::find(rows.begin(), rows.end(), 63), rows.end());
  for (const Outlier& o : outliers) EXPECT_EQ(o.line, read.source_line(o.row));
}

TEST(Analysis, SplitsAreSeededPartitions) {
  constexpr int kN = 103;
  std::vector<int> id, ver, id2, ver2;
  HoldoutSplit(kN, 0.3, 9, &id, &ver);
  HoldoutSplit(kN, 0.3, 9, &id2, &ver2);
  EXPECT_EQ(ver, ver2);
  EXPECT_EQ(ver.size(), 31u);
  EXPECT_EQ(id.size() + ver.size(), static_cast<size_t>(kN));
  const auto folds = KFolds(kN, 5, 3);
  std::vector<int> seen(kN, 0);
  for (const auto& f : folds) {
    for (int r : f) ++seen[r];
  }
  for (int c : seen) EXPECT_EQ(c, 1);
}

TEST(Analysis, SequentialSplitsAreContiguousBlocks) {
  constexpr int kN = 103;
  std::vector<int> id, ver;
  HoldoutSplit(kN, 0.3, 9, &id, &ver, SplitKind::kSequential);
  ASSERT_EQ(ver.size(), 31u);
  ASSERT_EQ(id.size(), 72u);
  for (int i = 0; i < 72; ++i) EXPECT_EQ(id[i], i);
  for (int i = 0; i < 31; ++i) EXPECT_EQ(ver[i], 72 + i);
  // The seed plays no part.
  std::vector<int> id2, ver2;
  HoldoutSplit(kN, 0.3, 1234, &id2, &ver2, SplitKind::kSequential);
  EXPECT_EQ(ver, ver2);

  const auto folds = KFolds(kN, 5, 3, SplitKind::kSequential);
  ASSERT_EQ(folds.size(), 5u);
  int next = 0;
  for (const auto& f : folds) {
    EXPECT_GE(f.size(), 20u);
    EXPECT_LE(f.size(), 21u);
    for (int r : f) EXPECT_EQ(r, next++);  // consecutive rows, folds in order
  }
  EXPECT_EQ(next, kN);

  SplitKind kind = SplitKind::kRandom;
  EXPECT_TRUE(ParseSplitKind("sequential", &kind));
  EXPECT_EQ(kind, SplitKind::kSequential);
  EXPECT_STREQ(SplitKindName(kind), "sequential");
  EXPECT_FALSE(ParseSplitKind("time", &kind));
}

}  // namespace registration_test
}  // namespace
}  // namespace lpoe
