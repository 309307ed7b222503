// Issue 11 (cost): the normal equations of joint-space terms formed by their structure (per row
// J_q^T J_q, J_frames^T J_q and the regressors' non-zero entries, solvers/src/linearization/normal_equations.h)
// equal the dense ones (rows with every column), for every term kind: compliance and harmonics
// (one joint per parameter), a term whose parameters move several joints, reduced bases, joint
// state away from zero, position and pose data. And the reduction of the terms chooses the same
// combinations as from the dense normal matrix.
#include <cmath>
#include <limits>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include <Eigen/QR>
#include <gtest/gtest.h>

#include "identifiability/identifiability.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/linear_solver.h"
#include "lpoe/model/parameterization.h"
#include "lpoe/model/simulation.h"
#include "linearization/normal_equations.h"
#include "coupled_joint_term.h"

namespace lpoe {
namespace {
namespace joint_normal_equations_test {

// Position rows, with the given joint-block options.
internal::NormalEquationsOptions PositionRows(const internal::JointColumnsOptions& joint = {}) {
  internal::NormalEquationsOptions o;
  o.joint = joint;
  return o;
}

// Pose rows (rotation weighted 1000 mm per rad) when `pose`, else position rows.
internal::NormalEquationsOptions Rows(bool pose, const internal::JointColumnsOptions& joint = {}) {
  internal::NormalEquationsOptions o = PositionRows(joint);
  o.use_orientation = pose;
  o.orientation_weight = 1000.0;
  return o;
}

constexpr double kRelative = 1e-9;

// Declares one joint per parameter but moves another one (a wrong ParameterJoint).
class LyingTerm : public JointTerm {
 public:
  explicit LyingTerm(int n) : n_(n) {}
  std::string name() const override { return "lying"; }
  int num_joints() const override { return n_; }
  int num_parameters() const override { return 1; }
  std::string ParameterName(int) const override { return "x"; }
  void Regressor(const double* q, double* Y) const override {
    for (int j = 0; j < n_; ++j) Y[j] = j == 1 ? q[0] : 0.0;
  }
  int ParameterJoint(int) const override { return 0; }

