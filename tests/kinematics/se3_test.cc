// Tests of the SE(3) / se(3) maps of se3.h: round trips, the adjoint identity, hat/vee, quaternions,
// roll-pitch-yaw, and the derivatives that ceres::Jet carries through exp and log (including exactly
// at the identity, where the Taylor branches must keep them exact).
#include "lpoe/kinematics/se3.h"

#include <cmath>

#include <ceres/jet.h>
#include <gtest/gtest.h>

#include "test_util.h"

namespace lpoe {

// Explicit instantiations with a Jet: the templates must compile for automatic differentiation.
using Jet6 = ceres::Jet<double, 6>;
template SE3<Jet6> ExpSE3(const Eigen::MatrixBase<Vector6<Jet6>>& xi);
template Vector6<Jet6> LogSE3(const SE3<Jet6>& X);
template Vector3<Jet6> LogSO3(const Matrix3<Jet6>& R);
template Matrix6<Jet6> Adjoint(const SE3<Jet6>& X);
template Eigen::Matrix<Jet6, 4, 1> RotationToQuaternion(const Matrix3<Jet6>& R);
template Matrix3<Jet6> QuaternionToRotation(const Eigen::Matrix<Jet6, 4, 1>& q);
template Matrix3<Jet6> RotationFromRpy(const Jet6& roll, const Jet6& pitch, const Jet6& yaw);

namespace {
namespace se3_test {

using testing::RelativeMaxDifference;
using testing::TestRandom;

constexpr int kTrials = 500;
constexpr uint64_t kSeed = 20220101;
constexpr double kTranslationBound = 1000.0;  // mm
// Absolute tolerance for quantities of order 1 (rotations, unit vectors).
constexpr double kTolerance = 1e-12;
// Tolerance relative to max(1, |value|) for twists and transforms with millimetre translations.
constexpr double kRelativeTolerance = 1e-11;
// Central finite differences: step and agreement with the analytic / Jet derivative.
constexpr double kFdStep = 1e-6;
constexpr double kFdTolerance = 1e-7;

// exp(A) of a 4x4 matrix by scaling and squaring of the Taylor series: an independent reference.
Eigen::Matrix4d MatrixExponential(const Eigen::Matrix4d& A) {
  int squarings = 0;
  double norm = A.cwiseAbs().rowwise().sum().maxCoeff();
  while (norm > 0.25) {
    norm *= 0.5;
    ++squarings;
  }
  const Eigen::Matrix4d B = A / std::ldexp(1.0, squarings);
  Eigen::Matrix4d term = Eigen::Matrix4d::Identity();
  Eigen::Matrix4d sum = Eigen::Matrix4d::Identity();
  for (int k = 1; k <= 30; ++k) {
    term = term * B / static_cast<double>(k);
    sum += term;
  }
  for (int k = 0; k < squarings; ++k) sum = sum * sum;
  return sum;
}

double TransformDifference(const SE3d& a, const SE3d& b) {
  const double scale = std::max(1.0, b.t.cwiseAbs().maxCoeff());
  return std::max((a.R - b.R).cwiseAbs().maxCoeff(),
                  (a.t - b.t).cwiseAbs().maxCoeff() / scale);
}

double TwistDifference(const Vector6d& a, const Vector6d& b) {
  const double scale = std::max(1.0, b.cwiseAbs().maxCoeff());
  return (a - b).cwiseAbs().maxCoeff() / scale;
}

Vector6d Unit6(int k) { return Vector6d::Unit(k); }

// ---------------------------------------------------------------------------------------------
// Hat / vee.

TEST(Se3, HatIsCrossProductAndVeeInvertsIt) {
  TestRandom rng(kSeed);
  for (int trial = 0; trial < kTrials; ++trial) {
    const Eigen::Vector3d w = rng.Vector3(3.0), x = rng.Vector3(3.0);
    const Eigen::Matrix3d W = Hat3(w);
    EXPECT_LT((W * x - w.cross(x)).norm(), kTolerance);
    EXPECT_LT((W + W.transpose()).norm(), kTolerance) << "hat(w) must be skew-symmetric";
    EXPECT_LT((Vee3(W) - w).norm(), kTolerance);
  }
}

TEST(Se3, Hat6HasRotationFirstAndVee6InvertsIt) {
  TestRandom rng(kSeed + 1);
  for (int trial = 0; trial < kTrials; ++trial) {
    const Vector6d xi = rng.Twist(rng.Uniform(0, 3), 100.0);
    const Eigen::Matrix4d X = Hat6(xi);
    const Eigen::Vector3d p = rng.Vector3(100.0);
    // xi^ [p; 1] = [omega x p + v; 0] for xi = (omega, v).
    const Eigen::Vector4d image = X * p.homogeneous();
    EXPECT_LT((image.head<3>() - (xi.head<3>().cross(p) + xi.tail<3>())).norm(),
              kRelativeTolerance * 1e3);
    EXPECT_EQ(image(3), 0.0);
    EXPECT_LT((Vee6(X) - xi).norm(), kTolerance);
  }
}

// ---------------------------------------------------------------------------------------------
// exp and log.

TEST(Se3, ExpMatchesMatrixExponential) {
  TestRandom rng(kSeed + 2);
  for (int trial = 0; trial < kTrials; ++trial) {
    const Vector6d xi = rng.Twist(rng.Uniform(0, 3.0), 500.0);
    const Eigen::Matrix4d reference = MatrixExponential(Hat6(xi));
    const Eigen::Matrix4d ours = ExpSE3(xi).Matrix();
    EXPECT_LT(RelativeMaxDifference(ours, reference), kRelativeTolerance) << xi.transpose();
    EXPECT_LT((ExpSO3(xi.head<3>()) - reference.topLeftCorner<3, 3>()).cwiseAbs().maxCoeff(),
              kTolerance);
  }
}

TEST(Se3, ExpLogRoundTrip) {
  TestRandom rng(kSeed + 3);
  for (int trial = 0; trial < kTrials; ++trial) {
    // |omega| < pi: log(exp(xi)) is xi itself.
    const Vector6d xi = rng.Twist(rng.Uniform(0, kPi - 1e-3), kTranslationBound);
    EXPECT_LT(TwistDifference(LogSE3(ExpSE3(xi)), xi), kRelativeTolerance) << xi.transpose();
    // exp(log(T)) is T for any transform.
    const SE3d T = rng.Pose(kTranslationBound);
    EXPECT_LT(TransformDifference(ExpSE3(LogSE3(T)), T), kRelativeTolerance);
    EXPECT_LE(LogSE3(T).head<3>().norm(), kPi + kTolerance);
  }
}

TEST(Se3, ExpLogRoundTripNearZero) {
  TestRandom rng(kSeed + 4);
  constexpr double kAngles[] = {1e-9, 3e-9, 1e-7, 9.99e-5, 1.001e-4, 1e-3};
  for (double angle : kAngles) {
    for (int trial = 0; trial < kTrials / 10; ++trial) {
      const Vector6d xi = rng.Twist(angle, kTranslationBound);
      const Vector6d back = LogSE3(ExpSE3(xi));
      // The rotation part keeps its relative precision even at 1e-9 rad.
      EXPECT_LT((back.head<3>() - xi.head<3>()).norm(), 1e-9 * angle) << "angle " << angle;
      EXPECT_LT((back.tail<3>() - xi.tail<3>()).norm(), kRelativeTolerance * kTranslationBound)
          << "angle " << angle;
      // And exp agrees with the matrix exponential on both sides of the Taylor branch.
      EXPECT_LT(RelativeMaxDifference(ExpSE3(xi).Matrix(), MatrixExponential(Hat6(xi))),
                kRelativeTolerance)
          << "angle " << angle;
    }
  }
}

TEST(Se3, ExpLogExactlyZero) {
  const Vector6d zero = Vector6d::Zero();
  const SE3d I = ExpSE3(zero);
  EXPECT_EQ(I.R, Eigen::Matrix3d::Identity());
  EXPECT_EQ(I.t, Eigen::Vector3d::Zero());
  EXPECT_EQ(LogSE3(SE3d::Identity()), zero);

  // A pure translation: omega exactly zero, v not.
  Vector6d xi = Vector6d::Zero();
  xi.tail<3>() << 12.5, -3.0, 700.0;
  const SE3d T = ExpSE3(xi);
  EXPECT_EQ(T.R, Eigen::Matrix3d::Identity());
  EXPECT_LT((T.t - xi.tail<3>()).norm(), kTolerance);
  EXPECT_LT((LogSE3(T) - xi).norm(), kTolerance);
}

TEST(Se3, ExpLogRoundTripNearPi) {
  TestRandom rng(kSeed + 5);
  for (int trial = 0; trial < kTrials; ++trial) {
    const Vector6d xi = rng.Twist(kPi - 1e-7, kTranslationBound);
    EXPECT_LT(TwistDifference(LogSE3(ExpSE3(xi)), xi), 1e-9) << xi.transpose();
  }
}

TEST(Se3, ExpLogAtPiExactly) {
  TestRandom rng(kSeed + 6);
  for (int trial = 0; trial < kTrials; ++trial) {
    const Eigen::Vector3d axis = rng.UnitVector();
    Vector6d xi;
    xi << kPi * axis, rng.Vector3(kTranslationBound);
    const SE3d T = ExpSE3(xi);
    const Vector6d back = LogSE3(T);
    // At pi the axis sign is ambiguous; the angle is pi, the axis is +-axis, and exp(log(T)) = T.
    EXPECT_NEAR(back.head<3>().norm(), kPi, 1e-9);
    EXPECT_LT(back.head<3>().normalized().cross(axis).norm(), 1e-9);
    EXPECT_LT(TransformDifference(ExpSE3(back), T), kRelativeTolerance);
  }
  // Rotations by pi built exactly (R = 2 a a^T - I) take each branch of Shepperd's method.
  const Eigen::Vector3d axes[] = {Eigen::Vector3d::UnitX(), Eigen::Vector3d::UnitY(),
                                  Eigen::Vector3d::UnitZ(),
                                  Eigen::Vector3d(1, 2, -2).normalized()};
  for (const Eigen::Vector3d& a : axes) {
    const Eigen::Matrix3d R = 2 * a * a.transpose() - Eigen::Matrix3d::Identity();
    const Eigen::Vector3d w = LogSO3(R);
    EXPECT_NEAR(w.norm(), kPi, kTolerance) << a.transpose();
    EXPECT_LT(w.normalized().cross(a).norm(), kTolerance) << a.transpose();
    EXPECT_LT((ExpSO3(w) - R).cwiseAbs().maxCoeff(), kTolerance) << a.transpose();
  }
}

// ---------------------------------------------------------------------------------------------
// Adjoint and bracket.

TEST(Se3, AdjointIdentity) {
  TestRandom rng(kSeed + 7);
  for (int trial = 0; trial < kTrials; ++trial) {
    const SE3d T = rng.Pose(kTranslationBound);
    const Vector6d xi = rng.Twist(rng.Uniform(0, 2.0), 100.0);
    // T exp(xi^) T^-1 == exp((Ad_T xi)^).
    const Eigen::Matrix4d lhs = (T * ExpSE3(xi) * T.Inverse()).Matrix();
    const Eigen::Matrix4d rhs = ExpSE3(Vector6d(Adjoint(T) * xi)).Matrix();
    EXPECT_LT(RelativeMaxDifference(lhs, rhs), kRelativeTolerance);
    // Ad is a homomorphism: Ad_{T1 T2} = Ad_T1 Ad_T2, Ad_{T^-1} = Ad_T^-1.
    const SE3d T2 = rng.Pose(kTranslationBound);
    EXPECT_LT(RelativeMaxDifference(Adjoint(T * T2), Adjoint(T) * Adjoint(T2)), kRelativeTolerance);
    EXPECT_LT(RelativeMaxDifference(Adjoint(T.Inverse()) * Adjoint(T), Matrix6d::Identity()),
              kRelativeTolerance);
  }
}

TEST(Se3, LieBracketMatrixIsTheCommutator) {
  TestRandom rng(kSeed + 8);
  for (int trial = 0; trial < kTrials; ++trial) {
    const Vector6d xi = rng.Twist(1.0, 10.0), eta = rng.Twist(1.0, 10.0);
    const Eigen::Matrix4d commutator = Hat6(xi) * Hat6(eta) - Hat6(eta) * Hat6(xi);
    EXPECT_LT((LieBracketMatrix(xi) * eta - Vee6(commutator)).norm(), kRelativeTolerance * 100);
  }
}

// ---------------------------------------------------------------------------------------------
// Quaternions and roll-pitch-yaw.

TEST(Se3, QuaternionRotationRoundTrip) {
  TestRandom rng(kSeed + 9);
  for (int trial = 0; trial < kTrials; ++trial) {
    // Angles up to pi, so that every branch of Shepperd's method is taken.
    const Eigen::Matrix3d R = ExpSO3(Eigen::Vector3d(rng.Uniform(0, kPi) * rng.UnitVector()));
    const Eigen::Vector4d q = RotationToQuaternion(R);
    EXPECT_NEAR(q.norm(), 1.0, kTolerance);
    EXPECT_GE(q(3), 0.0);
    EXPECT_LT((QuaternionToRotation(q) - R).cwiseAbs().maxCoeff(), kTolerance);
    // Same quaternion as Eigen's, up to sign; Eigen stores (x, y, z, w) in coeffs().
    const Eigen::Vector4d eigen_q = Eigen::Quaterniond(R).coeffs();
    EXPECT_LT(std::min((q - eigen_q).norm(), (q + eigen_q).norm()), kTolerance);
    // QuaternionToRotation normalizes its input.
    EXPECT_LT((QuaternionToRotation(Eigen::Vector4d(2.5 * q)) - R).cwiseAbs().maxCoeff(),
              kTolerance);
  }
}

TEST(Se3, RpyFromRotationInvertsRotationFromRpy) {
  TestRandom rng(kSeed + 10);
  for (int trial = 0; trial < kTrials; ++trial) {
    const double roll = rng.Uniform(-kPi + 1e-6, kPi - 1e-6);
    const double pitch = rng.Uniform(-kPi / 2 + 1e-6, kPi / 2 - 1e-6);
    const double yaw = rng.Uniform(-kPi + 1e-6, kPi - 1e-6);
    const Eigen::Matrix3d R = RotationFromRpy(roll, pitch, yaw);
    // URDF convention: R = Rz(yaw) Ry(pitch) Rx(roll).
    const Eigen::Matrix3d reference =
        (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) *
         Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
         Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
            .toRotationMatrix();
    EXPECT_LT((R - reference).cwiseAbs().maxCoeff(), kTolerance);
    const Eigen::Vector3d rpy = RpyFromRotation(R);
    EXPECT_LT((rpy - Eigen::Vector3d(roll, pitch, yaw)).cwiseAbs().maxCoeff(), 1e-9)
        << roll << " " << pitch << " " << yaw;
  }
}

TEST(Se3, RpyAtAndNearGimbalLockReproducesTheRotation) {
  // At |pitch| = pi/2 only yaw -/+ roll is defined: the split is arbitrary, but the rotation must be
  // reproduced to round-off, at and near the singularity.
  TestRandom rng(kSeed + 11);
  for (double pitch : {kPi / 2, -kPi / 2, kPi / 2 - 1e-7, -kPi / 2 + 1e-9, kPi / 2 - 1e-4}) {
    for (int trial = 0; trial < kTrials / 10; ++trial) {
      const Eigen::Matrix3d R =
          RotationFromRpy(rng.Uniform(-kPi, kPi), pitch, rng.Uniform(-kPi, kPi));
      const Eigen::Vector3d rpy = RpyFromRotation(R);
      EXPECT_NEAR(rpy(1), pitch, 1e-7) << "pitch " << pitch;
      EXPECT_LT((RotationFromRpy(rpy(0), rpy(1), rpy(2)) - R).cwiseAbs().maxCoeff(), kTolerance)
          << "pitch " << pitch;
    }
  }
}

TEST(Se3, ProjectToRotationRestoresOrthonormality) {
  TestRandom rng(kSeed + 12);
  for (int trial = 0; trial < kTrials / 10; ++trial) {
    const Eigen::Matrix3d R = ExpSO3(Eigen::Vector3d(rng.Uniform(0, kPi) * rng.UnitVector()));
    Eigen::Matrix3d noisy = R;
    for (int k = 0; k < 9; ++k) noisy(k) += rng.Uniform(-1e-6, 1e-6);
    const Eigen::Matrix3d P = ProjectToRotation(noisy);
    EXPECT_LT((P.transpose() * P - Eigen::Matrix3d::Identity()).norm(), kTolerance);
    EXPECT_NEAR(P.determinant(), 1.0, kTolerance);
    EXPECT_LT((P - R).cwiseAbs().maxCoeff(), 1e-5);
  }
}

// ---------------------------------------------------------------------------------------------
// Derivatives through ceres::Jet.

Vector6<Jet6> InfinitesimalTwist(const Vector6d& at) {
  Vector6<Jet6> xi;
  for (int k = 0; k < 6; ++k) xi(k) = Jet6(at(k), k);
  return xi;
}

// d/d xi_k of a 4x4 matrix-valued function of Jets.
Eigen::Matrix4d JetDerivative(const Matrix4<Jet6>& M, int k) {
  Eigen::Matrix4d d;
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) d(r, c) = M(r, c).v(k);
  }
  return d;
}

Eigen::Matrix4d Values(const Matrix4<Jet6>& M) {
  Eigen::Matrix4d d;
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) d(r, c) = M(r, c).a;
  }
  return d;
}

