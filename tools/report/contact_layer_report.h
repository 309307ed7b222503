// The residual layer and the joint-error choice of a contact calibration (ballbar distances, probe contacts;
// docs/residual_layer.md, "Projected observations") in the text output and the JSON report, one
// text for lpoe_calibrate and Python's lpoe.calibrate.
#ifndef LPOE_TOOLS_REPORT_CONTACT_LAYER_REPORT_H_
#define LPOE_TOOLS_REPORT_CONTACT_LAYER_REPORT_H_

#include <string>

#include "lpoe/contact_pipeline.h"

namespace lpoe {
namespace tools {

// The layer's lines: the auto choice's table (when it ran), the fit, its length scales and, per kind, the RMS without and with it on the
// identification rows, the held-out rows and the k-fold folds (`kfold` > 0). Empty when no layer
// was asked for; "residual layer: none (why)" when its fit failed.
std::string ContactLayerText(const ContactPipelineResult& run, int kfold);
// The report's "residual_layer" object (JSON text): requested (the option's text), fitted,
// message, selection (auto: folds, seed, candidates, best, chosen, reason; else null), the layer's hyperparameters and figures, and per kind the RMS without and with it.
std::string ContactLayerJsonText(const ContactPipelineResult& run, const std::string& requested);
// The report's "joint_error_selection" object (JSON text) of --joint_errors=auto / joint_errors=
// 'auto' (the tracker report's joint_errors.selection, for contact data): folds, seed, candidates
// (terms, converged, failure, identified_combinations, fold_rms and, when converged, cv_rms,
// cv_mse, cv_mse_standard_error), best, chosen, reason, tilt_message (the tilt's candidacy); keys
// in that order. `sel` must have run.
std::string ContactSelectionJsonText(const JointErrorSelection& sel);
// The body of a contact calibration's JSON report (JSON text), lpoe_calibrate's and
// lpoe.calibrate's (each adds its own "tool" and the tool its files): solver, iterations,
// cost_before, cost_after, measurement_kinds (per kind: the table's figures, the held-out rows'
// as "verification" with `verify_given` naming its source, the k-fold figures when `kfold` > 0,
// per pivot or plane), features (pivots, planes), parameters, base, scale, left_out, joint_errors,
// joint_error_selection (when it ran) and residual_layer (`residual_model`: the option's text);
// keys in that order. Names are written as valid UTF-8 (ValidUtf8).
std::string ContactReportJsonText(const ContactPipelineResult& run, bool verify_given, int kfold,
                                  const std::string& residual_model);

}  // namespace tools
}  // namespace lpoe

#endif  // LPOE_TOOLS_REPORT_CONTACT_LAYER_REPORT_H_
