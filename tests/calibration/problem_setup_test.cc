// One calibration problem: what is estimated is decided once (internal::SetUpProblem,
// solvers/src/calibration/problem_setup.h) and both solvers read it. With an unmeasured tool, the
// compliance term and the gravity tilt, CalibrateLinear, CalibrateCeres and CalibrationProblem solve
// the same directions (names, offsets, bases, the ones left out with their reasons); leaving the
// unmeasured tool out before or after the tilt is added gives the same list; the prior is anchored
// at the start model and resolved once, for the identifiable parameterization only.
#include <memory>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "calibration/problem_setup.h"
#include "identifiability/identifiability.h"
#include "lpoe/ceres_solver.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/linear_solver.h"
#include "lpoe/problem_builder.h"
#include "lpoe/model/simulation.h"

namespace lpoe {
namespace {
namespace problem_setup_test {

// cobot6 with a payload (gravity torques for the compliance term) and a second tool no row
// measures; 150 rows of the first tool from the paper's errors with 0.03 mm noise.
struct Fixture {
  RobotModel nominal = MakeCobot6();
  MeasurementSet data{6};
  std::shared_ptr<const JointTerm> compliance;
  Fixture() {
    nominal.payload.mass = 1.0;
    nominal.payload.com = Eigen::Vector3d(0, 0, 50);
    Tool spare;
    spare.name = "spare";
    spare.origin = SE3d(Eigen::Matrix3d::Identity(), Eigen::Vector3d(-50, 10, 70));
    nominal.tools.push_back(spare);
    KinematicErrors errors = PaperTable2Errors();
    errors.frame.push_back(Vector6d::Zero());
    const RobotModel actual = ApplyErrors(nominal, errors);
    SimulationOptions options;
    options.count = 150;
    options.noise_sigma = 0.03;
    options.seed = 42;
    data = SimulateMeasurements(actual, errors.joint_zero, options);
    EXPECT_TRUE(MakeJointTerm("compliance", nominal, &compliance).ok());
  }
};

void ExpectSameDirections(const Parameterization& a, const Parameterization& b) {
  ASSERT_EQ(a.num_parameters, b.num_parameters);
  ASSERT_EQ(a.basis.size(), b.basis.size());
  for (size_t f = 0; f < a.basis.size(); ++f) {
    EXPECT_EQ(a.offset[f], b.offset[f]) << f;
    ASSERT_EQ(a.basis[f].cols(), b.basis[f].cols()) << f;
    EXPECT_TRUE(a.basis[f] == b.basis[f]) << f;
  }
  ASSERT_EQ(a.joint_blocks.size(), b.joint_blocks.size());
  for (size_t k = 0; k < a.joint_blocks.size(); ++k) {
    EXPECT_EQ(a.joint_blocks[k].term->name(), b.joint_blocks[k].term->name());
    EXPECT_EQ(a.joint_blocks[k].offset, b.joint_blocks[k].offset);
    ASSERT_EQ(a.joint_blocks[k].basis.cols(), b.joint_blocks[k].basis.cols());
    EXPECT_TRUE(a.joint_blocks[k].basis == b.joint_blocks[k].basis);
  }
  ASSERT_EQ(a.bilinear_blocks.size(), b.bilinear_blocks.size());
  for (size_t i = 0; i < a.bilinear_blocks.size(); ++i) {
    EXPECT_EQ(a.bilinear_blocks[i].effect, b.bilinear_blocks[i].effect);
    EXPECT_EQ(a.bilinear_blocks[i].partner, b.bilinear_blocks[i].partner);
    EXPECT_EQ(a.bilinear_blocks[i].offset, b.bilinear_blocks[i].offset);
  }
  ASSERT_EQ(a.parameters.size(), b.parameters.size());
  for (size_t k = 0; k < a.parameters.size(); ++k) {
    EXPECT_EQ(a.parameters[k].name, b.parameters[k].name);
  }
  ASSERT_EQ(a.unidentifiable.size(), b.unidentifiable.size());
  for (size_t k = 0; k < a.unidentifiable.size(); ++k) {
    EXPECT_EQ(a.unidentifiable[k].name, b.unidentifiable[k].name);
    EXPECT_EQ(a.unidentifiable[k].reason, b.unidentifiable[k].reason);
  }
}

int ListedAsNeverMeasured(const Parameterization& p) {
  int n = 0;
  for (const Direction& d : p.unidentifiable) {
    n += d.name.rfind("spare.", 0) == 0 && d.reason.find("never measured") != std::string::npos;
  }
  return n;
}

TEST(ProblemSetup, BothSolversEstimateTheSameDirections) {
  const Fixture f;
  // The compliance solution the tilt starts from (its columns vanish at zero compliance).
  LinearSolverOptions lo;
  lo.joint_terms = {f.compliance};
  const CalibrationResult first = CalibrateLinear(f.nominal, f.data, lo);
  ASSERT_TRUE(first.converged()) << first.message;
  EXPECT_EQ(ListedAsNeverMeasured(first.parameterization), 3);  // the spare tool's translations
  lo.bilinear_effects = {std::make_shared<const GravityTiltModel>(f.nominal)};
  lo.initial_joint_terms = first.joint_terms;
  CeresSolverOptions co;
  co.joint_terms = lo.joint_terms;
  co.bilinear_effects = lo.bilinear_effects;
  co.initial_joint_terms = lo.initial_joint_terms;
  const CalibrationResult lin = CalibrateLinear(f.nominal, f.data, lo);
  const CalibrationResult cer = CalibrateCeres(f.nominal, f.data, co);
  ASSERT_EQ(lin.parameterization.bilinear_blocks.size(), 1u) << lin.message;
  EXPECT_EQ(ListedAsNeverMeasured(lin.parameterization), 3);
  ExpectSameDirections(lin.parameterization, cer.parameterization);

  CalibrationProblemOptions po;
  po.joint_terms = lo.joint_terms;
  po.bilinear_effects = lo.bilinear_effects;
  po.initial_joint_terms = lo.initial_joint_terms;
  const CalibrationProblem problem(f.nominal, f.data, po);
  ASSERT_TRUE(problem.block_status().ok()) << problem.block_status().message();
  ExpectSameDirections(problem.SolvedParameterization(), lin.parameterization);
  // The spare tool is not solved; every joint and the measured tool are.
  const int n = f.nominal.num_joints();
  for (int j = 0; j < n; ++j) EXPECT_TRUE(problem.frame_solved(j));
  EXPECT_TRUE(problem.frame_solved(n));
  EXPECT_FALSE(problem.frame_solved(n + 1));
}

TEST(ProblemSetup, UnmeasuredToolsLeftOutBeforeOrAfterTheTilt) {
  const Fixture f;
  LinearSolverOptions lo;
  lo.joint_terms = {f.compliance};
  lo.bilinear_effects = {std::make_shared<const GravityTiltModel>(f.nominal)};
  const internal::ProblemSetup s =
      internal::SetUpProblem(f.nominal, f.data, internal::ProblemSetupRequestOf(lo));
  ASSERT_TRUE(s.block_status.ok()) << s.block_status.message();
  ASSERT_EQ(s.all.bilinear_blocks.size(), 1u);
  // `all` keeps the spare tool's basis; the solved list has it left out, as if it were left out
  // after the tilt was added.
  EXPECT_GT(s.all.num_parameters, s.solved.num_parameters);
  Parameterization after = s.all;
  internal::LeaveOutUnmeasuredTools(f.nominal, f.data, &after);
  ExpectSameDirections(s.solved, after);
  EXPECT_EQ(s.identifiable, s.solved.num_parameters);  // no gauge: identifiable parameterization
  EXPECT_EQ(s.equations, 3L * f.data.size());
  EXPECT_EQ(s.initial_joint_state.size(), s.solved.num_joint_parameters());
}

TEST(ProblemSetup, PriorAnchoredAtTheStartForTheIdentifiableParameterizationOnly) {
  const Fixture f;
  LinearSolverOptions lo;
  lo.prior = std::make_shared<const ParameterPrior>();
  const internal::ProblemSetup s =
      internal::SetUpProblem(f.nominal, f.data, internal::ProblemSetupRequestOf(lo));
  ASSERT_TRUE(s.prior.active);
  ASSERT_TRUE(s.anchored_prior && s.anchored_prior->reference);
  for (int j = 0; j < f.nominal.num_joints(); ++j) {
    EXPECT_TRUE(s.prior.reference.joints[j].origin.t == f.nominal.joints[j].origin.t);
  }
  EXPECT_EQ(s.prior.frame_sqrt.size(), static_cast<size_t>(f.nominal.num_frames()));
  // The Ceres side: the problem resolves the same prior.
  CalibrationProblemOptions po;
  po.prior = lo.prior;
  const CalibrationProblem problem(f.nominal, f.data, po);
  ASSERT_TRUE(problem.setup().prior.active);
  for (size_t k = 0; k < s.prior.frame_sqrt.size(); ++k) {
    EXPECT_TRUE(problem.setup().prior.frame_sqrt[k] == s.prior.frame_sqrt[k]) << k;
  }
  // The full parameterization stays the paper's pseudo-inverse: no prior.
  lo.parameterization = ParameterizationKind::kFull;
  const internal::ProblemSetup full =
      internal::SetUpProblem(f.nominal, f.data, internal::ProblemSetupRequestOf(lo));
  EXPECT_FALSE(full.prior.active);
  EXPECT_TRUE(full.full);
  EXPECT_LT(full.identifiable, full.solved.num_parameters);  // the gauge directions
}

}  // namespace problem_setup_test
}  // namespace
}  // namespace lpoe
