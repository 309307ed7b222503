// SE(3) and so(3) / se(3) maps, templated on the scalar so that the same code runs on double and on
// ceres::Jet (automatic differentiation).
//
// Conventions (docs/conventions.md):
//   * a twist is xi = (omega, v): rotation first, then translation;
//   * hat(xi) = [[omega^, v], [0, 0]];
//   * Ad_T = [[R, 0], [t^ R, R]], so that T exp(xi^) = exp((Ad_T xi)^) T;
//   * T_a_b maps coordinates in frame b to frame a.
//
// Every function that divides by an angle has a Taylor branch near zero whose derivatives are exact
// to the order kept, so that Jets evaluated exactly at the identity carry the right derivative
// (sqrt(0) has an infinite derivative; the branches never take it).
#ifndef LPOE_SE3_H_
#define LPOE_SE3_H_

#include <cmath>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace lpoe {

template <typename T>
using Vector3 = Eigen::Matrix<T, 3, 1>;
template <typename T>
using Vector6 = Eigen::Matrix<T, 6, 1>;
template <typename T>
using Matrix3 = Eigen::Matrix<T, 3, 3>;
template <typename T>
using Matrix4 = Eigen::Matrix<T, 4, 4>;
template <typename T>
using Matrix6 = Eigen::Matrix<T, 6, 6>;

using Vector6d = Vector6<double>;
using Matrix6d = Matrix6<double>;

// pi, and the factor from degrees (where users read angles) to radians (everything inside).
inline constexpr double kPi = 3.14159265358979323846;
inline constexpr double kDegreesToRadians = kPi / 180.0;

namespace internal {
// Below this squared angle the rotation log (LogSO3) replaces its closed form by a Taylor series,
// accurate to better than 1e-20 relative there.
constexpr double kSmallAngleSquared = 1e-8;
// Below this squared angle (theta < 0.1) the Rodrigues coefficients A, B, C and the log's D use their
// Taylor series to th^8 (truncation error below 3e-18 relative there). The closed forms of B, C and D
// cancel catastrophically for small angles: their values lose eps / th^2 and their Jet derivatives
// eps / th^4 of relative precision (at th = 1e-4, D and dB/d th^2 would be wrong in the first digit).
constexpr double kSeriesAngleSquared = 1e-2;
}  // namespace internal

// omega^ : the cross-product matrix, hat(w) * x == w.cross(x).
template <typename Derived>
Matrix3<typename Derived::Scalar> Hat3(const Eigen::MatrixBase<Derived>& w) {
  using T = typename Derived::Scalar;
  Matrix3<T> m;
  m << T(0), -w(2), w(1), w(2), T(0), -w(0), -w(1), w(0), T(0);
  return m;
}

// Inverse of Hat3 (takes the skew-symmetric part).
template <typename Derived>
Vector3<typename Derived::Scalar> Vee3(const Eigen::MatrixBase<Derived>& m) {
  using T = typename Derived::Scalar;
  return Vector3<T>(T(0.5) * (m(2, 1) - m(1, 2)), T(0.5) * (m(0, 2) - m(2, 0)),
                    T(0.5) * (m(1, 0) - m(0, 1)));
}

// xi^ for xi = (omega, v): the 4x4 matrix [[omega^, v], [0, 0]].
template <typename Derived>
Matrix4<typename Derived::Scalar> Hat6(const Eigen::MatrixBase<Derived>& xi) {
  using T = typename Derived::Scalar;
  Matrix4<T> m = Matrix4<T>::Zero();
  m.template topLeftCorner<3, 3>() = Hat3(xi.template head<3>());
  m.template topRightCorner<3, 1>() = xi.template tail<3>();
  return m;
}

// Inverse of Hat6.
template <typename Derived>
Vector6<typename Derived::Scalar> Vee6(const Eigen::MatrixBase<Derived>& m) {
  using T = typename Derived::Scalar;
  Vector6<T> xi;
  xi.template head<3>() = Vee3(m.template topLeftCorner<3, 3>());
  xi.template tail<3>() = m.template topRightCorner<3, 1>();
  return xi;
}

// A rigid transform: x_a = R * x_b + t. Kept as (R, t) rather than a 4x4 so that composition costs
// 36 + 9 multiplications and a Jet chain stays small.
template <typename T>
struct SE3 {
  Matrix3<T> R = Matrix3<T>::Identity();
  Vector3<T> t = Vector3<T>::Zero();

  SE3() = default;
  SE3(const Matrix3<T>& rotation, const Vector3<T>& translation) : R(rotation), t(translation) {}

  static SE3 Identity() { return SE3(); }

