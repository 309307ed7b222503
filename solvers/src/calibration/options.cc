#include "lpoe/options.h"

#include <cmath>
#include <limits>
#include <sstream>

#include <glog/logging.h>

#include "io/parse_util.h"

namespace lpoe {
namespace {

constexpr double kUnbounded = std::numeric_limits<double>::infinity();

OptionSpec Text(const char* scope, const char* name, const char* default_text, const char* help) {
  OptionSpec s;
  s.scope = scope;
  s.name = name;
  s.default_text = default_text;
  s.help = help;
  return s;
}

OptionSpec Number(const char* scope, const char* name, const char* default_text, double lo,
                  double hi, const char* help, bool lo_open = false, bool hi_open = false) {
  OptionSpec s = Text(scope, name, default_text, help);
  s.has_range = true;
  s.lo = lo;
  s.hi = hi;
  s.lo_open = lo_open;
  s.hi_open = hi_open;
  return s;
}

// lpoe_calibrate's options that lpoe.calibrate shares, in the order of lpoe.calibrate's keywords
// (the default prior's standard deviations, lpoe/model/prior.h and docs/identifiability.md "The prior",
// among them): default, range and help of the flag and of the keyword argument.
std::vector<OptionSpec> CalibrateOptions() {
  const char* kCalibrate = "lpoe_calibrate";
  return {
      Text(kCalibrate, "solver", "linear",
           "linear: the paper's iterative least squares; ceres: Levenberg-Marquardt on SE(3) "
           "manifolds (robust losses, a-priori covariance)."),
      Text(kCalibrate, "parameterization", "identifiable",
           "identifiable: only the directions the data can see (27 for a 6R arm with position "
           "data); full: 6 per local frame, solved as a minimum-norm pseudo-inverse (the "
           "paper's 42)."),
      Text(kCalibrate, "data_kind", "auto",
           "position | pose | distance | plane | auto (distance: ballbar, plane: touch probe; "
           "docs/measurements.md): pose-based calibration (paper eqs. 17-24) uses the measured "
           "orientations; auto picks pose when the CSV has quat_* columns."),
      Text(kCalibrate, "joint_errors", "none",
           "Joint-space error terms identified with the geometry: none | a comma-separated list "
           "of the registry's terms (compliance, harmonics, ...: docs/joint_errors.md lists "
           "them; e.g. compliance,harmonics) | auto (gravity and payload from the model; the identified "
           "values are written to the model's joint_errors). Add tilt to a list with compliance "
           "(compliance,tilt) to identify the tilt of the model's gravity too, when the data "
           "determine it (the tilted gravity goes into the calibrated model). auto: k-fold "
           "cross-validation on the identification rows (--kfold folds, 5 when not given; "
           "--split_seed) picks the simplest set within one standard error of the lowest "
           "held-out error among every subset of the terms, with the tilt among the "
           "candidates when identifiable (docs/joint_errors.md)."),
      Text(kCalibrate, "residual_model", "none",
           "Learned residual layer after the parametric solve (docs/residual_layer.md): none | "
           "gp (a sparse Gaussian process over the joint configuration and the SMR, fitted on "
           "the identification residuals, stored in --output and used by every prediction) | "
           "auto (k-fold cross-validation by configuration, --kfold folds or 5, picks none or "
           "gp by the one-standard-error rule). Held-out figures include a layer fitted on the "
           "training rows only."),
      Text(kCalibrate, "register", "true",
           "Register the model to the measurement frame first when the measurements are not in "
           "its base frame (a rigid fit that moves the base by more than 50 mm or 0.05 rad): "
           "rigid fit, then base and tool frames, then everything."),
      Text(kCalibrate, "holdout", "0",
           "Instead of --verify: hold out this fraction of the measurements (0 <= f < 1) "
           "for verification, chosen as --split says."),
      Text(kCalibrate, "kfold", "0",
           "Also run k-fold cross-validation with this many folds (>= 2; 0 = off) on the "
           "identification set and report each fold's held-out errors."),
      Text(kCalibrate, "split", "random",
           "How --holdout, --kfold and --joint_errors=auto split the data, always by "
           "configuration (rows with the same joint values, e.g. several SMRs at one pose, stay "
           "on one side): random (seeded by "
           "--split_seed) | sequential (the held-out fraction is the last rows of the file and "
           "the folds are contiguous blocks: the honest choice when the rows were measured one "
           "after another and the cell drifts)."),
      Text(kCalibrate, "split_seed", "1", "Seed of the --holdout and --kfold splits."),
      Number(kCalibrate, "outlier_threshold", "5", 1, 1e6,
             "List points whose error after the fit exceeds this many robust sigmas."),
      Number(kCalibrate, "max_iterations", "30", 1, 10000, "Iteration limit."),
      Number(kCalibrate, "step_tolerance", "1e-10", 1e-300, 1e-3,
             "Convergence (linear solver): stop when |x| falls below this (mm or rad; at most "
             "1e-3). Large-residual data also stop when the step is below --sd_fraction standard "
             "deviations of every parameter or no longer reduces the cost (docs/pipeline.md).",
             true),
      Number(kCalibrate, "sd_fraction", "0.01", 0, 0.5,
             "Convergence (both solvers): stop when the step is below this fraction of every "
             "parameter's standard deviation (0 = off, at most 0.5)."),
      Number(kCalibrate, "max_condition", "1e8", 10, 1e16,
             "Refuse data whose column-scaled Jacobian has a larger condition number."),
      Number(kCalibrate, "noise_sigma", "0.03", 1e-6, 100,
             "Expected tracker noise per axis (mm) for the plausibility verdict: residuals far "
             "above it (plus the ~0.3 mm a geometric model leaves on a real robot) fail."),
      Text(kCalibrate, "loss", "none",
           "Ceres solver: robust loss against gross errors in the data: none | huber | cauchy."),
      Number(kCalibrate, "loss_scale", "1", 1e-6, 1e4,
             "Ceres solver: scale of the robust loss in mm (errors above it are down-weighted)."),
      Number(kCalibrate, "sigma", "1", 1e-6, 1e3,
             "Ceres solver: measurement noise per axis in mm (residual whitening; sets the scale "
             "of the covariance), in [1e-6, 1e3]. Default (not given): estimated, the covariance "
             "scaled by the noise estimated from the residuals as with the linear solver (the "
             "default value 1 printed below is then only the whitening unit)."),
      Number(kCalibrate, "threads", "0", 0, 256,
             "Ceres solver: threads (0: all hardware threads; at most 256)."),
      Text(kCalibrate, "fixed_tools", "",
           "Comma-separated tools of the model whose frames are known (SMR nests measured on "
           "the fixture, e.g. smr1,smr2,smr3): held as given, so that the flange frame is "
           "identified in full, the last joint's zero and the rotation about its axis included "
           "(docs/identifiability.md, 'Known SMR nests'). The model's tools with fixed: true "
           "are held too; the calibrated model records them."),
      Number(kCalibrate, "prior_scale", "1", 0, 1e6,
             "The prior on weakly determined directions (docs/identifiability.md): every standard "
             "deviation below multiplied by this (larger: looser); 0: no prior, plain least "
             "squares."),
      Number(kCalibrate, "prior_translation", "5", 1e-3, 1e4,
             "Prior standard deviation of the joint frames' translations (mm)."),
      Number(kCalibrate, "prior_rotation", "20", 1e-3, 1e4,
             "Prior standard deviation of the joint frames' rotations, joint zeros included "
             "(mrad)."),
      Number(kCalibrate, "prior_tool_translation", "20", 1e-3, 1e4,
             "Prior standard deviation of the tool points (SMRs) about their fitted start (mm)."),
      Number(kCalibrate, "prior_joint_terms", "5", 1e-3, 1e4,
             "Prior standard deviation of each joint-space term parameter, as its RMS effect on "
             "the joint values over the data (mrad)."),
      Text(kCalibrate, "hold_scale", "auto",
           "Distance and plane data: auto | on | off. auto holds the robot's scale at the "
           "nominal model's when no file measures a length (probe contacts on planes alone: "
           "the scale is not determined by them; docs/identifiability.md)."),
  };
}

std::vector<OptionSpec> MakeOptions() {
  const char* kCompensate = "lpoe_compensate";
  const char* kPlan = "lpoe_plan";
  const char* kCompare = "lpoe_compare";
  const char* kSimulate = "lpoe_simulate";
  std::vector<OptionSpec> options = {
      // ---- Every tool: the model, its chain, the units of the files, quiet, the main output.
      Text("", "model", "",
           "Robot model: YAML, or URDF when the name ends in .urdf (metres converted to mm, fixed "
           "joints folded in; --base_link, --tip_link and --tool_links select the chain). Which "
           "model (nominal or calibrated) and its default: see the usage above."),
      Text("", "base_link", "",
           "URDF --model: the link whose frame is the model's base frame. Default: the root link."),
      Text("", "tip_link", "",
           "URDF --model: the link that ends the chain (e.g. tool0). Needed when moving joints "
           "lead to several leaf links (the error lists them). Default: the one candidate tip."),
      Text("", "tool_links", "",
           "URDF --model: comma-separated links fixed to the last moving link that are the "
           "measured tools (CSV target names). Default: the tip link."),
      Text("", "angle_unit", "rad",
           "Unit of revolute joint values in every CSV file the tool reads or writes: rad | deg."),
      Text("", "length_unit", "mm",
           "Unit of positions (x, y, z columns) and prismatic joint values in every CSV file the "
           "tool reads or writes: mm | m. Flags that are lengths stay in mm."),
      Text("", "quiet", "false",
           "No progress display and no informational messages; results, warnings and errors "
           "still print."),
      Text("", "output", "",
           "The tool's main output file (what it holds: see the usage above). Checked before any "
           "work, written atomically, never over an input."),
      // ---- lpoe_compare.
      Number(kCompare, "tolerance_mm", "1e-6", 0, 1000, ""),
      Number(kCompare, "noise_sigma", "0.03", 1e-6, 100, ""),
      // ---- lpoe_simulate.
      Number(kSimulate, "noise_sigma", "0", 0, 1e4, ""),
      Number(kSimulate, "orientation_noise_sigma", "0", 0, 1, ""),
      Number(kSimulate, "error_rotation", "0.005", 0, 1, ""),
      Number(kSimulate, "error_translation", "3", 0, 1e3, ""),
      Number(kSimulate, "error_tilt", "0.03", 0, 1, ""),
      Number(kSimulate, "error_zero", "0.03", 0, 1e3, ""),
      // ---- lpoe_compensate.
      Text(kCompensate, "joints_target", "pose",
           "Joint-program mode: reach the nominal tool 'pose' or only its 'position'."),
      Text(kCompensate, "frame", "base",
           "Frame of the --targets poses and of a --program's poses: base (the model's base "
           "frame, the chain's base link; carried into the calibrated model's frame by its "
           "recorded registration) | measurement (the frame of the calibration's measurements, "
           "e.g. the tracker's) | link:NAME (a base frame of the models, e.g. link:base, "
           "ur_description's UR controller Base). --program default: link:base for URScript "
           "when the models have it, else base."),
      Number(kCompensate, "threads", "0", 0, 256,
             "Worker threads (0: all cores; the output order is the input's)."),
      Number(kCompensate, "max_iterations", "100", 1, 10000, "Newton iterations per attempt."),
      Number(kCompensate, "restarts", "8", 0, 100,
             "Restarts from perturbed seeds when a solve stalls."),
      Number(kCompensate, "position_tolerance", "1e-7", 0, kUnbounded,
             "Target reached when the position error is below (mm).", true, true),
      Number(kCompensate, "orientation_tolerance", "1e-10", 0, kUnbounded,
             "... and the orientation error below (rad).", true, true),
      Number(kCompensate, "singular_threshold", "0.001", 0, kUnbounded,
             "Smallest singular value (mm per rad; rotation rows weighted 100 mm/rad) below which "
             "a row is 'singular'.", false, true),
      // ---- lpoe_plan.
      Text(kPlan, "seed", "1",
           "Seed of the sampled candidates, workspace and random comparison plans."),
      Text(kPlan, "criterion", "D",
           "D (default: parameters) | A | E | I (average position variance over the workspace) "
           "| O1 | O3 (observability indices; see docs/planning.md)."),
      Text(kPlan, "joint_errors", "none",
           "Joint-space error terms the calibration will identify: none | a comma-separated "
           "list of the registry's terms (compliance, harmonics, ...: docs/joint_errors.md) | "
           "auto, with ',tilt' in a list with compliance for the "
           "gravity tilt. Their identifiable combinations join the parameters the plan must "
           "determine (and the predicted accuracy). 'auto' plans for every term lpoe_calibrate "
           "--joint_errors=auto may choose (all of them; the tilt too when the model carries "
           "compliance values): a plan that identifies the richest model identifies each of its "
           "subsets. The tilt's information is proportional to the compliance values, so "
           "'tilt' needs a --model that carries them (a calibrated model's YAML); with a "
           "nominal model it is refused (docs/planning.md)."),
      Text(kPlan, "measurement", "position",
           "position (a tracker) | ballbar (poses on the --pivots' spheres within the bar's "
           "stroke) | plane (probe contacts on the --planes' faces); docs/measurements.md."),
      Number(kPlan, "candidate_count", "5000", 1, 1000000,
             "Configurations sampled when no --candidates file is given."),
      Number(kPlan, "workspace_count", "1000", 1, 1000000,
             "Configurations sampled when no --workspace file is given."),
      Number(kPlan, "random_draws", "30", 1, 10000,
             "Random plans of the same size evaluated for comparison."),
      Number(kPlan, "acceptance_angle", "30", 0, 90,
             "Half-angle (degrees) of the cone around an SMR's facing direction within which the "
             "tracker must lie.", true),
      Number(kPlan, "min_singularity", "0.01", 0, 1,
             "Drop candidates whose singularity measure (smallest singular value of the "
             "length-normalized geometric Jacobian, docs/planning.md) is below this; 0: keep all.",
             false, true),
      Number(kPlan, "max_range", "0", 0, kUnbounded,
             "Maximum tracker-to-SMR distance (mm); 0: unlimited.", false, true),
      Number(kPlan, "target_accuracy", "0", 0, kUnbounded,
             "--count=auto: predicted held-out RMS to reach (mm).", false, true),
      Number(kPlan, "unmodelled_error", "0.03", 0, 1e3,
             "What the calibrated model will not explain (mm per axis): its bias on the "
             "calibration enters the plan's predicted error and the exchange (docs/planning.md); "
             "from an earlier calibration, its verification RMS / sqrt(3) less the noise in "
             "quadrature; 0: none. A --model carrying a residual layer gives its own (signal and "
             "length scales) unless this is given."),
      Number(kPlan, "unmodelled_length", "1", 0, kUnbounded,
             "Length scale (rad; mm for prismatic joints) over which the unmodelled error varies "
             "with each joint.", true, true),
      Number(kPlan, "noise_sigma", "0", 0, kUnbounded,
             "Measurement noise per axis (mm): scales the predicted accuracy into mm; required "
             "with --count=auto.", false, true),
  };
  // ---- lpoe_calibrate (and lpoe.calibrate).
  const std::vector<OptionSpec> calibrate = CalibrateOptions();
  options.insert(options.end(), calibrate.begin(), calibrate.end());
  return options;
}

}  // namespace

const std::vector<OptionSpec>& Options() {
  static const std::vector<OptionSpec> options = MakeOptions();
  return options;
}

const OptionSpec* FindOption(const std::string& tool, const std::string& name) {
  const OptionSpec* shared = nullptr;
  for (const OptionSpec& s : Options()) {
    if (name != s.name) continue;
    if (tool == s.scope) return &s;
    if (s.scope[0] == '\0') shared = &s;
  }
  return shared;
}

const char* OptionHelp(const std::string& tool, const std::string& name) {
  const OptionSpec* s = FindOption(tool, name);
  CHECK(s != nullptr) << "no option " << name << " of " << tool;
  return s->help;
}

double OptionDefault(const std::string& tool, const std::string& name) {
  const OptionSpec* s = FindOption(tool, name);
  CHECK(s != nullptr) << "no option " << name << " of " << tool;
  double v = 0;
  CHECK(internal::ParseNumber(s->default_text, &v) == internal::NumberParse::kOk) << name;
  return v;
}

const char* OptionDefaultText(const std::string& tool, const std::string& name) {
  const OptionSpec* s = FindOption(tool, name);
  CHECK(s != nullptr) << "no option " << name << " of " << tool;
  return s->default_text;
}

bool OptionDefaultBool(const std::string& tool, const std::string& name) {
  const std::string text = OptionDefaultText(tool, name);
  CHECK(text == "true" || text == "false") << name << ": not a flag's default: " << text;
  return text == "true";
}

std::string OptionRangeText(const OptionSpec& s) {
  if (!s.has_range) return "";
  auto number = [](double v) {
    return std::isinf(v) ? std::string(v > 0 ? "inf" : "-inf") : internal::FormatNumber(v);
  };
  return std::string(s.lo_open ? "(" : "[") + number(s.lo) + ", " + number(s.hi) +
         (s.hi_open ? ")" : "]");
}

Status CheckOption(const std::string& tool, const std::string& name, double value) {
  const OptionSpec* s = FindOption(tool, name);
  if (s == nullptr || !s->has_range) return Status::Ok();
  const bool ok = (s->lo_open ? value > s->lo : value >= s->lo) &&
                  (s->hi_open ? value < s->hi : value <= s->hi);
  if (ok) return Status::Ok();
  std::ostringstream os;
  os << "--" << name << " must be in " << OptionRangeText(*s) << ", got " << value;
  return Status::Error(os.str());
}

}  // namespace lpoe
