// Tests of the measurement model (measurement_model.h) and of joint-space parameter blocks
// (joint_term.h): Jacobians with respect to the joint values against finite differences and
// autodiff through Jet joint values, and a test-only joint-space term that both solvers recover from
// simulated data and agree on.
#include "lpoe/measurements/measurement_model.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include <ceres/jet.h>
#include <gtest/gtest.h>

#include "lpoe/ceres_solver.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/linear_solver.h"
#include "lpoe/model/simulation.h"
#include "test_util.h"

namespace lpoe {
namespace {
namespace measurement_model_test {

constexpr int kConfigurations = 8;
constexpr double kStep = 1e-6;                // rad or mm, central differences
constexpr double kFiniteDifferenceTol = 1e-6;  // relative to the Jacobian's largest entry
constexpr double kJetTolerance = 1e-10;       // relative: two exact derivatives
constexpr int kPoses = 120;
constexpr double kRecoveryTolerance = 1e-8;  // per joint-scale parameter, noise-free data
constexpr double kAgreementMm = 1e-9;        // linear vs Ceres predictions

// A test-only joint-space term: a scale error of each joint's reading, dq_j = k_j q_j (an encoder
// with a slightly wrong gear ratio). Separable from the geometry for joints that move.
class JointScaleTerm : public JointTerm {
 public:
  explicit JointScaleTerm(int n) : n_(n) {}
  std::string name() const override { return "scale"; }
  int num_joints() const override { return n_; }
  int num_parameters() const override { return n_; }
  std::string ParameterName(int k) const override { return "joint" + std::to_string(k + 1); }
  void Regressor(const double* q, double* Y) const override {
    for (int k = 0; k < n_ * n_; ++k) Y[k] = 0.0;
    for (int j = 0; j < n_; ++j) Y[j * n_ + j] = q[j];
  }

 private:
  int n_;
};

// A test-only term with a constant offset and a scale per joint, dq_j = c_j + k_j q_j: the offsets
// are not separable from the local frames and must be left out.
class OffsetAndScaleTerm : public JointTerm {
 public:
  explicit OffsetAndScaleTerm(int n) : n_(n) {}
  std::string name() const override { return "offset_scale"; }
  int num_joints() const override { return n_; }
  int num_parameters() const override { return 2 * n_; }
  std::string ParameterName(int k) const override {
    return "joint" + std::to_string(k % n_ + 1) + (k < n_ ? ".c" : ".k");
  }
  void Regressor(const double* q, double* Y) const override {
    for (int k = 0; k < n_ * 2 * n_; ++k) Y[k] = 0.0;
    for (int j = 0; j < n_; ++j) {
      Y[j * n_ + j] = 1.0;
      Y[(n_ + j) * n_ + j] = q[j];
    }
  }

