// Tests of the paper's linearized iterative least squares (linear_solver.h) on the section-4
// reproduction (cobot6, Table 2, 100 configurations: 70 identify, 30 verify) and on the other test
// robots: exact recovery on noise-free data, the paper's accuracy at sigma = 0.03 mm, the literal
// "variance 0.2" reading, agreement of the two parameterizations, and refusal of data that cannot
// identify the model.
#include "lpoe/linear_solver.h"

#include <cmath>
#include <cstdio>
#include <iostream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "lpoe/analysis.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/parallel.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/model/simulation.h"
#include "lpoe/model/statistics.h"
#include "test_util.h"

namespace lpoe {
namespace {
namespace linear_solver_test {

constexpr int kRows = 100;
constexpr int kIdentificationRows = 70;
constexpr uint64_t kDataSeed = 2022;
constexpr uint64_t kErrorSeed = 7;
// Noise-free data: the calibrated model must reproduce held-out points to this (mm) ...
constexpr double kNoiseFreeMaxError = 1e-6;
// ... and orientations to this (rad), in pose mode.
constexpr double kNoiseFreeMaxOrientationError = 1e-9;
constexpr int kNoiseFreeMaxIterations = 10;
// docs/conventions.md: sigma = 0.03 mm per axis reproduces the paper's figures; held-out per-axis
// maximum error versus the measured points.
constexpr double kPaperSigma = 0.03;
constexpr double kPaperHeldOutPerAxisMax = 0.15;
// Both parameterizations predict the same positions (mm).
constexpr double kParameterizationAgreement = 1e-6;

const std::vector<ParameterizationKind> kKinds = {ParameterizationKind::kIdentifiable,
                                                  ParameterizationKind::kFull};

// `rows` rows measured on the paper's actual robot (Table 2 errors) with the paper's noise.
MeasurementSet PaperData(int rows) {
  SimulationOptions o;
  o.count = rows;
  o.noise_sigma = kPaperSigma;
  const KinematicErrors errors = PaperTable2Errors();
  return SimulateMeasurements(ApplyErrors(MakeCobot6(), errors), errors.joint_zero, o);
}

struct DataSet {
  RobotModel nominal;
  RobotModel actual;
  MeasurementSet identification;
  MeasurementSet verification;
};

DataSet MakeDataSet(const RobotModel& nominal, const KinematicErrors& errors, double sigma,
                    bool pose, uint64_t seed = kDataSeed) {
  DataSet d;
  d.nominal = nominal;
  d.actual = ApplyErrors(nominal, errors);
  SimulationOptions options;
  options.count = kRows;
  options.noise_sigma = sigma;
  options.pose = pose;
  options.seed = seed;
  const MeasurementSet all = SimulateMeasurements(d.actual, errors.joint_zero, options);
  all.SplitAt(kIdentificationRows, &d.identification, &d.verification);
  return d;
}

DataSet Section4(double sigma, bool pose = false) {
  return MakeDataSet(MakeCobot6(), PaperTable2Errors(), sigma, pose);
}

// Largest rotation error |log(R_measured R_model^T)| over the rows (rad).
double MaxOrientationError(const RobotModel& model, const MeasurementSet& data) {
  double worst = 0;
  for (int r = 0; r < data.size(); ++r) {
    const SE3d T = ToolPose(model, data.q(r), data.target(r));
    worst = std::max(
        worst, LogSO3(Eigen::Matrix3d(data.orientation(r) * T.R.transpose())).norm());
  }
  return worst;
}

std::string Figures(const ErrorStatistics& s) {
  char line[200];
  std::snprintf(line, sizeof(line),
                "max |e| x %.4f y %.4f z %.4f norm %.4f mm; mean norm %.4f mm; rms norm %.4f mm",
                s.axis[0].max_abs, s.axis[1].max_abs, s.axis[2].max_abs, s.norm.max_abs,
                s.norm.mean_abs, s.norm.rms);
  return line;
}

double PerAxisMax(const ErrorStatistics& s) {
  return std::max({s.axis[0].max_abs, s.axis[1].max_abs, s.axis[2].max_abs});
}

void ExpectExactRecovery(const DataSet& d, bool pose, const std::string& label) {
  for (ParameterizationKind kind : kKinds) {
    SCOPED_TRACE(label + ", " + ParameterizationName(kind) + (pose ? ", pose" : ", position"));
    LinearSolverOptions options;
    options.parameterization = kind;
    options.use_orientation = pose;
    options.max_iterations = kNoiseFreeMaxIterations;
    const CalibrationResult result = CalibrateLinear(d.nominal, d.identification, options);
    ASSERT_EQ(result.termination, Termination::kConverged) << result.message;
    EXPECT_LE(result.iterations, kNoiseFreeMaxIterations);
    const ErrorStatistics before = PositionErrorStatistics(d.nominal, d.verification);
    const ErrorStatistics after = PositionErrorStatistics(result.model, d.verification);
    EXPECT_GT(before.norm.max_abs, 1.0) << "the errors must be visible before calibration";
    EXPECT_LE(after.norm.max_abs, kNoiseFreeMaxError);
    EXPECT_LE(PositionErrorStatistics(result.model, d.identification).norm.max_abs,
              kNoiseFreeMaxError);
    if (pose) {
      EXPECT_LE(MaxOrientationError(result.model, d.verification), kNoiseFreeMaxOrientationError);
    }
    std::cout << "[noise-free] " << label << ", " << ParameterizationName(kind)
              << (pose ? ", pose" : ", position") << ": " << result.iterations
              << " iterations, held-out max error " << after.norm.max_abs << " mm (before "
              << before.norm.max_abs << " mm)\n";
  }
}

TEST(LinearSolver, Section4NoiseFreePositionRecoversTheRobot) {
  ExpectExactRecovery(Section4(0.0), false, "cobot6 Table 2");
}

TEST(LinearSolver, Section4NoiseFreePoseRecoversTheRobot) {
  ExpectExactRecovery(Section4(0.0, /*pose=*/true), true, "cobot6 Table 2");
}

TEST(LinearSolver, OtherRobotsNoiseFreeRecovery) {
  const testing::NamedRobot robots[] = {{"ur5_like", MakeUr5Like()},
                                        {"arm7", MakeSevenJointArm()},
                                        {"arm_prismatic", MakeArmWithPrismatic()}};
  for (const testing::NamedRobot& robot : robots) {
    const KinematicErrors errors = RandomErrors(robot.model, 0.005, 3.0, 0.03, 0.03, kErrorSeed);
    for (bool pose : {false, true}) {
      ExpectExactRecovery(MakeDataSet(robot.model, errors, 0.0, pose), pose, robot.name);
    }
  }
}

TEST(LinearSolver, Section4PaperNoiseMatchesThePaperFigures) {
  const DataSet d = Section4(kPaperSigma);
  for (ParameterizationKind kind : kKinds) {
    SCOPED_TRACE(ParameterizationName(kind));
    LinearSolverOptions options;
    options.parameterization = kind;
    const CalibrationResult result = CalibrateLinear(d.nominal, d.identification, options);
    ASSERT_EQ(result.termination, Termination::kConverged) << result.message;
    const ErrorStatistics id_after = PositionErrorStatistics(result.model, d.identification);
    const ErrorStatistics before = PositionErrorStatistics(d.nominal, d.verification);
    const ErrorStatistics after = PositionErrorStatistics(result.model, d.verification);
    EXPECT_LE(after.axis[0].max_abs, kPaperHeldOutPerAxisMax);
    EXPECT_LE(after.axis[1].max_abs, kPaperHeldOutPerAxisMax);
    EXPECT_LE(after.axis[2].max_abs, kPaperHeldOutPerAxisMax);
    // The residual is the noise: 2 cost / (rows - parameters) estimates sigma^2 (183 degrees of
    // freedom: a relative standard error of 10%, allowed 35%).
    const double dof = 3.0 * kIdentificationRows - 27;
    EXPECT_NEAR(2 * result.final_cost / dof, kPaperSigma * kPaperSigma,
                0.35 * kPaperSigma * kPaperSigma);
    const std::string name = std::string("sigma_0.03_") + ParameterizationName(kind);
    std::cout << "[sigma 0.03 mm, " << ParameterizationName(kind) << "] " << result.iterations
              << " iterations\n  identification after: " << Figures(id_after)
              << "\n  verification before:   " << Figures(before)
              << "\n  verification after:    " << Figures(after) << "\n";
    ::testing::Test::RecordProperty(name + "_iterations", result.iterations);
    ::testing::Test::RecordProperty(name + "_heldout", Figures(after));
    ::testing::Test::RecordProperty(name + "_identification", Figures(id_after));
  }
}

TEST(LinearSolver, Section4LiteralVariance02Converges) {
  // The paper's "Gaussian noise with variance 0.2": sigma = sqrt(0.2) = 0.447 mm per axis. It cannot
  // reproduce the paper's figures (docs/conventions.md); it must still converge and improve.
  const double sigma = std::sqrt(0.2);
  const DataSet d = Section4(sigma);
  for (ParameterizationKind kind : kKinds) {
    SCOPED_TRACE(ParameterizationName(kind));
    LinearSolverOptions options;
    options.parameterization = kind;
    const CalibrationResult result = CalibrateLinear(d.nominal, d.identification, options);
    ASSERT_EQ(result.termination, Termination::kConverged) << result.message;
    const ErrorStatistics id_after = PositionErrorStatistics(result.model, d.identification);
    const ErrorStatistics before = PositionErrorStatistics(d.nominal, d.verification);
    const ErrorStatistics after = PositionErrorStatistics(result.model, d.verification);
    // Sanity bounds only: much better than the nominal model, and within 6 sigma per axis.
    EXPECT_LT(PerAxisMax(after), 0.2 * PerAxisMax(before));
    EXPECT_LT(PerAxisMax(after), 6 * sigma);
    const std::string name = std::string("variance_0.2_") + ParameterizationName(kind);
    std::cout << "[variance 0.2 (sigma 0.447 mm), " << ParameterizationName(kind) << "] "
              << result.iterations << " iterations\n  identification after: " << Figures(id_after)
              << "\n  verification before:   " << Figures(before)
              << "\n  verification after:    " << Figures(after) << "\n";
    ::testing::Test::RecordProperty(name + "_iterations", result.iterations);
    ::testing::Test::RecordProperty(name + "_heldout", Figures(after));
  }
}

TEST(LinearSolver, FullAndIdentifiableGiveTheSamePredictions) {
  for (bool pose : {false, true}) {
    SCOPED_TRACE(pose ? "pose" : "position");
    const DataSet d = Section4(kPaperSigma, pose);
    LinearSolverOptions options;
    options.use_orientation = pose;
    options.parameterization = ParameterizationKind::kIdentifiable;
    const CalibrationResult identifiable = CalibrateLinear(d.nominal, d.identification, options);
    options.parameterization = ParameterizationKind::kFull;
    const CalibrationResult full = CalibrateLinear(d.nominal, d.identification, options);
    ASSERT_EQ(identifiable.termination, Termination::kConverged) << identifiable.message;
    ASSERT_EQ(full.termination, Termination::kConverged) << full.message;
    EXPECT_EQ(identifiable.parameterization.num_parameters, pose ? 30 : 27);
    EXPECT_EQ(full.parameterization.num_parameters, 42);
    EXPECT_EQ(identifiable.rank, pose ? 30 : 27);
    EXPECT_EQ(full.rank, pose ? 30 : 27);
    double worst = 0;
    for (const MeasurementSet* set : {&d.identification, &d.verification}) {
      for (int r = 0; r < set->size(); ++r) {
        worst = std::max(worst, (ToolPosition(identifiable.model, set->q(r)) -
                                 ToolPosition(full.model, set->q(r)))
                                    .norm());
      }
    }
    EXPECT_LE(worst, kParameterizationAgreement);
    EXPECT_NEAR(identifiable.final_cost, full.final_cost, 1e-9 * identifiable.final_cost);
    std::cout << "[full vs identifiable, " << (pose ? "pose" : "position")
              << "] largest difference of predicted positions " << worst << " mm\n";
  }
}

TEST(LinearSolver, HistoryIsRecordedAndTheErrorDecreases) {
  const DataSet d = Section4(kPaperSigma);
  for (ParameterizationKind kind : kKinds) {
    SCOPED_TRACE(ParameterizationName(kind));
    LinearSolverOptions options;
    options.parameterization = kind;
    std::vector<int> reported;
    options.on_iteration = [&](const IterationRecord& r) { reported.push_back(r.iteration); };
    const CalibrationResult result = CalibrateLinear(d.nominal, d.identification, options);
    ASSERT_EQ(result.termination, Termination::kConverged) << result.message;
    ASSERT_EQ(static_cast<int>(result.history.size()), result.iterations + 1);
    const ErrorStatistics nominal = PositionErrorStatistics(d.nominal, d.identification);
    const ErrorStatistics after = PositionErrorStatistics(result.model, d.identification);
    EXPECT_NEAR(result.history.front().max_error, nominal.norm.max_abs, 1e-9);
    EXPECT_NEAR(result.history.front().mean_error, nominal.norm.mean_abs, 1e-9);
    EXPECT_NEAR(result.history.back().max_error, after.norm.max_abs, 1e-9);
    EXPECT_LT(result.history.back().max_error, 0.05 * result.history.front().max_error);
    EXPECT_LT(result.history[1].max_error, result.history[0].max_error);
    for (size_t k = 0; k < result.history.size(); ++k) {
      EXPECT_EQ(result.history[k].iteration, static_cast<int>(k));
      if (k > 0) {
        EXPECT_LE(result.history[k].cost, result.history[k - 1].cost);
      }
      if (k + 1 < result.history.size()) {
        EXPECT_GT(result.history[k].step_norm, 0.0);
      }
    }
    // The last row carries the step the convergence message quotes (convergence.h).
    char quoted[64];
    std::snprintf(quoted, sizeof(quoted), "|x| = %.3g", result.history.back().step_norm);
    EXPECT_NE(result.message.find(quoted), std::string::npos) << result.message;
    EXPECT_NE(result.stop_rule, StopRule::kNone);
    EXPECT_NEAR(result.final_cost, result.history.back().cost, 1e-12);
    std::vector<int> expected;
    for (int k = 1; k <= result.iterations; ++k) expected.push_back(k);
    EXPECT_EQ(reported, expected);
  }
}

TEST(LinearSolver, CovarianceIsComputedForTheIdentifiableParameterization) {
  const DataSet d = Section4(kPaperSigma);
  const CalibrationResult result = CalibrateLinear(d.nominal, d.identification);
  ASSERT_EQ(result.termination, Termination::kConverged) << result.message;
  ASSERT_EQ(result.covariance.rows(), 27);
  ASSERT_EQ(result.covariance.cols(), 27);
  EXPECT_LT((result.covariance - result.covariance.transpose()).cwiseAbs().maxCoeff(),
            1e-12 * result.covariance.cwiseAbs().maxCoeff());
  EXPECT_GT(result.covariance.diagonal().minCoeff(), 0.0);
  EXPECT_EQ(result.singular_values.size(), 27);
  EXPECT_GT(result.condition_number, 1.0);
  EXPECT_LT(result.condition_number, 1e8);
}

TEST(LinearSolver, FewerRowsThanUnknownsIsNotIdentifiable) {
  const DataSet d = Section4(0.0);
  const MeasurementSet few = d.identification.Subset({0, 1, 2, 3, 4, 5, 6, 7});  // 24 equations
  for (ParameterizationKind kind : kKinds) {
    SCOPED_TRACE(ParameterizationName(kind));
    LinearSolverOptions options;
    options.parameterization = kind;
    const CalibrationResult result = CalibrateLinear(d.nominal, few, options);
    EXPECT_EQ(result.termination, Termination::kNotIdentifiable);
    EXPECT_NE(result.message.find("27"), std::string::npos) << result.message;
    EXPECT_NE(result.message.find("8 measurements"), std::string::npos) << result.message;
    // Nothing was solved: the model is the nominal one.
    EXPECT_EQ(ToolPosition(result.model, few.q(0)), ToolPosition(d.nominal, few.q(0)));
  }
}

TEST(LinearSolver, IdenticalPosesAreNotIdentifiable) {
  const DataSet d = Section4(0.0);
  const MeasurementSet same = d.identification.Subset(std::vector<int>(kIdentificationRows, 3));
  for (ParameterizationKind kind : kKinds) {
    SCOPED_TRACE(ParameterizationName(kind));
    LinearSolverOptions options;
    options.parameterization = kind;
    const CalibrationResult result = CalibrateLinear(d.nominal, same, options);
    EXPECT_EQ(result.termination, Termination::kNotIdentifiable) << result.message;
    EXPECT_NE(result.message.find("rank"), std::string::npos) << result.message;
    EXPECT_LT(result.rank, 27);
    EXPECT_EQ(ToolPosition(result.model, same.q(0)), ToolPosition(d.nominal, same.q(0)));
  }
}

TEST(LinearSolver, PosesThatNeverMoveJoint6AreNotIdentifiable) {
  const KinematicErrors errors = PaperTable2Errors();
  const RobotModel actual = ApplyErrors(MakeCobot6(), errors);
  SimulationOptions sim;
  sim.count = kIdentificationRows;
  sim.seed = kDataSeed;
  sim.lower.assign(6, -kPi);
  sim.upper.assign(6, kPi);
  sim.lower[5] = sim.upper[5] = 0.7;  // joint 6 held still
  const MeasurementSet data = SimulateMeasurements(actual, errors.joint_zero, sim);
  for (int r = 0; r < data.size(); ++r) ASSERT_EQ(data.q(r)[5], 0.7);
  for (ParameterizationKind kind : kKinds) {
    SCOPED_TRACE(ParameterizationName(kind));
    LinearSolverOptions options;
    options.parameterization = kind;
    const CalibrationResult result = CalibrateLinear(MakeCobot6(), data, options);
    EXPECT_EQ(result.termination, Termination::kNotIdentifiable) << result.message;
    EXPECT_LT(result.rank, 27);
    // The weakest directions named are those of the last joint and the tool.
    EXPECT_TRUE(result.message.find("joint6") != std::string::npos ||
                result.message.find("smr1") != std::string::npos)
        << result.message;
  }
}

TEST(LinearSolver, PoseModeWithoutOrientationsIsRefused) {
  const DataSet d = Section4(0.0, /*pose=*/false);
  LinearSolverOptions options;
  options.use_orientation = true;
  const CalibrationResult result = CalibrateLinear(d.nominal, d.identification, options);
  EXPECT_EQ(result.termination, Termination::kNotIdentifiable);
  EXPECT_FALSE(result.message.empty());
}

TEST(LinearSolver, IterationLimitIsReported) {
  const DataSet d = Section4(kPaperSigma);
  LinearSolverOptions options;
  options.max_iterations = 1;
  const CalibrationResult result = CalibrateLinear(d.nominal, d.identification, options);
  EXPECT_EQ(result.termination, Termination::kMaxIterations) << result.message;
  EXPECT_EQ(result.iterations, 1);
  EXPECT_FALSE(result.converged());
  // One step already removes most of the error (the paper's Fig. 6).
  EXPECT_LT(PositionErrorStatistics(result.model, d.identification).norm.max_abs,
            0.1 * PositionErrorStatistics(d.nominal, d.identification).norm.max_abs);
}

// The errors the solver's last linearization leaves (LinearSolverErrors) are those of the returned
// model: their statistics and outliers equal a direct recomputation, and the statistics at the
// start those of the start model.
TEST(LinearSolver, KeptErrorsEqualADirectRecomputation) {
  constexpr int kLargeRows = 30000;  // several chunks on several threads
  constexpr double kMomentTolerance = 1e-10;
  constexpr double kPercentileTolerance = 1e-7;
  MeasurementSet data = PaperData(kLargeRows);
  for (int r : {17, 12345, 29999}) data.mutable_position(r)(1) += 2.0;  // gross errors
  const RobotModel nominal = MakeCobot6();
  LinearSolverErrors kept;
  kept.want_start_statistics = true;
  LinearSolverOptions options;
  options.errors = &kept;
  const CalibrationResult result = CalibrateLinear(nominal, data, options);
  ASSERT_EQ(result.termination, Termination::kConverged) << result.message;
  ASSERT_EQ(kept.final_errors.size(), kLargeRows);
  ASSERT_TRUE(kept.have_start_statistics);
  auto expect_near = [&](const ErrorStatistics& got, const ErrorStatistics& want) {
    EXPECT_EQ(got.count, want.count);
    for (int a = 0; a < 4; ++a) {
      const AxisStatistics& g = a < 3 ? got.axis[a] : got.norm;
      const AxisStatistics& w = a < 3 ? want.axis[a] : want.norm;
      EXPECT_NEAR(g.max_abs, w.max_abs, kMomentTolerance * w.max_abs) << a;
      EXPECT_NEAR(g.mean_abs, w.mean_abs, kMomentTolerance * w.mean_abs) << a;
      EXPECT_NEAR(g.rms, w.rms, kMomentTolerance * w.rms) << a;
      EXPECT_NEAR(g.p95_abs, w.p95_abs, kPercentileTolerance * w.p95_abs) << a;
    }
  };
  expect_near(kept.final_errors.Statistics(), PositionErrorStatistics(result.model, data));
  expect_near(kept.start_statistics, PositionErrorStatistics(nominal, data));
  double sigma_kept = 0, sigma_direct = 0;
  const std::vector<Outlier> from_kept =
      FindOutliers(result.model, data, kept.final_errors, 5.0, &sigma_kept);
  const std::vector<Outlier> direct = FindOutliers(result.model, data, 5.0, &sigma_direct);
  EXPECT_NEAR(sigma_kept, sigma_direct, kPercentileTolerance * sigma_direct);
  ASSERT_EQ(from_kept.size(), 3u);
  ASSERT_EQ(direct.size(), from_kept.size());
  for (size_t k = 0; k < direct.size(); ++k) {
    EXPECT_EQ(from_kept[k].row, direct[k].row);
    EXPECT_EQ(from_kept[k].error, direct[k].error);
  }
  // Pose data keep nothing.
  const DataSet pose = Section4(0.0, true);
  LinearSolverOptions pose_options;
  pose_options.use_orientation = true;
  pose_options.errors = &kept;
  ASSERT_EQ(CalibrateLinear(pose.nominal, pose.identification, pose_options).termination,
            Termination::kConverged);
  EXPECT_TRUE(kept.final_errors.empty());
  EXPECT_FALSE(kept.have_start_statistics);
}

// The rows run in fixed chunks whose sums are added in order: the same calibration, bit for bit,
// on one thread or several.
TEST(LinearSolver, ResultDoesNotDependOnTheThreadCount) {
  constexpr int kLargeRows = 30000;
  const MeasurementSet data = PaperData(kLargeRows);
  std::vector<CalibrationResult> results;
  std::vector<ErrorStatistics> stats;
  for (int threads : {1, 2, 3}) {
    ThreadCountOverride() = threads;
    LinearSolverErrors kept;
    LinearSolverOptions options;
    options.errors = &kept;
    results.push_back(CalibrateLinear(MakeCobot6(), data, options));
    ASSERT_EQ(results.back().termination, Termination::kConverged);
    stats.push_back(kept.final_errors.Statistics());
  }
  ThreadCountOverride() = 0;
  for (size_t k = 1; k < results.size(); ++k) {
    SCOPED_TRACE(k);
    ASSERT_EQ(results[k].history.size(), results[0].history.size());
    for (size_t it = 0; it < results[0].history.size(); ++it) {
      EXPECT_EQ(results[k].history[it].cost, results[0].history[it].cost);
    }
    for (int f = 0; f < results[0].model.num_frames(); ++f) {
      EXPECT_EQ(testing::FrameOf(results[k].model, f).R, testing::FrameOf(results[0].model, f).R);
      EXPECT_EQ(testing::FrameOf(results[k].model, f).t, testing::FrameOf(results[0].model, f).t);
    }
    EXPECT_EQ(results[k].covariance, results[0].covariance);
    EXPECT_EQ(stats[k].norm.rms, stats[0].norm.rms);
    EXPECT_EQ(stats[k].norm.p95_abs, stats[0].norm.p95_abs);
  }
}

// The warm start (LinearSolverOptions::warm_start_rows): on large data the iterations after the
// first step run on a subsample, and the solve ends on all rows. The result is the cold solve's to
// within its convergence tolerance; the start model's record, statistics and identifiability are
// the cold solve's exactly; fewer linearizations go over all rows.
TEST(LinearSolver, WarmStartGivesTheColdSolution) {
  constexpr int kRows = 40000;
  constexpr int kSubsample = 4000;
  const MeasurementSet data = PaperData(kRows);
  const RobotModel nominal = MakeCobot6();
  auto solve = [&](bool warm, LinearSolverErrors* kept) {
    LinearSolverOptions options;
    options.warm_start_min_rows = kRows;
    options.warm_start_rows = warm ? kSubsample : 0;
    kept->want_start_statistics = true;
    options.errors = kept;
    return CalibrateLinear(nominal, data, options);
  };
  LinearSolverErrors kept_warm, kept_cold;
  const CalibrationResult warm = solve(true, &kept_warm);
  const CalibrationResult cold = solve(false, &kept_cold);
  ASSERT_EQ(warm.termination, Termination::kConverged) << warm.message;
  ASSERT_EQ(cold.termination, Termination::kConverged) << cold.message;
  EXPECT_EQ(warm.warm_start_rows, kSubsample);
  EXPECT_EQ(cold.warm_start_rows, 0);

  // The history: the start record on all rows (the same pass), then the subsample's iterations
  // (marked with their rows), then at least two on all rows; fewer of those than cold.
  int full_warm = 0, sub_warm = 0;
  for (size_t k = 0; k < warm.history.size(); ++k) {
    EXPECT_EQ(warm.history[k].iteration, static_cast<int>(k));
    EXPECT_TRUE(warm.history[k].rows == 0 || warm.history[k].rows == kSubsample) << k;
    (warm.history[k].rows == 0 ? full_warm : sub_warm) += 1;
  }
  for (const IterationRecord& r : cold.history) EXPECT_EQ(r.rows, 0);
  ASSERT_GE(sub_warm, 1);
  EXPECT_EQ(warm.history.front().rows, 0);
  EXPECT_EQ(warm.history[1].rows, kSubsample);
  EXPECT_EQ(warm.history.back().rows, 0);
  EXPECT_EQ(warm.history[warm.history.size() - 2].rows, 0);
  EXPECT_LT(full_warm, static_cast<int>(cold.history.size()));
  EXPECT_EQ(warm.iterations, static_cast<int>(warm.history.size()) - 1);
  EXPECT_EQ(warm.history.front().cost, cold.history.front().cost);
  EXPECT_EQ(warm.history.front().step_norm, cold.history.front().step_norm);
  EXPECT_EQ(warm.rank, cold.rank);
  EXPECT_EQ(warm.condition_number, cold.condition_number);
  EXPECT_EQ(warm.singular_values, cold.singular_values);

  // The solution: the same to within the stopping rule (each solve stops where its step is at most
  // sd_fraction = 0.01 standard deviations of every parameter, so the two are within twice that of
  // each other), and the same fit.
  ASSERT_EQ(warm.covariance.rows(), cold.covariance.rows());
  ASSERT_GT(cold.covariance.rows(), 0);
  EXPECT_NEAR(warm.final_cost, cold.final_cost, 1e-9 * cold.final_cost);
  const Eigen::VectorXd dx = ParameterDifference(cold.parameterization, cold.model, warm.model);
  const double fraction = LinearSolverOptions().convergence.sd_fraction;
  for (int i = 0; i < dx.size(); ++i) {
    const double sd = std::sqrt(cold.covariance(i, i));
    EXPECT_LE(std::abs(dx(i)), 2 * fraction * sd) << cold.parameterization.parameters[i].name;
  }
  const double c_scale = cold.covariance.cwiseAbs().maxCoeff();
  EXPECT_LT((warm.covariance - cold.covariance).cwiseAbs().maxCoeff(), 1e-6 * c_scale);
  const std::vector<Eigen::Vector3d> ew = PositionErrors(warm.model, data);
  const std::vector<Eigen::Vector3d> ec = PositionErrors(cold.model, data);
  double largest = 0;
  for (int r = 0; r < kRows; ++r) largest = std::max(largest, (ew[r] - ec[r]).norm());
  EXPECT_LT(largest, 1e-7);  // mm; the noise is 1e-2

  // The errors kept for the analysis: the start model's and the returned model's, on all rows.
  ASSERT_TRUE(kept_warm.have_start_statistics);
  EXPECT_EQ(kept_warm.start_statistics.count, kRows);
  EXPECT_EQ(kept_warm.start_statistics.norm.rms, kept_cold.start_statistics.norm.rms);
  EXPECT_EQ(kept_warm.start_statistics.norm.p95_abs, kept_cold.start_statistics.norm.p95_abs);
  ASSERT_EQ(kept_warm.final_errors.size(), kRows);
  const ErrorStatistics after = kept_warm.final_errors.Statistics();
  const ErrorStatistics direct = PositionErrorStatistics(warm.model, data);
  EXPECT_NEAR(after.norm.rms, direct.norm.rms, 1e-10 * direct.norm.rms);
  EXPECT_NEAR(after.norm.max_abs, direct.norm.max_abs, 1e-10 * direct.norm.max_abs);
  EXPECT_NEAR(after.norm.rms, kept_cold.final_errors.Statistics().norm.rms, 1e-9 * after.norm.rms);
}

// Below warm_start_min_rows (the default 10^5 among them) nothing changes: the result is the one
// without a warm start, bit for bit.
TEST(LinearSolver, NoWarmStartBelowItsRowCount) {
  constexpr int kRows = 20000;
  const MeasurementSet data = PaperData(kRows);
  LinearSolverOptions defaults;
  ASSERT_GT(defaults.warm_start_min_rows, kRows);
  LinearSolverOptions above = defaults;  // one row more than there are
  above.warm_start_min_rows = kRows + 1;
  above.warm_start_rows = 1000;
  LinearSolverOptions off = defaults;
  off.warm_start_rows = 0;
  off.warm_start_min_rows = 0;
  const CalibrationResult base = CalibrateLinear(MakeCobot6(), data, off);
  ASSERT_EQ(base.termination, Termination::kConverged) << base.message;
  for (const LinearSolverOptions& options : {defaults, above}) {
    const CalibrationResult r = CalibrateLinear(MakeCobot6(), data, options);
    ASSERT_EQ(r.termination, Termination::kConverged);
    EXPECT_EQ(r.warm_start_rows, 0);
    ASSERT_EQ(r.history.size(), base.history.size());
    for (size_t k = 0; k < r.history.size(); ++k) {
      EXPECT_EQ(r.history[k].rows, 0);
      EXPECT_EQ(r.history[k].cost, base.history[k].cost);
    }
    EXPECT_EQ(r.covariance, base.covariance);
    for (int f = 0; f < r.model.num_frames(); ++f) {
      EXPECT_EQ(testing::FrameOf(r.model, f).R, testing::FrameOf(base.model, f).R);
      EXPECT_EQ(testing::FrameOf(r.model, f).t, testing::FrameOf(base.model, f).t);
    }
  }
  // At the threshold it applies.
  above.warm_start_min_rows = kRows;
  EXPECT_EQ(CalibrateLinear(MakeCobot6(), data, above).warm_start_rows, 1000);
}

}  // namespace linear_solver_test
}  // namespace
}  // namespace lpoe
