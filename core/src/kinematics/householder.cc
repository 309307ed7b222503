#include "lpoe/kinematics/householder.h"

#include <algorithm>

#include <glog/logging.h>

#include "lpoe/kinematics/eigen_decompositions.h"

namespace lpoe {

Eigen::MatrixXd HouseholderQColumns(const Eigen::HouseholderQR<Eigen::MatrixXd>& qr,
                                    Eigen::Index first, Eigen::Index count) {
  constexpr Eigen::Index kEigenBlock = 48;  // HouseholderSequence's BlockSize
  const Eigen::Index P = qr.rows();
  const Eigen::Index reflectors = qr.hCoeffs().size();
  CHECK(first >= 0 && count >= 0 && first + count <= P);
  if (reflectors > kEigenBlock || count < 2) {
    return Eigen::MatrixXd(qr.householderQ()).middleCols(first, count);
  }
  Eigen::MatrixXd Q = Eigen::MatrixXd::Identity(P, P).middleCols(first, count);
  Eigen::VectorXd workspace(count);
  const auto H = qr.householderQ();
  for (Eigen::Index j = reflectors - 1; j >= 0; --j) {
    // Columns before global index j are zero in H_j's rows and stay exactly as they are; at least
    // two columns, so that the product stays a matrix product.
    const Eigen::Index c0 = std::min(std::max<Eigen::Index>(0, j - first), count - 2);
    Q.bottomRightCorner(P - j, count - c0)
        .applyHouseholderOnTheLeft(H.essentialVector(j), qr.hCoeffs().coeff(j), workspace.data());
  }
  return Q;
}

}  // namespace lpoe
