// The stopping rules of convergence.h: large-residual data (0.4 mm noise plus an unmodelled
// joint-dependent error, as real robots leave after a geometric calibration) make Gauss-Newton
// converge linearly; both solvers must still end "converged" within a few iterations, and the last
// row of the history must carry the step the message quotes.
#include "lpoe/convergence.h"

#include <cmath>
#include <cstdio>
#include <random>
#include <string>

#include <Eigen/Cholesky>
#include <Eigen/LU>
#include <gtest/gtest.h>

#include "lpoe/ceres_solver.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/linear_solver.h"
#include "lpoe/model/simulation.h"
#include "lpoe/model/statistics.h"

namespace lpoe {
namespace {
namespace convergence_test {

constexpr int kPoses = 1500;
constexpr double kNoiseMm = 0.4;
// Unmodelled joint-dependent error: each joint is off by this amplitude times (sin 2q + cos q)
// (rad), as gear harmonics would: about 1.8 mm mean error left after the calibration. With joint
// ranges of +-0.5 rad (a robot measured near one working posture) Gauss-Newton then converges
// linearly, each step about 0.02 times the previous.
constexpr double kHarmonicRad = 1e-2;
constexpr double kJointRange = 0.5;
// "A few" iterations: the real data settled after about 5.
constexpr int kFewIterations = 5;

struct LargeResidualData {
  RobotModel nominal;
  MeasurementSet data;
};

LargeResidualData MakeLargeResidualData() {
  LargeResidualData d;
  d.nominal = MakeCobot6();
  const RobotModel actual = ApplyErrors(d.nominal, PaperTable2Errors());
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> angle(-kJointRange, kJointRange);
  std::normal_distribution<double> noise(0.0, kNoiseMm);
  d.data = MeasurementSet(d.nominal.num_joints());
  std::vector<double> q(6), qa(6);
  for (int r = 0; r < kPoses; ++r) {
    for (int j = 0; j < 6; ++j) {
      q[j] = angle(rng);
      qa[j] = q[j] + kHarmonicRad * (std::sin(2 * q[j]) + std::cos(q[j]));
    }
    Eigen::Vector3d p = ToolPosition(actual, qa.data(), 0);
    for (int a = 0; a < 3; ++a) p(a) += noise(rng);
    d.data.Add(q.data(), p);
  }
  return d;
}

const LargeResidualData& Data() {
  static const LargeResidualData* d = new LargeResidualData(MakeLargeResidualData());
  return *d;
}

// The figure "|x| = <v>" of a message, as printed with %.3g.
std::string Quoted(double v) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), "|x| = %.3g", v);
  return buf;
}

TEST(Convergence, LinearSolverConvergesOnLargeResidualData) {
  const LargeResidualData& d = Data();
  const CalibrationResult r = CalibrateLinear(d.nominal, d.data);
  ASSERT_EQ(r.termination, Termination::kConverged) << r.message;
  EXPECT_LE(r.iterations, kFewIterations) << r.message;
  EXPECT_NE(r.stop_rule, StopRule::kAbsoluteStep) << r.message;
  // The residual is the noise plus the unmodelled error, not less.
  const double rms = PositionErrorStatistics(r.model, d.data).norm.rms;
  EXPECT_GT(rms, std::sqrt(3.0) * kNoiseMm * 0.9);
  EXPECT_NE(r.message.find(Quoted(r.history.back().step_norm)), std::string::npos)
      << r.message;
}

TEST(Convergence, TheAbsoluteRuleAloneNeedsManyMoreIterations) {
  // The old behaviour: the absolute rule alone waits for |x| < 1e-10 while the solution has long
  // settled (fails if the data converged quadratically, i.e. if this were not a linear case).
  const LargeResidualData& d = Data();
  LinearSolverOptions o;
  o.convergence.sd_fraction = 0;
  o.convergence.relative_step_tolerance = 0;
  o.convergence.relative_cost_tolerance = -1;  // off (not a valid user setting)
  const CalibrationResult r = CalibrateLinear(d.nominal, d.data, o);
  std::string s;
  for (const auto& h : r.history) s += std::to_string(h.step_norm) + " ";
  ASSERT_EQ(r.termination, Termination::kConverged) << r.message << s;
  EXPECT_GT(r.iterations, kFewIterations + 1) << r.message;
  // Linear convergence: the step shrinks by a roughly constant ratio, far from quadratic.
  const auto& h = r.history;
  ASSERT_GE(h.size(), 7u);
  for (int k = 3; k <= 5; ++k) {
    const double ratio = h[k + 1].step_norm / h[k].step_norm;
    EXPECT_GT(ratio, 1e-3) << k;
    EXPECT_LT(ratio, 0.5) << k;
  }
  // The new rules stop where the old one would have stopped, within the noise.
  const CalibrationResult fast = CalibrateLinear(d.nominal, d.data);
  double worst = 0;
  for (int row = 0; row < d.data.size(); row += 7) {
    worst = std::max(worst, (ToolPosition(fast.model, d.data.q(row), 0) -
                             ToolPosition(r.model, d.data.q(row), 0)).norm());
  }
  EXPECT_LT(worst, 1e-3 * kNoiseMm);
}

