#include "lpoe/se3_manifold.h"

#include <random>

#include <Eigen/QR>
#include <ceres/manifold_test_utils.h>
#include <gtest/gtest.h>

#include "lpoe/kinematics/eigen_decompositions.h"
#include "lpoe/model/parameterization.h"

namespace lpoe {
namespace {
namespace se3_manifold_test {

using ceres::HasCorrectMinusJacobianAt;
using ceres::HasCorrectPlusJacobianAt;
using ceres::HasCorrectRightMultiplyByPlusJacobianAt;
using ceres::MinusPlusIsIdentityAt;
using ceres::MinusPlusJacobianIsIdentityAt;
using ceres::PlusMinusIsIdentityAt;
using ceres::Vector;
using ceres::XMinusXIsZeroAt;
using ceres::XPlusZeroIsXAt;

constexpr int kNumTrials = 20;
// Invariants checked against Ridders numeric differentiation (as ceres's own manifold tests).
constexpr double kTolerance = 1e-9;
constexpr double kExactTolerance = 1e-12;

SE3d RandomPose(std::mt19937_64* rng) {
  std::normal_distribution<double> normal;
  Vector6d xi;
  for (int k = 0; k < 3; ++k) xi(k) = normal(*rng);           // up to ~pi rotations
  for (int k = 3; k < 6; ++k) xi(k) = 300.0 * normal(*rng);   // mm
  return ExpSE3(xi);
}

Vector RandomPoint(std::mt19937_64* rng) {
  Vector x(kSe3AmbientSize);
  Se3ToArray(RandomPose(rng), x.data());
  return x;
}

Vector RandomTangent(int k, double scale, std::mt19937_64* rng) {
  std::normal_distribution<double> normal;
  Vector d(k);
  for (int i = 0; i < k; ++i) d(i) = scale * normal(*rng);
  return d;
}

void CheckInvariants(const Se3Manifold& manifold, uint64_t seed) {
  std::mt19937_64 rng(seed);
  const int k = manifold.TangentSize();
  for (int trial = 0; trial < kNumTrials; ++trial) {
    const Vector x = RandomPoint(&rng);
    const Vector delta = RandomTangent(k, 0.3, &rng);
    Vector y(kSe3AmbientSize);
    ASSERT_TRUE(manifold.Plus(x.data(), RandomTangent(k, 0.3, &rng).data(), y.data()));
    EXPECT_THAT_MANIFOLD_INVARIANTS_HOLD(manifold, x, delta, y, kTolerance);
  }
}

Eigen::MatrixXd RevoluteBasis() {
  return IdentifiableJointBasis((Vector6d() << 0, 0, 1, 0, 0, 0).finished());
}

Eigen::MatrixXd ToolPositionBasis() {
  Eigen::MatrixXd B = Eigen::MatrixXd::Zero(6, 3);
  B.bottomRows<3>().setIdentity();
  return B;
}

TEST(Se3Manifold, InvariantsHoldRevoluteBasis) {
  const Se3Manifold manifold(RevoluteBasis());
  EXPECT_EQ(manifold.TangentSize(), 4);
  CheckInvariants(manifold, 1);
}

TEST(Se3Manifold, InvariantsHoldToolPositionBasis) {
  const Se3Manifold manifold(ToolPositionBasis());
  EXPECT_EQ(manifold.TangentSize(), 3);
  CheckInvariants(manifold, 2);
}

TEST(Se3Manifold, InvariantsHoldFull) {
  const Se3Manifold manifold;
  EXPECT_EQ(manifold.TangentSize(), 6);
  EXPECT_EQ(manifold.AmbientSize(), 7);
  CheckInvariants(manifold, 3);
}

TEST(Se3Manifold, InvariantsHoldRandomOrthonormalBasis) {
  std::mt19937_64 rng(4);
  std::normal_distribution<double> normal;
  Eigen::MatrixXd A(6, 5);
  for (int i = 0; i < A.size(); ++i) A.data()[i] = normal(rng);
  const Eigen::MatrixXd B = Eigen::HouseholderQR<Eigen::MatrixXd>(A).householderQ() *
                            Eigen::MatrixXd::Identity(6, 5);
  CheckInvariants(Se3Manifold(B), 5);
}

// Plus is the right perturbation of eq. (19): T exp((B delta)^), as ApplyUpdate computes it.
TEST(Se3Manifold, PlusIsRightPerturbation) {
  std::mt19937_64 rng(6);
  const Se3Manifold manifold(RevoluteBasis());
  for (int trial = 0; trial < kNumTrials; ++trial) {
    const SE3d T = RandomPose(&rng);
    const Vector delta = RandomTangent(4, 0.5, &rng);
    Vector x(7), out(7);
    Se3ToArray(T, x.data());
    ASSERT_TRUE(manifold.Plus(x.data(), delta.data(), out.data()));
    const SE3d expected = T * ExpSE3(Vector6d(RevoluteBasis() * delta));
    const SE3d actual = Se3FromArray(out.data());
    EXPECT_LT((actual.R - expected.R).norm(), kExactTolerance);
    EXPECT_LT((actual.t - expected.t).norm(), kExactTolerance * 1e3);
    EXPECT_NEAR(out.head<4>().norm(), 1.0, kExactTolerance);
  }
}

TEST(Se3Manifold, ArrayRoundTrip) {
  std::mt19937_64 rng(7);
  for (int trial = 0; trial < kNumTrials; ++trial) {
    const SE3d T = RandomPose(&rng);
    double x[7];
    Se3ToArray(T, x);
    const SE3d back = Se3FromArray(x);
    EXPECT_LT((back.R - T.R).norm(), kExactTolerance);
    EXPECT_LT((back.t - T.t).norm(), kExactTolerance);
    EXPECT_GE(x[3], 0.0);
  }
}

TEST(Se3ManifoldDeathTest, RejectsNonOrthonormalBasis) {
  Eigen::MatrixXd B = RevoluteBasis();
  B.col(0) *= 2.0;
  EXPECT_DEATH(Se3Manifold manifold(B), "orthonormal");
}

}  // namespace se3_manifold_test
}  // namespace
}  // namespace lpoe
