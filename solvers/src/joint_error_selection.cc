// --joint_errors=auto: the joint-error terms chosen by k-fold cross-validation on the
// identification rows (docs/joint_errors.md, "Choosing the terms").
#include <algorithm>
#include <cmath>
#include <sstream>
#include <string>
#include <vector>

#include "lpoe/joint_errors.h"
#include "lpoe/joint_term.h"
#include "lpoe/pipeline.h"

namespace lpoe {
namespace {

std::string Label(const std::vector<std::string>& terms) {
  if (terms.empty()) return "none";
  std::string s;
  for (const std::string& t : terms) s += (s.empty() ? "" : ",") + t;
  return s;
}

// The candidate's calibration on every fold's training rows and its errors on the held-out rows.
JointErrorCandidate CrossValidate(const RobotModel& nominal, const MeasurementSet& identification,
                                  const std::vector<std::vector<int>>& folds,
                                  const PipelineOptions& base,
                                  const std::vector<std::string>& terms) {
  JointErrorCandidate c;
  c.terms = terms;
  c.label = Label(terms);
  PipelineOptions options = base;
  options.joint_errors = terms;
  options.joint_errors_auto = false;
  std::vector<double> squared;  // per held-out point: |e|^2
  for (size_t f = 0; f < folds.size(); ++f) {
    const MeasurementSet train =
        identification.Subset(Complement(identification.size(), folds[f]));
    const MeasurementSet test = identification.Subset(folds[f]);
    const CalibrationResult r =
        SolveCalibration(nominal, train, options,
                         "auto " + c.label + " fold " + std::to_string(f + 1), nullptr, nullptr,
                         nullptr);
    if (!r.converged()) {
      c.failure = "fold " + std::to_string(f + 1) + ": " + TerminationName(r.termination) +
                  " (" + r.message + ")";
      return c;
    }
    c.parameters = std::max(c.parameters, r.parameterization.num_joint_parameters());
    if (r.gravity_tilt.identified) ++c.tilt_folds;
    RobotModel geometric = r.model;
    geometric.joint_errors = JointErrorTerms();
    const std::vector<Eigen::Vector3d> e =
        PositionErrors(geometric, WithEffectiveJointValues(r.joint_terms, test));
    double sum = 0;
    for (const Eigen::Vector3d& v : e) {
      squared.push_back(v.squaredNorm());
      sum += v.squaredNorm();
    }
    c.fold_rms.push_back(e.empty() ? 0.0 : std::sqrt(sum / e.size()));
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

JointErrorSelection SelectJointErrors(const RobotModel& nominal,
                                      const MeasurementSet& identification,
                                      const PipelineOptions& options) {
  JointErrorSelection sel;
  sel.ran = true;
  std::vector<int> configuration_of_row;
  const int configurations = ConfigurationGroups(identification, &configuration_of_row);
  sel.folds = std::max(2, std::min(options.joint_error_folds, configurations));
  sel.seed = options.split_seed;
  sel.split = options.split;
  const auto folds = KFolds(identification, sel.folds, sel.seed, sel.split);
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
        if (std::find(sets[k].begin(), sets[k].end(), "compliance") == sets[k].end()) continue;
        std::vector<std::string> with_tilt = sets[k];
        with_tilt.push_back(kGravityTiltName);
        sets.push_back(with_tilt);
      }
    }
  }
  for (const auto& terms : sets) {
    if (options.on_stage) options.on_stage("cross-validating joint errors: " + Label(terms));
    sel.candidates.push_back(CrossValidate(nominal, identification, folds, options, terms));
  }
  // Simplest first (fewest identified combinations; ties keep the listed order).
  std::stable_sort(sel.candidates.begin(), sel.candidates.end(),
                   [](const JointErrorCandidate& a, const JointErrorCandidate& b) {
                     return a.parameters < b.parameters;
                   });
  for (size_t k = 0; k < sel.candidates.size(); ++k) {
    const JointErrorCandidate& c = sel.candidates[k];
    if (c.ok && (sel.best < 0 || c.cv_mse < sel.candidates[sel.best].cv_mse)) {
      sel.best = static_cast<int>(k);
    }
  }
  std::ostringstream why;
  if (sel.best < 0) {
    // Nothing converged on every fold: the geometric model (the main run reports its failure).
    for (size_t k = 0; k < sel.candidates.size(); ++k) {
      if (sel.candidates[k].terms.empty()) sel.chosen = static_cast<int>(k);
    }
    why << "no candidate converged on every fold; geometry alone";
    sel.reason = why.str();
    return sel;
  }
  const JointErrorCandidate& best = sel.candidates[sel.best];
  const double limit = best.cv_mse + best.cv_mse_se;
  for (size_t k = 0; k < sel.candidates.size() && sel.chosen < 0; ++k) {
    if (sel.candidates[k].ok && sel.candidates[k].cv_mse <= limit) sel.chosen = static_cast<int>(k);
  }
  const JointErrorCandidate& chosen = sel.candidates[sel.chosen];
  why << "one-standard-error rule: lowest CV mean squared error " << best.cv_mse << " mm^2 ("
      << best.label << ", standard error " << best.cv_mse_se << " mm^2); " << chosen.label
      << " is the simplest candidate within " << limit << " mm^2";
  sel.reason = why.str();
  return sel;
}

}  // namespace lpoe
