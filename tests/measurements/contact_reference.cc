// The plain least-squares reference of the contact tests (contact_reference.h).
#include "measurements/contact_reference.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include <Eigen/Dense>

#include "lpoe/kinematics/kinematics.h"
#include "lpoe/kinematics/se3.h"
#include "lpoe/measurements/measurement_kinds.h"
#include "test_util.h"

namespace lpoe {
namespace testing {
namespace {

// With `hold_scale` (planes alone, whose least squares would otherwise shrink the robot) one more
// row holds the size of the predicted points, sum_j (Pn_j - mean Pn) . P_j / sum_j |Pn_j - mean
// Pn|^2 = 1 (a sum over the frames' translations would not do: the directions along the joint
// axes are free and move it without moving a point).
void AddReferenceScaleRow(const RobotModel& nominal, const Reference& ref,
                          const ContactMeasurementSet& data, Eigen::VectorXd* r,
                          Eigen::MatrixXd* J) {
  Eigen::Matrix3Xd W(3, data.size());
  for (int i = 0; i < data.size(); ++i) W.col(i) = ToolPosition(nominal, data.joints(i), data.rows[i].target);
  W.colwise() -= Eigen::Vector3d(W.rowwise().mean());
  const double den = W.squaredNorm();
  double S = 0;
  Eigen::RowVectorXd a = Eigen::RowVectorXd::Zero(J->cols());
  Eigen::MatrixXd Jf;
  for (int i = 0; i < data.size(); ++i) {
    const Eigen::Vector3d P = ToolPositionJacobian(ref.model, data.joints(i), data.rows[i].target, &Jf);
    S += W.col(i).dot(P) / den;
    a.head(Jf.cols()) += W.col(i).transpose() * Jf / den;
  }
  const double sigma = 1e-3;  // enough to hold it (moving it by 1e-3 costs what the data do)
  r->conservativeResize(r->size() + 1);
  (*r)(r->size() - 1) = (S - 1) / sigma;
  J->conservativeResize(J->rows() + 1, Eigen::NoChange);
  J->row(J->rows() - 1) = a / sigma;
}

}  // namespace

void ReferenceRows(const Reference& ref, const ContactMeasurementSet& data, Eigen::VectorXd* r,
                   Eigen::MatrixXd* J) {
  const int F = ref.model.num_frames();
  const int cols = 6 * F + 3 * static_cast<int>(ref.pivots.size()) + 4 * static_cast<int>(ref.planes.size());
  r->resize(data.size());
  J->setZero(data.size(), cols);
  Eigen::MatrixXd Jf;
  for (int i = 0; i < data.size(); ++i) {
    const ContactRow& row = data.rows[i];
    const Eigen::Vector3d P = ToolPositionJacobian(ref.model, data.joints(i), row.target, &Jf);
    if (row.kind == MeasurementKindId::kDistance) {
      const Eigen::Vector3d c = ref.pivots[row.feature];
      const Eigen::Vector3d u = (P - c).normalized();
      (*r)(i) = ((P - c).norm() - row.value) / row.sigma;
      J->row(i).head(6 * F) = u.transpose() * Jf / row.sigma;
      J->block(i, 6 * F + 3 * row.feature, 1, 3) = -u.transpose() / row.sigma;
    } else {
      const Eigen::Vector4d& pl = ref.planes[row.feature];
      const double norm = pl.head<3>().norm();
      const Eigen::Vector3d n = pl.head<3>() / norm;
      (*r)(i) = (n.dot(P) - pl(3) - row.value) / row.sigma;
      J->row(i).head(6 * F) = n.transpose() * Jf / row.sigma;
      const int at = 6 * F + 3 * static_cast<int>(ref.pivots.size()) + 4 * row.feature;
      // d(n.P)/d(raw normal) = (I - n n^T) P / |raw|.
      J->block(i, at, 1, 3) = ((Eigen::Matrix3d::Identity() - n * n.transpose()) * P).transpose() /
                              (norm * row.sigma);
      (*J)(i, at + 3) = -1.0 / row.sigma;
    }
  }
}

int StepFramesAndPivots(const Eigen::VectorXd& x, RobotModel* model,
                        std::vector<Eigen::Vector3d>* pivots) {
  const int F = model->num_frames();
  const int n = model->num_joints();
  for (int f = 0; f < F; ++f) {
    SE3d& T = f < n ? model->joints[f].origin : model->tools[f - n].origin;
    T = T * ExpSE3(Vector6d(x.segment<6>(6 * f)));
  }
  int at = 6 * F;
  for (Eigen::Vector3d& c : *pivots) {
    c += x.segment<3>(at);
    at += 3;
  }
  return at;
}

Reference PlainLeastSquares(const RobotModel& nominal, const ContactFeatures& start,
                            const ContactMeasurementSet& data, bool hold_scale,
                            Eigen::MatrixXd* J_start) {
  const Reference ref{nominal, start.pivots, start.planes};
  Eigen::VectorXd r;
  ReferenceRows(ref, data, &r, J_start);
  auto rows = [&](const Reference& s, Eigen::VectorXd* r, Eigen::MatrixXd* J) {
    ReferenceRows(s, data, r, J);
    if (hold_scale) AddReferenceScaleRow(nominal, s, data, r, J);
  };
  auto step = [](const Reference& s, const Eigen::VectorXd& x) {
    Reference next = s;
    int at = StepFramesAndPivots(x, &next.model, &next.pivots);
    for (Eigen::Vector4d& pl : next.planes) {
      pl += x.segment<4>(at);
      at += 4;
      pl.head<3>().normalize();  // the same plane, unit normal
    }
    return next;
  };
  return DampedLeastSquares(ref, rows, step);
}

}  // namespace testing
}  // namespace lpoe
