#include "identifiability.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <vector>

#include <Eigen/Eigenvalues>

#include "lpoe/kinematics.h"

namespace lpoe {
namespace internal {

Eigen::VectorXd ColumnScale(const Eigen::MatrixXd& H) {
  Eigen::VectorXd d(H.rows());
  for (int j = 0; j < H.rows(); ++j) d(j) = H(j, j) > 0 ? 1.0 / std::sqrt(H(j, j)) : 1.0;
  return d;
}

Identifiability Analyze(const Eigen::MatrixXd& H) {
  const Eigen::VectorXd d = ColumnScale(H);
  const Eigen::MatrixXd Hs = d.asDiagonal() * H * d.asDiagonal();
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(Hs);
  Identifiability out;
  out.condition = std::numeric_limits<double>::infinity();
  const int P = static_cast<int>(H.rows());
  out.singular_values.resize(P);
  for (int k = 0; k < P; ++k) {
    out.singular_values(k) = std::sqrt(std::max(0.0, eig.eigenvalues()(P - 1 - k)));
  }
  const double smax = out.singular_values(0);
  // Numerical rank of the scaled Jacobian; sqrt(eps) relative since we work on J^T J.
  const double tol = smax * 1e-8;
  for (int k = 0; k < P; ++k) out.rank += out.singular_values(k) > tol;
  const double smin = out.singular_values(P - 1);
  out.condition = smin > 0 ? smax / smin : std::numeric_limits<double>::infinity();
  out.weakest = eig.eigenvectors().col(0);
  return out;
}

std::string WeakestDirections(const Parameterization& p, const Eigen::VectorXd& v) {
  std::vector<int> idx(v.size());
  for (int k = 0; k < v.size(); ++k) idx[k] = k;
  std::sort(idx.begin(), idx.end(), [&](int a, int b) { return std::abs(v(a)) > std::abs(v(b)); });
  std::ostringstream os;
  for (int k = 0; k < std::min<int>(3, static_cast<int>(idx.size())); ++k) {
    if (k) os << ", ";
    os << p.parameters[idx[k]].name;
  }
  return os.str();
}

Eigen::MatrixXd NormalMatrix(const RobotModel& model, const MeasurementSet& data,
                             const Parameterization& p, bool use_orientation,
                             double orientation_weight) {
  return NormalEquationsOf(model, data, p, use_orientation, orientation_weight, false).H;
}

std::string TooFewEquationsMessage(int rows, long equations, int identifiable, int per_row) {
  std::ostringstream os;
  os << rows << " measurements give " << equations << " equations, fewer than the "
     << identifiable << " identifiable parameters; at least "
     << (identifiable + per_row - 1) / per_row
     << " configurations are needed (several times that for a reliable calibration)";
  return os.str();
}

std::string NotIdentifiableMessage(const Identifiability& id, int identifiable,
                                   double max_condition_number, const Parameterization& p) {
  std::ostringstream os;
  os << "the data cannot identify the model: the column-scaled Jacobian has rank " << id.rank
     << " of " << identifiable << " and condition number " << id.condition << " (limit "
     << max_condition_number << "); weakest directions: " << WeakestDirections(p, id.weakest)
     << ". The poses are too few or too similar: measure configurations that move every joint";
  return os.str();
}

}  // namespace internal
}  // namespace lpoe