TEST(Convergence, CeresConvergesOnLargeResidualDataToTheSameSolution) {
  const LargeResidualData& d = Data();
  CeresSolverOptions o;
  o.num_threads = 1;
  o.max_iterations = 30;
  const CalibrationResult c = CalibrateCeres(d.nominal, d.data, o);
  ASSERT_EQ(c.termination, Termination::kConverged) << c.message;
  EXPECT_LE(c.iterations, kFewIterations) << c.message;
  const CalibrationResult l = CalibrateLinear(d.nominal, d.data);
  ASSERT_TRUE(l.converged());
  // Both stopped well within a standard deviation of the minimum: their predictions agree far
  // below the noise.
  double worst = 0;
  for (int r = 0; r < d.data.size(); r += 7) {
    worst = std::max(worst, (ToolPosition(c.model, d.data.q(r), 0) -
                             ToolPosition(l.model, d.data.q(r), 0)).norm());
  }
  EXPECT_LT(worst, 0.01 * kNoiseMm);
}

TEST(Convergence, RulesFireOnTheirOwnQuantities) {
  ConvergenceOptions o;
  ConvergenceState s;
  s.step = Eigen::VectorXd::Constant(3, 1e-3);
  s.parameter_scale = 1000;
  s.cost = 100;
  EXPECT_FALSE(TestConvergence(o, s).converged());
  s.standard_deviation = Eigen::VectorXd::Constant(3, 1.0);  // step 1e-3 sd
  EXPECT_EQ(TestConvergence(o, s).rule, StopRule::kStatisticalStep);
  s.standard_deviation.resize(0);
  s.previous_cost = 100 + 1e-11;
  EXPECT_EQ(TestConvergence(o, s).rule, StopRule::kCost);
  s.previous_cost = 101;
  EXPECT_FALSE(TestConvergence(o, s).converged());
  s.step = Eigen::VectorXd::Constant(3, 1e-11);
  EXPECT_EQ(TestConvergence(o, s).rule, StopRule::kAbsoluteStep);
  o.step_tolerance = 1e-20;
  EXPECT_EQ(TestConvergence(o, s).rule, StopRule::kRelativeStep);
}

TEST(Convergence, StandardDeviationsOfAKnownProblem) {
  // y = x + noise, two parameters, H = diag(4, 1) (4 and 1 equations' worth), cost 0.5 * 6 * s^2.
  Eigen::MatrixXd H = Eigen::Vector2d(4, 1).asDiagonal();
  const Eigen::VectorXd sd = StandardDeviations(H, 0.5 * 6 * 0.25, 6);
  ASSERT_EQ(sd.size(), 2);
  EXPECT_NEAR(sd(0), 0.5 * 0.5, 1e-12);
  EXPECT_NEAR(sd(1), 0.5, 1e-12);
  EXPECT_EQ(StandardDeviations(H, 1.0, 0).size(), 0);
  EXPECT_TRUE(ValidateConvergenceOptions(ConvergenceOptions()).empty());
  ConvergenceOptions bad;
  bad.step_tolerance = INFINITY;
  EXPECT_FALSE(ValidateConvergenceOptions(bad).empty());
}

// A dense, badly scaled H: the standard deviations (the diagonal of the inverse from the Cholesky
// factor alone) equal those of the whole inverse.
TEST(Convergence, StandardDeviationsOfADenseProblemEqualTheWholeInverses) {
  std::mt19937 rng(5);
  std::normal_distribution<double> normal;
  const int rows = 120, P = 40;
  Eigen::MatrixXd J(rows, P);
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < P; ++c) J(r, c) = normal(rng) * std::pow(10.0, (c % 7) - 3);
  }
  const Eigen::MatrixXd H = J.transpose() * J;
  const double cost = 3.7;
  const long dof = rows - P;
  const Eigen::VectorXd sd = StandardDeviations(H, cost, dof);
  ASSERT_EQ(sd.size(), P);
  const Eigen::MatrixXd inverse = H.fullPivLu().inverse();
  for (int k = 0; k < P; ++k) {
    const double expected = std::sqrt(2.0 * cost / dof * inverse(k, k));
    EXPECT_NEAR(sd(k), expected, 1e-9 * expected) << k;
  }
  // From a factor the caller has (the linear solver's step), under another scale: the same.
  Eigen::VectorXd d(P);
  for (int k = 0; k < P; ++k) d(k) = (1 + 0.5 * (k % 3)) / std::sqrt(H(k, k));
  const Eigen::MatrixXd Hs = d.asDiagonal() * H * d.asDiagonal();
  const Eigen::LLT<Eigen::MatrixXd> llt(Hs);
  ASSERT_EQ(llt.info(), Eigen::Success);
  const Eigen::VectorXd from_factor = StandardDeviationsFromFactor(llt.matrixLLT(), d, cost, dof);
  ASSERT_EQ(from_factor.size(), P);
  for (int k = 0; k < P; ++k) EXPECT_NEAR(from_factor(k), sd(k), 1e-9 * sd(k)) << k;
  EXPECT_EQ(StandardDeviationsFromFactor(llt.matrixLLT(), d, cost, 0).size(), 0);
  // The whole inverse from the same factor (the linear solver's covariance).
  const Eigen::MatrixXd inverse_s = InverseFromCholeskyFactor(llt.matrixLLT());
  const Eigen::MatrixXd expected_s = Hs.fullPivLu().inverse();
  EXPECT_EQ(inverse_s, inverse_s.transpose());
  EXPECT_LE((inverse_s - expected_s).cwiseAbs().maxCoeff(), 1e-9 * expected_s.cwiseAbs().maxCoeff());
  for (int k = 0; k < P; ++k) {
    EXPECT_NEAR(inverse_s(k, k), expected_s(k, k), 1e-9 * expected_s(k, k)) << k;
  }
}

}  // namespace convergence_test
}  // namespace
}  // namespace lpoe
