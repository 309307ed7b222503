// Issue 42, the linear solver as a Gauss-Newton loop over the one CalibrationProblem
// (solvers/src/calibration/solve_on_problem.h, lpoe/problem_builder.h): the problem's state is the
// solver's (Update exact, undone by SetValues), CalibrateLinear is the loop on the problem its
// options describe, and both solvers' identifiability checks are the problem's one function.
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <gtest/gtest.h>

#include "calibration/solve_on_problem.h"
#include "lpoe/ceres_solver.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/linear_solver.h"
#include "lpoe/problem_builder.h"
#include "lpoe/model/simulation.h"
#include "lpoe/model/statistics.h"

namespace lpoe {
namespace {
namespace linear_problem_test {

constexpr int kRows = 70;
constexpr double kNoiseSigma = 0.03;  // mm per axis, docs/conventions.md

MeasurementSet Simulate(const RobotModel& nominal, int rows, uint64_t seed) {
  const KinematicErrors errors = PaperTable2Errors();
  SimulationOptions options;
  options.count = rows;
  options.noise_sigma = kNoiseSigma;
  options.seed = seed;
  return SimulateMeasurements(ApplyErrors(nominal, errors), errors.joint_zero, options);
}

bool SameFrames(const RobotModel& a, const RobotModel& b) {
  if (a.num_frames() != b.num_frames()) return false;
  const int n = a.num_joints();
  for (int f = 0; f < a.num_frames(); ++f) {
    const SE3d& x = f < n ? a.joints[f].origin : a.tools[f - n].origin;
    const SE3d& y = f < n ? b.joints[f].origin : b.tools[f - n].origin;
    if (!(x.R == y.R && x.t == y.t)) return false;
  }
  return true;
}

// The loop on a problem built by the caller (the pipeline's way) is CalibrateLinear bit for bit,
// and leaves the problem at the solution; the solution recovers the simulated errors (the fit is
// at the noise level).
TEST(LinearProblem, SolveOnTheProblemIsCalibrateLinearAndLeavesItThere) {
  const RobotModel nominal = MakeCobot6();
  const MeasurementSet data = Simulate(nominal, kRows, 5);
  LinearSolverOptions lo;
  const CalibrationResult reference = CalibrateLinear(nominal, data, lo);
  ASSERT_TRUE(reference.converged()) << reference.message;
  EXPECT_LT(PositionErrorStatistics(reference.model, data).norm.rms,
            3 * kNoiseSigma * std::sqrt(3.0));

  CalibrationProblem problem(nominal, data, CalibrationProblemOptions());
  const CalibrationResult on = internal::CalibrateLinearOn(&problem, lo);
  ASSERT_TRUE(on.converged()) << on.message;
  EXPECT_TRUE(SameFrames(on.model, reference.model));
  EXPECT_EQ(on.final_cost, reference.final_cost);
  EXPECT_EQ(on.iterations, reference.iterations);
  ASSERT_EQ(on.history.size(), reference.history.size());
  for (size_t k = 0; k < on.history.size(); ++k) {
    EXPECT_EQ(on.history[k].cost, reference.history[k].cost) << k;
  }
  EXPECT_EQ(on.covariance, reference.covariance);
  EXPECT_TRUE(SameFrames(problem.Model(), on.model));
  // The problem's own normal equations at the solution: the gradient vanishes (a minimum).
  const ProblemNormalEquations ne = problem.NormalEquations();
  const Eigen::VectorXd d = ne.H.diagonal().cwiseSqrt().cwiseInverse();
  EXPECT_LT((d.asDiagonal() * ne.g).norm(), 1e-4 * std::sqrt(2.0 * ne.cost));
}

// Update applies the step to the frames exactly (the model it returns is ApplyUpdate's, bit for
// bit), SetValues undoes it, and a block changed from outside (Ceres writes the 7 numbers) is read
// from its values.
TEST(LinearProblem, UpdateIsExactAndUndone) {
  const RobotModel nominal = MakeCobot6();
  const MeasurementSet data = Simulate(nominal, kRows, 6);
  CalibrationProblem problem(nominal, data, CalibrationProblemOptions());
  const Parameterization& p = problem.SolvedParameterization();
  Eigen::VectorXd x(p.num_parameters);
  for (int k = 0; k < x.size(); ++k) x(k) = 1e-3 * std::sin(1.0 + k);  // rad or mm
  const CalibrationProblem::Values start = problem.values();
  RobotModel expected = nominal;
  ApplyUpdate(p, x, &expected);
  problem.Update(x);
  EXPECT_TRUE(SameFrames(problem.Model(), expected));
  EXPECT_FALSE(SameFrames(problem.Model(), nominal));
  // A second step from there, as the solver's next iteration.
  ApplyUpdate(p, 0.5 * x, &expected);
  problem.Update(0.5 * x);
  EXPECT_TRUE(SameFrames(problem.Model(), expected));
  problem.SetValues(start);
  EXPECT_TRUE(SameFrames(problem.Model(), nominal));
  // Frame 1's block moved by 1 mm along x from outside: the model follows the block's values.
  double* block = problem.frame_block(1);
  ASSERT_NE(block, nullptr);
  block[4] += 1.0;
  const RobotModel moved = problem.Model();
  EXPECT_NEAR((moved.joints[1].origin.t - nominal.joints[1].origin.t).norm(), 1.0, 1e-12);
  EXPECT_TRUE(moved.joints[2].origin.t == nominal.joints[2].origin.t);
  // SetFrames puts every frame at a given model's, exactly.
  problem.SetFrames(expected);
  EXPECT_TRUE(SameFrames(problem.Model(), expected));
}

// One identifiability check: the linear solver's refusal is the problem's (CalibrationProblem::
// AnalyzeNormalMatrix on the solver's linearization), the same numbers and message as Analyze()
// (the Ceres solver's) on the same problem, and both solvers refuse data of one pose alike.
TEST(LinearProblem, OneIdentifiabilityCheckForBothSolvers) {
  const RobotModel nominal = MakeCobot6();
  const MeasurementSet data = Simulate(nominal, kRows, 7);
  MeasurementSet same(nominal.num_joints());
  for (int r = 0; r < kRows; ++r) same.Add(data.q(r % 2), data.position(r % 2), 0);
  LinearSolverOptions lo;
  const CalibrationResult linear = CalibrateLinear(nominal, same, lo);
  EXPECT_EQ(linear.termination, Termination::kNotIdentifiable);
  CeresSolverOptions co;
  co.num_threads = 1;
  const CalibrationResult ceres = CalibrateCeres(nominal, same, co);
  EXPECT_EQ(ceres.termination, Termination::kNotIdentifiable);
  CalibrationProblem poor(nominal, same, CalibrationProblemOptions());
  const ProblemAnalysis a = poor.Analyze();
  const ProblemAnalysis b = poor.AnalyzeNormalMatrix(poor.NormalEquations().H);
  EXPECT_FALSE(a.identifiable);
  EXPECT_FALSE(b.identifiable);
  EXPECT_EQ(a.rank, b.rank);
  EXPECT_EQ(linear.rank, a.rank);
  EXPECT_EQ(ceres.rank, a.rank);
  EXPECT_LT(a.rank, a.num_parameters);
  EXPECT_EQ(linear.message, a.message);
  EXPECT_EQ(ceres.message, a.message);
  EXPECT_NE(a.message.find("cannot identify"), std::string::npos) << a.message;

  // Identifiable data: the linear solver reports the problem's rank and condition number.
  CalibrationProblem good(nominal, data, CalibrationProblemOptions());
  const ProblemAnalysis g = good.Analyze();
  ASSERT_TRUE(g.identifiable) << g.message;
  const CalibrationResult solved = CalibrateLinear(nominal, data, lo);
  ASSERT_TRUE(solved.converged()) << solved.message;
  EXPECT_EQ(solved.rank, g.rank);
  EXPECT_NEAR(solved.condition_number, g.condition_number, 1e-9 * g.condition_number);
}

}  // namespace linear_problem_test
}  // namespace
}  // namespace lpoe
