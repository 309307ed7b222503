// --residual_model: the learned residual layer after the parametric solve, and auto's choice
// between none and gp by k-fold cross-validation by configuration (docs/residual_layer.md).
#include <algorithm>
#include <cmath>
#include <mutex>
#include <string>
#include <vector>

#include "identifiability/cross_validation.h"
#include "lpoe/parallel.h"
#include "lpoe/pipeline.h"
#include "lpoe/model/residual_layer.h"
#include "lpoe/model/statistics.h"

namespace lpoe {

bool ParseResidualModelKind(const std::string& text, ResidualModelKind* kind) {
  if (text == "none") {
    *kind = ResidualModelKind::kNone;
  } else if (text == "gp") {
    *kind = ResidualModelKind::kGp;
  } else if (text == "auto") {
    *kind = ResidualModelKind::kAuto;
  } else {
    return false;
  }
  return true;
}

const char* ResidualModelKindName(ResidualModelKind kind) {
  switch (kind) {
    case ResidualModelKind::kNone:
      return "none";
    case ResidualModelKind::kGp:
      return "gp";
    case ResidualModelKind::kAuto:
      return "auto";
  }
  return "none";
}

std::vector<Eigen::Vector3d> ParametricResiduals(const CalibrationResult& result,
                                                 const MeasurementSet& data) {
  RobotModel geometric = result.model;
  geometric.joint_errors = JointErrorTerms();
  geometric.residual_layer = nullptr;
  return PositionErrors(geometric, WithEffectiveJointValues(result.joint_terms, data));
}

Status FitResidualLayerOn(const CalibrationResult& result, const MeasurementSet& data,
                          const ResidualLayerOptions& options, ResidualLayer* layer,
                          ResidualLayerFit* fit) {
  const std::vector<Eigen::Vector3d> e = ParametricResiduals(result, data);
  const int n = data.num_joints();
  std::vector<double> q(static_cast<size_t>(data.size()) * n);
  std::vector<int> tools(data.size());
  for (int r = 0; r < data.size(); ++r) {
    std::copy(data.q(r), data.q(r) + n, q.begin() + static_cast<long>(r) * n);
    tools[r] = data.target(r);
  }
  return FitResidualLayer(q, tools, e, n, result.model.num_tools(), options, layer, fit);
}

ResidualModelSelection SelectResidualModel(const RobotModel& nominal,
                                           const MeasurementSet& identification,
                                           const PipelineOptions& options) {
  ResidualModelSelection sel;
  const std::vector<std::vector<int>> folds =
      internal::FoldsByConfiguration(identification, options, &sel);
  std::mutex progress;
  PipelineOptions base = internal::SerializedProgress(options, &progress);
  base.residual_model = ResidualModelKind::kNone;
  if (options.on_stage) options.on_stage("cross-validating the residual layer");
  // Per fold, the held-out errors without (none) and with (gp) the layer fitted on its training
  // residuals.
  std::vector<internal::FoldErrors> outcomes[2];
  outcomes[0].resize(sel.folds);
  outcomes[1].resize(sel.folds);
  // One task per fold (the calibration and the layer fit of a fold are independent of the others);
  // each writes only its outcome, combined in fold order.
  ForEachTask(sel.folds, ThreadsFor(sel.folds), [&](int f, int /*thread*/) {
    internal::FoldErrors& none = outcomes[0][f];
    internal::FoldErrors& gp = outcomes[1][f];
    const internal::FoldCalibration c = internal::CalibrateFold(
        nominal, identification, folds[f], f + 1, base,
        "auto residual fold " + std::to_string(f + 1));
    if (!c.ok) {
      none.failure = gp.failure = c.failure;
      return;
    }
    ResidualLayer layer;
    if (Status s = FitResidualLayerOn(c.result, c.train, options.residual_layer, &layer, nullptr);
        !s.ok()) {
      none.failure = gp.failure = "fold " + std::to_string(f + 1) + ": " + s.message();
      return;
    }
    const std::vector<Eigen::Vector3d> e = ParametricResiduals(c.result, c.test);
    for (int row = 0; row < c.test.size(); ++row) {
      none.squared.push_back(e[row].squaredNorm());
      gp.squared.push_back((e[row] - layer.Mean(c.test.q(row), c.test.target(row))).squaredNorm());
    }
    none.ok = gp.ok = true;
  });
  internal::ChooseResidualModel(outcomes, &sel);
  return sel;
}

}  // namespace lpoe
