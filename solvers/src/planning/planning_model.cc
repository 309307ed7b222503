// Measurement planning, the model (lpoe/planning.h): the parameters a plan identifies and the rows
// one pose contributes (PlanningModel), and whether the gravity tilt can be planned for.
#include "lpoe/planning.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <memory>
#include <numeric>
#include <random>
#include <sstream>
#include <string>
#include <utility>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <Eigen/SVD>
#include <glog/logging.h>

#include "calibration/block_kind.h"
#include "linearization/joint_term_columns.h"
#include "identifiability/identifiability.h"
#include "planning/planning_internal.h"
#include "lpoe/analysis.h"
#include "lpoe/kinematics/eigen_decompositions.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/linear_solver.h"
#include "lpoe/measurements/measurements.h"

namespace lpoe {
using planning_internal::kRotationErrorScale;
using planning_internal::kTranslationErrorScale;
using planning_internal::kJointErrorEffectScale;

namespace {

// The frame directions identifiable from positions, then the joint-space terms reduced as the
// solvers reduce them on the data `reference` (every tool at every configuration).
Parameterization PlanningParameterization(
    const RobotModel& model, const std::vector<std::shared_ptr<const JointTerm>>& terms,
    const std::vector<double>& reference) {
  // The frames lose what the calibration of such data would leave out (structural_identifiability.h),
  // decided at the model planned for, so that a plan never counts a direction the calibration then
  // finds undetermined (a tool point on the last axis: that axis' tilt).
  const int n = model.num_joints();
  CHECK_EQ(reference.size() % std::max(n, 1), 0u);
  const int count = std::max(1, static_cast<int>(reference.size() / std::max(n, 1)));
  const std::vector<double> zero(n, 0.0);
  MeasurementSet data(n);
  data.Reserve(count * model.num_tools());
  for (int r = 0; r < count; ++r) {
    for (int t = 0; t < model.num_tools(); ++t) {
      data.Add(reference.empty() ? zero.data() : reference.data() + static_cast<size_t>(r) * n,
               Eigen::Vector3d::Zero(), t);
    }
  }
  internal::SolverParameterizationRequest request;  // position rows, the solvers' defaults
  request.terms = terms;
  return internal::SolverParameterization(model, data, request);
}


}  // namespace

// ---------------------------------------------------------------------------------------------------

PlanningModel::PlanningModel(const RobotModel& model)
    : model_(model),
      parameterization_(PlanningParameterization(model_, {}, {})),
      basis_(model_, parameterization_) {}

Status PlanningGravityTiltStatus(const RobotModel& model,
                                 const std::vector<std::shared_ptr<const JointTerm>>& terms) {
  // The term the tilt's block kind is bilinear with (calibration/block_kind.h).
  const std::string partner = internal::FindBilinearBlockKind(kGravityTiltName)->partner_term();
  bool compliance = false;
  for (const auto& term : terms) compliance = compliance || term->name() == partner;
  if (!compliance) return Status::Error(kGravityTiltNeedsCompliance);
  const std::vector<double>& c = model.joint_errors.Values(partner);
  if (std::all_of(c.begin(), c.end(), [](double v) { return v == 0; })) {
    return Status::Error(
        "the gravity tilt cannot be planned for with a model that carries no compliance values: "
        "the tilt is seen only through the gravity torques' compliance offsets, so its "
        "information is proportional to the compliance products, which a calibration identifies "
        "(at zero compliance the tilt's columns vanish). Plan with compliance (poses that load "
        "the joints differently serve the tilt too) and calibrate with compliance,tilt, which "
        "checks at the compliance solution whether the data determine the tilt; or plan a "
        "recalibration from a calibrated model whose YAML carries joint_errors: compliance");
  }
  if (Status s = model.Validate(); !s.ok()) return s;
  return Status::Ok();
}

PlanningModel::PlanningModel(const RobotModel& model,
                             const std::vector<std::shared_ptr<const JointTerm>>& terms,
                             const std::vector<double>& reference, bool gravity_tilt)
    : model_(model),
      parameterization_(PlanningParameterization(model_, terms, reference)),
      basis_(model_, parameterization_),
      tilt_(gravity_tilt ? internal::FindBilinearBlockKind(kGravityTiltName)->MakeEffect(model_)
                         : nullptr) {
  if (tilt_) {
    const Status s = PlanningGravityTiltStatus(model_, terms);
    CHECK(s.ok()) << s.message();
    const std::vector<double>& c = model_.joint_errors.Values(tilt_->partner());
    tilt_partner_values_ =
        Eigen::Map<const Eigen::VectorXd>(c.data(), static_cast<Eigen::Index>(c.size()));
    tilt_partner_basis_ = Eigen::MatrixXd::Identity(tilt_partner_values_.size(),
                                                    tilt_partner_values_.size());
  }
  // O3's scale of the joint-space combinations: RMS tool effect of each column over the reference.
  const int frames = parameterization_.num_frame_parameters();
  const int k = num_joint_parameters();
  Eigen::VectorXd sum = Eigen::VectorXd::Zero(k);
  const int n = model_.num_joints();
  const int count = n > 0 ? static_cast<int>(reference.size() / n) : 0;
  std::vector<int> all(model_.num_tools());
  std::iota(all.begin(), all.end(), 0);
  Eigen::MatrixXd J;
  for (int r = 0; r < count && k > 0; ++r) {
    Rows(reference.data() + static_cast<size_t>(r) * n, all, &J);
    sum += J.rightCols(k).colwise().squaredNorm().transpose();
  }
  joint_error_scale_.resize(k);
  const double rows = std::max(1, count * model_.num_tools());
  for (int j = 0; j < k; ++j) {
    const double rms = std::sqrt(sum(j) / rows);
    joint_error_scale_(j) = rms > 0 ? kJointErrorEffectScale / rms : 1.0;
  }
  CHECK_EQ(frames + k, num_parameters());
}

void PlanningModel::Rows(const double* q, const std::vector<int>& tools, Eigen::MatrixXd* J) const {
  const int rows = 3 * static_cast<int>(tools.size());
  J->resize(rows, num_parameters());
  const int n = model_.num_joints();
  std::vector<FrameRt> frames(n + 1);
  const bool joint_blocks = !parameterization_.joint_blocks.empty();
  // The joint-term columns [Y_b(q) basis_b] (num_joints x the blocks' columns), the solvers' own
  // (joint_term_columns.h): the same for every tool.
  const int joint_offset = parameterization_.num_frame_parameters();
  Eigen::MatrixXd R;
  if (joint_blocks) internal::JointTermColumns(parameterization_, n).Evaluate(0, q, &R);
  // The gravity tilt's joint-space columns at zero tilt and the model's compliance values:
  // d(dq)/dt = sum_a (dg/dt)_a Y_a(q) theta (n x 2), the solvers' own (BilinearJointColumns) at
  // their linearisation point.
  Eigen::MatrixXd D;
  if (tilt_) {
    thread_local std::vector<Eigen::MatrixXd> Z;
    tilt_->RowRegressors(tilt_partner_basis_, q, &Z);
    const std::vector<double> zero(tilt_->num_parameters(), 0.0);
    BilinearJointColumns(*tilt_, zero.data(), Z, tilt_partner_values_.data(), nullptr, nullptr,
                         &D);
  }
  const int tilt_offset = parameterization_.num_parameters;
  Eigen::Matrix<double, 3, Eigen::Dynamic> J_q(3, n);
  for (size_t k = 0; k < tools.size(); ++k) {
    basis_.Position(q, tools[k], J->data() + 3 * k, rows, frames.data());
    if (!joint_blocks && !tilt_) continue;
    basis_.PositionJointJacobian(frames.data(), J_q.data(), 3);
    if (R.cols() > 0) J->block(3 * k, joint_offset, 3, R.cols()).noalias() = J_q * R;
    if (tilt_) J->block(3 * k, tilt_offset, 3, D.cols()).noalias() = J_q * D;
  }
}

Eigen::VectorXd PlanningModel::ErrorScale() const {
  Eigen::VectorXd e(num_parameters());
  const int frames = parameterization_.num_frame_parameters();
  e.tail(num_joint_parameters()) = joint_error_scale_;
  for (int j = 0; j < frames; ++j) {
    const auto& v = parameterization_.parameters[j].vector;
    e(j) = std::hypot(kRotationErrorScale * v.head<3>().norm(),
                      kTranslationErrorScale * v.tail<3>().norm());
  }
  return e;
}


}  // namespace lpoe