 private:
  int n_;
};

TEST(MeasurementModel, JointJacobiansMatchFiniteDifferences) {
  testing::TestRandom rng(3);
  for (const auto& robot : testing::TestRobotsWithTiltedVariants(11)) {
    const RobotModel& m = robot.model;
    for (int c = 0; c < kConfigurations; ++c) {
      std::vector<double> q = rng.Configuration(m);
      Eigen::MatrixXd Jp, Jpose;
      const Eigen::Vector3d P = ToolPositionJointJacobian(m, q.data(), 0, &Jp);
      const SE3d T = ToolPoseJointJacobian(m, q.data(), 0, &Jpose);
      EXPECT_LT((P - ToolPosition(m, q.data())).norm(), 1e-9);
      Eigen::MatrixXd Fp(3, m.num_joints()), Fpose(6, m.num_joints());
      for (int i = 0; i < m.num_joints(); ++i) {
        std::vector<double> qp = q, qm = q;
        qp[i] += kStep;
        qm[i] -= kStep;
        Fp.col(i) = (ToolPosition(m, qp.data()) - ToolPosition(m, qm.data())) / (2 * kStep);
        Fpose.col(i) = (LogSE3(ToolPose(m, qp.data()) * T.Inverse()) -
                        LogSE3(ToolPose(m, qm.data()) * T.Inverse())) /
                       (2 * kStep);
      }
      EXPECT_LT((Jp - Fp).cwiseAbs().maxCoeff(), kFiniteDifferenceTol * Jp.cwiseAbs().maxCoeff())
          << robot.name;
      EXPECT_LT((Jpose - Fpose).cwiseAbs().maxCoeff(),
                kFiniteDifferenceTol * Jpose.cwiseAbs().maxCoeff())
          << robot.name;
    }
  }
}

TEST(MeasurementModel, JetJointValuesGiveTheJointJacobian) {
  // The chain templated on the joint values: q as Jets carries dP/dq and dT/dq exactly.
  constexpr int kMaxJoints = 8;
  using Jet = ceres::Jet<double, kMaxJoints>;
  testing::TestRandom rng(5);
  for (const auto& robot : testing::TestRobotsWithTiltedVariants(13)) {
    const RobotModel& m = robot.model;
    ASSERT_LE(m.num_joints(), kMaxJoints);
    const std::vector<double> q = rng.Configuration(m);
    std::vector<Jet> qj(m.num_joints());
    for (int i = 0; i < m.num_joints(); ++i) qj[i] = Jet(q[i], i);
    std::vector<SE3<Jet>> origins;
    for (const Joint& j : m.joints) origins.push_back(j.origin.cast<Jet>());
    const SE3<Jet> tool = m.tools[0].origin.cast<Jet>();
    Eigen::MatrixXd Jp, Jpose;
    ToolPositionJointJacobian(m, q.data(), 0, &Jp);
    const SE3d T = ToolPoseJointJacobian(m, q.data(), 0, &Jpose);
    const Vector3<Jet> P = ChainPosition(m, origins.data(), tool.t, qj.data());
    const Vector3<Jet> P2 =
        ChainPosition<Jet>(JointMotions<Jet>(m, qj.data()), m.num_joints(), origins.data(), tool.t);
    const Vector6<Jet> y = LogSE3(ChainPose(m, origins.data(), tool, qj.data()) *
                                  T.Inverse().cast<Jet>());
    const double scale = Jp.cwiseAbs().maxCoeff();
    for (int i = 0; i < m.num_joints(); ++i) {
      for (int r = 0; r < 3; ++r) {
        EXPECT_NEAR(P(r).v(i), Jp(r, i), kJetTolerance * scale) << robot.name;
        EXPECT_NEAR(P2(r).v(i), Jp(r, i), kJetTolerance * scale) << robot.name;
      }
      for (int r = 0; r < 6; ++r) {
        EXPECT_NEAR(y(r).v(i), Jpose(r, i), kJetTolerance * scale) << robot.name;
      }
    }
  }
}

TEST(MeasurementModel, ParameterJacobianOfJointBlocksMatchesFiniteDifferences) {
  const RobotModel m = MakeCobot6();
  Parameterization p =
      MakeParameterization(m, ParameterizationKind::kIdentifiable, DataKind::kPosition);
  auto term = std::make_shared<JointScaleTerm>(m.num_joints());
  AddJointBlock(term, &p);
  JointTermValues values{term, Eigen::VectorXd::Constant(m.num_joints(), 3e-4)};
  testing::TestRandom rng(7);
  const std::vector<double> q = rng.Configuration(m);
  Eigen::MatrixXd J;
  const Eigen::Vector3d P = PredictPositionJacobian(m, p, {values}, q.data(), 0, &J);
  EXPECT_LT((P - PredictPosition(m, {values}, q.data())).norm(), 1e-12);
  ASSERT_EQ(J.cols(), p.num_parameters);
  for (int k = 0; k < m.num_joints(); ++k) {
    JointTermValues plus = values, minus = values;
    plus.theta(k) += kStep;
    minus.theta(k) -= kStep;
    const Eigen::Vector3d fd =
        (PredictPosition(m, {plus}, q.data()) - PredictPosition(m, {minus}, q.data())) /
        (2 * kStep);
    const int column = p.joint_blocks[0].offset + k;
    EXPECT_LT((J.col(column) - fd).norm(), kFiniteDifferenceTol * J.col(column).norm() + 1e-9);
  }
}

// Noise-free data from an actual robot with geometric errors and joint-scale errors.
struct ScaleData {
  RobotModel nominal = MakeCobot6();
  Eigen::VectorXd scale;
  MeasurementSet identification, verification;
  RobotModel actual;
};

ScaleData MakeScaleData() {
  ScaleData d;
  d.actual = ApplyErrors(d.nominal, RandomErrors(d.nominal, 0.003, 1.0, 0.002, 0.0, 21));
  const int n = d.nominal.num_joints();
  d.scale.resize(n);
  d.scale << 2e-4, -3e-4, 1.5e-4, -1e-4, 2.5e-4, -2e-4;  // 0.01-0.03 % of the reading
  testing::TestRandom rng(23);
  d.identification = MeasurementSet(n);
  d.verification = MeasurementSet(n);
  for (int r = 0; r < 2 * kPoses; ++r) {
    const std::vector<double> q = rng.Configuration(d.nominal);
    std::vector<double> q_actual = q;
    for (int j = 0; j < n; ++j) q_actual[j] += d.scale(j) * q[j];
    (r < kPoses ? d.identification : d.verification)
        .Add(q.data(), ToolPosition(d.actual, q_actual.data()));
  }
  return d;
}

// Both solvers on the identification data with one joint-space term.
struct BothSolvers {
  CalibrationResult linear, ceres;
};

BothSolvers SolveWithTerm(const ScaleData& d, std::shared_ptr<const JointTerm> term) {
  LinearSolverOptions lo;
  lo.joint_terms = {term};
  CeresSolverOptions co;
  co.joint_terms = {term};
  co.num_threads = 1;
  return {CalibrateLinear(d.nominal, d.identification, lo),
          CalibrateCeres(d.nominal, d.identification, co)};
}

// Largest difference between the two solvers' predictions on the verification data (mm).
double WorstAgreement(const ScaleData& d, const BothSolvers& s) {
  double worst = 0;
  for (int r = 0; r < d.verification.size(); ++r) {
    const double* q = d.verification.q(r);
    worst = std::max(worst, (PredictPosition(s.linear.model, s.linear.joint_terms, q) -
                             PredictPosition(s.ceres.model, s.ceres.joint_terms, q))
                                .norm());
  }
  return worst;
}

TEST(MeasurementModel, BothSolversRecoverATestOnlyJointTermAndAgree) {
  const ScaleData d = MakeScaleData();
  const BothSolvers s = SolveWithTerm(d, std::make_shared<JointScaleTerm>(d.nominal.num_joints()));
  const CalibrationResult& lin = s.linear;
  const CalibrationResult& cer = s.ceres;
  ASSERT_TRUE(lin.converged()) << lin.message;
  ASSERT_TRUE(cer.converged()) << cer.message;
  ASSERT_EQ(lin.joint_terms.size(), 1u);
  ASSERT_EQ(cer.joint_terms.size(), 1u);
  EXPECT_EQ(lin.parameterization.num_parameters, 27 + 6);
  for (int j = 0; j < d.nominal.num_joints(); ++j) {
    EXPECT_NEAR(lin.joint_terms[0].theta(j), d.scale(j), kRecoveryTolerance) << "joint " << j;
    EXPECT_NEAR(cer.joint_terms[0].theta(j), d.scale(j), kRecoveryTolerance) << "joint " << j;
  }
  double worst_error = 0;
  for (int r = 0; r < d.verification.size(); ++r) {
    const Eigen::Vector3d a = PredictPosition(lin.model, lin.joint_terms, d.verification.q(r));
    worst_error = std::max(worst_error, (a - d.verification.position(r)).norm());
  }
  EXPECT_LT(WorstAgreement(d, s), kAgreementMm);
  EXPECT_LT(worst_error, 1e-6);  // mm: the model with the term reproduces the actual robot

  // Without the term, the same data leave a clear residual (the term is not absorbed).
  const CalibrationResult geometric = CalibrateLinear(d.nominal, d.identification);
  ASSERT_TRUE(geometric.converged());
  EXPECT_GT(geometric.history.back().max_error, 0.05);
  // The covariance covers the joint block too.
  EXPECT_EQ(lin.covariance.rows(), lin.parameterization.num_parameters);
}

TEST(MeasurementModel, CombinationsNotSeparableFromTheGeometryAreLeftOut) {
  const ScaleData d = MakeScaleData();
  const int n = d.nominal.num_joints();
  const BothSolvers s = SolveWithTerm(d, std::make_shared<OffsetAndScaleTerm>(n));
  const CalibrationResult& lin = s.linear;
  const CalibrationResult& cer = s.ceres;
  ASSERT_TRUE(lin.converged()) << lin.message;
  ASSERT_TRUE(cer.converged()) << cer.message;
  const Parameterization& p = lin.parameterization;
  ASSERT_EQ(p.joint_blocks.size(), 1u);
  EXPECT_EQ(p.joint_blocks[0].basis.cols(), n);  // the scales; the n offsets are left out
  int dropped = 0;
  for (const Direction& dir : p.unidentifiable) {
    if (dir.joint_block != 0) continue;
    ++dropped;
    EXPECT_NE(dir.name.find(".c"), std::string::npos) << dir.name;
    EXPECT_FALSE(dir.reason.empty());
    EXPECT_LT(dir.combination.tail(n).norm(), 1e-6) << dir.name;  // pure offsets
  }
  EXPECT_EQ(dropped, n);
  // The kept combinations still recover the scales, and the solvers agree.
  for (int j = 0; j < n; ++j) {
    EXPECT_NEAR(lin.joint_terms[0].theta(n + j), d.scale(j), 1e-7);
    EXPECT_NEAR(cer.joint_terms[0].theta(n + j), d.scale(j), 1e-7);
  }
  EXPECT_LT(WorstAgreement(d, s), kAgreementMm);
}

TEST(MeasurementModel, UnknownJointTermIsRejectedWithItsName) {
  std::shared_ptr<const JointTerm> term;
  const Status s = MakeJointTerm("no_such_term", MakeCobot6(), &term);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("no_such_term"), std::string::npos);
}

}  // namespace measurement_model_test
}  // namespace
}  // namespace lpoe
