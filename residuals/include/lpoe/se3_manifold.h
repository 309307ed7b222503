// The SE(3) manifold of one local frame T_{i-1,i}(0), for Ceres (docs/conventions.md, docs/architecture.md).
//
// Ambient parameters: 7 doubles [qx qy qz qw tx ty tz], the unit quaternion of the rotation R
// (Eigen's storage order, scalar last) followed by the translation t (mm), of T = (R, t).
//
// Tangent parameters: k doubles delta, the coordinates of a right perturbation (paper eq. (19))
// in a 6 x k basis B with orthonormal columns, written in the frame's own (omega, v) coordinates:
//
//   Plus(x, delta)  = x [+] delta = T(x) exp((B delta)^)
//   Minus(y, x)     = y [-] x     = B^T log(T(x)^-1 T(y))^vee
//
// B is the frame's identifiable basis from parameterization.h: k = 4 for a revolute joint frame
// (rotation about and translation along the joint axis are left out), 2 for a prismatic one, 3 for a
// tool measured by position only (its rotation is never seen), 6 for a tool with pose data, and 6
// with B = I for the paper's full parameterization ("diagnosis" variant).
//
// Contract (as ceres/manifold.h): x must hold a unit quaternion; Plus keeps it unit (quaternion
// product with a unit quaternion). For every delta, Minus(Plus(x, delta), x) == delta as long as
// |B delta|'s rotation is below pi; Plus(x, Minus(y, x)) == y for every y of the form Plus(x, .).
// When y is not reachable from x along span(B) (k < 6), Minus returns the least-squares projection
// B^T log(..) of the full difference. Minus takes the shortest rotation (quaternion with w >= 0), so
// y and the same pose with the negated quaternion give the same difference.
#ifndef LPOE_SE3_MANIFOLD_H_
#define LPOE_SE3_MANIFOLD_H_

#include <Eigen/Core>
#include <ceres/manifold.h>

#include "lpoe/kinematics/se3.h"

namespace lpoe {

// Size of the ambient parameter block of one frame.
constexpr int kSe3AmbientSize = 7;

// Writes T as [qx qy qz qw tx ty tz] (the quaternion with w >= 0).
void Se3ToArray(const SE3d& T, double* x);
// Reads [qx qy qz qw tx ty tz] (the quaternion is normalized): Se3FromArray of se3.h, for any
// scalar.

class Se3Manifold : public ceres::Manifold {
 public:
  // `basis` is 6 x k, 1 <= k <= 6, with orthonormal columns (checked), in (omega, v) order.
  explicit Se3Manifold(const Eigen::MatrixXd& basis);
  // The full manifold: B = I, k = 6.
  Se3Manifold();
  ~Se3Manifold() override = default;

  // 7.
  int AmbientSize() const override { return kSe3AmbientSize; }
  // k, the number of columns of the basis.
  int TangentSize() const override { return static_cast<int>(basis_.cols()); }

  // x: 7 numbers (ambient), delta: k numbers (tangent), x_plus_delta: 7 numbers.
  // x_plus_delta = T(x) exp((B delta)^): q' = q (x) dq with dq the unit quaternion of
  // exp((B delta)_omega), t' = R(x) t_delta + t. Always returns true.
  bool Plus(const double* x, const double* delta, double* x_plus_delta) const override;

  // jacobian: 7 x k, row-major, D_2 Plus(x, 0):
  //   [[ 0.5 L(q)_{:,0:3}, 0 ], [ 0, R(x) ]] * B
  // with L(q) the 4x4 matrix of left quaternion multiplication (q (x) p = L(q) p, p stored x,y,z,w).
  bool PlusJacobian(const double* x, double* jacobian) const override;

  // y, x: 7 numbers each; y_minus_x: k numbers, B^T log(T(x)^-1 T(y))^vee (shortest rotation).
  bool Minus(const double* y, const double* x, double* y_minus_x) const override;

  // jacobian: k x 7, row-major, D_1 Minus(x, x):
  //   B^T [[ 2 [w I - v^, -v], 0 ], [ 0, R(x)^T ]]   for q(x) = (v, w),
  // so that MinusJacobian * PlusJacobian = B^T B = I_k.
  bool MinusJacobian(const double* x, double* jacobian) const override;

  const Eigen::MatrixXd& basis() const { return basis_; }

 private:
  Eigen::MatrixXd basis_;  // 6 x k
};

}  // namespace lpoe

#endif  // LPOE_SE3_MANIFOLD_H_