namespace lpoe {

Eigen::MatrixXd PlanningPriorInformation(const PlanningModel& pm, const ParameterPrior& prior,
                                         double sigma) {
  const int P = pm.num_parameters();
  Eigen::MatrixXd M = Eigen::MatrixXd::Zero(P, P);
  const RobotModel& model = prior.reference ? *prior.reference : pm.model();
  if (model.num_frames() != pm.model().num_frames()) return M;
  ParameterPrior free = prior;
  FreeRegistrationDirections(model, &free);
  const Parameterization& p = pm.parameterization();
  for (int f = 0; f < static_cast<int>(p.basis.size()); ++f) {
    const Eigen::MatrixXd& B = p.basis[f];
    if (B.cols() == 0) continue;
    const Eigen::Index k = B.cols();
    M.block(p.offset[f], p.offset[f], k, k) =
        sigma * sigma * B.transpose() * FrameInformation(free, model, f) * B;
  }
  // Joint-space terms the prior covers (a previous calibration with --joint_errors: its
  // covariance block lists them): basis_b^T Lambda_b basis_b / scale^2 on the term's
  // combinations, as the solvers weigh it (prior_terms.cc). Terms it does not list get none.
  for (const JointBlock& b : p.joint_blocks) {
    const Eigen::Index k = b.basis.cols();
    if (k == 0) continue;
    for (const JointTermPrior& t : prior.joint_terms) {
      if (t.name != b.term->name() || t.information.rows() != b.basis.rows() ||
          t.information.cols() != b.basis.rows()) {
        continue;
      }
      M.block(b.offset, b.offset, k, k) = sigma * sigma / (prior.scale * prior.scale) *
                                          b.basis.transpose() * t.information * b.basis;
    }
  }
  return M;
}

}  // namespace lpoe