TEST(Se3, JetExpDerivativeAtZeroIsTheGenerators) {
  const Matrix4<Jet6> M = ExpSE3(InfinitesimalTwist(Vector6d::Zero())).Matrix();
  EXPECT_EQ(Values(M), Eigen::Matrix4d::Identity());
  for (int k = 0; k < 6; ++k) {
    const Eigen::Matrix4d generator = Hat6(Unit6(k));
    EXPECT_LT((JetDerivative(M, k) - generator).cwiseAbs().maxCoeff(), kTolerance) << "k = " << k;
    // Central finite differences agree.
    const Eigen::Matrix4d fd =
        (ExpSE3(Vector6d(kFdStep * Unit6(k))).Matrix() -
         ExpSE3(Vector6d(-kFdStep * Unit6(k))).Matrix()) / (2 * kFdStep);
    EXPECT_LT((fd - generator).cwiseAbs().maxCoeff(), kFdTolerance) << "k = " << k;
  }
}

TEST(Se3, JetExpDerivativeMatchesFiniteDifferences) {
  TestRandom rng(kSeed + 13);
  // Random twists, and twists on both sides of the Taylor branch (theta^2 = 1e-8).
  std::vector<Vector6d> points;
  for (int trial = 0; trial < 50; ++trial) points.push_back(rng.Twist(rng.Uniform(0, 3), 100.0));
  for (double angle : {1e-9, 0.7e-4, 1.3e-4}) points.push_back(rng.Twist(angle, 100.0));
  for (const Vector6d& xi : points) {
    const Matrix4<Jet6> M = ExpSE3(InfinitesimalTwist(xi)).Matrix();
    EXPECT_LT((Values(M) - ExpSE3(xi).Matrix()).cwiseAbs().maxCoeff(), kTolerance * 100);
    for (int k = 0; k < 6; ++k) {
      const Eigen::Matrix4d fd = (ExpSE3(Vector6d(xi + kFdStep * Unit6(k))).Matrix() -
                                  ExpSE3(Vector6d(xi - kFdStep * Unit6(k))).Matrix()) /
                                 (2 * kFdStep);
      EXPECT_LT(RelativeMaxDifference(JetDerivative(M, k), fd), kFdTolerance)
          << "xi " << xi.transpose() << ", k = " << k;
    }
  }
}

