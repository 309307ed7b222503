// The calibration workflow as one library call, shared by lpoe_calibrate and lpoe_compare (and any
// program that calibrates): register the model to the measurement frame, solve, analyse
// (identifiability, errors before/after, outliers), cross-validate, and judge plausibility. It
// writes nothing: the caller writes its outputs once the final status (termination and verdict) is
// known, so that a failed run leaves no output behind.
#ifndef LPOE_PIPELINE_H_
#define LPOE_PIPELINE_H_

#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "lpoe/analysis.h"
#include "lpoe/calibration.h"
#include "lpoe/ceres_solver.h"
#include "lpoe/linear_solver.h"
#include "lpoe/plausibility.h"
#include "lpoe/registration.h"
#include "lpoe/model/residual_layer.h"
#include "lpoe/model/statistics.h"

namespace lpoe {

enum class SolverKind { kLinear, kCeres };

// The learned residual layer after the parametric solve (lpoe/model/residual_layer.h,
// docs/residual_layer.md): none, a Gaussian process, or chosen by k-fold cross-validation.
enum class ResidualModelKind { kNone, kGp, kAuto };
bool ParseResidualModelKind(const std::string& text, ResidualModelKind* kind);  // none|gp|auto
const char* ResidualModelKindName(ResidualModelKind kind);

struct PipelineOptions {
  SolverKind solver = SolverKind::kLinear;
  // The solvers' options; their parameterization and use_orientation are set from the two fields
  // below, their on_iteration from `on_iteration`.
  LinearSolverOptions linear;
  CeresSolverOptions ceres;
  ParameterizationKind parameterization = ParameterizationKind::kIdentifiable;
  bool use_orientation = false;
  // The prior both solvers use (lpoe/model/prior.h, docs/identifiability.md "The prior"): by default the
  // nominal model's tolerances about the registered start model, which holds the directions the
  // data determine only weakly and moves nothing the data determine. Null: plain least squares.
  // With a null reference, the reference is the start model (registered, tool points fitted).
  // Identifiable parameterization only (the full one is the paper's pseudo-inverse).
  std::shared_ptr<const ParameterPrior> prior = std::make_shared<const ParameterPrior>();
  // Stages 1-2 of registration.h first (skipped when the data are in the base frame already).
  bool register_frames = true;
  // Joint-space error terms to identify with the geometry, by registry name (joint_term.h,
  // JointTermNames(): "compliance", "harmonics", ...), in registry order. Built on the registered
  // start model; the identified values are stored in the calibrated model's joint_errors (so its
  // YAML carries them) and in result.joint_terms. "tilt" (with "compliance" only) also identifies
  // the tilt of the model's gravity when the data determine it (docs/joint_errors.md, "Gravity
  // tilt"): the compliance solve first, the tilt's check at its solution (result.gravity_tilt.message when it fails),
  // then the solve with the tilt from there; the tilted gravity goes into the calibrated model.
  std::vector<std::string> joint_errors;
  // The tilt counts as identifiable when each angle's predicted standard deviation is at most this
  // (rad; 0.1 deg) and its columns keep joint_term_tolerance of their norm.
  double gravity_tilt_max_sigma = 0.1 * 3.14159265358979323846 / 180.0;
  // Instead of `joint_errors`: choose the terms by cross-validation (SelectJointErrors) among every
  // subset of the registry's terms, on `joint_error_folds` folds of the identification rows (seed
  // `split_seed`).
  bool joint_errors_auto = false;
  int joint_error_folds = 5;
  int kfold = 0;  // >= 2: k-fold cross-validation on the identification rows
  // The folds of `kfold` and of `joint_errors_auto`: seeded random, or contiguous blocks in row
  // order (analysis.h, SplitKind).
  uint64_t split_seed = 1;
  SplitKind split = SplitKind::kRandom;
  double outlier_threshold = 5.0;
  // After the parametric solve: a residual layer fitted on its identification residuals (gp), or
  // chosen between none and gp by the one-standard-error rule on joint_error_folds folds by
  // configuration (auto; SelectResidualModel). The layer is stored in result.model.residual_layer;
  // the verification (and k-fold) errors include a layer fitted on the training rows only.
  ResidualModelKind residual_model = ResidualModelKind::kNone;
  ResidualLayerOptions residual_layer;
  PlausibilityOptions plausibility;
  // With joint-space terms: also re-fit the geometry alone on the same data (PipelineResult::
  // geometry_only), the best model for outputs that carry geometry only (URDF, UR kinematics): the
  // geometry identified together with the terms is not the best geometry without them.
  bool refit_geometry = false;
  // Progress: the stage ("calibrating", "fold 2") and each iteration's record.
  std::function<void(const std::string& stage, const IterationRecord&)> on_iteration;
  // Progress: called when a stage without iterations starts ("registering", "analysing").
  std::function<void(const std::string& stage)> on_stage;
};

struct FoldSummary {
  int fold = 0;  // 1-based
  int identification_rows = 0;
  Termination termination = Termination::kNumericalFailure;
  ErrorStatistics verification_after;
};

// A candidate of a k-fold cross-validation by configuration (--joint_errors=auto,
// --residual_model=auto): its cross-validated held-out error.
struct CrossValidatedCandidate {
  std::string label;             // what is printed for it ("none", "compliance", "gp", ...)
  bool ok = false;               // every fold's calibration (and layer fit) succeeded
  std::string failure;           // why not (first failing fold)
  double cv_rms = 0;             // pooled held-out RMS of the error norm, mm
  double cv_mse = 0;             // its square (mean squared error norm), mm^2
  double cv_mse_se = 0;          // standard error of cv_mse over the held-out points, mm^2
  std::vector<double> fold_rms;  // held-out RMS per fold, mm (up to the first failing fold)
};

// --joint_errors=auto: one candidate set of terms and its cross-validated held-out error; label
// "none", "compliance", "harmonics", "compliance,tilt", ...
struct JointErrorCandidate : CrossValidatedCandidate {
  // Registry names, then bilinear effects (lpoe/joint_error_list.h); empty: the geometry alone.
  std::vector<std::string> terms;
  int parameters = 0;              // identified joint-error combinations (largest over the folds)
  // Per bilinear effect among the terms (the gravity tilt): the folds whose calibration identified
  // it (the others kept it out, as a calibration with these terms does when its check fails).
  std::map<std::string, int> identified_folds;
  int IdentifiedFolds(const std::string& effect) const {
    const auto it = identified_folds.find(effect);
    return it == identified_folds.end() ? 0 : it->second;
  }
};

// --joint_errors=auto and one bilinear effect (lpoe/joint_error_list.h; the gravity tilt): it joins
// the candidates that have its partner ("compliance,tilt", "compliance,harmonics,tilt", ...) only
// when the identification rows determine it (its check at the solution with every registry term
// and it); else why not.
struct BilinearCandidacy {
  std::string name;         // "tilt"
  bool candidates = false;  // joined the candidates
  std::string message;      // why not
};

// How an automatic choice cross-validated (its folds) and what it chose: indices into its
// selection's candidates.
struct CrossValidationChoice {
  bool ran = false;
  int folds = 0;
  uint64_t seed = 0;
  SplitKind split = SplitKind::kRandom;
  int best = -1;    // lowest cv_mse
  int chosen = -1;  // the simplest within one standard error of the best
  std::string reason;
};

struct JointErrorSelection : CrossValidationChoice {
  std::vector<JointErrorCandidate> candidates;  // in order of increasing parameters
  // Each bilinear effect's candidacy, in the registry's order.
  std::vector<BilinearCandidacy> bilinear;
  // The entry of effect `name`; an empty one (not a candidate, no message) when there is none.
  BilinearCandidacy Bilinear(const std::string& name) const {
    for (const BilinearCandidacy& b : bilinear) {
      if (b.name == name) return b;
    }
    return BilinearCandidacy{name, false, ""};
  }
};

// Cross-validates each candidate set of terms on options.joint_error_folds seeded folds of
// `identification` with the pipeline's solver and registration, and chooses by the
// one-standard-error rule: the candidate with the fewest identified joint-error combinations whose
// pooled held-out mean squared error is at most the lowest one plus that lowest estimate's standard
// error (docs/joint_errors.md). The candidates: every subset of the registry (2^T sets for T terms,
// 8 with today's three), and each subset with compliance again with the gravity tilt when the tilt
// is identifiable (2^(T-1) more). Cost: one solve with every term and the tilt (the tilt's check),
// then one per candidate and fold: 1 + 8 k solves, 1 + 12 k with the tilt, for
// k = options.joint_error_folds (k = 5: 41 or 61).
JointErrorSelection SelectJointErrors(const RobotModel& nominal,
                                      const MeasurementSet& identification,
                                      const PipelineOptions& options);

// --residual_model=auto: one candidate, label "none" or "gp", and its cross-validated held-out
// error.
struct ResidualModelCandidate : CrossValidatedCandidate {};

struct ResidualModelSelection : CrossValidationChoice {
  std::vector<ResidualModelCandidate> candidates;  // none, gp
};

// Cross-validates the parametric model alone ("none") against it plus a layer fitted on each
// fold's training residuals ("gp"), on options.joint_error_folds folds by configuration (seed
// options.split_seed, options.split), with the calibration `options` asks for (joint errors as
// given: run after the joint-error choice); one-standard-error rule, none being the simpler.
// Cost: one calibration and one layer fit per fold.
ResidualModelSelection SelectResidualModel(const RobotModel& nominal,
                                           const MeasurementSet& identification,
                                           const PipelineOptions& options);

// The layer of a run (options.residual_model gp, or auto choosing gp).
struct ResidualLayerSummary {
  bool requested = false;  // gp, or auto (whatever it chose)
  bool fitted = false;     // result.model carries a layer
  std::string message;     // why not, when requested and not fitted
  ResidualLayerFit fit;
  int inducing = 0;
  ErrorStatistics identification_with_layer;  // the calibrated model with its layer
  ErrorStatistics verification_parametric;    // verification errors without the layer
};

// The residuals (measured - predicted, mm) of a calibration result's model with its joint terms
// (no layer) on `data`.
std::vector<Eigen::Vector3d> ParametricResiduals(const CalibrationResult& result,
                                                 const MeasurementSet& data);
// Fits a layer on those residuals at data's joint values and tools.
Status FitResidualLayerOn(const CalibrationResult& result, const MeasurementSet& data,
                          const ResidualLayerOptions& options, ResidualLayer* layer,
                          ResidualLayerFit* fit);

struct PipelineResult {
  bool registered = false;  // registration was run (options.register_frames)
  RegistrationReport registration;
  // The nominal model in the measurement frame (rigid fit folded into the base when registration
  // moved it): "before calibration".
  RobotModel before;
  RobotModel start;  // what the solver started from
  CalibrationResult result;
  // result.model without its joint_errors (the geometry alone). Errors after calibration are those
  // of `geometric` on the effective joint values of result.joint_terms (the solvers' cost).
  RobotModel geometric;
  // The following are filled unless result.termination is kNotIdentifiable.
  IdentifiabilityReport identifiability;
  ErrorStatistics identification_before, identification_after;
  bool has_verification = false;
  ErrorStatistics verification_before, verification_after;
  double robust_sigma = 0;
  std::vector<Outlier> outliers;
  std::vector<FoldSummary> folds;
  ErrorStatistics folds_pooled;
  Verdict verdict;  // of a converged result
  JointErrorSelection joint_error_selection;  // options.joint_errors_auto
  ResidualModelSelection residual_model_selection;  // options.residual_model auto
  ResidualLayerSummary residual_layer;
  // options.refit_geometry with joint-space terms in the result: the geometry-only calibration of
  // the same data and its errors (verification ones when has_verification).
  bool has_geometry_only = false;
  CalibrationResult geometry_only;
  ErrorStatistics geometry_only_identification, geometry_only_verification;
};

// Registration then the chosen solver on `data` (no analysis). `registration` and `before` may be
// null. A registration that fails returns kNotIdentifiable with its message.
CalibrationResult SolveCalibration(const RobotModel& nominal, const MeasurementSet& data,
                                   const PipelineOptions& options, const std::string& stage,
                                   RegistrationReport* registration, RobotModel* before,
                                   RobotModel* start);

// The whole workflow. `verification` may be empty. Cross-validation and the verdict run only when
// the main calibration converged.
PipelineResult RunCalibrationPipeline(const RobotModel& nominal,
                                      const MeasurementSet& identification,
                                      const MeasurementSet& verification,
                                      const PipelineOptions& options);

}  // namespace lpoe

#endif  // LPOE_PIPELINE_H_
