// Ballbar and plane calibration with Ceres (lpoe/contact_calibration.h): the same frames, features
// and cost as CalibrateContactsLinear, the residuals of the kinds' templates differentiated by
// Ceres's autodiff.
#include <memory>
#include <vector>

#include <ceres/ceres.h>
#include <ceres/product_manifold.h>
#include <ceres/sphere_manifold.h>

#include "linearization/joint_term_columns.h"
#include "contact/contact_kinds.h"
#include "lpoe/contact_calibration.h"
#include "lpoe/measurements/distance_measurement.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/measurements/plane_measurement.h"
#include "lpoe/measurements/position_measurement.h"
#include "lpoe/se3_manifold.h"

namespace lpoe {
namespace {

// One row's residual: the kind's templated Residual on the n joint frames, the tool's frame and
// (distance, plane) the feature's block.
template <typename Kind>
class ContactRowFunctor {
 public:
  ContactRowFunctor(std::shared_ptr<const RobotModel> model, const Kind& kind, const double* q,
                    const typename Kind::Observation& observation)
      : model_(std::move(model)), kind_(kind), motions_(*model_, q), observation_(observation) {}
  template <typename T>
  bool operator()(T const* const* parameters, T* residuals) const {
    kind_.Residual(model_->num_joints(), parameters, motions_, observation_, residuals);
    return true;
  }

 private:
  std::shared_ptr<const RobotModel> model_;
  Kind kind_;
  JointMotions<double> motions_;
  typename Kind::Observation observation_;
};

// The scale hold (contact_calibration.h): (S(model) - 1) / sigma with S = sum_j w_j . P_j over the
// rows' predicted points, a function of every frame block. Its Jacobian is computed in the frames'
// tangent coordinates (BasisJacobian, as the linear solver's) and given to Ceres in the ambient
// coordinates through each manifold's MinusJacobian (MinusJacobian * PlusJacobian = I).
class ScaleHoldCost : public ceres::CostFunction {
 public:
  ScaleHoldCost(const RobotModel& start, const ContactParameterization& p,
                const ContactMeasurementSet& data, double sigma)
      : model_(start), p_(p), frames_(p.frames), data_(data), sigma_(sigma) {
    // The frame blocks alone (the hold is on the frames' predictions at the joint values read).
    frames_.joint_blocks.clear();
    frames_.num_parameters = p.frames.num_frame_parameters();
    frames_.parameters.resize(frames_.num_parameters);
    for (int f = 0; f < start.num_frames(); ++f) {
      mutable_parameter_block_sizes()->push_back(kSe3AmbientSize);
      manifolds_.emplace_back(p.frames.basis[f].cols() > 0 ? new Se3Manifold(p.frames.basis[f])
                                                           : nullptr);
    }
    set_num_residuals(1);
  }
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    RobotModel m = model_;
    const int n = m.num_joints();
    for (int f = 0; f < m.num_frames(); ++f) {
      (f < n ? m.joints[f].origin : m.tools[f - n].origin) = Se3FromArray(parameters[f]);
    }
    const int P = frames_.num_parameters;
    BasisJacobian bj(m, frames_);
    std::vector<FrameRt> scratch(n + 1);
    Eigen::Matrix<double, 3, Eigen::Dynamic> Jp(3, std::max(P, 1));
    Eigen::RowVectorXd g = Eigen::RowVectorXd::Zero(std::max(P, 1));
    double S = 0;
    for (int i = 0; i < data_.size(); ++i) {
      const Eigen::Vector3d X =
          bj.Position(data_.joints(i), data_.rows[i].target, Jp.data(), 3, scratch.data());
      S += p_.scale_weights.col(i).dot(X);
      if (jacobians != nullptr) g.head(P) += p_.scale_weights.col(i).transpose() * Jp.leftCols(P);
    }
    residuals[0] = (S - 1.0) / sigma_;
    if (jacobians != nullptr) {
      for (int f = 0; f < m.num_frames(); ++f) {
        if (jacobians[f] == nullptr) continue;
        Eigen::Map<Eigen::Matrix<double, 1, kSe3AmbientSize>> out(jacobians[f]);
        out.setZero();
        const int k = static_cast<int>(p_.frames.basis[f].cols());
        if (k == 0) continue;
        Eigen::Matrix<double, Eigen::Dynamic, kSe3AmbientSize, Eigen::RowMajor> minus(k, kSe3AmbientSize);
        manifolds_[f]->MinusJacobian(parameters[f], minus.data());
        out = g.segment(p_.frames.offset[f], k) * minus / sigma_;
      }
    }
    return true;
  }

