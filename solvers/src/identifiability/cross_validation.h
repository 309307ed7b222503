// k-fold cross-validation by configuration on the identification rows, shared by the automatic
// choices (--joint_errors=auto in joint_error_selection.cc, --residual_model=auto in
// residual_model_selection.cc): the folds, the calibration of one fold, the pooled held-out score
// of a candidate and the one-standard-error rule (docs/joint_errors.md, "Choosing the terms").
// Internal to lpoe_solvers.
#ifndef LPOE_SOLVERS_SRC_CROSS_VALIDATION_H_
#define LPOE_SOLVERS_SRC_CROSS_VALIDATION_H_

#include <cstdint>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "lpoe/analysis.h"
#include "lpoe/pipeline.h"

namespace lpoe {
namespace internal {

// The folds of a selection: k = options.joint_error_folds clamped to [2, configurations], seed
// options.split_seed, options.split (written to *choice, marked ran); returns fold f's
// identification rows (k lists).
std::vector<std::vector<int>> FoldsByConfiguration(const MeasurementSet& identification,
                                                   const PipelineOptions& options,
                                                   CrossValidationChoice* choice);

// `options` for calibrations run side by side: its progress callbacks (on_iteration, on_stage),
// when set, called one at a time under *mutex. joint_errors_auto off (a fold's calibration does not
// choose again). *mutex must outlive the returned options' use.
PipelineOptions SerializedProgress(const PipelineOptions& options, std::mutex* mutex);

// One fold's calibration on the identification rows outside `fold` and its training and held-out
// rows. fold_number is 1-based (named in `stage` by the caller and in the failure).
struct FoldCalibration {
  FoldCalibration(MeasurementSet train_rows, MeasurementSet test_rows)
      : train(std::move(train_rows)), test(std::move(test_rows)) {}
  MeasurementSet train;
  MeasurementSet test;
  CalibrationResult result;
  bool ok = false;      // the calibration converged
  std::string failure;  // else "fold N: <termination> (<message>)"
};
FoldCalibration CalibrateFold(const RobotModel& nominal, const MeasurementSet& identification,
                              const std::vector<int>& fold, int fold_number,
                              const PipelineOptions& options, const std::string& stage);

// A candidate's outcome on one fold: its |e|^2 per held-out point, or why the fold failed.
struct FoldErrors {
  bool ok = false;
  std::string failure;
  std::vector<double> squared;
};

// Fills c's score from its folds' errors (in fold order): fold_rms per fold; the first failing
// fold fails it (c->failure, fold_rms up to it); else the pooled mean squared error of every
// held-out point, its RMS and standard error (fewer than 2 points fail). c->label is left as is.
void ScoreFolds(const std::vector<FoldErrors>& folds, CrossValidatedCandidate* c);

// The one-standard-error rule over candidates listed simplest first: choice->best is the lowest
// cv_mse among the ok ones, choice->chosen the first ok one within one standard error of it,
// choice->reason says so. Returns false (and leaves chosen and reason alone) when no candidate is
// ok.
bool ChooseWithinOneStandardError(const std::vector<const CrossValidatedCandidate*>& candidates,
                                  CrossValidationChoice* choice);

// The same over a selection's candidates (JointErrorSelection, ResidualModelSelection).
template <typename Selection>
bool ChooseWithinOneStandardError(Selection* selection) {
  std::vector<const CrossValidatedCandidate*> list;
  for (const auto& c : selection->candidates) list.push_back(&c);
  return ChooseWithinOneStandardError(list, selection);
}

// --joint_errors=auto's choice (tracker and contact rows alike): the candidates ordered simplest
// first (fewest identified combinations; ties keep the listed order), then the one-standard-error
// rule; when no candidate converged on every fold, the geometric model.
void ChooseJointErrors(JointErrorSelection* selection);

// --residual_model=auto's choice from the folds' errors without (outcomes[0]) and with
// (outcomes[1]) the layer: the one-standard-error rule, none when cross-validation failed.
void ChooseResidualModel(const std::vector<FoldErrors> outcomes[2],
                         ResidualModelSelection* selection);

}  // namespace internal
}  // namespace lpoe

#endif  // LPOE_SOLVERS_SRC_CROSS_VALIDATION_H_
