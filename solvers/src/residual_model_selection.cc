// --residual_model: the learned residual layer after the parametric solve, and auto's choice
// between none and gp by k-fold cross-validation by configuration (docs/residual_layer.md).
#include <algorithm>
#include <cmath>
#include <mutex>
#include <sstream>
#include <string>
#include <vector>

#include "lpoe/parallel.h"
#include "lpoe/pipeline.h"
#include "lpoe/residual_layer.h"
#include "lpoe/statistics.h"

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

namespace {

struct FoldOutcome {
  bool ok = false;
  std::string failure;
  std::vector<double> squared[2];  // none, gp: |e|^2 per held-out point
};

ResidualModelCandidate Combine(const std::string& label, int which,
                               const std::vector<FoldOutcome>& outcomes) {
  ResidualModelCandidate c;
  c.label = label;
  std::vector<double> squared;
  for (const FoldOutcome& o : outcomes) {
    if (!o.ok) {
      c.failure = o.failure;
      return c;
    }
    double sum = 0;
    for (double s : o.squared[which]) sum += s;
    c.fold_rms.push_back(o.squared[which].empty() ? 0.0
                                                  : std::sqrt(sum / o.squared[which].size()));
    squared.insert(squared.end(), o.squared[which].begin(), o.squared[which].end());
  }
  const double n = static_cast<double>(squared.size());
  if (n < 2) {
    c.failure = "fewer than 2 held-out points";
    return c;
  }
  double mean = 0;
  for (double s : squared) mean += s;
  mean /= n;
  double var = 0;
  for (double s : squared) var += (s - mean) * (s - mean);
  var /= n - 1;
  c.ok = std::isfinite(mean);
  c.cv_mse = mean;
  c.cv_rms = std::sqrt(mean);
  c.cv_mse_se = std::sqrt(var / n);
  return c;
}

}  // namespace

ResidualModelSelection SelectResidualModel(const RobotModel& nominal,
                                           const MeasurementSet& identification,
                                           const PipelineOptions& options) {
  ResidualModelSelection sel;
  sel.ran = true;
  std::vector<int> configuration_of_row;
  const int configurations = ConfigurationGroups(identification, &configuration_of_row);
  sel.folds = std::max(2, std::min(options.joint_error_folds, configurations));
  sel.seed = options.split_seed;
  sel.split = options.split;
  const auto folds = KFolds(identification, sel.folds, sel.seed, sel.split);
  PipelineOptions base = options;
  base.joint_errors_auto = false;
  base.residual_model = ResidualModelKind::kNone;
  std::mutex progress;
  if (options.on_iteration) {
    base.on_iteration = [&progress, &options](const std::string& stage, const IterationRecord& r) {
      std::lock_guard<std::mutex> lock(progress);
      options.on_iteration(stage, r);
    };
  }
  if (options.on_stage) {
    base.on_stage = [&progress, &options](const std::string& stage) {
      std::lock_guard<std::mutex> lock(progress);
      options.on_stage(stage);
    };
    options.on_stage("cross-validating the residual layer");
  }
  std::vector<FoldOutcome> outcomes(sel.folds);
  // One task per fold (the calibration and the layer fit of a fold are independent of the others);
  // each writes only its outcome, combined in fold order.
  ForEachTask(sel.folds, ThreadsFor(sel.folds), [&](int f, int /*thread*/) {
    FoldOutcome& o = outcomes[f];
    const MeasurementSet train = identification.Subset(Complement(identification.size(), folds[f]));
    const MeasurementSet test = identification.Subset(folds[f]);
    const CalibrationResult r =
        SolveCalibration(nominal, train, base, "auto residual fold " + std::to_string(f + 1),
                         nullptr, nullptr, nullptr);
    if (!r.converged()) {
      o.failure = "fold " + std::to_string(f + 1) + ": " + TerminationName(r.termination) + " (" +
                  r.message + ")";
      return;
    }
    ResidualLayer layer;
    if (Status s = FitResidualLayerOn(r, train, options.residual_layer, &layer, nullptr); !s.ok()) {
      o.failure = "fold " + std::to_string(f + 1) + ": " + s.message();
      return;
    }
    const std::vector<Eigen::Vector3d> e = ParametricResiduals(r, test);
    for (int row = 0; row < test.size(); ++row) {
      o.squared[0].push_back(e[row].squaredNorm());
      o.squared[1].push_back(
          (e[row] - layer.Mean(test.q(row), test.target(row))).squaredNorm());
    }
    o.ok = true;
  });
  sel.candidates.push_back(Combine("none", 0, outcomes));
  sel.candidates.push_back(Combine("gp", 1, outcomes));
  for (size_t k = 0; k < sel.candidates.size(); ++k) {
    const ResidualModelCandidate& c = sel.candidates[k];
    if (c.ok && (sel.best < 0 || c.cv_mse < sel.candidates[sel.best].cv_mse)) {
      sel.best = static_cast<int>(k);
    }
  }
  std::ostringstream why;
  if (sel.best < 0) {
    sel.chosen = 0;
    why << "cross-validation failed (" << sel.candidates[0].failure << "); no layer";
    sel.reason = why.str();
    return sel;
  }
  const ResidualModelCandidate& best = sel.candidates[sel.best];
  const double limit = best.cv_mse + best.cv_mse_se;
  for (size_t k = 0; k < sel.candidates.size() && sel.chosen < 0; ++k) {
    if (sel.candidates[k].ok && sel.candidates[k].cv_mse <= limit) sel.chosen = static_cast<int>(k);
  }
  const ResidualModelCandidate& chosen = sel.candidates[sel.chosen];
  why << "one-standard-error rule: lowest CV mean squared error " << best.cv_mse << " mm^2 ("
      << best.label << ", standard error " << best.cv_mse_se << " mm^2); " << chosen.label
      << " is the simplest candidate within " << limit << " mm^2";
  sel.reason = why.str();
  return sel;
}

}  // namespace lpoe