 private:
  RobotModel model_;
  const ContactParameterization& p_;
  Parameterization frames_;
  const ContactMeasurementSet& data_;
  double sigma_;
  std::vector<std::unique_ptr<Se3Manifold>> manifolds_;
};

// The gauge rows on the features (ContactParameterization::gauge_rows): linear in the blocks'
// ambient values, pivots (3) then planes (4).
class GaugeHoldCost : public ceres::CostFunction {
 public:
  GaugeHoldCost(const ContactParameterization& p) : rows_(p.gauge_rows), values_(p.gauge_values),
                                                    sigma_(p.gauge_sigma) {
    for (int k = 0; k < p.num_pivots; ++k) mutable_parameter_block_sizes()->push_back(3);
    for (int k = 0; k < p.num_planes; ++k) mutable_parameter_block_sizes()->push_back(4);
    set_num_residuals(static_cast<int>(rows_.rows()));
  }
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const int blocks = static_cast<int>(parameter_block_sizes().size());
    Eigen::VectorXd f(rows_.cols());
    int at = 0;
    for (int b = 0; b < blocks; ++b) {
      const int size = parameter_block_sizes()[b];
      for (int k = 0; k < size; ++k) f(at + k) = parameters[b][k];
      at += size;
    }
    Eigen::Map<Eigen::VectorXd>(residuals, rows_.rows()) = (rows_ * f - values_) / sigma_;
    if (jacobians != nullptr) {
      at = 0;
      for (int b = 0; b < blocks; ++b) {
        const int size = parameter_block_sizes()[b];
        if (jacobians[b] != nullptr) {
          Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
              jacobians[b], rows_.rows(), size) = rows_.middleCols(at, size) / sigma_;
        }
        at += size;
      }
    }
    return true;
  }

 private:
  Eigen::MatrixXd rows_;
  Eigen::VectorXd values_;
  double sigma_;
};

// The same row with joint-space blocks (one Euclidean block x_b of k_b numbers per term, after the
// frames and the feature): the chain evaluated at q_eff = q + sum_b R_b x_b with R_b = Y_b(q)
// basis_b (fixed data of the row), Jet joint values through the chain.
template <typename Kind>
class ContactJointRowFunctor {
 public:
  ContactJointRowFunctor(std::shared_ptr<const RobotModel> model, const Kind& kind, const double* q,
                         const typename Kind::Observation& observation, Eigen::MatrixXd R,
                         std::vector<int> block_sizes, int first_joint_block)
      : model_(std::move(model)),
        kind_(kind),
        q_(q, q + model_->num_joints()),
        observation_(observation),
        R_(std::move(R)),
        block_sizes_(std::move(block_sizes)),
        first_joint_block_(first_joint_block) {}
  template <typename T>
  bool operator()(T const* const* parameters, T* residuals) const {
    const int n = model_->num_joints();
    std::vector<T> q_eff(n);
    for (int j = 0; j < n; ++j) q_eff[j] = T(q_[j]);
    int column = 0;
    for (size_t b = 0; b < block_sizes_.size(); ++b) {
      const T* x = parameters[first_joint_block_ + b];
      for (int c = 0; c < block_sizes_[b]; ++c, ++column) {
        for (int j = 0; j < n; ++j) q_eff[j] += R_(j, column) * x[c];
      }
    }
    const JointMotions<T> motions(*model_, q_eff.data());
    kind_.Residual(n, parameters, motions, observation_, residuals);
    return true;
  }

