#include "lpoe/se3.h"

#include <cmath>

#include <Eigen/SVD>

namespace lpoe {

Eigen::Vector3d RpyFromRotation(const Eigen::Matrix3d& R) {
  // R = Rz(y) Ry(p) Rx(r): R(2,0) = -sin p, R(2,1) = cos p sin r, R(2,2) = cos p cos r,
  // R(1,0) = sin y cos p, R(0,0) = cos y cos p.
  const double sp = -R(2, 0);
  const double cp = std::hypot(R(0, 0), R(1, 0));
  const double pitch = std::atan2(sp, cp);
  if (cp < 1e-12) {
    // Gimbal lock: only yaw -/+ roll is defined; put it all in yaw.
    const double yaw = std::atan2(-R(0, 1), R(1, 1));
    return Eigen::Vector3d(0.0, pitch, yaw);
  }
  return Eigen::Vector3d(std::atan2(R(2, 1), R(2, 2)), pitch, std::atan2(R(1, 0), R(0, 0)));
}

Eigen::Matrix3d ProjectToRotation(const Eigen::Matrix3d& M) {
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(M, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
  D(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1.0 : 1.0;
  return svd.matrixU() * D * svd.matrixV().transpose();
}

}  // namespace lpoe
