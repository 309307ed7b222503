// k-fold cross-validation by configuration, shared by --joint_errors=auto and
// --residual_model=auto (cross_validation.h).
#include "identifiability/cross_validation.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include "lpoe/calibration.h"

namespace lpoe {
namespace internal {

std::vector<std::vector<int>> FoldsByConfiguration(const MeasurementSet& identification,
                                                   const PipelineOptions& options,
                                                   CrossValidationChoice* choice) {
  std::vector<int> configuration_of_row;
  const int configurations = ConfigurationGroups(identification, &configuration_of_row);
  choice->ran = true;
  choice->folds = std::max(2, std::min(options.joint_error_folds, configurations));
  choice->seed = options.split_seed;
  choice->split = options.split;
  return KFolds(identification, choice->folds, choice->seed, choice->split);
}

PipelineOptions SerializedProgress(const PipelineOptions& options, std::mutex* mutex) {
  PipelineOptions out = options;
  out.joint_errors_auto = false;
  if (options.on_iteration) {
    out.on_iteration = [mutex, &options](const std::string& stage, const IterationRecord& r) {
      std::lock_guard<std::mutex> lock(*mutex);
      options.on_iteration(stage, r);
    };
  }
  if (options.on_stage) {
    out.on_stage = [mutex, &options](const std::string& stage) {
      std::lock_guard<std::mutex> lock(*mutex);
      options.on_stage(stage);
    };
  }
  return out;
}

FoldCalibration CalibrateFold(const RobotModel& nominal, const MeasurementSet& identification,
                              const std::vector<int>& fold, int fold_number,
                              const PipelineOptions& options, const std::string& stage) {
  FoldCalibration out(identification.Subset(Complement(identification.size(), fold)),
                      identification.Subset(fold));
  out.result = SolveCalibration(nominal, out.train, options, stage, nullptr, nullptr, nullptr);
  out.ok = out.result.converged();
  if (!out.ok) {
    out.failure = "fold " + std::to_string(fold_number) + ": " +
                  TerminationName(out.result.termination) + " (" + out.result.message + ")";
  }
  return out;
}

void ScoreFolds(const std::vector<FoldErrors>& folds, CrossValidatedCandidate* c) {
  std::vector<double> squared;
  for (const FoldErrors& o : folds) {
    if (!o.ok) {
      c->failure = o.failure;
      return;
    }
    double sum = 0;
    for (double s : o.squared) sum += s;
    c->fold_rms.push_back(o.squared.empty() ? 0.0 : std::sqrt(sum / o.squared.size()));
    squared.insert(squared.end(), o.squared.begin(), o.squared.end());
  }
  const double n = static_cast<double>(squared.size());
  if (n < 2) {
    c->failure = "fewer than 2 held-out points";
    return;
  }
  double mean = 0;
  for (double s : squared) mean += s;
  mean /= n;
  double var = 0;
  for (double s : squared) var += (s - mean) * (s - mean);
  var /= n - 1;
  c->ok = std::isfinite(mean);
  c->cv_mse = mean;
  c->cv_rms = std::sqrt(mean);
  c->cv_mse_se = std::sqrt(var / n);
}

bool ChooseWithinOneStandardError(const std::vector<const CrossValidatedCandidate*>& candidates,
                                  CrossValidationChoice* choice) {
  int* best = &choice->best;
  int* chosen = &choice->chosen;
  *best = -1;
  for (size_t k = 0; k < candidates.size(); ++k) {
    const CrossValidatedCandidate& c = *candidates[k];
    if (c.ok && (*best < 0 || c.cv_mse < candidates[*best]->cv_mse)) *best = static_cast<int>(k);
  }
  if (*best < 0) return false;
  const CrossValidatedCandidate& b = *candidates[*best];
  const double limit = b.cv_mse + b.cv_mse_se;
  *chosen = -1;
  for (size_t k = 0; k < candidates.size() && *chosen < 0; ++k) {
    if (candidates[k]->ok && candidates[k]->cv_mse <= limit) *chosen = static_cast<int>(k);
  }
  const CrossValidatedCandidate& c = *candidates[*chosen];
  std::ostringstream why;
  why << "one-standard-error rule: lowest CV mean squared error " << b.cv_mse << " mm^2 ("
      << b.label << ", standard error " << b.cv_mse_se << " mm^2); " << c.label
      << " is the simplest candidate within " << limit << " mm^2";
  choice->reason = why.str();
  return true;
}

void ChooseJointErrors(JointErrorSelection* selection) {
  std::stable_sort(selection->candidates.begin(), selection->candidates.end(),
                   [](const JointErrorCandidate& a, const JointErrorCandidate& b) {
                     return a.parameters < b.parameters;
                   });
  if (!ChooseWithinOneStandardError(selection)) {
    // Nothing converged on every fold: the geometric model (the main run reports its failure).
    for (size_t k = 0; k < selection->candidates.size(); ++k) {
      if (selection->candidates[k].terms.empty()) selection->chosen = static_cast<int>(k);
    }
    selection->reason = "no candidate converged on every fold; geometry alone";
  }
}

void ChooseResidualModel(const std::vector<FoldErrors> outcomes[2],
                         ResidualModelSelection* selection) {
  const char* const labels[2] = {"none", "gp"};
  for (int which = 0; which < 2; ++which) {
    ResidualModelCandidate c;
    c.label = labels[which];
    ScoreFolds(outcomes[which], &c);
    selection->candidates.push_back(c);
  }
  if (!ChooseWithinOneStandardError(selection)) {
    selection->chosen = 0;
    selection->reason =
        "cross-validation failed (" + selection->candidates[0].failure + "); no layer";
  }
}

}  // namespace internal
}  // namespace lpoe
