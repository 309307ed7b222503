#include <memory>
#include <random>
#include <vector>

#include <ceres/dynamic_autodiff_cost_function.h>
#include <ceres/gradient_checker.h>
#include <gtest/gtest.h>

#include "lpoe/terms/joint_errors.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/model/parameterization.h"
#include "lpoe/measurement_residual.h"
#include "lpoe/se3_manifold.h"
#include "lpoe/model/simulation.h"

namespace lpoe {
namespace {
namespace residuals_test {

constexpr int kNumConfigurations = 10;
constexpr double kSigma = 0.05;               // mm
constexpr double kOrientationWeight = 500.0;  // mm per rad
// GradientChecker: autodiff against numeric differentiation, relative.
constexpr double kGradientCheckPrecision = 1e-6;
// Autodiff (through the manifold) against the analytic Jacobians of kinematics.h, relative.
constexpr double kJacobianTolerance = 1e-9;

using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

PositionMeasurement PositionKind() {
  PositionMeasurement kind;
  kind.inverse_sigma = 1.0 / kSigma;
  return kind;
}

PoseMeasurement PoseKind() {
  PoseMeasurement kind;
  kind.inverse_sigma = 1.0 / kSigma;
  kind.orientation_weight = kOrientationWeight;
  return kind;
}

// cobot6 with a second tool, so that residuals on tool 1 are exercised too.
RobotModel TwoToolCobot() {
  RobotModel model = MakeCobot6();
  Tool second;
  second.name = "smr2";
  second.origin = SE3d(RotationFromRpy(0.3, -0.2, 0.5), Eigen::Vector3d(-30, 25, 80));
  model.tools.push_back(second);
  return model;
}

// The same with every frame and axis perturbed, so that no Jacobian entry is a near-cancellation
// (GradientChecker judges each entry relative to itself).
RobotModel PerturbedTwoToolCobot() {
  const RobotModel model = TwoToolCobot();
  return ApplyErrors(model, RandomErrors(model, 0.05, 5.0, 0.05, 0.0, 17));
}

std::vector<double> RandomQ(int n, std::mt19937_64* rng) {
  std::uniform_real_distribution<double> u(-M_PI, M_PI);
  std::vector<double> q(n);
  for (double& v : q) v = u(*rng);
  return q;
}

// Parameter blocks [joints..., tool] as 7-arrays, and their manifolds.
struct Blocks {
  std::vector<std::vector<double>> storage;
  std::vector<const double*> pointers;
  std::vector<std::unique_ptr<Se3Manifold>> manifolds;
  std::vector<const ceres::Manifold*> manifold_pointers;
  std::vector<int> frames;  // frame index of each block
};

Blocks MakeBlocks(const RobotModel& model, const Parameterization& p, int tool) {
  Blocks b;
  const int n = model.num_joints();
  for (int i = 0; i <= n; ++i) b.frames.push_back(i < n ? i : n + tool);
  for (int f : b.frames) {
    const SE3d& T = f < n ? model.joints[f].origin : model.tools[f - n].origin;
    b.storage.emplace_back(kSe3AmbientSize);
    Se3ToArray(T, b.storage.back().data());
    b.manifolds.push_back(std::make_unique<Se3Manifold>(p.basis[f]));
  }
  for (auto& s : b.storage) b.pointers.push_back(s.data());
  for (auto& m : b.manifolds) b.manifold_pointers.push_back(m.get());
  return b;
}

// Autodiff Jacobian of `cost` in the tangent spaces of the blocks, num_residuals x num_parameters
// in the parameterization's column order.
Eigen::MatrixXd TangentJacobian(const ceres::CostFunction& cost, const Blocks& b,
                                const Parameterization& p, Eigen::VectorXd* residuals) {
  const int m = cost.num_residuals();
  residuals->resize(m);
  std::vector<RowMajor> ambient(b.pointers.size(), RowMajor(m, kSe3AmbientSize));
  std::vector<double*> jac;
  for (auto& a : ambient) jac.push_back(a.data());
  EXPECT_TRUE(cost.Evaluate(b.pointers.data(), residuals->data(), jac.data()));
  Eigen::MatrixXd out = Eigen::MatrixXd::Zero(m, p.num_parameters);
  for (size_t i = 0; i < b.pointers.size(); ++i) {
    const int k = b.manifolds[i]->TangentSize();
    RowMajor plus(kSe3AmbientSize, k);
    EXPECT_TRUE(b.manifolds[i]->PlusJacobian(b.pointers[i], plus.data()));
    out.middleCols(p.offset[b.frames[i]], k) = ambient[i] * plus;
  }
  return out;
}

Eigen::MatrixXd Restrict(const Eigen::MatrixXd& J_frames, const Parameterization& p) {
  Eigen::MatrixXd out(J_frames.rows(), p.num_parameters);
  for (size_t f = 0; f < p.basis.size(); ++f) {
    out.middleCols(p.offset[f], p.basis[f].cols()) = J_frames.middleCols(6 * f, 6) * p.basis[f];
  }
  return out;
}

double RelativeDifference(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  return (a - b).norm() / b.norm();
}

TEST(PositionResidual, GradientCheckerPasses) {
  const RobotModel model = PerturbedTwoToolCobot();
  const auto shared = std::make_shared<const RobotModel>(model);
  std::mt19937_64 rng(1);
  for (ParameterizationKind kind : {ParameterizationKind::kIdentifiable, ParameterizationKind::kFull}) {
    const Parameterization p = MakeParameterization(model, kind, DataKind::kPosition);
    for (int trial = 0; trial < kNumConfigurations; ++trial) {
      const int tool = trial % 2;
      const std::vector<double> q = RandomQ(model.num_joints(), &rng);
      const Eigen::Vector3d measured = ToolPosition(model, q.data(), tool) + Eigen::Vector3d(1, -2, 0.5);
      std::unique_ptr<ceres::CostFunction> cost(
          PositionResidual::Create(shared, PositionKind(), q.data(), measured));
      const Blocks b = MakeBlocks(model, p, tool);
      ceres::NumericDiffOptions numeric;
      ceres::GradientChecker checker(cost.get(), &b.manifold_pointers, numeric);
      ceres::GradientChecker::ProbeResults results;
      EXPECT_TRUE(checker.Probe(b.pointers.data(), kGradientCheckPrecision, &results))
          << results.error_log;
    }
  }
}

TEST(PositionResidual, MatchesAnalyticJacobianAndValue) {
  const RobotModel model = TwoToolCobot();
  const auto shared = std::make_shared<const RobotModel>(model);
  std::mt19937_64 rng(2);
  for (ParameterizationKind kind : {ParameterizationKind::kIdentifiable, ParameterizationKind::kFull}) {
    const Parameterization p = MakeParameterization(model, kind, DataKind::kPosition);
    for (int trial = 0; trial < kNumConfigurations; ++trial) {
      const int tool = trial % 2;
      const std::vector<double> q = RandomQ(model.num_joints(), &rng);
      const Eigen::Vector3d measured(100, 200, 300);
      std::unique_ptr<ceres::CostFunction> cost(
          PositionResidual::Create(shared, PositionKind(), q.data(), measured));
      const Blocks b = MakeBlocks(model, p, tool);
      Eigen::VectorXd r;
      const Eigen::MatrixXd J_auto = TangentJacobian(*cost, b, p, &r);
      Eigen::MatrixXd J_frames;
      const Eigen::Vector3d P = ToolPositionJacobian(model, q.data(), tool, &J_frames);
      const Eigen::MatrixXd J_analytic = Restrict(J_frames, p) / kSigma;
      EXPECT_LT(RelativeDifference(J_auto, J_analytic), kJacobianTolerance);
      EXPECT_LT((r - (P - measured) / kSigma).norm(), 1e-9 * r.norm());
    }
  }
}

// With joint-space blocks (q_eff = q + R x, x in two blocks of 2 and 3): the value is the residual at
// q_eff, the blocks' Jacobian columns are (dr/dq) R (chain rule), and every block passes the
// gradient checker.
TEST(PositionResidual, JointSpaceBlocksFollowTheChainRule) {
  const RobotModel model = PerturbedTwoToolCobot();
  const auto shared = std::make_shared<const RobotModel>(model);
  const Parameterization p =
      MakeParameterization(model, ParameterizationKind::kIdentifiable, DataKind::kPosition);
  const int n = model.num_joints();
  const std::vector<int> block_sizes = {2, 3};
  std::mt19937_64 rng(6);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int trial = 0; trial < kNumConfigurations; ++trial) {
    const int tool = trial % 2;
    const std::vector<double> q = RandomQ(n, &rng);
    Eigen::MatrixXd R(n, 5);
    for (int k = 0; k < R.size(); ++k) R(k) = u(rng);
    std::vector<std::vector<double>> x = {{u(rng) * 1e-2, u(rng) * 1e-2},
                                          {u(rng) * 1e-2, u(rng) * 1e-2, u(rng) * 1e-2}};
    Eigen::VectorXd x_all(5);
    x_all << x[0][0], x[0][1], x[1][0], x[1][1], x[1][2];
    const Eigen::VectorXd q_eff = Eigen::Map<const Eigen::VectorXd>(q.data(), n) + R * x_all;
    const Eigen::Vector3d measured =
        ToolPosition(model, q.data(), tool) + Eigen::Vector3d(1, -2, 0.5);
    std::unique_ptr<ceres::CostFunction> cost(PositionResidual::Create(
        shared, PositionKind(), q.data(), measured, R, block_sizes));
    ASSERT_EQ(cost->parameter_block_sizes().size(), static_cast<size_t>(n + 3));
    Blocks b = MakeBlocks(model, p, tool);
    for (auto& block : x) b.pointers.push_back(block.data());
    b.manifold_pointers.push_back(nullptr);
    b.manifold_pointers.push_back(nullptr);

    Eigen::Vector3d r;
    std::vector<RowMajor> jac;
    for (int s : cost->parameter_block_sizes()) jac.emplace_back(3, s);
    std::vector<double*> jac_pointers;
    for (auto& j : jac) jac_pointers.push_back(j.data());
    ASSERT_TRUE(cost->Evaluate(b.pointers.data(), r.data(), jac_pointers.data()));
    Eigen::Matrix<double, 3, Eigen::Dynamic> J_q;
    const Eigen::Vector3d P = ToolPositionJointJacobian(model, q_eff.data(), tool, &J_q);
    EXPECT_LT((r - (P - measured) / kSigma).norm(), 1e-9 * r.norm());
    const Eigen::MatrixXd expected = J_q * R / kSigma;
    EXPECT_LT(RelativeDifference(jac[n + 1], expected.leftCols(2)), kJacobianTolerance);
    EXPECT_LT(RelativeDifference(jac[n + 2], expected.rightCols(3)), kJacobianTolerance);

    ceres::NumericDiffOptions numeric;
    ceres::GradientChecker checker(cost.get(), &b.manifold_pointers, numeric);
    ceres::GradientChecker::ProbeResults results;
    EXPECT_TRUE(checker.Probe(b.pointers.data(), kGradientCheckPrecision, &results))
        << results.error_log;
  }
}

// The functor before the motions in double: every autodiff pass evaluates the chain on the motions
// of q_eff as Jets (blocks: the n + 1 frames, then q_eff), the reference for the cached motions.
template <typename Kind>
struct JetMotionsResidual {
  std::shared_ptr<const RobotModel> model;
  Kind kind;
  typename Kind::Observation observation;
  template <typename T>
  bool operator()(T const* const* parameters, T* residuals) const {
    const int n = model->num_joints();
    kind.Residual(n, parameters, JointMotions<T>(*model, parameters[n + 1]), observation,
                  residuals);
    return true;
  }
};

// Kind's residual with one joint-space block x of n values and R = I (q_eff = q + x, dr/dx =
// dr/dq_eff) against full autodiff through Jet motions: equal values and Jacobians (to 1e-12
// relative) at x1, then at x2 (residuals only, then with Jacobians), then at x1 again, so that
// motions kept from another q_eff would show.
template <typename Kind>
void ExpectMotionsInDoubleMatchJetMotions(const RobotModel& model, const Kind& kind,
                                          DataKind data_kind,
                                          typename Kind::Observation (*observe)(
                                              const RobotModel&, const double*, int)) {
  const auto shared = std::make_shared<const RobotModel>(model);
  const Parameterization p = MakeParameterization(model, ParameterizationKind::kIdentifiable,
                                                  data_kind);
  const int n = model.num_joints();
  const int m = Kind::kResiduals;
  std::mt19937_64 rng(12);
  std::uniform_real_distribution<double> u(-1, 1);
  for (int trial = 0; trial < kNumConfigurations; ++trial) {
    const int tool = trial % 2;
    const std::vector<double> q = RandomQ(n, &rng);
    const typename Kind::Observation measured = observe(model, q.data(), tool);
    std::unique_ptr<ceres::CostFunction> cost(MeasurementResidual<Kind>::Create(
        shared, kind, q.data(), measured, Eigen::MatrixXd::Identity(n, n), {n}));
    ceres::DynamicAutoDiffCostFunction<JetMotionsResidual<Kind>, MeasurementResidual<Kind>::kStride>
        reference(new JetMotionsResidual<Kind>{shared, kind, measured});
    for (int i = 0; i <= n; ++i) reference.AddParameterBlock(kSe3AmbientSize);
    reference.AddParameterBlock(n);
    reference.SetNumResiduals(m);
    ASSERT_EQ(cost->parameter_block_sizes().size(), static_cast<size_t>(n + 2));

    Blocks b = MakeBlocks(model, p, tool);
    std::vector<double> x1(n), x2(n);
    for (int j = 0; j < n; ++j) {
      x1[j] = 0.05 * u(rng);
      x2[j] = 0.05 * u(rng);
    }
    for (int step = 0; step < 4; ++step) {
      const std::vector<double>& x = step == 0 || step == 3 ? x1 : x2;
      const bool with_jacobians = step != 1;
      std::vector<double> q_eff(n);
      for (int j = 0; j < n; ++j) q_eff[j] = q[j] + x[j];
      std::vector<const double*> ours = b.pointers, theirs = b.pointers;
      ours.push_back(x.data());
      theirs.push_back(q_eff.data());
      std::vector<RowMajor> J, J_ref;
      std::vector<double*> J_ptr, J_ref_ptr;
      for (int i = 0; i < n + 2; ++i) {
        const int size = i <= n ? kSe3AmbientSize : n;
        J.emplace_back(m, size);
        J_ref.emplace_back(m, size);
      }
      for (int i = 0; i < n + 2; ++i) {
        J_ptr.push_back(J[i].data());
        J_ref_ptr.push_back(J_ref[i].data());
      }
      Eigen::VectorXd r(m), r_ref(m);
      ASSERT_TRUE(cost->Evaluate(ours.data(), r.data(), with_jacobians ? J_ptr.data() : nullptr));
      ASSERT_TRUE(reference.Evaluate(theirs.data(), r_ref.data(),
                                     with_jacobians ? J_ref_ptr.data() : nullptr));
      EXPECT_LE((r - r_ref).norm(), 1e-12 * r_ref.norm()) << "trial " << trial << " step " << step;
      if (!with_jacobians) continue;
      for (int i = 0; i < n + 2; ++i) {
        EXPECT_LE((J[i] - J_ref[i]).norm(), 1e-12 * J_ref[i].norm())
            << "trial " << trial << " step " << step << " block " << i;
      }
    }
  }
}

Eigen::Vector3d OffsetPosition(const RobotModel& model, const double* q, int tool) {
  return ToolPosition(model, q, tool) + Eigen::Vector3d(1, -2, 0.5);
}

SE3d OffsetPose(const RobotModel& model, const double* q, int tool) {
  return ToolPose(model, q, tool) *
         ExpSE3(Vector6d((Vector6d() << 0.01, -0.02, 0.005, 1, 2, -1).finished()));
}

// On cobot6 (revolute-z joints: plane rotations) and with every axis perturbed (general motions).
TEST(PositionResidual, MotionsInDoubleMatchFullAutodiffThroughJetMotions) {
  for (const RobotModel& model : {TwoToolCobot(), PerturbedTwoToolCobot()}) {
    ExpectMotionsInDoubleMatchJetMotions(model, PositionKind(), DataKind::kPosition,
                                         &OffsetPosition);
  }
}

TEST(PoseResidual, MotionsInDoubleMatchFullAutodiffThroughJetMotions) {
  for (const RobotModel& model : {TwoToolCobot(), PerturbedTwoToolCobot()}) {
    ExpectMotionsInDoubleMatchJetMotions(model, PoseKind(), DataKind::kPose, &OffsetPose);
  }
}

TEST(PoseResidual, GradientCheckerPasses) {
  const RobotModel model = PerturbedTwoToolCobot();
  const auto shared = std::make_shared<const RobotModel>(model);
  const Parameterization p =
      MakeParameterization(model, ParameterizationKind::kIdentifiable, DataKind::kPose);
  std::mt19937_64 rng(3);
  for (int trial = 0; trial < kNumConfigurations; ++trial) {
    const int tool = trial % 2;
    const std::vector<double> q = RandomQ(model.num_joints(), &rng);
    const SE3d measured =
        ToolPose(model, q.data(), tool) * ExpSE3(Vector6d((Vector6d() << 0.01, -0.02, 0.005, 1, 2, -1).finished()));
    std::unique_ptr<ceres::CostFunction> cost(
        PoseResidual::Create(shared, PoseKind(), q.data(), measured));
    const Blocks b = MakeBlocks(model, p, tool);
    ceres::NumericDiffOptions numeric;
    ceres::GradientChecker checker(cost.get(), &b.manifold_pointers, numeric);
    ceres::GradientChecker::ProbeResults results;
    EXPECT_TRUE(checker.Probe(b.pointers.data(), kGradientCheckPrecision, &results))
        << results.error_log;
  }
}

// At a perfect fit (y = 0, where the log's Jacobian is the identity) the residual's Jacobian is
// -diag(w, w, w, 1, 1, 1) A B / sigma with A the adjoint stack of eq. (18).
TEST(PoseResidual, MatchesAnalyticJacobianAtTheFit) {
  const RobotModel model = TwoToolCobot();
  const auto shared = std::make_shared<const RobotModel>(model);
  std::mt19937_64 rng(4);
  for (ParameterizationKind kind : {ParameterizationKind::kIdentifiable, ParameterizationKind::kFull}) {
    const Parameterization p = MakeParameterization(model, kind, DataKind::kPose);
    for (int trial = 0; trial < kNumConfigurations; ++trial) {
      const int tool = trial % 2;
      const std::vector<double> q = RandomQ(model.num_joints(), &rng);
      Eigen::MatrixXd J_frames;
      const SE3d pose = ToolPoseJacobian(model, q.data(), tool, &J_frames);
      std::unique_ptr<ceres::CostFunction> cost(
          PoseResidual::Create(shared, PoseKind(), q.data(), pose));
      const Blocks b = MakeBlocks(model, p, tool);
      Eigen::VectorXd r;
      const Eigen::MatrixXd J_auto = TangentJacobian(*cost, b, p, &r);
      Eigen::MatrixXd J_analytic = -Restrict(J_frames, p) / kSigma;
      J_analytic.topRows<3>() *= kOrientationWeight;
      EXPECT_LT(RelativeDifference(J_auto, J_analytic), kJacobianTolerance);
      EXPECT_LT(r.norm(), 1e-8);
    }
  }
}

TEST(PoseResidual, ValueIsWeightedLogOfTheError) {
  const RobotModel model = MakeCobot6();
  const auto shared = std::make_shared<const RobotModel>(model);
  const Parameterization p =
      MakeParameterization(model, ParameterizationKind::kIdentifiable, DataKind::kPose);
  std::mt19937_64 rng(5);
  const std::vector<double> q = RandomQ(model.num_joints(), &rng);
  const Vector6d error = (Vector6d() << 0.002, -0.001, 0.003, 0.5, -0.25, 1.0).finished();
  const SE3d measured = ExpSE3(error) * ToolPose(model, q.data(), 0);
  std::unique_ptr<ceres::CostFunction> cost(
      PoseResidual::Create(shared, PoseKind(), q.data(), measured));
  const Blocks b = MakeBlocks(model, p, 0);
  Eigen::VectorXd r(6);
  ASSERT_TRUE(cost->Evaluate(b.pointers.data(), r.data(), nullptr));
  Vector6d expected = error / kSigma;
  expected.head<3>() *= kOrientationWeight;
  EXPECT_LT((r - expected).norm(), 1e-9 * expected.norm());
}

}  // namespace residuals_test
}  // namespace
}  // namespace lpoe
