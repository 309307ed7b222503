// The machine-readable calibration report (JSON; schema in docs/report.md).
#ifndef LPOE_TOOLS_REPORT_H_
#define LPOE_TOOLS_REPORT_H_

#include <string>
#include <utility>
#include <vector>

#include "lpoe/analysis.h"
#include "lpoe/calibration.h"
#include "lpoe/io/io.h"
#include "lpoe/pipeline.h"
#include "lpoe/io/urdf.h"
#include "lpoe/plausibility.h"
#include "lpoe/recalibration.h"
#include "lpoe/registration.h"
#include "lpoe/model/statistics.h"

namespace lpoe {
namespace tools {

// One measured point with its position error (measured - predicted, mm) before and after the
// calibration. `q` and `measured` feed the HTML report's plots (not written to the JSON).
struct PointResidual {
  int line = 0;    // line in its input file (0 when unknown)
  int target = 0;  // tool (SMR) index
  Eigen::Vector3d before = Eigen::Vector3d::Zero(), after = Eigen::Vector3d::Zero();
  Eigen::Vector3d measured = Eigen::Vector3d::Zero();
  std::vector<double> q;  // joint values (rad / mm)
};

// What the reports show: the pipeline's result (registration, calibration, identifiability,
// statistics, outliers, folds, plausibility verdict) and the run's inputs and outputs.
struct RunSummary : PipelineResult {
  std::string model_path, measurements_path, verification_source;
  std::string split = "random";  // --split of --holdout, --kfold and auto's folds
  std::string solver, parameterization, data_kind, angle_unit;
  CsvReadReport skipped;
  // --joint_errors: what was asked for ("none", a list or "auto"); for auto, the choice is the
  // pipeline's joint_error_selection.
  std::string joint_errors_requested = "none";
  // --residual_model: none | gp | auto (the choice is the pipeline's residual_model_selection).
  std::string residual_model_requested = "none";
  std::vector<std::string> outputs;  // files written
  // Each model written and what it predicts on its own: the YAML carries every term,
  // a URDF or UR kinematics file the geometry only (a geometry-only re-fit after joint-space
  // terms, no residual layer). `reduced`: it carries less than the calibration.
  struct OutputModel {
    std::string flag, path;
    double rms_mm = 0;   // RMS error of its own predictions on `set`
    std::string set;     // verification | identification
    bool reduced = false;
    std::string note;    // what it lacks, for the reports
  };
  std::vector<OutputModel> output_models;
  // A model read from a URDF: for each frame (joints, then tools) the URDF element its parameters
  // change (UrdfFrameElements); empty otherwise.
  std::vector<std::string> urdf_frames;
  bool forced = false;  // written although the verdict failed (--force)
  // --prior (docs/recalibration.md): the prior's file and the groups the new data showed changed
  // (the report's "recalibration", present only with a prior).
  std::string prior_path;
  std::vector<ChangedGroup> changed_groups;

  // Per-point data (AddPointResiduals) and the model the "before" errors refer to (the nominal
  // model, after the rigid registration when there was one).
  RobotModel before_model;
  std::vector<PointResidual> identification_points, verification_points;
  std::string tool_name = "lpoe_calibrate";

