// The residual layer of a contact calibration (lpoe/contact_pipeline.h, FitContactResidualLayer;
// docs/residual_layer.md, "Projected observations").
#include <algorithm>
#include <cmath>
#include <vector>

#include "contact/contact_kinds.h"
#include "lpoe/contact_pipeline.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/kinematics/kinematics.h"

namespace lpoe {

Status FitContactResidualLayer(const ContactCalibrationResult& result,
                               const ContactMeasurementSet& data,
                               const ResidualLayerOptions& options, ResidualLayer* layer,
                               ResidualLayerFit* fit) {
  const RobotModel& model = result.model;
  const int n = model.num_joints();
  if (data.num_joints != n) {
    return Status::Error("the residual layer's rows have a different number of joints");
  }
  // The rows' noise relative to the median: a row's direction and value are both scaled by
  // median / sigma, so that every observation has the same noise (u . m scales with u).
  std::vector<double> sigmas;
  for (const ContactRow& row : data.rows) sigmas.push_back(row.sigma);
  if (sigmas.empty()) return Status::Error("the residual layer needs at least 3 rows");
  std::nth_element(sigmas.begin(), sigmas.begin() + sigmas.size() / 2, sigmas.end());
  const double reference = sigmas[sigmas.size() / 2];
  std::vector<double> q, values;
  std::vector<int> tools;
  std::vector<Eigen::Vector3d> directions;
  std::vector<double> q_eff(n);
  for (int i = 0; i < data.size(); ++i) {
    const ContactRow& row = data.rows[i];
    const double* qc = data.joints(i);
    const double* qp = qc;
    if (!model.joint_errors.empty()) {
      EffectiveJoints(model, qc, q_eff.data());
      qp = q_eff.data();
    }
    const Eigen::Vector3d P = ToolPosition(model, qp, row.target);
    const double w = row.sigma > 0 && reference > 0 ? reference / row.sigma : 1.0;
    auto add = [&](const Eigen::Vector3d& u, double y) {
      q.insert(q.end(), qc, qc + n);
      tools.push_back(row.target);
      directions.push_back(w * u);
      values.push_back(w * y);
    };
    // Through the kind table (contact_kinds.h): a feature's kind is seen along its Projection,
    // a tracker row along each axis.
    const bool projected = internal::VisitContactRowKind(row.kind, [&](auto tag) {
      using Kind = typename decltype(tag)::type;
      if constexpr (Kind::kFeatureSize > 0) {
        Eigen::Vector3d u;
        double error = 0;
        if (!Kind::Projection(P, internal::ContactFeatureData<Kind>(result.features, row.feature),
                              row.value, &u, &error)) {
          return false;
        }
        add(u, -error);
      } else {
        for (int c = 0; c < 3; ++c) add(Eigen::Vector3d::Unit(c), row.position(c) - P(c));
      }
      return true;
    });
    if (!projected) return Status::Error(data.Where(i) + ": the ball is at its pivot");
  }
  return FitResidualLayerProjected(q, tools, directions, values, n, model.num_tools(), options,
                                   layer, fit);
}

}  // namespace lpoe
