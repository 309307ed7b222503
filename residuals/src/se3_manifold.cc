#include "lpoe/se3_manifold.h"

#include <cmath>

#include <glog/logging.h>

namespace lpoe {
namespace {

using Quaternion = Eigen::Vector4d;  // x, y, z, w

// Tolerance of the orthonormality check of the basis.
constexpr double kBasisTolerance = 1e-9;

}  // namespace

void Se3ToArray(const SE3d& T, double* x) {
  const Eigen::Vector4d q = RotationToQuaternion(T.R);
  for (int k = 0; k < 4; ++k) x[k] = q(k);
  for (int k = 0; k < 3; ++k) x[4 + k] = T.t(k);
}

Se3Manifold::Se3Manifold(const Eigen::MatrixXd& basis) : basis_(basis) {
  CHECK_EQ(basis_.rows(), 6) << "an SE(3) tangent basis has 6 rows";
  CHECK(basis_.cols() >= 1 && basis_.cols() <= 6) << "basis has " << basis_.cols() << " columns";
  const Eigen::MatrixXd gram = basis_.transpose() * basis_;
  CHECK(gram.isApprox(Eigen::MatrixXd::Identity(basis_.cols(), basis_.cols()), kBasisTolerance))
      << "the basis columns must be orthonormal";
}

Se3Manifold::Se3Manifold() : Se3Manifold(Eigen::MatrixXd::Identity(6, 6)) {}

bool Se3Manifold::Plus(const double* x, const double* delta, double* x_plus_delta) const {
  const Eigen::Map<const Eigen::VectorXd> d(delta, basis_.cols());
  const Vector6d xi = basis_ * d;
  const Quaternion q(x[0], x[1], x[2], x[3]);
  const SE3d T = Se3FromArray(x);
  const SE3d dT = ExpSE3(xi);
  // The rotation is composed on quaternions, not through R, so that Plus(x, 0) returns x exactly
  // (same sign of q) and the result stays a unit quaternion.
  const Quaternion q_out = QuaternionProduct(q, QuaternionExp<double>(xi.head<3>()));
  const Eigen::Vector3d t_out = T.R * dT.t + T.t;  // eq. (19): T exp(xi^)
  for (int k = 0; k < 4; ++k) x_plus_delta[k] = q_out(k);
  for (int k = 0; k < 3; ++k) x_plus_delta[4 + k] = t_out(k);
  return true;
}

bool Se3Manifold::PlusJacobian(const double* x, double* jacobian) const {
  const Eigen::Vector3d v(x[0], x[1], x[2]);
  const double w = x[3];
  Eigen::Matrix<double, 7, 6> J6 = Eigen::Matrix<double, 7, 6>::Zero();
  // d(q (x) [omega / 2, 1]) / d omega = 0.5 L(q)_{:, 0:3}.
  J6.block<3, 3>(0, 0) = 0.5 * (w * Eigen::Matrix3d::Identity() + Hat3(v));
  J6.block<1, 3>(3, 0) = -0.5 * v.transpose();
  // t' = R t_delta + t, t_delta = v + O(|xi|^2).
  J6.block<3, 3>(4, 3) = Se3FromArray(x).R;
  Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> J(
      jacobian, kSe3AmbientSize, basis_.cols());
  J = J6 * basis_;
  return true;
}

bool Se3Manifold::Minus(const double* y, const double* x, double* y_minus_x) const {
  const SE3d Tx = Se3FromArray(x);
  const SE3d Ty = Se3FromArray(y);
  const Vector6d xi = LogSE3(Tx.Inverse() * Ty);
  Eigen::Map<Eigen::VectorXd> out(y_minus_x, basis_.cols());
  out = basis_.transpose() * xi;
  return true;
}

bool Se3Manifold::MinusJacobian(const double* x, double* jacobian) const {
  const Eigen::Vector3d v(x[0], x[1], x[2]);
  const double w = x[3];
  Eigen::Matrix<double, 6, 7> J6 = Eigen::Matrix<double, 6, 7>::Zero();
  // omega = 2 vec(q(x)^* (x) q(y)) + O(|omega|^2); the radial direction of q(y) has no effect.
  J6.block<3, 3>(0, 0) = 2.0 * (w * Eigen::Matrix3d::Identity() - Hat3(v));
  J6.block<3, 1>(0, 3) = -2.0 * v;
  // v = R(x)^T (t(y) - t(x)) + O(|xi|^2).
  J6.block<3, 3>(3, 4) = Se3FromArray(x).R.transpose();
  Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> J(
      jacobian, basis_.cols(), kSe3AmbientSize);
  J = basis_.transpose() * J6;
  return true;
}

}  // namespace lpoe
