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
// whether the gravity tilt was identified and how many joint-space combinations were.
struct FoldOutcome {
  internal::FoldErrors errors;
  int parameters = 0;  // identified joint-space combinations
  bool tilt = false;   // the gravity tilt was identified
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
  out.tilt = f.result.gravity_tilt.identified;
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
    if (o.tilt) ++c.tilt_folds;
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
  // the sets with the next term, and so on. With the gravity tilt, every set that has compliance
  // once more with the tilt (2^(T-1) sets). Each candidate is one solve per fold.
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
  {
    // The gravity tilt joins the compliance candidates only when these rows determine it (its
    // check at the solution with every registry term of all identification rows: the fullest
    // model, whose residuals estimate the noise best).
    if (options.on_stage) options.on_stage("checking the gravity tilt");
    PipelineOptions check = options;
    check.joint_errors = registry;
    check.joint_errors.push_back(kGravityTiltName);
    check.joint_errors_auto = false;
    const CalibrationResult r = SolveCalibration(nominal, identification, check,
                                                 "auto gravity tilt check", nullptr, nullptr,
                                                 nullptr);
    sel.tilt_candidates = r.gravity_tilt.identified;
    sel.tilt_message = r.gravity_tilt.identified ? std::string()
                       : !r.gravity_tilt.message.empty()
                           ? r.gravity_tilt.message
                           : "gravity tilt not identifiable from these data; kept at the model's "
                             "gravity (the compliance calibration did not converge: " +
                                 r.message + ")";
    if (sel.tilt_candidates) {
      for (size_t k = 0; k < num_sets; ++k) {
        // The sets holding the term the tilt's block kind is bilinear with (block_kind.h).
        const std::string partner = internal::FindBlockKind(kGravityTiltName)->partner_term();
        if (std::find(sets[k].begin(), sets[k].end(), partner) == sets[k].end()) continue;
        std::vector<std::string> with_tilt = sets[k];
        with_tilt.push_back(kGravityTiltName);
        sets.push_back(with_tilt);
      }
    }
  }
  sel.candidates = CrossValidateAll(nominal, identification, folds, options, sets);
  internal::ChooseJointErrors(&sel);
  return sel;
}

}  // namespace lpoe
