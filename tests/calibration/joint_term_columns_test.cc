// Issue 42: a row's joint-term columns R = [Y_b(q) basis_b] written once
// (solvers/src/linearization/joint_term_columns.h), the columns both solvers take (the Ceres
// problem's residuals and the linear assembly). They are checked against the core's own joint
// values with the terms (EffectiveJointValues: R is d(q_eff)/dx, by finite differences, and
// R x = q_eff - q), with reduced, identity and empty bases, a term moving several joints and
// columns past the blocks'; and the slot form (the reduction's stored regressors) gives the same
// columns as the terms' regressors.
#include <cmath>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include <Eigen/QR>
#include <gtest/gtest.h>

#include "linearization/joint_term_columns.h"
#include "linearization/normal_equations.h"
#include "coupled_joint_term.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/model/parameterization.h"
#include "lpoe/model/simulation.h"

namespace lpoe {
namespace {
namespace joint_term_columns_test {

struct ColumnsSetup {
  RobotModel nominal = MakeCobot6();
  MeasurementSet data;
  Parameterization p;
  explicit ColumnsSetup(int count = 40) {
    nominal.payload.mass = 0.8;
    nominal.payload.com = Eigen::Vector3d(5, -3, 40);
    SimulationOptions options;
    options.count = count;
    options.seed = 9;
    data = SimulateMeasurements(nominal, std::vector<double>(nominal.num_joints(), 0.0), options);
    p = MakeParameterization(nominal, ParameterizationKind::kIdentifiable, DataKind::kPosition);
    for (const char* name : {"compliance", "harmonics", "gear_ratio"}) {
      std::shared_ptr<const JointTerm> t;
      EXPECT_TRUE(MakeJointTerm(name, nominal, &t).ok()) << name;
      AddJointBlock(t, &p);
    }
    AddJointBlock(std::make_shared<testing::CoupledJointTerm>(
                      nominal.num_joints(), testing::CoupledJointTerm::Form::kSine),
                  &p);
    // compliance: reduced (random orthonormal combinations); harmonics: the identity (as added);
    // gear_ratio: no columns; coupled: reduced.
    std::mt19937 rng(17);
    std::normal_distribution<double> normal;
    for (int b : {0, 3}) {
      const int P = p.joint_blocks[b].term->num_parameters();
      const int k = P - 1;
      Eigen::MatrixXd A(P, k);
      for (int i = 0; i < A.size(); ++i) A.data()[i] = normal(rng);
      const Eigen::MatrixXd Q = A.householderQr().householderQ() * Eigen::MatrixXd::Identity(P, k);
      SetJointBlockBasis(b, Q, "test", &p);
    }
    SetJointBlockBasis(2, Eigen::MatrixXd(p.joint_blocks[2].term->num_parameters(), 0), "test", &p);
  }
  // The terms' values theta_b = basis_b x_b of the joint state x (the blocks' columns in order).
  std::vector<JointTermValues> Values(const Eigen::VectorXd& x) const {
    std::vector<JointTermValues> out;
    int column = 0;
    for (const JointBlock& b : p.joint_blocks) {
      const int k = static_cast<int>(b.basis.cols());
      out.push_back({b.term, b.basis * x.segment(column, k)});
      column += k;
    }
    return out;
  }
};

// R is the derivative of the core's q_eff = q + sum_b Y_b(q) theta_b in the joint state, by central
// differences, and R x its offsets; the columns past the blocks' are zero.
TEST(JointTermColumns, AreTheDerivativeOfTheEffectiveJointValues) {
  const ColumnsSetup s;
  const int n = s.nominal.num_joints();
  int K = 0;
  for (const JointBlock& b : s.p.joint_blocks) K += static_cast<int>(b.basis.cols());
  ASSERT_EQ(s.p.joint_blocks[1].basis.rows(), s.p.joint_blocks[1].basis.cols());
  ASSERT_EQ(s.p.joint_blocks[2].basis.cols(), 0);
  internal::JointTermColumns columns(s.p, n, K + 2);
  EXPECT_EQ(columns.num_columns(), K + 2);
  std::mt19937 rng(5);
  std::normal_distribution<double> normal;
  Eigen::VectorXd x(K);
  for (int k = 0; k < K; ++k) x(k) = 1e-3 * normal(rng);
  Eigen::MatrixXd R;
  Eigen::VectorXd plus(n), minus(n), q_eff(n);
  const double h = 1e-4;
  for (int r = 0; r < s.data.size(); ++r) {
    const double* q = s.data.q(r);
    columns.Evaluate(r, q, &R);
    ASSERT_EQ(R.rows(), n);
    ASSERT_EQ(R.cols(), K + 2);
    EXPECT_EQ(R.rightCols(2).cwiseAbs().maxCoeff(), 0.0);
    EffectiveJointValues(s.Values(x), n, q, q_eff.data());
    const Eigen::VectorXd offsets = q_eff - Eigen::Map<const Eigen::VectorXd>(q, n);
    EXPECT_LE((R.leftCols(K) * x - offsets).cwiseAbs().maxCoeff(),
              1e-12 * offsets.cwiseAbs().maxCoeff());
    for (int k = 0; k < K; ++k) {
      Eigen::VectorXd e = x;
      e(k) += h;
      EffectiveJointValues(s.Values(e), n, q, plus.data());
      e(k) -= 2 * h;
      EffectiveJointValues(s.Values(e), n, q, minus.data());
      const Eigen::VectorXd fd = (plus - minus) / (2 * h);
      EXPECT_LE((R.col(k) - fd).cwiseAbs().maxCoeff(), 1e-8 * (1 + fd.cwiseAbs().maxCoeff()))
          << "row " << r << " column " << k;
    }
  }
}

// The reduction's slots (BuildJointSpaceRegressors, what the Ceres problem reads when they were
// stored) give the terms' columns, and a columns object switched back to the terms gives them again.
TEST(JointTermColumns, SlotsGiveTheTermsColumns) {
  const ColumnsSetup s;
  const int n = s.nominal.num_joints();
  const internal::JointSpaceRegressors regs = internal::BuildJointSpaceRegressors(s.p, s.data);
  ASSERT_EQ(regs.values.cols(), s.data.size());
  internal::JointTermColumns from_terms(s.p, n);
  internal::JointTermColumns from_slots(s.p, n);
  from_slots.UseSlots(&regs);
  Eigen::MatrixXd a, b;
  for (int r = 0; r < s.data.size(); ++r) {
    from_terms.Evaluate(r, s.data.q(r), &a);
    from_slots.Evaluate(r, s.data.q(r), &b);
    ASSERT_GT(a.cwiseAbs().maxCoeff(), 0.0);
    EXPECT_LE((a - b).cwiseAbs().maxCoeff(), 1e-14 * a.cwiseAbs().maxCoeff()) << "row " << r;
  }
  from_slots.UseSlots(nullptr);
  from_slots.Evaluate(3, s.data.q(3), &b);
  from_terms.Evaluate(3, s.data.q(3), &a);
  EXPECT_EQ(a, b);
}

}  // namespace joint_term_columns_test
}  // namespace
}  // namespace lpoe
