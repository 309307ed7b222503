// Ballbar and plane calibration with Ceres (lpoe/contact_calibration.h): the same frames, features
// and cost as CalibrateContactsLinear, the residuals of the kinds' templates differentiated by
// Ceres's autodiff.
#include <memory>
#include <vector>

#include <ceres/ceres.h>
#include <ceres/product_manifold.h>
#include <ceres/sphere_manifold.h>

#include "lpoe/contact_calibration.h"
#include "lpoe/distance_measurement.h"
#include "lpoe/kinematics.h"
#include "lpoe/plane_measurement.h"
#include "lpoe/position_measurement.h"
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

// The scale hold (contact_calibration.h): (S(model) - 1) / sigma over every frame block; S is
// linear in the translations [4..6] of the blocks.
class ScaleHoldCost : public ceres::CostFunction {
 public:
  ScaleHoldCost(const RobotModel& nominal, double sigma) : sigma_(sigma) {
    const int n = nominal.num_joints();
    double den = 0;
    for (int f = 0; f < nominal.num_frames(); ++f) {
      const Eigen::Vector3d t = f < n ? nominal.joints[f].origin.t : nominal.tools[f - n].origin.t;
      t0_.push_back(t);
      den += t.squaredNorm();
      mutable_parameter_block_sizes()->push_back(kSe3AmbientSize);
    }
    den_ = den;
    set_num_residuals(1);
  }
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    double num = 0;
    for (size_t f = 0; f < t0_.size(); ++f) {
      for (int k = 0; k < 3; ++k) num += t0_[f](k) * parameters[f][4 + k];
    }
    residuals[0] = (num / den_ - 1.0) / sigma_;
    if (jacobians != nullptr) {
      for (size_t f = 0; f < t0_.size(); ++f) {
        if (jacobians[f] == nullptr) continue;
        for (int k = 0; k < 4; ++k) jacobians[f][k] = 0;
        for (int k = 0; k < 3; ++k) jacobians[f][4 + k] = t0_[f](k) / (den_ * sigma_);
      }
    }
    return true;
  }

 private:
  std::vector<Eigen::Vector3d> t0_;
  double den_ = 1;
  double sigma_ = 1;
};

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

}  // namespace

ContactCalibrationResult CalibrateContactsCeres(const RobotModel& nominal,
                                                const ContactMeasurementSet& data,
                                                const ContactCalibrationOptions& options) {
  ContactCalibrationResult result;
  result.solver = "ceres";
  result.model = nominal;
  Status s = InitialContactFeatures(nominal, data, &result.features);
  if (s.ok()) {
    s = MakeContactParameterization(nominal, result.features, data, options,
                                    &result.parameterization);
  }
  if (!s.ok()) {
    result.message = s.message();
    return result;
  }
  const ContactParameterization& p = result.parameterization;
  const int n = nominal.num_joints();
  const int frames = nominal.num_frames();
  std::vector<double> blocks(static_cast<size_t>(kSe3AmbientSize) * frames);
  for (int f = 0; f < frames; ++f) {
    Se3ToArray(f < n ? nominal.joints[f].origin : nominal.tools[f - n].origin,
               blocks.data() + kSe3AmbientSize * f);
  }
  std::vector<double> pivots(3 * p.num_pivots), planes(4 * p.num_planes);
  for (int k = 0; k < p.num_pivots; ++k) {
    for (int a = 0; a < 3; ++a) pivots[3 * k + a] = result.features.pivots[k](a);
  }
  for (int k = 0; k < p.num_planes; ++k) {
    for (int a = 0; a < 4; ++a) planes[4 * k + a] = result.features.planes[k](a);
  }
  auto model_ptr = std::make_shared<const RobotModel>(nominal);
  ceres::Problem::Options problem_options;
  problem_options.manifold_ownership = ceres::TAKE_OWNERSHIP;
  ceres::Problem problem(problem_options);
  auto frame_block = [&](int f) { return blocks.data() + kSe3AmbientSize * f; };
  for (int f = 0; f < frames; ++f) problem.AddParameterBlock(frame_block(f), kSe3AmbientSize);
  for (int k = 0; k < p.num_pivots; ++k) problem.AddParameterBlock(pivots.data() + 3 * k, 3);
  for (int k = 0; k < p.num_planes; ++k) {
    problem.AddParameterBlock(
        planes.data() + 4 * k, 4,
        new ceres::ProductManifold<ceres::SphereManifold<3>, ceres::EuclideanManifold<1>>());
  }
  for (int i = 0; i < data.size(); ++i) {
    const ContactRow& row = data.rows[i];
    std::vector<double*> b;
    for (int f = 0; f < n; ++f) b.push_back(frame_block(f));
    b.push_back(frame_block(n + row.target));
    const double w = 1.0 / row.sigma;
    ceres::CostFunction* cost = nullptr;
    switch (row.kind) {
      case MeasurementKindId::kDistance:
        cost = MakeRowCost(model_ptr, DistanceMeasurement{w}, data.joints(i), row.value, 3);
        b.push_back(pivots.data() + 3 * row.feature);
        break;
      case MeasurementKindId::kPlane:
        cost = MakeRowCost(model_ptr, PlaneMeasurement{w}, data.joints(i), row.value, 4);
        b.push_back(planes.data() + 4 * row.feature);
        break;
      default:
        cost = MakeRowCost(model_ptr, PositionMeasurement{w}, data.joints(i),
                           Eigen::Vector3d(row.position), 0);
    }
    problem.AddResidualBlock(cost, nullptr, b);
  }
  if (p.scale_held) {
    std::vector<double*> b;
    for (int f = 0; f < frames; ++f) b.push_back(frame_block(f));
    problem.AddResidualBlock(new ScaleHoldCost(nominal, options.scale_sigma), nullptr, b);
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
  result.iterations = static_cast<int>(summary.iterations.size());
  result.initial_cost = summary.initial_cost;
  result.cost = summary.final_cost;
  result.errors = ContactErrors(result.model, result.features, data);
  result.scale = ScaleOf(result.model, nominal);
  result.ok = summary.IsSolutionUsable() && summary.termination_type == ceres::CONVERGENCE;
  result.message = result.ok ? "converged" : summary.message;
  return result;
}

}  // namespace lpoe