 private:
  std::shared_ptr<const RobotModel> model_;
  Kind kind_;
  std::vector<double> q_;
  typename Kind::Observation observation_;
  Eigen::MatrixXd R_;  // n x sum(block_sizes)
  std::vector<int> block_sizes_;
  int first_joint_block_;
};

template <typename Kind>
ceres::CostFunction* MakeJointRowCost(std::shared_ptr<const RobotModel> model, const Kind& kind,
                                      const double* q,
                                      const typename Kind::Observation& observation,
                                      int feature_size, Eigen::MatrixXd R,
                                      std::vector<int> block_sizes) {
  using Cost = ceres::DynamicAutoDiffCostFunction<ContactJointRowFunctor<Kind>, 4>;
  const int first = model->num_joints() + 1 + (feature_size > 0 ? 1 : 0);
  auto* cost = new Cost(new ContactJointRowFunctor<Kind>(model, kind, q, observation, std::move(R),
                                                         block_sizes, first));
  for (int i = 0; i <= model->num_joints(); ++i) cost->AddParameterBlock(kSe3AmbientSize);
  if (feature_size > 0) cost->AddParameterBlock(feature_size);
  for (int k : block_sizes) cost->AddParameterBlock(k);
  cost->SetNumResiduals(Kind::kResiduals);
  return cost;
}

template <typename Kind>
ceres::CostFunction* MakeRowCost(std::shared_ptr<const RobotModel> model, const Kind& kind,
                                 const double* q, const typename Kind::Observation& observation,
                                 int feature_size) {
  using Cost = ceres::DynamicAutoDiffCostFunction<ContactRowFunctor<Kind>, 4>;
  auto* cost = new Cost(new ContactRowFunctor<Kind>(model, kind, q, observation));
  for (int i = 0; i <= model->num_joints(); ++i) cost->AddParameterBlock(kSe3AmbientSize);
  if (feature_size > 0) cost->AddParameterBlock(feature_size);
  cost->SetNumResiduals(Kind::kResiduals);
  return cost;
}

// The problem's unknowns, as Ceres blocks: the frames (7 each), the pivots (3), the planes (4) and
// the joint-space blocks' x_b (theta_b = basis_b x_b, from zero; a block with nothing left has no
// columns and no parameter block).
struct ContactCeresBlocks {
  std::vector<double> frames, pivots, planes;
  std::vector<std::vector<double>> joint_x;
  std::vector<int> joint_sizes;  // of the joint blocks with columns
  double* frame(int f) { return frames.data() + kSe3AmbientSize * f; }
  // The Ceres block of feature k of a kind with a feature.
  template <typename Kind>
  double* feature(int k) {
    return (Kind::kKind == MeasurementKindId::kDistance ? pivots : planes).data() +
           Kind::kFeatureSize * k;
  }
};

