// The calibration run for ballbar distances and probe contacts (docs/measurements.md), as
// lpoe_calibrate, lpoe_compare and Python's lpoe.calibrate all run it: the hold-out split (or the
// rows of a verification set), the calibration by the chosen solver, the held-out errors, the
// k-fold cross-validation, and the figures per kind and per pivot / plane that the reports print.
// The callers read their inputs and write their outputs; the figures are computed once, here.
#ifndef LPOE_CONTACT_PIPELINE_H_
#define LPOE_CONTACT_PIPELINE_H_

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "lpoe/contact_calibration.h"
#include "lpoe/measurements/contact_measurements.h"
#include "lpoe/measurements/measurement_kinds.h"
#include "lpoe/measurements/measurements.h"
#include "lpoe/pipeline.h"
#include "lpoe/model/residual_layer.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/status.h"

namespace lpoe {

// Error figures of one kind's rows (or one feature's rows).
struct ContactKindFigures {
  int rows = 0;
  double rms = 0;      // mm (position rows: per axis)
  double max_abs = 0;  // mm (position rows: |e|)
  double sigma = 0;    // median of the rows' noise (mm)
};

// The figures of the rows of `kind` (and, when feature >= 0, of that pivot / plane only);
// `errors` as ContactErrors gives them, one per row of `data`.
ContactKindFigures ContactFigures(const ContactMeasurementSet& data,
                                  const std::vector<double>& errors, MeasurementKindId kind,
                                  int feature = -1);
// pass: RMS within twice the expected noise; check: within five times; fail beyond; none: no rows.
const char* ContactKindVerdict(const ContactKindFigures& f);

// One pivot's (distance) or plane's (plane) figures.
struct ContactFeatureSummary {
  std::string name;
  ContactKindFigures fit, held, kfold;  // held.rows, kfold.rows 0 when not computed
};

struct ContactKindSummary {
  const MeasurementKindInfo* kind = nullptr;
  ContactKindFigures fit;    // on the identification rows
  ContactKindFigures held;   // on the held-out or verification rows (rows 0 when none)
  ContactKindFigures kfold;  // cross-validated, on the identification rows (when k-fold ran)
  // With a residual layer, `held` and `kfold` include it (each fold's own layer); these are the
  // same rows' figures without it (rows 0 without a layer), and `fit_with_layer` the
  // identification rows' with it (`fit` and the verdict stay the parametric model's).
  ContactKindFigures held_parametric, kfold_parametric, fit_with_layer;
  std::vector<ContactFeatureSummary> features;  // distance: per pivot; plane: per plane
};

struct ContactPipelineOptions {
  std::string solver = "linear";  // "linear" | "ceres"
  ContactCalibrationOptions calibration;
  double holdout = 0;       // fraction of the rows held out, [0, 1)
  uint64_t split_seed = 0;  // the hold-out draw; the k-fold draw uses split_seed + 1
  int kfold = 0;            // 0: off, else the number of folds (>= 2)
  // --joint_errors=auto: the terms chosen by SelectContactJointErrors (calibration.joint_terms
  // is then ignored); the choice is in ContactPipelineResult::joint_error_selection.
  bool joint_errors_auto = false;
  // The learned residual layer (docs/residual_layer.md, "Projected observations"): kGp fits one
  // on the identification rows' residuals after the calibration, stored in calibration.model;
  // every k-fold fold fits its own on its training rows. kAuto chooses between none and gp by
  // cross-validation on the identification rows (`kfold` folds, 5 when 0; drawn with
  // split_seed + 2), the one-standard-error rule of the tracker path, none the simpler.
  ResidualModelKind residual_model = ResidualModelKind::kNone;
  ResidualLayerOptions residual_layer;
};

// The residual layer of a contact run.
struct ContactLayerSummary {
  bool requested = false;
  bool fitted = false;   // calibration.model carries a layer
  std::string message;   // why not, when requested and not fitted
  ResidualLayerFit fit;
  int inducing = 0;
};

// The folds of --joint_errors=auto with distance and plane rows when --kfold is not given.
constexpr int kContactAutoFolds = 5;

struct ContactPipelineResult {
  // ok false: `message` says why; failed_fold >= 0 when a k-fold fit failed (its result in
  // fold_failure), kfold_too_large when there are fewer identification rows than folds.
  bool ok = false;
  std::string message;
  ContactCalibrationResult calibration;
  int failed_fold = -1;
  ContactCalibrationResult fold_failure;
  bool kfold_too_large = false;
  ContactMeasurementSet identification, held;
  bool held_from_verification = false;
  std::vector<double> held_errors;  // per row of `held`
  std::vector<double> fold_errors;  // per row of `identification` (k-fold)
  // With a layer: held_errors and fold_errors include it; these are without it.
  std::vector<double> held_errors_parametric, fold_errors_parametric;
  std::vector<double> errors_with_layer;  // per identification row, with the layer
  ContactLayerSummary residual_layer;
  ResidualModelSelection residual_model_selection;  // options.residual_model kAuto
  // The kinds with identification rows, in MeasurementKinds() order (pose is not a contact kind).
  std::vector<ContactKindSummary> kinds;
  // The worst of the kinds' verdicts on the identification rows ("pass" when every kind passes).
  std::string verdict;
  // With joint_errors_auto: every candidate's cross-validated error and the choice (ran false
  // otherwise).
  JointErrorSelection joint_error_selection;
};

// The rows of the verification sets `parts` (distance or plane rows of the pivots and planes that
// `data` names) as one set; an error naming the first pivot or plane `data` does not have.
Status ContactVerificationSet(const ContactMeasurementSet& data,
                              const std::vector<ContactMeasurementSet>& parts,
                              ContactMeasurementSet* verification);

// The solver `options.solver` on `data` from `start`. The held-out rows: `verification`'s when it
// has rows (then options.holdout must be 0), else a fraction options.holdout of `data` drawn with
// options.split_seed. With options.kfold > 0 the identification rows are shuffled (split_seed + 1)
// into k folds and each fold's rows are predicted by the calibration of the others.
ContactPipelineResult RunContactPipeline(const RobotModel& start, const ContactMeasurementSet& data,
                                         const ContactMeasurementSet& verification,
                                         const ContactPipelineOptions& options);

// --joint_errors=auto with distance and plane rows: the tracker's choice (SelectJointErrors,
// docs/joint_errors.md "Choosing the terms") on these rows. Every subset of the registry is a
// candidate (the gravity tilt is not: ContactRefusalReason("joint_errors_tilt")); the
// identification rows are shuffled (options.split_seed + 1, the draw of --kfold) into
// options.kfold folds (kContactAutoFolds when 0); each fold is calibrated with the candidate's
// terms by options.solver (its own pivots and planes, options.calibration otherwise) and its
// held-out rows predicted; the candidate's score is the pooled mean squared held-out error (mm^2:
// distances, plane offsets, tracker |e|). Candidates are ordered by the identified joint-space
// combinations (what a kind cannot separate is left out of a candidate's count as the contact
// calibration leaves it out: e.g. the first joint's compliance with ballbar data), and the
// one-standard-error rule chooses. Cost: 2^T k contact calibrations.
JointErrorSelection SelectContactJointErrors(const RobotModel& start,
                                             const ContactMeasurementSet& identification,
                                             const ContactPipelineOptions& options);
// Fits a residual layer on the residuals of a contact calibration `result` on `data`: each
// distance row observes the layer's correction along the bar (u = (p - c) / |p - c|, at the
// model's prediction p), each plane row along its normal, each tracker position row every axis;
// the value is minus the row's error (ContactErrors without a layer), rows weighted by their noise
// relative to the median (lpoe/model/residual_layer.h, FitResidualLayerProjected).
Status FitContactResidualLayer(const ContactCalibrationResult& result,
                               const ContactMeasurementSet& data,
                               const ResidualLayerOptions& options, ResidualLayer* layer,
                               ResidualLayerFit* fit);

// The joint-space terms of a --joint_errors text (Python's joint_errors=) for distance or plane
// data, built on `reference` (the start model): "none" (no terms) or a list of the registry's
// terms, in registry order. "auto" (ContactPipelineOptions::joint_errors_auto chooses them) and
// the gravity tilt are refused with their reasons.
Status ContactJointTerms(const std::string& text, const RobotModel& reference,
                         std::vector<std::shared_ptr<const JointTerm>>* terms);

// Why an option of the position calibration is refused with distance or plane data (one text for
// lpoe_calibrate and Python): "joint_errors_auto", "joint_errors_tilt", "loss", "fixed_tools",
// "parameterization" (full), "urdf_with_tracker" (--urdf_output / --ur_kinematics_output with a
// tracker file among the files). Empty for any other name.
std::string ContactRefusalReason(const std::string& option);

// The input files of a contact calibration: distance and plane CSVs (and, when allowed, tracker
// position files), each detected from its columns, read with its noise sigmas[i] (0: the file's
// sigma column), combined into one set.
struct ContactInputOptions {
  CsvOptions units;
  const MeasurementKindInfo* forced_kind = nullptr;  // --data_kind (null: auto)
  // Non-empty: tracker files are refused with "<file>: " and this text.
  std::string tracker_refusal;
  // Each file's noise (mm); empty or 0: its sigma column (a tracker file needs one here).
  std::vector<double> sigmas;
};
struct ContactInputs {
  ContactMeasurementSet data;
  MeasurementSet tracker;          // the tracker files' rows (for registration)
  std::vector<std::string> kinds;  // each file's kind name
};
// usage_error (may be null) is set when the refusal is the caller's (a tracker file without a
// noise, a tracker file where none is allowed), cleared when the file is at fault.
Status ReadContactInputs(const std::vector<std::string>& files, const RobotModel& nominal,
                         const ContactInputOptions& options, ContactInputs* out,
                         bool* usage_error);

}  // namespace lpoe

#endif  // LPOE_CONTACT_PIPELINE_H_