  SE3 operator*(const SE3& other) const { return SE3(R * other.R, R * other.t + t); }
  Vector3<T> operator*(const Vector3<T>& p) const { return R * p + t; }

  SE3 Inverse() const {
    const Matrix3<T> rt = R.transpose();
    return SE3(rt, -(rt * t));
  }

  Matrix4<T> Matrix() const {
    Matrix4<T> m = Matrix4<T>::Identity();
    m.template topLeftCorner<3, 3>() = R;
    m.template topRightCorner<3, 1>() = t;
    return m;
  }

  template <typename U>
  SE3<U> cast() const {
    return SE3<U>(R.template cast<U>(), t.template cast<U>());
  }
};

using SE3d = SE3<double>;

// A rigid transform stored as a unit quaternion (x, y, z, w) and a translation, as the Ceres
// parameter blocks hold it ([qx qy qz qw tx ty tz]). Acting on a point costs 18 multiplications and
// needs no rotation matrix, which is what the autodiff position residual evaluates dozens of times
// per Jacobian. The quaternion must be of unit norm (the SE(3) manifold keeps it so).
template <typename T>
struct QuaternionTransform {
  const T* q;  // x, y, z, w
  const T* t;
  Vector3<T> operator*(const Vector3<T>& p) const {
    // p' = p + 2 w (v x p) + 2 v x (v x p), v = (x, y, z).
    const Vector3<T> v(q[0], q[1], q[2]);
    const Vector3<T> u = T(2) * v.cross(p);
    return p + q[3] * u + v.cross(u) + Vector3<T>(t[0], t[1], t[2]);
  }
};

// Coefficients of Rodrigues' formula: A = sin(th)/th, B = (1 - cos th)/th^2, C = (th - sin th)/th^3,
// from th^2 so that no square root of zero is taken.
template <typename T>
void RodriguesCoefficients(const T& theta_sq, T* a, T* b, T* c) {
  using std::cos;
  using std::sin;
  using std::sqrt;
  if (theta_sq < T(internal::kSeriesAngleSquared)) {
    const T& x = theta_sq;  // Horner form of the series in th^2, to th^8
    *a = T(1) - x / T(6) * (T(1) - x / T(20) * (T(1) - x / T(42) * (T(1) - x / T(72))));
    *b = T(0.5) * (T(1) - x / T(12) * (T(1) - x / T(30) * (T(1) - x / T(56) * (T(1) - x / T(90)))));
    *c = (T(1) - x / T(20) * (T(1) - x / T(42) * (T(1) - x / T(72) * (T(1) - x / T(110))))) / T(6);
    return;
  }
  const T theta = sqrt(theta_sq);
  const T s = sin(theta);
  const T co = cos(theta);
  *a = s / theta;
  *b = (T(1) - co) / theta_sq;
  *c = (theta - s) / (theta_sq * theta);
}

// exp: so(3) -> SO(3), R = I + A w^ + B w^2.
template <typename Derived>
Matrix3<typename Derived::Scalar> ExpSO3(const Eigen::MatrixBase<Derived>& w) {
  using T = typename Derived::Scalar;
  T a, b, c;
  RodriguesCoefficients<T>(w.squaredNorm(), &a, &b, &c);
  const Matrix3<T> W = Hat3(w);
  return Matrix3<T>::Identity() + a * W + b * (W * W);
}

// exp: se(3) -> SE(3) for xi = (omega, v): R = exp(omega^), t = V v, V = I + B w^ + C w^2.
template <typename Derived>
SE3<typename Derived::Scalar> ExpSE3(const Eigen::MatrixBase<Derived>& xi) {
  using T = typename Derived::Scalar;
  const Vector3<T> w = xi.template head<3>();
  const Vector3<T> v = xi.template tail<3>();
  T a, b, c;
  RodriguesCoefficients<T>(w.squaredNorm(), &a, &b, &c);
  const Matrix3<T> W = Hat3(w);
  const Matrix3<T> W2 = W * W;
  SE3<T> out;
  out.R = Matrix3<T>::Identity() + a * W + b * W2;
  out.t = v + b * (W * v) + c * (W2 * v);
  return out;
}

