// --joint_errors=auto: the joint-error terms chosen by k-fold cross-validation on the
// identification rows (docs/joint_errors.md, "Choosing the terms").
#include <algorithm>
#include <mutex>
#include <string>
#include <vector>

#include "calibration/block_kind.h"
#include "identifiability/cross_validation.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/parallel.h"
#include "lpoe/joint_error_list.h"
#include "lpoe/pipeline.h"

namespace lpoe {
namespace {

std::string Label(const std::vector<std::string>& terms) {
  if (terms.empty()) return "none";
  std::string s;
  for (const std::string& t : terms) s += (s.empty() ? "" : ",") + t;
  return s;
}

// One candidate's errors on one fold's held-out rows, calibrated on the fold's training rows; and
// which bilinear effects were identified and how many joint-space combinations were.
struct FoldOutcome {
  internal::FoldErrors errors;
  int parameters = 0;                 // identified joint-space combinations
  std::vector<std::string> bilinear;  // the bilinear effects identified (the gravity tilt)
};

FoldOutcome SolveFold(const RobotModel& nominal, const MeasurementSet& identification,
                      const std::vector<int>& fold, int fold_number,
                      const PipelineOptions& options, const std::string& label) {
  FoldOutcome out;
  const internal::FoldCalibration f =
      internal::CalibrateFold(nominal, identification, fold, fold_number, options,
                              "auto " + label + " fold " + std::to_string(fold_number));
  if (!f.ok) {
    out.errors.failure = f.failure;
    return out;
  }
  out.errors.ok = true;
  out.parameters = f.result.parameterization.num_joint_parameters();
  for (const std::string& name : options.joint_errors) {
    const internal::BilinearBlockKind* kind = internal::FindBilinearBlockKind(name);
    if (kind != nullptr && kind->Identified(f.result, nullptr)) out.bilinear.push_back(name);
  }
  for (const Eigen::Vector3d& v : ParametricResiduals(f.result, f.test)) {
    out.errors.squared.push_back(v.squaredNorm());
  }
  return out;
}

// The candidate from its folds' outcomes (in fold order): the first failing fold fails it.
JointErrorCandidate Combine(const std::vector<std::string>& terms,
                            const std::vector<FoldOutcome>& outcomes) {
  JointErrorCandidate c;
  c.terms = terms;
  c.label = Label(terms);
  std::vector<internal::FoldErrors> errors;
  for (const FoldOutcome& o : outcomes) {
    errors.push_back(o.errors);
    if (!o.errors.ok) break;
    c.parameters = std::max(c.parameters, o.parameters);
    for (const std::string& name : o.bilinear) ++c.identified_folds[name];
  }
  internal::ScoreFolds(errors, &c);
  return c;
}

// Every candidate on every fold: the (candidate, fold) calibrations are independent, so they run
// side by side on the hardware's threads (ForEachTask); each writes only its own outcome and the
// candidates are combined in order afterwards, so the selection does not depend on the threads.
// Progress callbacks are serialized.
std::vector<JointErrorCandidate> CrossValidateAll(
    const RobotModel& nominal, const MeasurementSet& identification,
    const std::vector<std::vector<int>>& folds, const PipelineOptions& base,
    const std::vector<std::vector<std::string>>& sets) {
  const int num_folds = static_cast<int>(folds.size());
  const int tasks = static_cast<int>(sets.size()) * num_folds;
  std::vector<FoldOutcome> outcomes(static_cast<size_t>(tasks));
  std::mutex progress;
  const PipelineOptions options = internal::SerializedProgress(base, &progress);
  ForEachTask(tasks, ThreadsFor(tasks), [&](int task, int /*thread*/) {
    const int k = task / num_folds, f = task % num_folds;
    PipelineOptions o = options;
    o.joint_errors = sets[k];
    if (f == 0 && o.on_stage) o.on_stage("cross-validating joint errors: " + Label(sets[k]));
    outcomes[task] = SolveFold(nominal, identification, folds[f], f + 1, o, Label(sets[k]));
  });
  std::vector<JointErrorCandidate> out;
  for (size_t k = 0; k < sets.size(); ++k) {
    out.push_back(Combine(sets[k], std::vector<FoldOutcome>(
                                       outcomes.begin() + static_cast<long>(k) * num_folds,
                                       outcomes.begin() + static_cast<long>(k + 1) * num_folds)));
  }
  return out;
}

}  // namespace

JointErrorSelection SelectJointErrors(const RobotModel& nominal,
                                      const MeasurementSet& identification,
                                      const PipelineOptions& options) {
  JointErrorSelection sel;
  const std::vector<std::vector<int>> folds =
      internal::FoldsByConfiguration(identification, options, &sel);
  // Every subset of the registry (JointTermNames(), 2^T sets for T terms), each in registry order
  // (compliance first: it keeps the combinations both terms could explain, joint_errors.md), listed
  // by the binary count of registry bits: none, compliance, harmonics, compliance,harmonics, then
  // the sets with the next term, and so on. With a bilinear effect (the gravity tilt), every set
  // that has its partner once more with it (2^(T-1) sets). Each candidate is one solve per fold.
  const std::vector<std::string> registry = JointTermNames();
  const size_t num_sets = size_t{1} << registry.size();
  std::vector<std::vector<std::string>> sets;
  for (size_t bits = 0; bits < num_sets; ++bits) {
    std::vector<std::string> set;
    for (size_t t = 0; t < registry.size(); ++t) {
      if (bits & (size_t{1} << t)) set.push_back(registry[t]);
    }
    sets.push_back(set);
  }
  // Each bilinear effect (the gravity tilt) joins the candidates that have its partner only when
  // these rows determine it: its check at the solution with every registry term and it, on all
  // identification rows (the fullest model, whose residuals estimate the noise best).
  const size_t num_term_sets = sets.size();
  for (const BilinearEffectName& effect : BilinearEffectNames()) {
    const internal::BilinearBlockKind* kind = internal::FindBilinearBlockKind(effect.name);
    if (options.on_stage) options.on_stage("checking the " + effect.description);
    PipelineOptions check = options;
    check.joint_errors = registry;
    check.joint_errors.push_back(effect.name);
    check.joint_errors_auto = false;
    const CalibrationResult r = SolveCalibration(nominal, identification, check,
                                                 "auto " + effect.description + " check", nullptr,
                                                 nullptr, nullptr);
    BilinearCandidacy candidacy;
    candidacy.name = effect.name;
    candidacy.candidates = kind->Identified(r, &candidacy.message);
    sel.bilinear.push_back(candidacy);
    if (!candidacy.candidates) continue;
    for (size_t k = 0; k < num_term_sets; ++k) {
      // The term sets holding the effect's partner.
      if (std::find(sets[k].begin(), sets[k].end(), effect.partner) == sets[k].end()) continue;
      std::vector<std::string> with = sets[k];
      with.push_back(effect.name);
      sets.push_back(with);
    }
  }
  sel.candidates = CrossValidateAll(nominal, identification, folds, options, sets);
  internal::ChooseJointErrors(&sel);
  return sel;
}

}  // namespace lpoe