ContactCeresBlocks MakeContactCeresBlocks(const RobotModel& nominal,
                                          const ContactCalibrationResult& start,
                                          ceres::Problem* problem) {
  const ContactParameterization& p = start.parameterization;
  const int n = nominal.num_joints();
  const int frames = nominal.num_frames();
  ContactCeresBlocks x;
  x.frames.resize(static_cast<size_t>(kSe3AmbientSize) * frames);
  for (int f = 0; f < frames; ++f) {
    Se3ToArray(f < n ? nominal.joints[f].origin : nominal.tools[f - n].origin, x.frame(f));
  }
  x.pivots.resize(3 * p.num_pivots);
  x.planes.resize(4 * p.num_planes);
  for (int k = 0; k < p.num_pivots; ++k) {
    for (int a = 0; a < 3; ++a) x.pivots[3 * k + a] = start.features.pivots[k](a);
  }
  for (int k = 0; k < p.num_planes; ++k) {
    for (int a = 0; a < 4; ++a) x.planes[4 * k + a] = start.features.planes[k](a);
  }
  for (int f = 0; f < frames; ++f) problem->AddParameterBlock(x.frame(f), kSe3AmbientSize);
  for (int k = 0; k < p.num_pivots; ++k) problem->AddParameterBlock(x.pivots.data() + 3 * k, 3);
  for (int k = 0; k < p.num_planes; ++k) {
    problem->AddParameterBlock(
        x.planes.data() + 4 * k, 4,
        new ceres::ProductManifold<ceres::SphereManifold<3>, ceres::EuclideanManifold<1>>());
  }
  const std::vector<JointBlock>& joint_blocks = p.frames.joint_blocks;
  x.joint_x.resize(joint_blocks.size());
  for (size_t b = 0; b < joint_blocks.size(); ++b) {
    const int k = static_cast<int>(joint_blocks[b].basis.cols());
    x.joint_x[b].assign(k, 0.0);
    if (k == 0) continue;
    problem->AddParameterBlock(x.joint_x[b].data(), k);
    x.joint_sizes.push_back(k);
  }
  return x;
}

// Row i's residual block: its kind's cost (the kind's templated Residual, through the kind table's
// dispatch) on the n joint frames, its tool's frame, its feature (distance, plane) and the joint
// blocks.
void AddContactRowResidual(const std::shared_ptr<const RobotModel>& model_ptr,
                           const ContactMeasurementSet& data, int i, ContactCeresBlocks* x,
                           internal::JointTermColumns* joint_columns, ceres::Problem* problem) {
  const ContactRow& row = data.rows[i];
  const int n = model_ptr->num_joints();
  std::vector<double*> b;
  for (int f = 0; f < n; ++f) b.push_back(x->frame(f));
  b.push_back(x->frame(n + row.target));
  const double w = 1.0 / row.sigma;
  const bool joint = !x->joint_sizes.empty();
  Eigen::MatrixXd R;  // [Y_b(q) basis_b]: the tracker solvers' columns (joint_term_columns.h)
  if (joint) joint_columns->Evaluate(i, data.joints(i), &R);
  ceres::CostFunction* cost =
      internal::VisitContactRowKind(row.kind, [&](auto tag) -> ceres::CostFunction* {
        using Kind = typename decltype(tag)::type;
        if constexpr (Kind::kFeatureSize > 0) {
          b.push_back(x->feature<Kind>(row.feature));
          return joint ? MakeJointRowCost(model_ptr, Kind{w}, data.joints(i), row.value,
                                          Kind::kFeatureSize, R, x->joint_sizes)
                       : MakeRowCost(model_ptr, Kind{w}, data.joints(i), row.value,
                                     Kind::kFeatureSize);
        } else {
          const Eigen::Vector3d position(row.position);
          return joint ? MakeJointRowCost(model_ptr, Kind{w}, data.joints(i), position, 0, R,
                                          x->joint_sizes)
                       : MakeRowCost(model_ptr, Kind{w}, data.joints(i), position, 0);
        }
      });
  if (joint) {
    for (std::vector<double>& xb : x->joint_x) {
      if (!xb.empty()) b.push_back(xb.data());
    }
  }
  problem->AddResidualBlock(cost, nullptr, b);
}

}  // namespace

