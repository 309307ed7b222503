#include "lpoe/registration.h"

#include <cmath>
#include <sstream>
#include <string>
#include <vector>

#include <Eigen/QR>
#include <Eigen/SVD>

#include "identifiability/identifiability.h"

#include "lpoe/kinematics/eigen_decompositions.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/linear_solver.h"
#include "lpoe/model/parameterization.h"
#include "lpoe/model/statistics.h"

namespace lpoe {
namespace {

double Rms(const RobotModel& model, const MeasurementSet& data) {
  return PositionErrorStatistics(model, data).norm.rms;
}

// Stage 2 directions: the base frame (joint 1's local frame, all 6) and each tool's position.
Parameterization BaseAndToolParameterization(const RobotModel& model) {
  Parameterization p = MakeParameterization(model, ParameterizationKind::kIdentifiable,
                                            DataKind::kPosition);
  Parameterization out;
  out.kind = ParameterizationKind::kIdentifiable;
  out.data = DataKind::kPosition;
  for (int f = 0; f < model.num_frames(); ++f) {
    Eigen::MatrixXd basis;
    if (f == 0) {
      basis = Eigen::MatrixXd::Identity(6, 6);
    } else if (f >= model.num_joints()) {
      basis = p.basis[f];
    } else {
      basis = Eigen::MatrixXd::Zero(6, 0);
    }
    out.offset.push_back(out.num_parameters);
    for (int c = 0; c < basis.cols(); ++c) {
      Direction d;
      d.frame = f;
      d.vector = basis.col(c);
      static const char* const kNames[6] = {"rx", "ry", "rz", "tx", "ty", "tz"};
      int k = 0;
      d.vector.cwiseAbs().maxCoeff(&k);
      d.name = (f < model.num_joints() ? model.joints[f].name
                                       : model.tools[f - model.num_joints()].name) +
               "." + kNames[k];
      out.parameters.push_back(d);
    }
    out.num_parameters += static_cast<int>(basis.cols());
    out.basis.push_back(basis);
  }
  return out;
}

// The directions of `p` that the data determine: a rank-revealing (column-pivoted) QR of the
// column-scaled J^T J keeps a maximal independent set, in pivot order; the others (a tool no row
// measures, the base's rotation about and translation along an axis that every joint shares, as on
// SCARA-like, planar and one-joint robots) are left at their values for the full calibration.
// `dropped` lists their names.
Parameterization DeterminedDirections(const RobotModel& model, const MeasurementSet& data,
                                      const Parameterization& p, std::vector<std::string>* dropped) {
  const Eigen::MatrixXd H = internal::NormalMatrix(model, data, p, false, 1.0);
  const Eigen::VectorXd d = internal::ColumnScale(H);
  const Eigen::MatrixXd Hs = d.asDiagonal() * H * d.asDiagonal();
  Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(Hs);
  // J^T J squares the condition number: 1e-12 here is 1e-6 on the Jacobian's singular values.
  qr.setThreshold(1e-12);
  std::vector<bool> keep(p.num_parameters, false);
  for (Eigen::Index k = 0; k < qr.rank(); ++k) keep[qr.colsPermutation().indices()(k)] = true;
  for (int k = 0; k < p.num_parameters; ++k) {
    if (!(d(k) > 0) || !std::isfinite(d(k))) keep[k] = false;  // a column no row sees
  }
  Parameterization out = p;
  out.parameters.clear();
  out.num_parameters = 0;
  for (size_t f = 0; f < p.basis.size(); ++f) {
    std::vector<int> cols;
    for (int c = 0; c < p.basis[f].cols(); ++c) {
      if (keep[p.offset[f] + c]) {
        cols.push_back(c);
        out.parameters.push_back(p.parameters[p.offset[f] + c]);
      } else if (dropped) {
        dropped->push_back(p.parameters[p.offset[f] + c].name);
      }
    }
    Eigen::MatrixXd basis(6, static_cast<Eigen::Index>(cols.size()));
    for (size_t c = 0; c < cols.size(); ++c) basis.col(c) = p.basis[f].col(cols[c]);
    out.basis[f] = basis;
    out.offset[f] = out.num_parameters;
    out.num_parameters += static_cast<int>(cols.size());
  }
  return out;
}

}  // namespace

Status FitRigidTransform(const std::vector<Eigen::Vector3d>& from,
                         const std::vector<Eigen::Vector3d>& to, SE3d* T_to_from) {
  const size_t n = from.size();
  if (n != to.size() || n < 3) {
    return Status::Error("a rigid fit needs at least 3 point pairs");
  }
  Eigen::Vector3d ca = Eigen::Vector3d::Zero(), cb = Eigen::Vector3d::Zero();
  for (size_t k = 0; k < n; ++k) {
    ca += from[k];
    cb += to[k];
  }
  ca /= static_cast<double>(n);
  cb /= static_cast<double>(n);
  Eigen::Matrix3d S = Eigen::Matrix3d::Zero();
  double spread = 0;
  for (size_t k = 0; k < n; ++k) {
    S += (to[k] - cb) * (from[k] - ca).transpose();
    spread += (from[k] - ca).squaredNorm();
  }
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(S, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Eigen::Vector3d sv = svd.singularValues();
  if (!(sv(1) > 1e-9 * std::max(1.0, sv(0))) || !(spread > 0)) {
    return Status::Error(
        "the measured points lie on a line or a single point: the measurement frame cannot be "
        "registered to the robot");
  }
  Eigen::Matrix3d D = Eigen::Matrix3d::Identity();
  D(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0 ? -1.0 : 1.0;
  T_to_from->R = svd.matrixU() * D * svd.matrixV().transpose();
  T_to_from->t = cb - T_to_from->R * ca;
  return Status::Ok();
}

Status RegisterToMeasurements(const RobotModel& nominal, const MeasurementSet& all_data,
                              RobotModel* registered, RegistrationReport* report) {
  // Registration only finds a starting point for the full calibration: an evenly spaced subset of
  // large data sets determines the base and tool frames just as well, at a fraction of the cost.
  MeasurementSet subset;
  if (all_data.size() > kMaxRegistrationRows) {
    std::vector<int> rows(kMaxRegistrationRows);
    for (int k = 0; k < kMaxRegistrationRows; ++k) {
      rows[k] = static_cast<int>(static_cast<long>(k) * all_data.size() / kMaxRegistrationRows);
    }
    subset = all_data.Subset(rows);
  }
  const MeasurementSet& data = all_data.size() > kMaxRegistrationRows ? subset : all_data;
  RegistrationReport local;
  RegistrationReport& r = report ? *report : local;
  r = RegistrationReport();
  r.rms_nominal = Rms(nominal, data);

  // Stage 1: rigid fit of the nominal predicted points to the measured ones.
  std::vector<Eigen::Vector3d> predicted(data.size()), measured(data.size());
  for (int k = 0; k < data.size(); ++k) {
    predicted[k] = ToolPosition(nominal, data.q(k), data.target(k));
    measured[k] = data.position(k);
  }
  SE3d T;
  if (Status s = FitRigidTransform(predicted, measured, &T); !s.ok()) return s;
  r.T_measurement_base = T;
  const double angle = LogSO3(T.R).norm();
  r.moved = T.t.norm() > kFrameMismatchMm || angle > kFrameMismatchRad;
  RobotModel model = nominal;
  model.joints[0].origin = T * model.joints[0].origin;
  model.gravity = T.R * model.gravity;  // gravity stays attached to the robot's base
  r.rms_rigid = Rms(model, data);

  // Stage 2: base frame and tool points with the nominal joints.
  std::vector<std::string> dropped;
  const Parameterization p =
      DeterminedDirections(model, data, BaseAndToolParameterization(model), &dropped);
  LinearSolverOptions options;
  options.parameterization_override = &p;
  options.compute_covariance = false;
  options.max_iterations = 50;
  options.step_tolerance = 1e-8;
  const CalibrationResult stage2 = CalibrateLinear(model, data, options);
  if (stage2.termination == Termination::kNotIdentifiable) {
    return Status::Error("registration (base and tool frames): " + stage2.message);
  }
  // Stage 2 only prepares the linearization point: an unconverged but improved model is still a
  // better start than the rigid fit.
  if (stage2.final_cost <= stage2.history.front().cost) model = stage2.model;
  r.rms_base_tools = Rms(model, data);

  std::ostringstream os;
  os << "registration: rigid fit moved the base by " << T.t.norm() << " mm and " << angle
     << " rad; rms error " << r.rms_nominal << " mm (nominal) -> " << r.rms_rigid
     << " mm (rigid) -> " << r.rms_base_tools << " mm (base and tools)";
  if (!dropped.empty()) {
    os << "; not determined by these data, left for the full calibration:";
    for (const std::string& name : dropped) os << " " << name;
  }
  r.message = os.str();
  *registered = std::move(model);
  return Status::Ok();
}

}  // namespace lpoe