  // lpoe_compare: the two solvers side by side (rows: quantity, linear, ceres, |difference|) and
  // whether their predicted positions agree within the tolerance.
  struct ComparisonRow {
    std::string quantity, linear, ceres, difference;
  };
  std::vector<ComparisonRow> comparison;
  bool solvers_agree = true;
};

// lpoe_compare's page: the Ceres run summarized as lpoe_calibrate's (statistics, per-point
// residuals, identifiability, outliers, verdict) plus the comparison rows. When the solvers
// disagree the verdict is "fail" with that reason.
struct ComparisonPage {
  std::string model_path, measurements_path, verification_source, angle_unit, parameterization;
  const PipelineResult* ceres = nullptr;
  const MeasurementSet* identification = nullptr;
  const MeasurementSet* verification = nullptr;
  std::vector<RunSummary::ComparisonRow> rows;
  bool agree = true;
};
Status ComparisonHtml(const ComparisonPage& page, std::string* html);

// For each frame of `model` read from `source` (its joints, then its tools), the URDF element whose
// <origin> its parameters change, as a person finds it in the file: "joint 'wrist_1_joint'
// (child link 'wrist_1_link')" for a joint's frame, "joint 'flange-tool0' (link 'tool0')" for a
// tool (the fixed joint to its link).
std::vector<std::string> UrdfFrameElements(const UrdfSource& source, const RobotModel& model);

// Copies what the pipeline found into `summary` (its PipelineResult part).
void AddPipelineResult(const PipelineResult& run, RunSummary* summary);

// Fills before_model and the per-point residuals of the identification and verification sets.
void AddPointResiduals(const RobotModel& before, const RobotModel& after,
                       const MeasurementSet& identification, const MeasurementSet& verification,
                       RunSummary* summary);


// --joint_errors=auto: the cross-validation table and the choice, as text (lpoe_calibrate prints it
// to stderr).
// `error`: what the held-out error is (the heading's "held-out position error").
std::string JointErrorSelectionTable(const JointErrorSelection& selection,
                                     const std::string& error = "position error");
// --residual_model=auto: the cross-validation table and the choice, as text.
std::string ResidualModelSelectionTable(const ResidualModelSelection& selection);
// The fitted layer in a line or two (or why there is none); "" when none was asked for.
std::string ResidualLayerSummaryText(const PipelineResult& run);
// The layer's length scales per joint, its tool correlation and configuration error, and a
// warning per joint whose length scale is below the data's spacing (ResidualLayerFit::spacing).
std::string ResidualLayerLengthScalesText(const ResidualLayer& layer, const ResidualLayerFit& fit,
                                          const RobotModel& model);
// "compliance, harmonics": the joint-error terms a model carries ("" when none).
std::string JointErrorTermNames(const RobotModel& model);
// The gravity tilt in degrees with its standard deviations, or why it was not identified (one
// line; empty when not asked for).
std::string GravityTiltSummary(const GravityTiltResult& tilt);
// One line per joint-space term of a calibration: parameters and identified combinations ("" when
// there are none).
std::string JointTermsIdentifiability(const CalibrationResult& result);

// Pretty-printed JSON, numbers with full precision, keys in a fixed order.
std::string RunSummaryToJson(const RunSummary& summary);
// The same document with the per-point arrays ("points") empty: every figure of the report at a
// size independent of the number of points (the HTML page reads this and draws the points from
// the summary itself).
std::string RunSummaryToJsonWithoutPoints(const RunSummary& summary);

// The self-contained HTML report (inline SVG plots, no scripts), rendered from the JSON document
// without its per-point arrays (RunSummaryToJsonWithoutPoints) and the summary's points.
// Deterministic; plots are decimated so 10^5 points stay well below 5 MB. Fails only when a plot
// cannot be rendered.
Status RunSummaryToHtml(const RunSummary& summary, std::string* html);

// The plot files of a run: the paper's Fig. 6, Figs. 7/9 and the error histogram, as PNG.
constexpr const char* kPlotFileNames[3] = {"convergence.png", "axis_errors.png",
                                           "error_histogram.png"};

// Renders the plot files (name, PNG bytes) in the order of kPlotFileNames.
Status RenderPlotFiles(const RunSummary& summary,
                       std::vector<std::pair<std::string, std::string>>* files);

// Writes them into `dir` (created if missing), each atomically; appends the paths written to
// summary->outputs.
Status WritePlotFiles(const std::string& dir, RunSummary* summary);

// Writes the HTML report to `path` atomically and appends it to summary->outputs.
Status WriteHtmlReport(const std::string& path, RunSummary* summary);

}  // namespace tools
}  // namespace lpoe

#endif  // LPOE_TOOLS_REPORT_H_