ContactCalibrationResult CalibrateContactsCeres(const RobotModel& nominal,
                                                const ContactMeasurementSet& data,
                                                const ContactCalibrationOptions& options) {
  ContactCalibrationResult result;
  if (!StartContactCalibration(nominal, data, options, "ceres", &result)) return result;
  const ContactParameterization& p = result.parameterization;
  const int n = nominal.num_joints();
  const int frames = nominal.num_frames();
  auto model_ptr = std::make_shared<const RobotModel>(nominal);
  ceres::Problem::Options problem_options;
  problem_options.manifold_ownership = ceres::TAKE_OWNERSHIP;
  ceres::Problem problem(problem_options);
  ContactCeresBlocks x = MakeContactCeresBlocks(nominal, result, &problem);
  std::vector<double>& pivots = x.pivots;
  std::vector<double>& planes = x.planes;
  std::vector<std::vector<double>>& joint_x = x.joint_x;
  const std::vector<JointBlock>& joint_blocks = p.frames.joint_blocks;
  auto frame_block = [&x](int f) { return x.frame(f); };
  internal::JointTermColumns joint_columns(p.frames, n);
  for (int i = 0; i < data.size(); ++i) {
    AddContactRowResidual(model_ptr, data, i, &x, &joint_columns, &problem);
  }
  if (p.num_gauge_rows() > 0) {
    std::vector<double*> b;
    for (int k = 0; k < p.num_pivots; ++k) b.push_back(pivots.data() + 3 * k);
    for (int k = 0; k < p.num_planes; ++k) b.push_back(planes.data() + 4 * k);
    problem.AddResidualBlock(new GaugeHoldCost(p), nullptr, b);
  }
  if (p.scale_held) {
    std::vector<double*> b;
    for (int f = 0; f < frames; ++f) b.push_back(frame_block(f));
    problem.AddResidualBlock(new ScaleHoldCost(nominal, p, data, options.scale_sigma), nullptr, b);
  }
  for (int f = 0; f < frames; ++f) {
    const Eigen::MatrixXd& B = p.frames.basis[f];
    if (B.cols() == 0) {
      problem.SetParameterBlockConstant(frame_block(f));
    } else {
      problem.SetManifold(frame_block(f), new Se3Manifold(B));
    }
  }
  ceres::Solver::Options solver_options;
  solver_options.linear_solver_type = ceres::DENSE_QR;
  solver_options.max_num_iterations = options.max_iterations;
  solver_options.function_tolerance = options.function_tolerance;
  solver_options.gradient_tolerance = 1e-16;
  solver_options.parameter_tolerance = 1e-14;
  solver_options.logging_type = ceres::SILENT;
  solver_options.num_threads = 1;
  ceres::Solver::Summary summary;
  ceres::Solve(solver_options, &problem, &summary);
  for (int f = 0; f < frames; ++f) {
    SE3d& T = f < n ? result.model.joints[f].origin : result.model.tools[f - n].origin;
    T = Se3FromArray(frame_block(f));
  }
  for (int k = 0; k < p.num_pivots; ++k) {
    result.features.pivots[k] = Eigen::Vector3d(pivots[3 * k], pivots[3 * k + 1], pivots[3 * k + 2]);
  }
  for (int k = 0; k < p.num_planes; ++k) {
    result.features.planes[k] =
        Eigen::Vector4d(planes[4 * k], planes[4 * k + 1], planes[4 * k + 2], planes[4 * k + 3]);
  }
  result.features.joint_theta.clear();
  for (size_t b = 0; b < joint_blocks.size(); ++b) {
    const int k = static_cast<int>(joint_x[b].size());
    result.features.joint_theta.push_back(
        k > 0 ? Eigen::VectorXd(joint_blocks[b].basis *
                                Eigen::Map<const Eigen::VectorXd>(joint_x[b].data(), k))
              : Eigen::VectorXd::Zero(joint_blocks[b].term->num_parameters()));
  }
  result.iterations = static_cast<int>(summary.iterations.size());
  result.initial_cost = summary.initial_cost;
  result.cost = summary.final_cost;
  FinishContactCalibration(nominal, data, &result);
  result.ok = summary.IsSolutionUsable() && summary.termination_type == ceres::CONVERGENCE;
  result.message = result.ok ? "converged" : summary.message;
  return result;
}

}  // namespace lpoe
