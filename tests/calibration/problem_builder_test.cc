#include "lpoe/problem_builder.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include <ceres/ceres.h>
#include <gtest/gtest.h>

#include "lpoe/ceres_solver.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/linear_solver.h"
#include "lpoe/model/simulation.h"
#include "lpoe/model/statistics.h"
#include "loaded_cobot6.h"

namespace lpoe {
namespace {
namespace problem_builder_test {

constexpr int kRows = 70;
constexpr double kNoiseSigma = 0.03;  // mm per axis, docs/conventions.md
// The builder's problem solved by the caller and CalibrateCeres agree to this (mm).
constexpr double kSameSolutionMm = 1e-9;
// One Gauss-Newton step of the builder's normal equations and of CalibrateLinear agree to this (mm).
constexpr double kSameStepMm = 1e-9;
// Prior test: pull one tool coordinate by this far (mm) with this standard deviation (mm).
constexpr double kPriorPullMm = 0.5;
constexpr double kPriorSigmaMm = 0.002;
// The nonlinear solution follows the linear prediction of the shift to this fraction.
constexpr double kPriorShiftTolerance = 1e-3;

MeasurementSet Simulate(const RobotModel& nominal, double sigma, int rows, uint64_t seed) {
  const KinematicErrors errors = PaperTable2Errors();
  SimulationOptions options;
  options.count = rows;
  options.noise_sigma = sigma;
  options.seed = seed;
  return SimulateMeasurements(ApplyErrors(nominal, errors), errors.joint_zero, options);
}

// The solver settings of CalibrateCeres (ceres_solver.h) for a caller's own solve.
ceres::Solver::Options SolverOptions() {
  ceres::Solver::Options o;
  o.linear_solver_type = ceres::DENSE_QR;
  o.minimizer_type = ceres::TRUST_REGION;
  o.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  o.max_num_iterations = 100;
  o.num_threads = 1;
  o.function_tolerance = 1e-15;
  o.gradient_tolerance = 1e-15;
  o.parameter_tolerance = 1e-13;
  o.logging_type = ceres::SILENT;
  return o;
}

double MaxPositionDifference(const RobotModel& a, const RobotModel& b, const MeasurementSet& d) {
  double worst = 0;
  for (int r = 0; r < d.size(); ++r) {
    const Eigen::Vector3d pa = ToolPose(a, d.q(r), d.target(r)).t;
    const Eigen::Vector3d pb = ToolPose(b, d.q(r), d.target(r)).t;
    worst = std::max(worst, (pa - pb).norm());
  }
  return worst;
}

// A caller's prior: tool translation coordinate `axis` (of the 7-number block) at `target`.
struct TranslationPrior {
  TranslationPrior(int axis, double target, double sigma)
      : axis(axis), target(target), sigma(sigma) {}
  template <typename T>
  bool operator()(const T* frame, T* residual) const {
    residual[0] = (frame[4 + axis] - T(target)) / T(sigma);
    return true;
  }
  int axis;
  double target, sigma;
};

TEST(ProblemBuilder, CallerSolveEqualsCalibrateCeres) {
  const RobotModel nominal = MakeCobot6();
  const MeasurementSet data = Simulate(nominal, kNoiseSigma, kRows, 3);
  CeresSolverOptions co;
  co.sigma = kNoiseSigma;
  co.num_threads = 1;
  // Ceres's own tolerances end both solves (the rules of convergence.h would end only ours).
  co.convergence.sd_fraction = 0;
  co.convergence.relative_step_tolerance = 0;
  co.convergence.relative_cost_tolerance = 0;
  co.convergence.step_tolerance = 1e-300;
  const CalibrationResult reference = CalibrateCeres(nominal, data, co);
  ASSERT_TRUE(reference.converged()) << reference.message;

  CalibrationProblemOptions po;
  po.sigma = kNoiseSigma;
  CalibrationProblem builder(nominal, data, po);
  ceres::Problem problem;
  const std::vector<ceres::ResidualBlockId> ids = builder.AddTo(&problem);
  EXPECT_EQ(static_cast<int>(ids.size()), data.size());
  EXPECT_EQ(problem.NumResidualBlocks(), data.size());
  EXPECT_EQ(problem.NumParameterBlocks(), nominal.num_frames());
  ceres::Solver::Summary summary;
  ceres::Solve(SolverOptions(), &problem, &summary);
  ASSERT_TRUE(summary.IsSolutionUsable()) << summary.message;
  EXPECT_LT(MaxPositionDifference(builder.Model(), reference.model, data), kSameSolutionMm);
  // The real errors were recovered (held-out check in ceres_solver_test): the fit is at noise level.
  EXPECT_LT(PositionErrorStatistics(builder.Model(), data).norm.rms, 3 * kNoiseSigma * std::sqrt(3));

  // The a-priori covariance of the caller's problem is CalibrateCeres's.
  Eigen::MatrixXd C;
  ASSERT_TRUE(builder.Covariance(&problem, 1, &C).ok());
  ASSERT_EQ(C.rows(), reference.covariance.rows());
  EXPECT_LT((C - reference.covariance).norm(), 1e-6 * reference.covariance.norm());

  // The normal equations' cost is Ceres's cost (same whitening).
  double cost = 0;
  problem.Evaluate(ceres::Problem::EvaluateOptions(), &cost, nullptr, nullptr, nullptr);
  EXPECT_NEAR(builder.NormalEquations().cost, cost, 1e-9 * cost);
}

// With joint-space terms (compliance + harmonics on data of an arm that deflects) and the blocks
// moved away from the start: the effective joint values from the reduction's slots are those of
// WithEffectiveJointValues on the terms' values, and the residuals of the rows AddTo builds (their
// regressors from the same slots) are the position errors at those joint values.
TEST(ProblemBuilder, JointSpaceRowsFromTheSlotsAreTheTerms) {
  const testing::LoadedCobot6 loaded = testing::MakeLoadedCobot6(150, kNoiseSigma, 5);
  const RobotModel& nominal = loaded.nominal;
  const MeasurementSet& data = loaded.data;
  CalibrationProblemOptions po;
  po.sigma = kNoiseSigma;
  for (const char* name : {"compliance", "harmonics"}) {
    std::shared_ptr<const JointTerm> term;
    ASSERT_TRUE(MakeJointTerm(name, nominal, &term).ok());
    po.joint_terms.push_back(term);
  }
  CalibrationProblem builder(nominal, data, po);
  const Parameterization solved = builder.SolvedParameterization();
  ASSERT_GT(solved.num_joint_parameters(), 0);
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> u(-1, 1);
  Eigen::VectorXd x(solved.num_parameters);
  for (int k = 0; k < x.size(); ++k) {
    x(k) = (k < solved.num_frame_parameters() ? 1e-4 : 1e-2) * u(rng);
  }
  builder.Update(x);

  const int n = nominal.num_joints();
  const std::vector<double> q_eff = builder.EffectiveJointValues();
  ASSERT_EQ(q_eff.size(), static_cast<size_t>(data.size()) * n);
  const MeasurementSet expected = WithEffectiveJointValues(builder.JointTerms(), data);
  double diff = 0, moved = 0;
  for (int r = 0; r < data.size(); ++r) {
    for (int j = 0; j < n; ++j) {
      diff = std::max(diff, std::abs(q_eff[r * n + j] - expected.q(r)[j]));
      moved = std::max(moved, std::abs(q_eff[r * n + j] - data.q(r)[j]));
    }
  }
  EXPECT_GT(moved, 1e-5);  // the terms shift the joints (rad)
  EXPECT_LT(diff, 1e-13);

  ceres::Problem problem;
  builder.AddTo(&problem);
  std::vector<double> residuals;
  ASSERT_TRUE(problem.Evaluate(ceres::Problem::EvaluateOptions(), nullptr, &residuals, nullptr,
                               nullptr));
  ASSERT_EQ(residuals.size(), static_cast<size_t>(3 * data.size()));
  const RobotModel model = builder.Model();
  double worst = 0;
  for (int r = 0; r < data.size(); ++r) {
    const Eigen::Vector3d e =
        ToolPosition(model, expected.q(r), data.target(r)) - data.position(r);
    for (int a = 0; a < 3; ++a) {
      worst = std::max(worst, std::abs(residuals[3 * r + a] * kNoiseSigma - e(a)));
    }
  }
  EXPECT_LT(worst, 1e-9);  // mm
}

TEST(ProblemBuilder, NormalEquationsAreTheLinearSolvers) {
  const RobotModel nominal = MakeCobot6();
  const MeasurementSet data = Simulate(nominal, kNoiseSigma, kRows, 4);
  LinearSolverOptions lo;
  lo.max_iterations = 1;
  const CalibrationResult one_step = CalibrateLinear(nominal, data, lo);
  ASSERT_EQ(one_step.iterations, 1);

  CalibrationProblem builder(nominal, data, CalibrationProblemOptions());
  const ProblemNormalEquations ne = builder.NormalEquations();
  ASSERT_TRUE(ne.finite);
  EXPECT_EQ(ne.names.size(), one_step.parameterization.parameters.size());
  for (size_t k = 0; k < ne.names.size(); ++k) {
    EXPECT_EQ(ne.names[k], one_step.parameterization.parameters[k].name);
  }
  EXPECT_TRUE(ne.H.isApprox(ne.H.transpose(), 1e-14));
  // Gauss-Newton: x = H^-1 g, with Jacobi column scaling as the linear solver.
  const Eigen::VectorXd d = ne.H.diagonal().cwiseSqrt().cwiseInverse();
  const Eigen::VectorXd x =
      d.asDiagonal() * (d.asDiagonal() * ne.H * d.asDiagonal()).llt().solve(d.asDiagonal() * ne.g);
  builder.Update(x);
  EXPECT_LT(MaxPositionDifference(builder.Model(), one_step.model, data), kSameStepMm);
  // The step reduced the cost by orders of magnitude (mm-level errors down to the noise).
  EXPECT_LT(builder.NormalEquations().cost, 1e-3 * ne.cost);

  // At the solution the normal matrix is the linear solver's: its covariance is s^2 H^-1.
  for (int it = 0; it < 10; ++it) {
    const ProblemNormalEquations step = builder.NormalEquations();
    builder.Update(step.H.ldlt().solve(step.g));
  }
  const CalibrationResult solved = CalibrateLinear(nominal, data, LinearSolverOptions());
  ASSERT_TRUE(solved.converged());
  const ProblemNormalEquations at = builder.NormalEquations();
  const double s2 = 2 * at.cost / (3.0 * data.size() - at.H.rows());
  const Eigen::MatrixXd covariance = s2 * at.H.inverse();
  EXPECT_LT((covariance - solved.covariance).norm(), 1e-6 * solved.covariance.norm());

  // The weighting: sigma scales H and g by 1 / sigma^2.
  CalibrationProblemOptions weighted;
  weighted.sigma = kNoiseSigma;
  CalibrationProblem w(nominal, data, weighted);
  const ProblemNormalEquations nw = w.NormalEquations();
  EXPECT_TRUE(nw.H.isApprox(ne.H / (kNoiseSigma * kNoiseSigma), 1e-12));
  EXPECT_TRUE(nw.g.isApprox(ne.g / (kNoiseSigma * kNoiseSigma), 1e-12));
}

TEST(ProblemBuilder, CallerPriorMovesTheSolutionAsPredicted) {
  const RobotModel nominal = MakeCobot6();
  const MeasurementSet data = Simulate(nominal, kNoiseSigma, kRows, 5);
  CalibrationProblemOptions po;
  po.sigma = kNoiseSigma;
  const int n = nominal.num_joints();

  // Unconstrained optimum x0 and its normal equations there (g ~ 0).
  CalibrationProblem free_builder(nominal, data, po);
  {
    ceres::Problem problem;
    free_builder.AddTo(&problem);
    ceres::Solver::Summary summary;
    ceres::Solve(SolverOptions(), &problem, &summary);
    ASSERT_TRUE(summary.IsSolutionUsable());
  }
  const ProblemNormalEquations ne = free_builder.NormalEquations();
  const double x0 = free_builder.frame_block(n)[4];  // tool x (mm); its rotation is not solved
  int k = -1;  // the parameter of the tool's x translation
  for (size_t i = 0; i < ne.parameterization.parameters.size(); ++i) {
    const Direction& dir = ne.parameterization.parameters[i];
    if (dir.frame == n && std::abs(dir.vector(3) - 1.0) < 1e-12) k = static_cast<int>(i);
  }
  ASSERT_GE(k, 0) << "no tool x direction";

  // The caller's problem: our residuals plus a prior on the tool's x.
  CalibrationProblem builder(nominal, data, po);
  ceres::Problem problem;
  builder.AddTo(&problem);
  const double target = x0 + kPriorPullMm;
  problem.AddResidualBlock(
      new ceres::AutoDiffCostFunction<TranslationPrior, 1, 7>(
          new TranslationPrior(0, target, kPriorSigmaMm)),
      nullptr, builder.frame_block(n));
  ceres::Solver::Summary summary;
  ceres::Solve(SolverOptions(), &problem, &summary);
  ASSERT_TRUE(summary.IsSolutionUsable());

  // Linear prediction: x = x0 + (H + w e_k e_k^T)^-1 w e_k d.
  Eigen::MatrixXd H = ne.H;
  const double w = 1.0 / (kPriorSigmaMm * kPriorSigmaMm);
  H(k, k) += w;
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(H.rows());
  rhs(k) = w * kPriorPullMm;
  const Eigen::VectorXd shift = H.ldlt().solve(rhs);
  const double moved = builder.frame_block(n)[4] - x0;
  EXPECT_GT(moved, 0.1 * kPriorPullMm);  // the prior pulls visibly...
  EXPECT_LT(moved, kPriorPullMm);        // ...against the data
  EXPECT_NEAR(moved, shift(k), kPriorShiftTolerance * kPriorPullMm);
  // The other parameters follow their correlation with the tool's x: the whole predicted shift.
  RobotModel predicted = free_builder.Model();
  ApplyUpdate(ne.parameterization, shift, &predicted);
  EXPECT_LT(MaxPositionDifference(builder.Model(), predicted, data),
            kPriorShiftTolerance * kPriorPullMm);

  // The covariance of the caller's problem counts the prior: (H + w e_k e_k^T)^-1.
  Eigen::MatrixXd C;
  ASSERT_TRUE(builder.Covariance(&problem, 1, &C).ok());
  const Eigen::MatrixXd expected = H.inverse();
  EXPECT_NEAR(C(k, k), expected(k, k), 1e-3 * expected(k, k));
  EXPECT_LT(C(k, k), 0.5 * ne.H.inverse()(k, k));  // the prior halves the variance at least
}

TEST(ProblemBuilder, CallerCanHoldFramesConstant) {
  const RobotModel nominal = MakeCobot6();
  const MeasurementSet data = Simulate(nominal, kNoiseSigma, kRows, 6);
  CalibrationProblem builder(nominal, data, CalibrationProblemOptions());
  ceres::Problem problem;
  builder.AddTo(&problem);
  problem.SetParameterBlockConstant(builder.frame_block(0));
  ceres::Solver::Summary summary;
  ceres::Solve(SolverOptions(), &problem, &summary);
  const RobotModel solved = builder.Model();
  EXPECT_TRUE(solved.joints[0].origin.t.isApprox(nominal.joints[0].origin.t, 0));
  EXPECT_GT((solved.joints[1].origin.t - nominal.joints[1].origin.t).norm(), 0.1);
}

TEST(ProblemBuilder, AnalyzeNamesWhatTheDataCannotIdentify) {
  const RobotModel nominal = MakeCobot6();
  const MeasurementSet data = Simulate(nominal, kNoiseSigma, kRows, 7);
  CalibrationProblem builder(nominal, data, CalibrationProblemOptions());
  const ProblemAnalysis a = builder.Analyze();
  EXPECT_TRUE(a.identifiable) << a.message;
  EXPECT_EQ(a.num_parameters, 27);  // 6 x 4 + 3 (docs/conventions.md)
  EXPECT_EQ(a.rank, 27);
  EXPECT_EQ(a.unidentifiable.size(), 15u);  // 6 x 2 + 3
  for (const Direction& d : a.unidentifiable) EXPECT_FALSE(d.reason.empty()) << d.name;

  // One pose measured over and over: enough equations, rank 3.
  MeasurementSet same(nominal.num_joints());
  for (int r = 0; r < kRows; ++r) same.Add(data.q(0), data.position(0), 0);
  CalibrationProblem poor(nominal, same, CalibrationProblemOptions());
  const ProblemAnalysis b = poor.Analyze();
  EXPECT_FALSE(b.identifiable);
  EXPECT_LT(b.rank, 27);
  EXPECT_GT(b.condition_number, 1e8);
  EXPECT_NE(b.message.find("cannot identify"), std::string::npos) << b.message;
  EXPECT_FALSE(b.weakest.empty());
  // ceres::Covariance fails on that problem, and the builder says so instead of returning garbage.
  ceres::Problem degenerate;
  poor.AddTo(&degenerate);
  Eigen::MatrixXd C;
  const Status cov = poor.Covariance(&degenerate, 1, &C);
  EXPECT_FALSE(cov.ok());
  EXPECT_NE(cov.message().find("rank-deficient"), std::string::npos) << cov.message();
  const MeasurementSet three = data.Subset({0, 1, 2});
  CalibrationProblem too_few(nominal, three, CalibrationProblemOptions());
  EXPECT_FALSE(too_few.Analyze().identifiable);
  EXPECT_FALSE(too_few.Analyze().message.empty());

  CalibrationProblemOptions bad;
  bad.loss = "square";
  EXPECT_NE(ValidateCalibrationProblem(nominal, data, bad).message().find("loss"),
            std::string::npos);
  bad = CalibrationProblemOptions();
  bad.use_orientation = true;
  EXPECT_FALSE(ValidateCalibrationProblem(nominal, data, bad).ok());
}

}  // namespace problem_builder_test
}  // namespace
}  // namespace lpoe