// Unit quaternion (x, y, z, w) of a rotation matrix, Shepperd's method: always takes the square root
// of the largest of the four candidates, so it is exact and differentiable for every rotation,
// including angles near pi.
template <typename T>
Eigen::Matrix<T, 4, 1> RotationToQuaternion(const Matrix3<T>& R) {
  using std::sqrt;
  Eigen::Matrix<T, 4, 1> q;  // x, y, z, w
  const T trace = R(0, 0) + R(1, 1) + R(2, 2);
  if (trace >= R(0, 0) && trace >= R(1, 1) && trace >= R(2, 2)) {
    const T s = T(2) * sqrt(T(1) + trace);
    q << (R(2, 1) - R(1, 2)) / s, (R(0, 2) - R(2, 0)) / s, (R(1, 0) - R(0, 1)) / s, T(0.25) * s;
  } else if (R(0, 0) >= R(1, 1) && R(0, 0) >= R(2, 2)) {
    const T s = T(2) * sqrt(T(1) + R(0, 0) - R(1, 1) - R(2, 2));
    q << T(0.25) * s, (R(0, 1) + R(1, 0)) / s, (R(0, 2) + R(2, 0)) / s, (R(2, 1) - R(1, 2)) / s;
  } else if (R(1, 1) >= R(2, 2)) {
    const T s = T(2) * sqrt(T(1) + R(1, 1) - R(0, 0) - R(2, 2));
    q << (R(0, 1) + R(1, 0)) / s, T(0.25) * s, (R(1, 2) + R(2, 1)) / s, (R(0, 2) - R(2, 0)) / s;
  } else {
    const T s = T(2) * sqrt(T(1) + R(2, 2) - R(0, 0) - R(1, 1));
    q << (R(0, 2) + R(2, 0)) / s, (R(1, 2) + R(2, 1)) / s, T(0.25) * s, (R(1, 0) - R(0, 1)) / s;
  }
  if (q(3) < T(0)) q = -q;  // w >= 0: the log then returns an angle in [0, pi].
  return q;
}

// Rotation matrix of a unit quaternion (x, y, z, w). The quaternion is normalized first.
template <typename T>
Matrix3<T> QuaternionToRotation(const Eigen::Matrix<T, 4, 1>& q_in) {
  using std::sqrt;
  const Eigen::Matrix<T, 4, 1> q = q_in / sqrt(q_in.squaredNorm());
  const T x = q(0), y = q(1), z = q(2), w = q(3);
  Matrix3<T> R;
  R << T(1) - T(2) * (y * y + z * z), T(2) * (x * y - z * w), T(2) * (x * z + y * w),
      T(2) * (x * y + z * w), T(1) - T(2) * (x * x + z * z), T(2) * (y * z - x * w),
      T(2) * (x * z - y * w), T(2) * (y * z + x * w), T(1) - T(2) * (x * x + y * y);
  return R;
}

// q (x) p for quaternions stored (x, y, z, w).
template <typename T>
Eigen::Matrix<T, 4, 1> QuaternionProduct(const Eigen::Matrix<T, 4, 1>& q,
                                         const Eigen::Matrix<T, 4, 1>& p) {
  const Vector3<T> qv = q.template head<3>(), pv = p.template head<3>();
  Eigen::Matrix<T, 4, 1> out;
  out.template head<3>() = q(3) * pv + p(3) * qv + qv.cross(pv);
  out(3) = q(3) * p(3) - qv.dot(pv);
  return out;
}

// Unit quaternion (x, y, z, w) of exp(omega^): (sin(th/2) omega / th, cos(th/2)), with a Taylor
// branch for small angles (no square root of zero).
template <typename T>
Eigen::Matrix<T, 4, 1> QuaternionExp(const Vector3<T>& omega) {
  using std::cos;
  using std::sin;
  using std::sqrt;
  const T th_sq = omega.squaredNorm();
  T s, c;  // sin(th/2) / th, cos(th/2)
  if (th_sq < T(internal::kSmallAngleSquared)) {
    s = T(0.5) - th_sq / T(48);
    c = T(1) - th_sq / T(8);
  } else {
    const T th = sqrt(th_sq);
    s = sin(T(0.5) * th) / th;
    c = cos(T(0.5) * th);
  }
  Eigen::Matrix<T, 4, 1> q;
  q << s * omega, c;
  return q;
}

// A transform from 7 numbers [qx qy qz qw tx ty tz] (the Ceres parameter blocks of the local frames,
// se3_manifold.h): R from the normalized quaternion, t from the last three numbers.
template <typename T>
SE3<T> Se3FromArray(const T* x) {
  const Eigen::Matrix<T, 4, 1> q(x[0], x[1], x[2], x[3]);
  return SE3<T>(QuaternionToRotation(q), Vector3<T>(x[4], x[5], x[6]));
}

