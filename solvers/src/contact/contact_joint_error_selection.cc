// --joint_errors=auto with ballbar distances and probe contacts (lpoe/contact_pipeline.h): the
// tracker's choice (docs/joint_errors.md, "Choosing the terms": every subset of the registry,
// k-fold cross-validation, the one-standard-error rule; solvers/src/identifiability/
// cross_validation.h) on the contact rows, each fold calibrated by the contact solver with its own
// pivots and planes.
#include <algorithm>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "identifiability/cross_validation.h"
#include "lpoe/joint_error_list.h"
#include "lpoe/contact_pipeline.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/parallel.h"

namespace lpoe {
namespace {

std::string ContactTermsLabel(const std::vector<std::string>& terms) {
  if (terms.empty()) return "none";
  std::string s;
  for (const std::string& t : terms) s += (s.empty() ? "" : ",") + t;
  return s;
}

struct ContactFoldOutcome {
  internal::FoldErrors errors;
  int parameters = 0;  // identified joint-space combinations
};

// The rows shuffled with `seed` and dealt into k folds (as RunContactPipeline's --kfold deals
// them), each fold's rows ascending.
std::vector<std::vector<int>> ContactFolds(int rows, int k, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::vector<int> order(rows);
  for (int i = 0; i < rows; ++i) order[i] = i;
  std::shuffle(order.begin(), order.end(), rng);
  std::vector<std::vector<int>> folds(k);
  for (int i = 0; i < rows; ++i) folds[i % k].push_back(order[i]);
  for (std::vector<int>& f : folds) std::sort(f.begin(), f.end());
  return folds;
}

}  // namespace

JointErrorSelection SelectContactJointErrors(const RobotModel& start,
                                             const ContactMeasurementSet& identification,
                                             const ContactPipelineOptions& options) {
  JointErrorSelection sel;
  sel.ran = true;
  sel.folds = std::max(2, std::min(options.kfold > 0 ? options.kfold : kContactAutoFolds,
                                   identification.size()));
  sel.seed = options.split_seed + 1;
  sel.split = SplitKind::kRandom;
  for (const BilinearEffectName& effect : BilinearEffectNames()) {
    sel.bilinear.push_back({effect.name, false,
                            "the " + effect.description +
                                " is not a candidate with distance or plane data: " +
                                ContactRefusalReason("joint_errors_tilt")});
  }
  const std::vector<std::vector<int>> folds = ContactFolds(identification.size(), sel.folds, sel.seed);
  // Every subset of the registry, in registry order, listed by the binary count of its bits (as
  // SelectJointErrors lists them).
  const std::vector<std::string> registry = JointTermNames();
  std::vector<std::vector<std::string>> sets;
  for (size_t bits = 0; bits < (size_t{1} << registry.size()); ++bits) {
    std::vector<std::string> set;
    for (size_t t = 0; t < registry.size(); ++t) {
      if (bits & (size_t{1} << t)) set.push_back(registry[t]);
    }
    sets.push_back(set);
  }
  // Each (candidate, fold) calibration is independent: side by side on the machine's threads,
  // each writing its own outcome, combined in order afterwards (the choice does not depend on the
  // threads).
  const int num_folds = static_cast<int>(folds.size());
  const int tasks = static_cast<int>(sets.size()) * num_folds;
  std::vector<ContactFoldOutcome> outcomes(static_cast<size_t>(tasks));
  ForEachTask(tasks, ThreadsFor(tasks), [&](int task, int /*thread*/) {
    const int k = task / num_folds, f = task % num_folds;
    ContactFoldOutcome& out = outcomes[task];
    ContactCalibrationOptions o = options.calibration;
    if (Status s = ContactJointTerms(ContactTermsLabel(sets[k]), start, &o.joint_terms); !s.ok()) {
      out.errors.failure = s.message();
      return;
    }
    std::vector<int> train;
    for (int g = 0; g < num_folds; ++g) {
      if (g != f) train.insert(train.end(), folds[g].begin(), folds[g].end());
    }
    std::sort(train.begin(), train.end());
    const ContactCalibrationResult r =
        options.solver == "ceres"
            ? CalibrateContactsCeres(start, identification.Subset(train), o)
            : CalibrateContactsLinear(start, identification.Subset(train), o);
    if (!r.ok) {
      out.errors.failure = "fold " + std::to_string(f + 1) + ": " + r.message;
      return;
    }
    out.errors.ok = true;
    out.parameters = r.parameterization.frames.num_joint_parameters();
    for (double e : ContactErrors(r.model, r.features, identification.Subset(folds[f]))) {
      out.errors.squared.push_back(e * e);
    }
  });
  for (size_t k = 0; k < sets.size(); ++k) {
    JointErrorCandidate c;
    c.terms = sets[k];
    c.label = ContactTermsLabel(sets[k]);
    std::vector<internal::FoldErrors> errors;
    for (int f = 0; f < num_folds; ++f) {
      const ContactFoldOutcome& o = outcomes[k * num_folds + f];
      errors.push_back(o.errors);
      if (!o.errors.ok) break;
      c.parameters = std::max(c.parameters, o.parameters);
    }
    internal::ScoreFolds(errors, &c);
    sel.candidates.push_back(c);
  }
  internal::ChooseJointErrors(&sel);
  return sel;
}

}  // namespace lpoe
