// The batched position residual block (solvers/src/linearization/batched_residual.h): its Jacobian against
// numeric differentiation (ceres::GradientChecker, through the manifolds), and calibrations with
// batched blocks against one block per row.
#include "linearization/batched_residual.h"

#include <memory>
#include <random>
#include <vector>

#include <ceres/ceres.h>
#include <gtest/gtest.h>

#include "lpoe/ceres_solver.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/linear_solver.h"
#include "lpoe/problem_builder.h"
#include "lpoe/model/simulation.h"

namespace lpoe {
namespace {
namespace batched_residual_test {

constexpr double kNoiseSigma = 0.03;  // mm per axis, docs/conventions.md
// GradientChecker: the block's analytic Jacobian against numeric differentiation, relative.
constexpr double kGradientCheckPrecision = 1e-6;
// Batched and per-row calibrations give the same model to this (mm, predicted positions).
constexpr double kSameSolutionMm = 1e-9;

RobotModel TwoToolCobot() {
  RobotModel model = MakeCobot6();
  Tool second;
  second.name = "smr2";
  second.origin = SE3d(Eigen::Matrix3d::Identity(), Eigen::Vector3d(-40, 30, 60));
  model.tools.push_back(second);
  return model;
}

// Rows of the actual robot `actual` at random joint values, tools alternating, with noise.
MeasurementSet Measure(const RobotModel& actual, int rows, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> angle(-M_PI, M_PI);
  std::normal_distribution<double> noise(0, kNoiseSigma);
  MeasurementSet data(actual.num_joints());
  std::vector<double> q(actual.num_joints());
  for (int r = 0; r < rows; ++r) {
    for (double& v : q) v = angle(rng);
    const int tool = r % actual.num_tools();
    const Eigen::Vector3d P = ToolPosition(actual, q.data(), tool);
    data.Add(q.data(), P + Eigen::Vector3d{noise(rng), noise(rng), noise(rng)}, tool, r + 2);
  }
  return data;
}

double MaxPositionDifference(const RobotModel& a, const RobotModel& b, const MeasurementSet& d) {
  double worst = 0;
  for (int r = 0; r < d.size(); ++r) {
    worst = std::max(worst, (ToolPosition(a, d.q(r), d.target(r)) -
                             ToolPosition(b, d.q(r), d.target(r))).norm());
  }
  return worst;
}

TEST(BatchedPositionResidual, GradientCheckerPasses) {
  const RobotModel nominal = TwoToolCobot();
  // The blocks at a model away from the nominal one (the Jacobian is evaluated there).
  // (The blocks hold the frames; the joint axes come from the model the block is given.)
  const RobotModel at = ApplyErrors(nominal, RandomErrors(nominal, 0.05, 5.0, 0.05, 0.0, 17));
  const MeasurementSet data = Measure(at, 9, 4);
  const auto shared = std::make_shared<const RobotModel>(at);
  const int n = nominal.num_joints();
  for (ParameterizationKind kind :
       {ParameterizationKind::kIdentifiable, ParameterizationKind::kFull}) {
    const Parameterization p = MakeParameterization(nominal, kind, DataKind::kPosition);
    std::vector<int> frames;
    std::vector<std::vector<double>> blocks;
    std::vector<std::unique_ptr<Se3Manifold>> manifolds;
    std::vector<const ceres::Manifold*> manifold_pointers;
    for (int f = 0; f < nominal.num_frames(); ++f) {
      frames.push_back(f);
      blocks.emplace_back(kSe3AmbientSize);
      Se3ToArray(f < n ? at.joints[f].origin : at.tools[f - n].origin, blocks.back().data());
      manifolds.push_back(std::make_unique<Se3Manifold>(p.basis[f]));
      manifold_pointers.push_back(manifolds.back().get());
    }
    std::vector<const double*> pointers;
    for (const auto& b : blocks) pointers.push_back(b.data());
    // Rows 2..8: both tools, and a batch that does not start at row 0.
    internal::BatchedPositionResidual cost(shared, p, frames, data, 2, 9, 1.0 / kNoiseSigma);
    ASSERT_EQ(cost.num_residuals(), 21);
    ceres::NumericDiffOptions numeric;
    ceres::GradientChecker checker(&cost, &manifold_pointers, numeric);
    ceres::GradientChecker::ProbeResults results;
    EXPECT_TRUE(checker.Probe(pointers.data(), kGradientCheckPrecision, &results))
        << results.error_log;
    // The residuals are those of the model at the blocks: (P_model - P_measured) / sigma.
    for (int r = 2; r < 9; ++r) {
      const Eigen::Vector3d e =
          (ToolPosition(at, data.q(r), data.target(r)) - data.position(r)) / kNoiseSigma;
      for (int a = 0; a < 3; ++a) EXPECT_NEAR(results.residuals(3 * (r - 2) + a), e(a), 1e-9);
    }
  }
}

// CalibrateCeres with batches of rows (uneven last batch, two tools) finds the model it finds with
// one block per row, in both parameterizations.
TEST(BatchedPositionResidual, CalibrationEqualsOneBlockPerRow) {
  const RobotModel nominal = TwoToolCobot();
  // Frame errors of the size of the paper's Table 2 (1 mrad, 0.5 mm), joint zeros 2 mrad.
  const KinematicErrors errors = RandomErrors(nominal, 0.001, 0.5, 0.0, 0.002, 8);
  const MeasurementSet data = Measure(ApplyErrors(nominal, errors), 250, 5);
  for (ParameterizationKind kind :
       {ParameterizationKind::kIdentifiable, ParameterizationKind::kFull}) {
    CeresSolverOptions o;
    o.parameterization = kind;
    o.sigma = kNoiseSigma;
    o.num_threads = 2;
    // Ceres's own tolerances end both solves.
    o.convergence.sd_fraction = 0;
    o.convergence.relative_step_tolerance = 0;
    o.convergence.relative_cost_tolerance = 0;
    o.convergence.step_tolerance = 1e-300;
    o.rows_per_block = 1;
    const CalibrationResult per_row = CalibrateCeres(nominal, data, o);
    o.rows_per_block = 64;
    const CalibrationResult batched = CalibrateCeres(nominal, data, o);
    ASSERT_TRUE(per_row.converged()) << per_row.message;
    ASSERT_TRUE(batched.converged()) << batched.message;
    EXPECT_LT(MaxPositionDifference(per_row.model, batched.model, data), kSameSolutionMm);
    EXPECT_NEAR(batched.final_cost, per_row.final_cost, 1e-9 * per_row.final_cost);
    // The calibration did something: the nominal model is a good part of a millimetre off.
    EXPECT_GT(MaxPositionDifference(nominal, batched.model, data), 0.3);
    if (kind == ParameterizationKind::kIdentifiable) {
      ASSERT_EQ(batched.covariance.rows(), per_row.covariance.rows());
      EXPECT_LT((batched.covariance - per_row.covariance).norm(),
                1e-6 * per_row.covariance.norm());
    }
  }
}

// Rows are batched only where a block may hold many rows: position data, no robust loss (Ceres
// applies it to a block's whole squared norm), no joint-space terms.
TEST(BatchedPositionResidual, BuilderBatchesOnlyWithoutLossOrJointTerms) {
  const RobotModel nominal = TwoToolCobot();
  const MeasurementSet data = Measure(nominal, 100, 6);
  CalibrationProblemOptions o;
  o.rows_per_block = 32;
  {
    CalibrationProblem builder(nominal, data, o);
    EXPECT_EQ(builder.BatchedRows(), 32);
    ceres::Problem problem;
    EXPECT_EQ(builder.AddTo(&problem).size(), 4u);  // 32 + 32 + 32 + 4 rows
    EXPECT_EQ(problem.NumResiduals(), 300);
  }
  o.loss = "huber";
  {
    CalibrationProblem builder(nominal, data, o);
    EXPECT_EQ(builder.BatchedRows(), 1);
    ceres::Problem problem;
    EXPECT_EQ(builder.AddTo(&problem).size(), 100u);
  }
  o.loss = "none";
  std::shared_ptr<const JointTerm> compliance;
  ASSERT_TRUE(MakeJointTerm("compliance", nominal, &compliance).ok());
  o.joint_terms = {compliance};
  CalibrationProblem builder(nominal, data, o);
  EXPECT_EQ(builder.BatchedRows(), 1);
}

}  // namespace batched_residual_test
}  // namespace
}  // namespace lpoe