// log: SO(3) -> so(3), through the quaternion: omega = 2 atan2(|v|, w) v / |v|. Exact near zero (Taylor
// branch on |v|^2) and near pi (the quaternion is computed by Shepperd's method).
template <typename T>
Vector3<T> LogSO3(const Matrix3<T>& R) {
  using std::atan2;
  using std::sqrt;
  const Eigen::Matrix<T, 4, 1> q = RotationToQuaternion(R);
  const Vector3<T> v = q.template head<3>();
  const T w = q(3);
  const T n_sq = v.squaredNorm();
  if (n_sq < T(internal::kSmallAngleSquared)) {
    // 2 atan(n / w) / n = 2 / w * (1 - n^2 / (3 w^2) + n^4 / (5 w^4)), w ~ 1 here.
    const T w_sq = w * w;
    return (T(2) / w) * (T(1) - n_sq / (T(3) * w_sq) + n_sq * n_sq / (T(5) * w_sq * w_sq)) * v;
  }
  const T n = sqrt(n_sq);
  return (T(2) * atan2(n, w) / n) * v;
}

// log: SE(3) -> se(3), xi = (omega, V^-1 t), V^-1 = I - w^/2 + D w^2 with
// D = (1 - A / (2 B)) / th^2, Taylor 1/12 + th^2/720 + th^4/30240 + th^6/1209600 + th^8/47900160
// below kSeriesAngleSquared.
template <typename T>
Vector6<T> LogSE3(const SE3<T>& X) {
  const Vector3<T> w = LogSO3(X.R);
  const T theta_sq = w.squaredNorm();
  T d;
  if (theta_sq < T(internal::kSeriesAngleSquared)) {
    const T& x = theta_sq;
    d = T(1.0 / 12.0) +
        x * (T(1.0 / 720.0) + x * (T(1.0 / 30240.0) + x * (T(1.0 / 1209600.0) + x / T(47900160))));
  } else {
    T a, b, c;
    RodriguesCoefficients<T>(theta_sq, &a, &b, &c);
    d = (T(1) - a / (T(2) * b)) / theta_sq;
  }
  const Matrix3<T> W = Hat3(w);
  Vector6<T> xi;
  xi.template head<3>() = w;
  xi.template tail<3>() = X.t - T(0.5) * (W * X.t) + d * (W * (W * X.t));
  return xi;
}

// Ad_T = [[R, 0], [t^ R, R]] for the (omega, v) order: T exp(xi^) T^-1 = exp((Ad_T xi)^).
// (The paper's eq. (16) is written for (v, omega); docs/conventions.md.)
template <typename T>
Matrix6<T> Adjoint(const SE3<T>& X) {
  Matrix6<T> ad;
  ad.template topLeftCorner<3, 3>() = X.R;
  ad.template topRightCorner<3, 3>().setZero();
  ad.template bottomLeftCorner<3, 3>() = Hat3(X.t) * X.R;
  ad.template bottomRightCorner<3, 3>() = X.R;
  return ad;
}

// ad_xi = [[w^, 0], [v^, w^]]: the Lie bracket [xi, eta] = ad_xi eta.
template <typename Derived>
Matrix6<typename Derived::Scalar> LieBracketMatrix(const Eigen::MatrixBase<Derived>& xi) {
  using T = typename Derived::Scalar;
  Matrix6<T> ad;
  const Matrix3<T> W = Hat3(xi.template head<3>());
  ad.template topLeftCorner<3, 3>() = W;
  ad.template topRightCorner<3, 3>().setZero();
  ad.template bottomLeftCorner<3, 3>() = Hat3(xi.template tail<3>());
  ad.template bottomRightCorner<3, 3>() = W;
  return ad;
}

// URDF convention: R = Rz(yaw) Ry(pitch) Rx(roll).
template <typename T>
Matrix3<T> RotationFromRpy(const T& roll, const T& pitch, const T& yaw) {
  using std::cos;
  using std::sin;
  const T cr = cos(roll), sr = sin(roll), cp = cos(pitch), sp = sin(pitch), cy = cos(yaw),
          sy = sin(yaw);
  Matrix3<T> R;
  R << cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr, sy * cp, sy * sp * sr + cy * cr,
      sy * sp * cr - cy * sr, -sp, cp * sr, cp * cr;
  return R;
}

// Inverse of RotationFromRpy for doubles (roll, pitch, yaw); pitch in [-pi/2, pi/2]. Reproduces the
// rotation to round-off also at and near gimbal lock (|pitch| = pi/2), where the split between roll
// and yaw is arbitrary.
Eigen::Vector3d RpyFromRotation(const Eigen::Matrix3d& R);

// Projects a nearly orthonormal matrix onto SO(3) (SVD); used on parsed input and after long chains.
Eigen::Matrix3d ProjectToRotation(const Eigen::Matrix3d& M);

}  // namespace lpoe

#endif  // LPOE_SE3_H_
