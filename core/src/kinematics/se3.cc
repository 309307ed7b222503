#include "lpoe/kinematics/se3.h"

#include <cmath>

#include <Eigen/SVD>

namespace lpoe {

Eigen::Vector3d RpyFromRotation(const Eigen::Matrix3d& R) {
  // R = Rz(yaw) Ry(pitch) Rx(roll). Reading roll and yaw off small matrix entries loses precision
  // near gimbal lock; instead take yaw first, then roll and pitch from Rz(-yaw) R = Ry(pitch) Rx(roll),
  // whose entries used here are of order one, so any error in yaw (ill-defined at gimbal lock) is
  // absorbed by roll and the rotation is reproduced exactly.
  const double yaw = std::atan2(R(1, 0), R(0, 0));
  const double c = std::cos(yaw), s = std::sin(yaw);
  const double m00 = c * R(0, 0) + s * R(1, 0);   //  cos(pitch) >= 0
  const double m11 = -s * R(0, 1) + c * R(1, 1);  //  cos(roll)
  const double m12 = -s * R(0, 2) + c * R(1, 2);  // -sin(roll)
  const double pitch = std::atan2(-R(2, 0), m00);
  const double roll = std::atan2(-m12, m11);
  return Eigen::Vector3d(roll, pitch, yaw);
}

Eigen::Matrix3d ProjectToRotation(const Eigen::Matrix3d& M) {
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(M, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
  D(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1.0 : 1.0;
  return svd.matrixU() * D * svd.matrixV().transpose();
}

}  // namespace lpoe