// d/d delta of log(T0 exp(delta^)) at delta = 0, by Jets and by central differences.
void ExpectLogDerivativeMatches(const SE3d& T0) {
  const SE3<Jet6> X = T0.cast<Jet6>() * ExpSE3(InfinitesimalTwist(Vector6d::Zero()));
  const Vector6<Jet6> log_jet = LogSE3(X);
  Matrix6d jet, fd;
  for (int r = 0; r < 6; ++r) {
    EXPECT_TRUE(std::isfinite(log_jet(r).a));
    for (int k = 0; k < 6; ++k) jet(r, k) = log_jet(r).v(k);
  }
  for (int k = 0; k < 6; ++k) {
    fd.col(k) = (LogSE3(T0 * ExpSE3(Vector6d(kFdStep * Unit6(k)))) -
                 LogSE3(T0 * ExpSE3(Vector6d(-kFdStep * Unit6(k))))) /
                (2 * kFdStep);
  }
  EXPECT_TRUE(jet.allFinite()) << jet;
  EXPECT_LT(RelativeMaxDifference(jet, fd), kFdTolerance) << "jet\n" << jet << "\nfd\n" << fd;
}

TEST(Se3, JetLogDerivativeAtIdentityIsFiniteAndIdentity) {
  // At the identity, d log(exp(delta)) / d delta = I.
  const SE3<Jet6> X = ExpSE3(InfinitesimalTwist(Vector6d::Zero()));
  const Vector6<Jet6> log_jet = LogSE3(X);
  Matrix6d jet;
  for (int r = 0; r < 6; ++r) {
    EXPECT_EQ(log_jet(r).a, 0.0);
    for (int k = 0; k < 6; ++k) jet(r, k) = log_jet(r).v(k);
  }
  EXPECT_TRUE(jet.allFinite());
  EXPECT_LT((jet - Matrix6d::Identity()).cwiseAbs().maxCoeff(), kTolerance) << jet;

  // The same through an input whose rotation is exactly I + hat(delta_omega) (not through exp).
  SE3<Jet6> Y;
  Vector6<Jet6> d = InfinitesimalTwist(Vector6d::Zero());
  Y.R = Matrix3<Jet6>::Identity() + Hat3(d.head<3>());
  Y.t = d.tail<3>();
  const Vector6<Jet6> log_y = LogSE3(Y);
  for (int r = 0; r < 6; ++r) {
    for (int k = 0; k < 6; ++k) jet(r, k) = log_y(r).v(k);
  }
  EXPECT_LT((jet - Matrix6d::Identity()).cwiseAbs().maxCoeff(), kTolerance) << jet;

  ExpectLogDerivativeMatches(SE3d::Identity());
}

TEST(Se3, JetLogDerivativeMatchesFiniteDifferences) {
  TestRandom rng(kSeed + 14);
  for (int trial = 0; trial < 50; ++trial) {
    SCOPED_TRACE(trial);
    ExpectLogDerivativeMatches(rng.Pose(100.0));
  }
  // Near the Taylor branch boundary and near (not at) pi.
  for (double angle : {1e-9, 0.7e-4, 1.3e-4, kPi - 1e-3}) {
    SCOPED_TRACE(angle);
    ExpectLogDerivativeMatches(ExpSE3(rng.Twist(angle, 100.0)));
  }
}

}  // namespace se3_test
}  // namespace
}  // namespace lpoe
