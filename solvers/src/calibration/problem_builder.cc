#include "lpoe/problem_builder.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <ceres/ceres.h>
#include <glog/logging.h>

#include "linearization/batched_residual.h"
#include "calibration/block_kind.h"
#include "linearization/joint_term_columns.h"
#include "identifiability/identifiability.h"
#include "identifiability/structural_identifiability.h"
#include "lpoe/kinematics/eigen_decompositions.h"
#include "lpoe/measurements/measurement_kind_dispatch.h"
#include "lpoe/measurement_residual.h"
#include "linearization/normal_equations.h"
#include "calibration/problem_setup.h"

namespace lpoe {

Status ValidateCalibrationProblemOptions(const CalibrationProblemOptions& options) {
  if (options.loss != "none" && options.loss != "huber" && options.loss != "cauchy") {
    return Status::Error("loss must be none, huber or cauchy, got '" + options.loss + "'");
  }
  if (!(options.sigma > 0) || !std::isfinite(options.sigma)) {
    return Status::Error("sigma must be a positive number of mm");
  }
  if (options.rows_per_block < 1) return Status::Error("rows_per_block must be >= 1");
  if (!(options.loss_scale > 0) || !std::isfinite(options.loss_scale)) {
    return Status::Error("loss_scale must be a positive number of mm");
  }
  if (!(options.orientation_weight > 0) || !std::isfinite(options.orientation_weight)) {
    return Status::Error("orientation_weight must be positive");
  }
  if (!(options.joint_term_tolerance > 0 && options.joint_term_tolerance < 1)) {
    return Status::Error("joint_term_tolerance must be in (0, 1)");
  }
  for (const auto& term : options.joint_terms) {
    if (term == nullptr) return Status::Error("a joint-space term is null");
  }
  // Each block kind asked for (block_kind.h: the gravity tilt) with the term it needs.
  return internal::CheckBlockKindPartners(options.joint_terms,
                                          internal::ProblemSetupRequestOf(options));
}

Status ValidateCalibrationProblem(const RobotModel& nominal, const MeasurementSet& data,
                                  const CalibrationProblemOptions& options) {
  if (Status s = ValidateCalibrationProblemOptions(options); !s.ok()) return s;
  if (data.num_joints() != nominal.num_joints()) {
    return Status::Error("the measurements have " + std::to_string(data.num_joints()) +
                         " joint values per row, the model " +
                         std::to_string(nominal.num_joints()) + " joints");
  }
  for (int r = 0; r < data.size(); ++r) {
    if (data.target(r) < 0 || data.target(r) >= nominal.num_tools()) {
      return Status::Error("row " + std::to_string(r) + ": tool index " +
                           std::to_string(data.target(r)) + " not in the model");
    }
  }
  if (options.use_orientation && !data.has_orientation()) {
    return Status::Error(
        "pose-based calibration needs measured orientations (quat_x..quat_w columns)");
  }
  return Status::Ok();
}

namespace {

// Every decision (parameterization, frames solved, prior, structure) once (problem_setup.h), for
// options that pass ValidateCalibrationProblem (CHECKed).
std::shared_ptr<const internal::ProblemSetup> ValidatedSetup(
    const RobotModel& nominal, const MeasurementSet& data,
    const CalibrationProblemOptions& options) {
  const Status s = ValidateCalibrationProblem(nominal, data, options);
  CHECK(s.ok()) << s.message();
  return std::make_shared<const internal::ProblemSetup>(
      internal::SetUpProblem(nominal, data, internal::ProblemSetupRequestOf(options)));
}

}  // namespace

CalibrationProblem::CalibrationProblem(const RobotModel& nominal, const MeasurementSet& data,
                                       const CalibrationProblemOptions& options)
    : CalibrationProblem(nominal, data, options, ValidatedSetup(nominal, data, options)) {}

CalibrationProblem::CalibrationProblem(const RobotModel& nominal, const MeasurementSet& data,
                                       const CalibrationProblemOptions& options,
                                       std::shared_ptr<const internal::ProblemSetup> setup_in)
    : nominal_(nominal), data_(&data), options_(options), setup_(std::move(setup_in)) {
  CHECK(setup_ != nullptr);
  const internal::ProblemSetup& setup = *setup_;
  parameterization_ = setup.all;
  block_status_ = setup.block_status;
  regressors_ = setup.regressors;
  analysed_ = setup.analysed;
  // The blocks, kind by kind in registry order (block_kind.h): solved frames, joint blocks, the
  // bilinear blocks. Their solved numbering is their order: check it against the setup's.
  for (const internal::BlockKind* kind : internal::BlockKinds()) {
    kind->AppendBlocks(setup, nominal_, &blocks_);
  }
  frame_blocks_.assign(nominal.num_frames(), -1);
  joint_blocks_.assign(parameterization_.joint_blocks.size(), -1);
  bilinear_blocks_.assign(parameterization_.bilinear_blocks.size(), -1);
  const Parameterization& solved = setup.solved;
  int solved_offset = 0;
  for (size_t i = 0; i < blocks_.size(); ++i) {
    ProblemBlock& b = blocks_[i];
    b.solved_offset = solved_offset;
    solved_offset += b.tangent_size;
    const int k = static_cast<int>(i);
    if (b.kind == &internal::FrameBlockKind()) {
      frame_blocks_[b.index] = k;
      CHECK_EQ(solved.offset[b.index], b.solved_offset);
      CHECK_EQ(solved.basis[b.index].cols(), b.tangent_size);
    } else if (b.kind == &internal::JointTermBlockKind()) {
      joint_blocks_[b.index] = k;
      CHECK_EQ(solved.joint_blocks[b.index].offset, b.solved_offset);
    } else {
      CHECK(b.kind->bilinear() != nullptr && b.kind->bilinear()->In(parameterization_))
          << b.kind->name();
      bilinear_blocks_[b.index] = k;
      CHECK_EQ(solved.bilinear_blocks[b.index].offset, b.solved_offset);
    }
  }
  CHECK_EQ(solved_offset, solved.num_parameters);
  for (int f = 0; f < nominal.num_frames(); ++f) {
    CHECK_EQ(frame_blocks_[f] >= 0, static_cast<bool>(setup.frame_solved[f])) << f;
  }
  current_ = nominal_;
  for (const ProblemBlock& b : blocks_) current_values_.push_back(b.values);
}

double* CalibrationProblem::bilinear_block(int b) {
  if (b < 0 || b >= static_cast<int>(bilinear_blocks_.size())) return nullptr;
  return blocks_[bilinear_blocks_[b]].values.data();
}

double* CalibrationProblem::frame_block(int f) {
  CHECK(f >= 0 && f < static_cast<int>(frame_blocks_.size()));
  return frame_blocks_[f] >= 0 ? blocks_[frame_blocks_[f]].values.data() : nullptr;
}

double* CalibrationProblem::joint_block(int b) {
  CHECK(b >= 0 && b < static_cast<int>(joint_blocks_.size()));
  return joint_blocks_[b] >= 0 ? blocks_[joint_blocks_[b]].values.data() : nullptr;
}

std::vector<double*> CalibrationProblem::parameter_blocks() {
  std::vector<double*> out;
  out.reserve(blocks_.size());
  for (ProblemBlock& b : blocks_) out.push_back(b.values.data());
  return out;
}

std::vector<int> CalibrationProblem::tangent_sizes() const {
  std::vector<int> out;
  out.reserve(blocks_.size());
  for (const ProblemBlock& b : blocks_) out.push_back(b.tangent_size);
  return out;
}

std::vector<int> CalibrationProblem::tangent_offsets() const {
  std::vector<int> out;
  out.reserve(blocks_.size());
  for (const ProblemBlock& b : blocks_) out.push_back(b.offset);
  return out;
}

namespace {

// The reduction's slots (the non-zero entries of d(dq)/d(theta) per row, slot_basis mapping the
// joint state's K parameters to the slots' ones) when they were stored for these rows and can serve
// the joint state: not with the gravity tilt, whose rows are not linear in it. Else nullptr.
const internal::JointSpaceRegressors* UsableSlots(const internal::JointSpaceRegressors* slots,
                                                  const Parameterization& p, int n, int rows,
                                                  Eigen::Index K) {
  const bool usable = K > 0 && !internal::HasNonlinearBlocks(p) && slots != nullptr &&
                      slots->num_joints == n &&
                      slots->values.cols() == rows &&
                      slots->values.rows() == slots->num_slots() &&
                      slots->slot_basis.rows() == slots->num_slots() &&
                      slots->slot_basis.cols() == K;
  return usable ? slots : nullptr;
}

// The normal equations' options of the problem's measurements, with its joint regressors.
internal::NormalEquationsOptions LinearizationOptions(const CalibrationProblemOptions& options,
                                                      const internal::JointSpaceRegressors* regs) {
  internal::NormalEquationsOptions o;
  o.use_orientation = options.use_orientation;
  o.orientation_weight = options.orientation_weight;
  o.joint.regressors = regs;
  return o;
}

}  // namespace

std::vector<ceres::ResidualBlockId> CalibrationProblem::AddTo(ceres::Problem* problem) {
  const Parameterization& p = parameterization_;
  const MeasurementSet& data = *data_;
  const int n = nominal_.num_joints();
  ceres::LossFunction* loss = nullptr;  // shared by all residual blocks; owned by the problem
  const double whitened_scale = options_.loss_scale / options_.sigma;
  if (options_.loss == "huber") loss = new ceres::HuberLoss(whitened_scale);
  if (options_.loss == "cauchy") loss = new ceres::CauchyLoss(whitened_scale);

  const auto shared_model = std::make_shared<const RobotModel>(nominal_);
  // A row's blocks: the n joint frames, its tool's frame, then the joint-space blocks in order.
  std::vector<double*> parameters(n + 1);
  for (int i = 0; i < n; ++i) parameters[i] = frame_block(i);
  std::vector<int> block_sizes;
  int K = 0;
  // The bilinear blocks after the linear joint blocks (p.bilinear_blocks' indices) and their
  // partners' indices among the joint-space blocks.
  std::vector<int> bilinear, partners;
  for (ProblemBlock& b : blocks_) {
    if (!b.kind->joint_space()) continue;
    parameters.push_back(b.values.data());
    if (b.kind != &internal::JointTermBlockKind()) {
      bilinear.push_back(b.index);
      continue;
    }
    CHECK(bilinear.empty()) << "the bilinear blocks come last";
    block_sizes.push_back(b.tangent_size);
    K += b.tangent_size;
  }
  for (int i : bilinear) {
    int k = 0, partner = -1;
    for (const ProblemBlock& b : blocks_) {
      if (b.kind != &internal::JointTermBlockKind()) continue;
      if (b.index == p.bilinear_blocks[i].partner) partner = k;
      ++k;
    }
    CHECK_GE(partner, 0);
    partners.push_back(partner);
  }
  std::vector<ceres::ResidualBlockId> ids;
  const int batch = BatchedRows();
  if (batch > 1) {
    // Every solved frame in each block: the joints, then the measured tools.
    std::vector<int> frames;
    std::vector<double*> blocks;
    for (ProblemBlock& b : blocks_) {
      if (b.kind != &internal::FrameBlockKind()) continue;
      frames.push_back(b.index);
      blocks.push_back(b.values.data());
    }
    for (int begin = 0; begin < data.size(); begin += batch) {
      const int end = std::min(data.size(), begin + batch);
      ids.push_back(problem->AddResidualBlock(
          new internal::BatchedPositionResidual(shared_model, parameterization_, frames, data,
                                                begin, end, 1.0 / options_.sigma),
          nullptr, blocks));
    }
  }
  // The rows' joint-term columns [Y_b(q) basis_b] (joint_term_columns.h), from the reduction's
  // slots when it stored them (regressors_: the non-zero entries of d(dq)/d(theta) per row), about
  // 89 x K multiply-adds per row on cobot6 instead of each term's n x P regressor.
  internal::JointTermColumns columns(p, n);
  CHECK_EQ(columns.num_columns(), K);
  columns.UseSlots(UsableSlots(regressors_.get(), p, n, data.size(), K));
  if (batch == 1) ids.reserve(data.size());
  // The rows' measurement kind (measurement_kind_dispatch.h): its templated residual, once per
  // solve.
  VisitTrackerKind(TrackerKindId(options_.use_orientation), [&](auto tag) {
    using Kind = typename decltype(tag)::type;
    const Kind kind = Kind::Make(1.0 / options_.sigma, options_.orientation_weight);
    for (int r = 0; batch == 1 && r < data.size(); ++r) {
      parameters[n] = frame_block(n + data.target(r));
      // This row's joint columns (data: evaluated once).
      Eigen::MatrixXd R(n, K);
      columns.Evaluate(r, data.q(r), &R);
      // The bilinear blocks' row data (block_kind.h: the gravity tilt's, with compliance).
      std::vector<std::shared_ptr<const BilinearRow>> rows;
      for (size_t i = 0; i < bilinear.size(); ++i) {
        rows.push_back(internal::BilinearRowOf(p, bilinear[i], data.q(r), partners[i]));
      }
      ceres::CostFunction* cost = MeasurementResidual<Kind>::Create(
          shared_model, kind, data.q(r), Kind::Observe(data, r), R, block_sizes, std::move(rows));
      ids.push_back(problem->AddResidualBlock(cost, loss, parameters));
    }
  });
  // Each block's manifold (the frames' Se3Manifold; the Euclidean kinds add nothing).
  for (ProblemBlock& b : blocks_) b.kind->AddManifold(p, &b, problem);
  return ids;
}

int CalibrationProblem::BatchedRows() const {
  bool joint_blocks = false;
  for (const ProblemBlock& b : blocks_) joint_blocks = joint_blocks || b.kind->joint_space();
  const bool batchable = !options_.use_orientation && options_.loss == "none" && !joint_blocks;
  return batchable ? std::max(1, options_.rows_per_block) : 1;
}

RobotModel CalibrationProblem::Model() const {
  RobotModel model = current_;
  // A block still holding the values current_ was written as keeps current_'s frame bit for bit
  // (no quaternion round trip): the nominal frame until Update() or SetFrames().
  for (size_t i = 0; i < blocks_.size(); ++i) {
    if (blocks_[i].values != current_values_[i]) blocks_[i].kind->WriteModel(blocks_[i], &model);
  }
  return model;
}

Eigen::VectorXd CalibrationProblem::JointState() const {
  const Parameterization& p = parameterization_;
  Eigen::VectorXd all = Eigen::VectorXd::Zero(p.num_parameters);
  for (const ProblemBlock& b : blocks_) b.kind->WriteCoordinates(b, &all);
  return all.tail(p.num_joint_parameters());
}

std::vector<double> CalibrationProblem::EffectiveJointValues() const {
  const MeasurementSet& data = *data_;
  const int n = data.num_joints();
  const Parameterization& p = parameterization_;
  if (data.size() == 0) return {};
  std::vector<double> q(data.q(0), data.q(0) + static_cast<size_t>(data.size()) * n);
  if (p.joint_blocks.empty()) return q;
  const Eigen::VectorXd x = JointState();
  const internal::JointSpaceRegressors* slots =
      UsableSlots(regressors_.get(), p, n, data.size(), x.size());
  if (slots == nullptr) {
    const MeasurementSet shifted = WithEffectiveJointValues(JointTerms(), data);
    std::copy(shifted.q(0), shifted.q(0) + q.size(), q.begin());
    return q;
  }
  // The slots' parameter values theta(slot) = slot_basis x, then per row and joint
  // dq_j = sum_{s in j} values(s, r) theta(s).
  const Eigen::VectorXd theta = slots->slot_basis * x;
  for (int r = 0; r < data.size(); ++r) {
    const double* v = slots->values.col(r).data();
    for (int j = 0; j < n; ++j) {
      double dq = 0;
      for (int s = slots->slot_begin[j]; s < slots->slot_begin[j + 1]; ++s) dq += v[s] * theta(s);
      q[static_cast<size_t>(r) * n + j] += dq;
    }
  }
  return q;
}

std::vector<JointTermValues> CalibrationProblem::JointTerms() const {
  const Parameterization& p = parameterization_;
  Eigen::VectorXd all = Eigen::VectorXd::Zero(p.num_parameters);
  for (const ProblemBlock& b : blocks_) b.kind->WriteCoordinates(b, &all);
  return JointValuesOf(p, all);
}

const Parameterization& CalibrationProblem::SolvedParameterization() const {
  return setup_->solved;
}

internal::NormalEquations CalibrationProblem::Linearize(
    const internal::NormalEquationsOptions& o) const {
  internal::NormalEquationsOptions with = o;
  with.use_orientation = options_.use_orientation;
  with.orientation_weight = options_.orientation_weight;
  if (with.joint.regressors == nullptr) with.joint.regressors = regressors_.get();
  return internal::NormalEquationsOf(Model(), *data_, SolvedParameterization(), JointState(), with);
}

CalibrationProblem::Values CalibrationProblem::values() const {
  Values v;
  for (const ProblemBlock& b : blocks_) v.blocks.push_back(b.values);
  v.model = current_;
  v.model_values = current_values_;
  return v;
}

void CalibrationProblem::SetValues(const Values& v) {
  CHECK_EQ(v.blocks.size(), blocks_.size());
  // Into the blocks' own storage: their addresses are Ceres's parameter blocks.
  for (size_t i = 0; i < blocks_.size(); ++i) {
    CHECK_EQ(v.blocks[i].size(), blocks_[i].values.size());
    std::copy(v.blocks[i].begin(), v.blocks[i].end(), blocks_[i].values.begin());
  }
  current_ = v.model;
  current_values_ = v.model_values;
}

void CalibrationProblem::SetFrames(const RobotModel& model) {
  CHECK_EQ(model.num_frames(), current_.num_frames());
  const int n = model.num_joints();
  current_ = Model();
  for (int f = 0; f < model.num_frames(); ++f) {
    const SE3d& T = f < n ? model.joints[f].origin : model.tools[f - n].origin;
    (f < n ? current_.joints[f].origin : current_.tools[f - n].origin) = T;
    if (frame_blocks_[f] >= 0) Se3ToArray(T, blocks_[frame_blocks_[f]].values.data());
  }
  for (size_t i = 0; i < blocks_.size(); ++i) current_values_[i] = blocks_[i].values;
}

ProblemNormalEquations CalibrationProblem::NormalEquations() const {
  ProblemNormalEquations out;
  out.parameterization = SolvedParameterization();
  const internal::NormalEquations lin =
      Linearize(LinearizationOptions(options_, regressors_.get()));
  const double w = 1.0 / (options_.sigma * options_.sigma);
  out.H = w * lin.H;
  out.g = w * lin.g;
  out.cost = w * lin.cost;
  out.finite = lin.finite;
  for (const Direction& d : out.parameterization.parameters) out.names.push_back(d.name);
  return out;
}

void CalibrationProblem::Update(const Eigen::VectorXd& x) {
  const Parameterization& solved = SolvedParameterization();
  CHECK_EQ(x.size(), solved.num_parameters) << "step of the wrong size";
  // Each block's step (its kind's: T_f exp((B_f x_f)^) for a frame, on the model's matrix; added
  // for a Euclidean block); the model the new values stand for, exactly, is kept (Model() returns
  // it while the blocks hold them).
  RobotModel model = Model();
  for (ProblemBlock& b : blocks_) b.kind->Plus(solved, x, b.solved_offset, &b, &model);
  current_ = std::move(model);
  for (size_t i = 0; i < blocks_.size(); ++i) current_values_[i] = blocks_[i].values;
}

ProblemAnalysis CalibrationProblem::Analyze(double max_condition_number) const {
  return AnalyzeWith(nullptr, max_condition_number);
}

ProblemAnalysis CalibrationProblem::AnalyzeNormalMatrix(const Eigen::MatrixXd& H,
                                                        double max_condition_number) const {
  return AnalyzeWith(&H, max_condition_number);
}

// The one identifiability check of both solvers: Analyze() (the Ceres solver's, H formed here,
// the weakest direction always computed) and AnalyzeNormalMatrix() (the linear solver's, on its
// own linearization with the prior's information).
ProblemAnalysis CalibrationProblem::AnalyzeWith(const Eigen::MatrixXd* H_solved,
                                                double max_condition_number) const {
  const Parameterization& p = parameterization_;
  const MeasurementSet& data = *data_;
  const bool full = options_.parameterization == ParameterizationKind::kFull;
  const MeasurementKindId tracker_kind = TrackerKindId(options_.use_orientation);
  const DataKind kind = TrackerDataKind(tracker_kind);
  const int per_row = TrackerResiduals(tracker_kind);
  const RobotModel model = Model();
  ProblemAnalysis out;
  // The identifiable directions of the solved frames (for the full parameterization, its
  // identifiable basis: the full J^T J is singular by construction), then the joint blocks.
  Parameterization all = p;
  if (full) {
    all = MakeParameterization(model, ParameterizationKind::kIdentifiable, kind);
    internal::LeaveOutStructurallyUnidentifiable(
        options_.structure_reference ? *options_.structure_reference : nominal_, *data_,
        options_.use_orientation, options_.orientation_weight, &all);
    CopyJointBlocks(p, &all);
  }
  Parameterization analysed;
  std::vector<int> columns;
  const bool given = H_solved != nullptr && !full;
  if (given) {
    // The caller's H is in the solved numbering (SolvedParameterization(): the same columns, or
    // a given parameterization's, setup().overridden).
    analysed.parameters = SolvedParameterization().parameters;
  } else {
    for (int f = 0; f < model.num_frames(); ++f) {
      if (!frame_solved(f)) continue;
      for (int c = 0; c < all.basis[f].cols(); ++c) {
        columns.push_back(all.offset[f] + c);
        analysed.parameters.push_back(all.parameters[all.offset[f] + c]);
      }
    }
    for (int k = all.num_frame_parameters(); k < all.num_parameters; ++k) {
      columns.push_back(k);
      analysed.parameters.push_back(all.parameters[k]);
    }
  }
  analysed.num_parameters = static_cast<int>(analysed.parameters.size());
  out.num_parameters = analysed.num_parameters;
  for (const Direction& d : analysed.parameters) out.parameter_names.push_back(d.name);
  Parameterization left_out = all;
  internal::LeaveOutUnmeasuredTools(model, data, &left_out);
  out.unidentifiable = left_out.unidentifiable;
  out.num_equations = static_cast<long>(per_row) * data.size();
  if (out.num_equations < out.num_parameters && H_solved == nullptr) {
    out.message = internal::TooFewEquationsMessage(data.size(), out.num_equations,
                                                   out.num_parameters, per_row);
    return out;
  }
  // At the start values the reduction's normal equations give H by projection (no pass).
  bool at_start = analysed_ != nullptr;
  for (const ProblemBlock& b : blocks_) at_start = at_start && b.kind->AtReductionPoint(b);
  Eigen::MatrixXd H_all;
  if (given) {
    CHECK_EQ(H_solved->rows(), out.num_parameters);
    out.normal_matrix = *H_solved;
  } else if (at_start && !internal::HasNonlinearBlocks(all) &&
      internal::SameFrameDirections(setup_->analysed_parameterization, all)) {
    H_all = internal::ProjectJointBlocks(*analysed_, all).H;
  } else {
    H_all = internal::NormalEquationsOf(model, data, all, JointState(),
                                        LinearizationOptions(options_, regressors_.get()))
                .H;
  }
  Eigen::MatrixXd& H = out.normal_matrix;
  if (H_all.size() > 0) {
    H.resize(out.num_parameters, out.num_parameters);
    for (int a = 0; a < out.num_parameters; ++a) {
      for (int b = 0; b < out.num_parameters; ++b) H(a, b) = H_all(columns[a], columns[b]);
    }
  }
  if (!H.allFinite()) {
    out.finite = false;
    out.message = "non-finite residuals or Jacobian at the nominal model (check the input values)";
    return out;
  }
  // Analyze(): the weakest direction always; AnalyzeNormalMatrix(): the eigenvalues decide, the
  // eigenvectors only for a refusal's message.
  internal::Identifiability id = internal::Analyze(H, H_solved == nullptr);
  out.rank = id.rank;
  out.condition_number = id.condition;
  out.singular_values = id.singular_values;
  out.identifiable = id.rank >= out.num_parameters && id.condition <= max_condition_number;
  if (!out.identifiable && id.weakest.size() == 0) id = internal::Analyze(H, true);
  if (id.weakest.size() > 0) out.weakest = internal::WeakestDirections(analysed, id.weakest);
  if (!out.identifiable) {
    out.message = internal::NotIdentifiableMessage(id, out.num_parameters, max_condition_number,
                                                   analysed);
  }
  return out;
}

Status CalibrationProblem::Covariance(ceres::Problem* problem, int num_threads,
                                      Eigen::MatrixXd* covariance, int null_space_rank) {
  ceres::Covariance::Options cov_options;
  cov_options.algorithm_type = ceres::DENSE_SVD;
  cov_options.num_threads = std::max(1, num_threads);
  // Full parameterization: the gauge directions are a known null space; take the pseudo-inverse
  // (singular values below min_reciprocal_condition_number are dropped).
  cov_options.null_space_rank =
      options_.parameterization == ParameterizationKind::kFull ? null_space_rank : 0;
  ceres::Covariance cov(cov_options);
  const std::vector<double*> blocks = parameter_blocks();
  const std::vector<int> sizes = tangent_sizes();  // in the order of parameter_blocks()
  // A frame with no columns (a fixed tool, or every direction left out) is a constant block: Ceres
  // would give it its ambient size, so it is not asked for (its rows of C are empty anyway).
  std::vector<const double*> const_blocks;
  for (size_t k = 0; k < blocks.size(); ++k) {
    if (sizes[k] > 0) const_blocks.push_back(blocks[k]);
  }
  int tangent = 0;
  for (int s : sizes) tangent += s;
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> C(tangent, tangent);
  if (!cov.Compute(const_blocks, problem) ||
      !cov.GetCovarianceMatrixInTangentSpace(const_blocks, C.data())) {
    return Status::Error("covariance not computed (rank-deficient Jacobian at the solution)");
  }
  *covariance = ScatterCovariance(C);
  return Status::Ok();
}

Eigen::MatrixXd CalibrationProblem::ScatterCovariance(const Eigen::MatrixXd& C) const {
  // Rows of C follow parameter_blocks(); scatter them to p's offsets.
  const Parameterization& p = parameterization_;
  const std::vector<int> sizes = tangent_sizes();
  const std::vector<int> offsets = tangent_offsets();
  Eigen::MatrixXd covariance = Eigen::MatrixXd::Zero(p.num_parameters, p.num_parameters);
  std::vector<int> c_offset(sizes.size());
  for (size_t a = 1; a < sizes.size(); ++a) c_offset[a] = c_offset[a - 1] + sizes[a - 1];
  for (size_t a = 0; a < sizes.size(); ++a) {
    for (size_t b = 0; b < sizes.size(); ++b) {
      covariance.block(offsets[a], offsets[b], sizes[a], sizes[b]) =
          C.block(c_offset[a], c_offset[b], sizes[a], sizes[b]);
    }
  }
  return covariance;
}

Status CalibrationProblem::NormalEquationsCovariance(Eigen::MatrixXd* covariance,
                                                     int null_space_rank) const {
  // H's columns are the solved parameters in parameter_blocks() order, as Covariance()'s C.
  const ProblemNormalEquations ne = NormalEquations();
  if (!ne.finite) return Status::Error("covariance not computed (non-finite normal equations)");
  Eigen::MatrixXd C;
  if (options_.parameterization == ParameterizationKind::kFull) {
    // The pseudo-inverse with Ceres's rule (DENSE_SVD, null_space_rank -1): eigenvalues below
    // min_reciprocal_condition_number times the largest are dropped.
    const double min_ratio = ceres::Covariance::Options().min_reciprocal_condition_number;
    Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(ne.H);
    const Eigen::VectorXd& l = eig.eigenvalues();
    const double largest = l.maxCoeff();
    Eigen::VectorXd inv_l = Eigen::VectorXd::Zero(l.size());
    for (int k = std::max(0, null_space_rank); k < l.size(); ++k) {  // ascending
      if (null_space_rank >= 0 || l(k) > min_ratio * largest) inv_l(k) = 1.0 / l(k);
    }
    if (null_space_rank >= 0 && null_space_rank < l.size() &&
        !(l(null_space_rank) > min_ratio * largest)) {
      return Status::Error("covariance not computed (rank-deficient Jacobian at the solution)");
    }
    C = eig.eigenvectors() * inv_l.asDiagonal() * eig.eigenvectors().transpose();
  } else {
    // Column-scaled for accuracy, as the linear solver's covariance.
    const Eigen::VectorXd d = internal::ColumnScale(ne.H);
    const Eigen::MatrixXd Hs = d.asDiagonal() * ne.H * d.asDiagonal();
    Eigen::LLT<Eigen::MatrixXd> llt(Hs);
    // Compute()'s test (DENSE_SVD): the reciprocal condition number of the Jacobian, here the
    // column-scaled one, i.e. the square root of the eigenvalue ratio of Hs.
    const double min_ratio = ceres::Covariance::Options().min_reciprocal_condition_number;
    const Eigen::VectorXd l =
        Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(Hs, Eigen::EigenvaluesOnly).eigenvalues();
    if (llt.info() != Eigen::Success || l.size() == 0 ||
        !(std::sqrt(std::max(0.0, l(0)) / l(l.size() - 1)) >= min_ratio)) {
      return Status::Error("covariance not computed (rank-deficient Jacobian at the solution)");
    }
    C = d.asDiagonal() * llt.solve(Eigen::MatrixXd::Identity(Hs.rows(), Hs.cols())) *
        d.asDiagonal();
  }
  *covariance = ScatterCovariance(C);
  return Status::Ok();
}

}  // namespace lpoe