 private:
  int n_;
};

struct Data {
  RobotModel nominal = MakeCobot6();
  RobotModel model;  // a linearization point away from nominal
  MeasurementSet data;
  std::vector<std::shared_ptr<const JointTerm>> terms;
  explicit Data(bool pose, int count = 157) {
    nominal.payload.mass = 0.8;
    nominal.payload.com = Eigen::Vector3d(5, -3, 40);
    const KinematicErrors errors = RandomErrors(nominal, 2e-3, 0.5, 1e-3, 2e-3, 21);
    RobotModel actual = ApplyErrors(nominal, errors);
    ApplyJointErrorPhysics(SmallArmJointErrors(nominal, SmallArmOptions()), {"compliance", "harmonics"}, &actual);
    SimulationOptions options;
    options.count = count;  // 157: not a multiple of the accumulation's block of poses
    options.noise_sigma = 0.01;
    options.pose = pose;
    options.orientation_noise_sigma = pose ? 1e-5 : 0.0;
    options.seed = 5;
    data = SimulateMeasurements(actual, errors.joint_zero, options);
    model = ApplyErrors(nominal, RandomErrors(nominal, 1e-3, 0.2, 5e-4, 1e-3, 4));
    for (const char* name : {"compliance", "harmonics"}) {
      std::shared_ptr<const JointTerm> t;
      EXPECT_TRUE(MakeJointTerm(name, nominal, &t).ok());
      terms.push_back(t);
    }
    terms.push_back(std::make_shared<testing::CoupledJointTerm>(
        nominal.num_joints(), testing::CoupledJointTerm::Form::kProduct));
  }
};

Parameterization WithTerms(const Data& d, bool pose, bool reduce) {
  Parameterization p = MakeParameterization(
      d.nominal, ParameterizationKind::kIdentifiable, pose ? DataKind::kPose : DataKind::kPosition);
  for (const auto& t : d.terms) AddJointBlock(t, &p);
  if (!reduce) return p;
  // Random orthonormal bases keeping most of each block: combinations that mix parameters.
  std::mt19937 rng(11);
  std::normal_distribution<double> normal;
  for (size_t b = 0; b < p.joint_blocks.size(); ++b) {
    const int P = p.joint_blocks[b].term->num_parameters();
    const int k = std::max(1, P - 2 - static_cast<int>(b));
    Eigen::MatrixXd A(P, k);
    for (int i = 0; i < A.size(); ++i) A.data()[i] = normal(rng);
    const Eigen::MatrixXd Q = A.householderQr().householderQ() * Eigen::MatrixXd::Identity(P, k);
    SetJointBlockBasis(static_cast<int>(b), Q, "test", &p);
  }
  return p;
}

double RelativeDifference(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  return (a - b).cwiseAbs().maxCoeff() / b.cwiseAbs().maxCoeff();
}

void ExpectStructuredEqualsDense(bool pose, bool reduce) {
  const Data d(pose);
  const Parameterization p = WithTerms(d, pose, reduce);
  const int K = p.num_joint_parameters();
  ASSERT_GT(K, 0);
  std::mt19937 rng(3);
  std::normal_distribution<double> normal;
  // Joint state of deflection size (1e-4 rad offsets at most).
  Eigen::VectorXd x(K);
  for (int k = 0; k < K; ++k) x(k) = 1e-4 * normal(rng);
  const internal::JointSpaceRegressors regs = internal::BuildJointSpaceRegressors(p, d.data);
  // Every kind is present: single-joint slots and slots of a term that moves every joint.
  EXPECT_GT(regs.num_slots(), p.joint_blocks[0].basis.rows() / 2);
  for (const Eigen::VectorXd& state : {Eigen::VectorXd(), x}) {
    internal::JointColumnsOptions dense;
    dense.dense = true;
    internal::JointColumnsOptions structured;
    structured.regressors = &regs;
    const internal::NormalEquations a =
        internal::NormalEquationsOf(d.model, d.data, p, state, Rows(pose, dense));
    const internal::NormalEquations b =
        internal::NormalEquationsOf(d.model, d.data, p, state, Rows(pose, structured));
    ASSERT_TRUE(a.finite && b.finite);
    EXPECT_LE(RelativeDifference(b.H, a.H), kRelative);
    // Every block on its own scale (the joint blocks are far smaller than the frames').
    const int F = p.num_frame_parameters();
    EXPECT_LE(RelativeDifference(b.H.topRightCorner(F, K), a.H.topRightCorner(F, K)), kRelative);
    EXPECT_LE(RelativeDifference(b.H.bottomRightCorner(K, K), a.H.bottomRightCorner(K, K)),
              kRelative);
    EXPECT_LE(RelativeDifference(b.g, a.g), kRelative);
    EXPECT_LE(RelativeDifference(b.g.tail(K), a.g.tail(K)), kRelative);
    EXPECT_NEAR(b.cost, a.cost, kRelative * a.cost);
    EXPECT_NEAR(b.max_error, a.max_error, kRelative * a.max_error);
    EXPECT_NEAR(b.mean_error, a.mean_error, kRelative * a.mean_error);
    EXPECT_EQ(b.H, b.H.transpose());
    // Regressors not stored (above kMaxJointRowsBytes): evaluated per row, the same numbers.
    internal::JointSpaceRegressors unstored = regs;
    unstored.values.resize(0, 0);
    internal::JointColumnsOptions evaluated;
    evaluated.regressors = &unstored;
    const internal::NormalEquations u =
        internal::NormalEquationsOf(d.model, d.data, p, state, Rows(pose, evaluated));
    EXPECT_LE(RelativeDifference(u.H, b.H), 1e-14);
    EXPECT_LE(RelativeDifference(u.g, b.g), 1e-14);
    // Without regressors given, the same (built for the call).
    const internal::NormalEquations c =
        internal::NormalEquationsOf(d.model, d.data, p, state, Rows(pose));
    EXPECT_EQ(c.H, b.H);
    EXPECT_EQ(c.g, b.g);
    // Gradient only: the same gradient, cost and frames' block; the joint blocks left out.
    internal::JointColumnsOptions gradient = structured;
    gradient.gradient_only = true;
    const internal::NormalEquations e =
        internal::NormalEquationsOf(d.model, d.data, p, state, Rows(pose, gradient));
    EXPECT_FALSE(e.joint_blocks);
    EXPECT_EQ(e.g, b.g);
    EXPECT_EQ(e.cost, b.cost);
    EXPECT_EQ(e.H.topLeftCorner(F, F), b.H.topLeftCorner(F, F));
    EXPECT_EQ(e.H.rightCols(K).cwiseAbs().maxCoeff(), 0.0);
  }
}

TEST(JointNormalEquations, StructuredEqualsDensePositionWholeBlocks) {
  ExpectStructuredEqualsDense(false, false);
}
TEST(JointNormalEquations, StructuredEqualsDensePositionReducedBlocks) {
  ExpectStructuredEqualsDense(false, true);
}
TEST(JointNormalEquations, StructuredEqualsDensePoseReducedBlocks) {
  ExpectStructuredEqualsDense(true, true);
}

// The four-row path (position data on revolute-z joints with canonical frame columns, as the
// solver's parameterization of cobot6: the rows four poses at a time with J_q beside the frame
// columns, the slots' blocks from the per-pose products J_q^T y, J_q^T J_q and A^T J_q as dot
// products over groups of poses) equals the rows one at a time with the slot columns, every block
// on its own scale: whole blocks (the reduction's analysis) and the solver's reduced blocks, with
// the coupled term too (slots in every joint), a joint state away from zero, gradient only; 157
// poses (a partial block) and 2100 (two chunks of rows, each more than one group of poses), with
// stored and with evaluated regressors.
TEST(JointNormalEquations, FourRowPathEqualsRowByRow) {
  for (const int count : {157, 2100}) {
    const Data d(false, count);
    Parameterization whole;
    internal::SolverParameterizationRequest request;
    request.terms = {d.terms[0], d.terms[1]};
    request.analysed_parameterization = &whole;
    const Parameterization solver = internal::SolverParameterization(d.nominal, d.data, request);
    ASSERT_EQ(solver.joint_blocks.size(), 2u);
    // A linearization point away from nominal as the solver's iterations reach it (ApplyUpdate:
    // the frames move, the joints stay revolute about z; d.model's errors change the twists).
    RobotModel model = d.nominal;
    {
      std::mt19937 rng(9);
      std::normal_distribution<double> normal;
      Eigen::VectorXd step(solver.num_parameters);
      for (int k = 0; k < step.size(); ++k) step(k) = 1e-3 * normal(rng);
      step.tail(solver.num_joint_parameters()).setZero();
      ApplyUpdate(solver, step, &model);
    }
    for (const bool reduce : {false, true}) {
      Parameterization p = reduce ? solver : whole;
      AddJointBlock(d.terms[2], &p);  // coupled
      const int K = p.num_joint_parameters();
      const int F = p.num_frame_parameters();
      Eigen::VectorXd x(K);
      std::mt19937 rng(7);
      std::normal_distribution<double> normal;
      for (int k = 0; k < K; ++k) x(k) = 1e-4 * normal(rng);
      const internal::JointSpaceRegressors regs = internal::BuildJointSpaceRegressors(p, d.data);
      internal::JointSpaceRegressors unstored = regs;
      unstored.values.resize(0, 0);
      for (const Eigen::VectorXd& state : {Eigen::VectorXd(), x}) {
        for (const bool gradient_only : {false, true}) {
          SCOPED_TRACE(::testing::Message() << count << " poses, reduce " << reduce << ", state "
                                            << state.size() << ", gradient only "
                                            << gradient_only);
          internal::JointColumnsOptions four;
          four.regressors = &regs;
          four.gradient_only = gradient_only;
          internal::JointColumnsOptions rows = four;
          rows.four_rows = false;
          const internal::NormalEquations a =
              internal::NormalEquationsOf(model, d.data, p, state, PositionRows(rows));
          const internal::NormalEquations b =
              internal::NormalEquationsOf(model, d.data, p, state, PositionRows(four));
          ASSERT_TRUE(a.finite && b.finite);
          EXPECT_FALSE(a.four_rows);
          EXPECT_TRUE(b.four_rows) << "the four-row path no longer applies to cobot6";
          EXPECT_EQ(b.joint_blocks, !gradient_only);
          EXPECT_LE(RelativeDifference(b.H.topLeftCorner(F, F), a.H.topLeftCorner(F, F)),
                    kRelative);
          EXPECT_LE(RelativeDifference(b.g.head(F), a.g.head(F)), kRelative);
          EXPECT_LE(RelativeDifference(b.g.tail(K), a.g.tail(K)), kRelative);
          EXPECT_NEAR(b.cost, a.cost, kRelative * a.cost);
          EXPECT_NEAR(b.max_error, a.max_error, kRelative * a.max_error);
          EXPECT_NEAR(b.mean_error, a.mean_error, kRelative * a.mean_error);
          EXPECT_EQ(b.H, b.H.transpose());
          if (gradient_only) {
            EXPECT_EQ(b.H.rightCols(K).cwiseAbs().maxCoeff(), 0.0);
          } else {
            EXPECT_LE(RelativeDifference(b.H.topRightCorner(F, K), a.H.topRightCorner(F, K)),
                      kRelative);
            EXPECT_LE(
                RelativeDifference(b.H.bottomRightCorner(K, K), a.H.bottomRightCorner(K, K)),
                kRelative);
          }
          if (!gradient_only) {  // and the dense rows
            internal::JointColumnsOptions dense;
            dense.dense = true;
            const internal::NormalEquations e =
                internal::NormalEquationsOf(model, d.data, p, state, PositionRows(dense));
            EXPECT_LE(RelativeDifference(b.H.topRightCorner(F, K), e.H.topRightCorner(F, K)),
                      kRelative);
            EXPECT_LE(
                RelativeDifference(b.H.bottomRightCorner(K, K), e.H.bottomRightCorner(K, K)),
                kRelative);
            EXPECT_LE(RelativeDifference(b.g.tail(K), e.g.tail(K)), kRelative);
          }
          // Regressors evaluated per group of poses instead of stored: the same numbers.
          internal::JointColumnsOptions evaluated = four;
          evaluated.regressors = &unstored;
          const internal::NormalEquations u =
              internal::NormalEquationsOf(model, d.data, p, state, PositionRows(evaluated));
          EXPECT_TRUE(u.four_rows);
          EXPECT_LE(RelativeDifference(u.H, b.H), 1e-14);
          EXPECT_LE(RelativeDifference(u.g.tail(K), b.g.tail(K)), 1e-14);
          EXPECT_EQ(u.cost, b.cost);
        }
      }
    }
  }
}

TEST(JointNormalEquations, ProjectionOfWholeBlocksEqualsTheReducedBlocks) {
  const Data d(false);
  const Parameterization whole = WithTerms(d, false, false);
  const Parameterization reduced = WithTerms(d, false, true);
  const internal::NormalEquations full =
      internal::NormalEquationsOf(d.model, d.data, whole, Eigen::VectorXd(), PositionRows());
  internal::JointColumnsOptions dense;
  dense.dense = true;
  const internal::NormalEquations direct =
      internal::NormalEquationsOf(d.model, d.data, reduced, Eigen::VectorXd(), PositionRows(dense));
  const internal::NormalEquations projected = internal::ProjectJointBlocks(full, reduced);
  EXPECT_LE(RelativeDifference(projected.H, direct.H), kRelative);
  EXPECT_LE(RelativeDifference(projected.g, direct.g), kRelative);
  const int K = reduced.num_joint_parameters();
  EXPECT_LE(RelativeDifference(projected.H.bottomRightCorner(K, K),
                               direct.H.bottomRightCorner(K, K)),
            kRelative);
  EXPECT_EQ(projected.cost, full.cost);
}

// A measurement that is not finite makes the normal equations non-finite (the solvers' "non-finite
// residuals" refusal), by structure, projected, and without joint blocks; finite data do not.
TEST(JointNormalEquations, NonFiniteDataAreFlagged) {
  Data d(false);
  const Parameterization whole = WithTerms(d, false, false);
  const Parameterization reduced = WithTerms(d, false, true);
  const Parameterization geometric =
      MakeParameterization(d.model, ParameterizationKind::kIdentifiable, DataKind::kPosition);
  const internal::JointSpaceRegressors regs = internal::BuildJointSpaceRegressors(whole, d.data);
  internal::JointColumnsOptions structured;
  structured.regressors = &regs;
  auto equations = [&](const Parameterization& p, bool with_regressors) {
    return internal::NormalEquationsOf(
        d.model, d.data, p, Eigen::VectorXd(),
        PositionRows(with_regressors ? structured : internal::JointColumnsOptions()));
  };
  EXPECT_TRUE(equations(whole, true).finite);
  EXPECT_TRUE(internal::ProjectJointBlocks(equations(whole, true), reduced).finite);
  EXPECT_TRUE(equations(geometric, false).finite);
  d.data.mutable_position(d.data.size() / 2)(1) = std::numeric_limits<double>::infinity();
  const internal::NormalEquations whole_ne = equations(whole, true);
  EXPECT_FALSE(whole_ne.finite);
  EXPECT_FALSE(internal::ProjectJointBlocks(whole_ne, reduced).finite);
  EXPECT_FALSE(equations(geometric, false).finite);
  d.data.mutable_position(d.data.size() / 2)(1) = std::nan("");
  EXPECT_FALSE(equations(whole, true).finite);
  EXPECT_FALSE(equations(geometric, false).finite);
}

// Slots that no row moves (joint 1 of cobot6 is vertical: no gravity torque) are dropped, and the
// regressors are checked against ParameterJoint.
TEST(JointNormalEquations, SlotsFollowTheRegressorsSparsity) {
  const Data d(false);
  Parameterization p = MakeParameterization(d.nominal, ParameterizationKind::kIdentifiable,
                                            DataKind::kPosition);
  AddJointBlock(d.terms[0], &p);  // compliance
  const internal::JointSpaceRegressors regs = internal::BuildJointSpaceRegressors(p, d.data);
  EXPECT_EQ(regs.slot_begin[1] - regs.slot_begin[0], 0);  // joint 1: nothing
  const int n = d.nominal.num_joints();
  for (int j = 1; j < n; ++j) {
    EXPECT_GT(regs.slot_begin[j + 1] - regs.slot_begin[j], 0) << j;
    EXPECT_LE(regs.slot_begin[j + 1] - regs.slot_begin[j], 4 * (n - j) + 1) << j;
  }
  Parameterization lying = MakeParameterization(d.nominal, ParameterizationKind::kIdentifiable,
                                                DataKind::kPosition);
  AddJointBlock(std::make_shared<LyingTerm>(n), &lying);
  EXPECT_DEATH(internal::BuildJointSpaceRegressors(lying, d.data), "ParameterJoint");
}

// The reduction keeps the same combinations as it does from the dense normal matrix (the
// algebra before the structured one).
TEST(JointNormalEquations, ReductionChoosesTheSameCombinations) {
  for (bool pose : {false, true}) {
    const Data d(pose);
    internal::NormalEquations analysed;
    Parameterization pi;
    internal::SolverParameterizationRequest request;
    request.use_orientation = pose;
    request.terms = d.terms;
    request.analysed = &analysed;
    request.analysed_parameterization = &pi;
    const Parameterization p = internal::SolverParameterization(d.nominal, d.data, request);
    internal::JointColumnsOptions dense;
    dense.dense = true;
    const Eigen::MatrixXd H =
        internal::NormalEquationsOf(d.nominal, d.data, pi, Eigen::VectorXd(), Rows(pose, dense)).H;
    EXPECT_LE(RelativeDifference(analysed.H, H), kRelative);
    const std::vector<Eigen::MatrixXd> bases = internal::JointBlockBases(H, pi, 1e-4);
    ASSERT_EQ(bases.size(), p.joint_blocks.size());
    for (size_t b = 0; b < bases.size(); ++b) {
      const Eigen::MatrixXd& B = p.joint_blocks[b].basis;
      ASSERT_EQ(B.cols(), bases[b].cols()) << b;
      ASSERT_GT(B.cols(), 0) << b;
      // The same span (the bases are orthonormal): equal projectors.
      EXPECT_LE((B * B.transpose() - bases[b] * bases[b].transpose()).cwiseAbs().maxCoeff(), 1e-8)
          << b;
    }
  }
}

// The linear solver's iterations with frozen joint blocks converge to the solution of the exact
// Gauss-Newton normal equations: at the returned model the exact gradient is zero to the step
// tolerance, and the covariance is the exact (J^T J)^-1 there.
TEST(JointNormalEquations, LinearSolverConvergesToTheExactStationaryPoint) {
  const Data d(false);
  LinearSolverOptions o;
  o.joint_terms = {d.terms[0], d.terms[1]};
  const CalibrationResult r = CalibrateLinear(d.nominal, d.data, o);
  ASSERT_TRUE(r.converged()) << r.message;
  const Parameterization& p = r.parameterization;
  const int K = p.num_joint_parameters();
  ASSERT_GT(K, 40);
  // The joint blocks' coordinates at the solution: theta_b = basis_b x_b.
  Eigen::VectorXd x(K);
  for (size_t b = 0; b < p.joint_blocks.size(); ++b) {
    const JointBlock& block = p.joint_blocks[b];
    x.segment(block.offset - p.num_frame_parameters(), block.basis.cols()) =
        block.basis.transpose() * r.joint_terms[b].theta;
  }
  internal::JointColumnsOptions dense;
  dense.dense = true;
  const internal::NormalEquations lin =
      internal::NormalEquationsOf(r.model, d.data, p, x, PositionRows(dense));
  // Newton step of the exact normal equations from the solution, column scaled.
  const Eigen::VectorXd s = internal::ColumnScale(lin.H);
  const Eigen::VectorXd step =
      s.asDiagonal() * (s.asDiagonal() * lin.H * s.asDiagonal()).llt().solve(s.asDiagonal() * lin.g);
  ASSERT_EQ(r.covariance.rows(), p.num_parameters);
  const double s2 = 2.0 * lin.cost / (3.0 * d.data.size() - p.num_parameters);
  const Eigen::MatrixXd C =
      s2 * s.asDiagonal() *
      (s.asDiagonal() * lin.H * s.asDiagonal()).llt().solve(
          Eigen::MatrixXd::Identity(p.num_parameters, p.num_parameters)) *
      s.asDiagonal();
  // What is left is below the convergence rule's fraction (1e-2) of every standard deviation.
  const Eigen::VectorXd sd = C.diagonal().cwiseSqrt();
  EXPECT_LT((step.array().abs() / sd.array()).maxCoeff(), 2e-2);
  EXPECT_LE(RelativeDifference(r.covariance.diagonal(), C.diagonal()), 1e-6);
  EXPECT_LE(r.iterations, 6);
}

}  // namespace joint_normal_equations_test
}  // namespace
}  // namespace lpoe
