// lpoe_calibrate: identify the local frames of a robot from tracker measurements.
//
// Reads a nominal model (YAML) and measurements (CSV), registers the model to the measurement frame,
// runs the chosen solver, prints the identifiability report, the convergence table and before/after
// errors on the identification and verification sets, and writes the calibrated model, a JSON
// report and plots. With no arguments it calibrates the shipped section-4 data set.
#include <algorithm>
#include <cmath>
#include <iomanip>
#include <cstdio>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>
#include <sys/stat.h>

#include <gflags/gflags.h>
#include <glog/logging.h>

#include "lpoe/joint_error_list.h"
#include "lpoe/analysis.h"
#include "lpoe/ceres_solver.h"
#include "lpoe/io/io.h"
#include "lpoe/linear_solver.h"
#include "lpoe/measurements/measurement_kind_dispatch.h"
#include "lpoe/options.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/pipeline.h"
#include "lpoe/recalibration.h"
#include "lpoe/model/refusals.h"
#include "lpoe/registration.h"
#include "lpoe/model/statistics.h"
#include "lpoe/io/urdf.h"
#include "common/output_files.h"
#include "report/plot.h"
#include "common/progress.h"
#include "report/report.h"
#include "common/common_flags.h"
#include "common/input_flags.h"
#include "lpoe_calibrate_contact.h"
#include "common/tool_common.h"

// The options lpoe.calibrate shares: default, range and help from the table (lpoe/options.h).
#define LPOE_DEFAULT(name) lpoe::OptionDefault("lpoe_calibrate", #name)
#define LPOE_TEXT(name) lpoe::OptionDefaultText("lpoe_calibrate", #name)
#define LPOE_FLAG(name) lpoe::OptionDefaultBool("lpoe_calibrate", #name)
#define LPOE_HELP(name) lpoe::OptionHelp("lpoe_calibrate", #name)

DEFINE_string(measurements, "",
              "Identification measurements (CSV: q1..qN,x,y,z[,target][,quat_x..quat_w]); or "
              "ballbar (q1..qN,distance[,pivot]) and touch-probe (q1..qN,plane[,offset]) files, "
              "several comma-separated (docs/measurements.md). "
              "Default: data/section4/identification.csv.");
DEFINE_string(verify, "",
              "Verification measurements (CSV), never used for identification. Default with the "
              "default measurements: data/section4/verification.csv.");
DEFINE_double(holdout, LPOE_DEFAULT(holdout), LPOE_HELP(holdout));
DEFINE_string(split, LPOE_TEXT(split), LPOE_HELP(split));
DEFINE_int32(kfold, static_cast<int32_t>(LPOE_DEFAULT(kfold)), LPOE_HELP(kfold));
DEFINE_uint64(split_seed, static_cast<uint64_t>(LPOE_DEFAULT(split_seed)), LPOE_HELP(split_seed));
DEFINE_string(urdf_output, "",
              "Also write the calibrated model as URDF. When --model is a URDF: that same file with "
              "only the calibrated joint origins (and axes) changed, every name, limit, mesh, "
              "inertial and extension tag kept, the tools as fixed links on the tip and the "
              "measurement (tracker) frame as the fixed link measurement_frame (docs/urdf.md). "
              "Otherwise a new URDF (links base_link, link1..linkN).");
DEFINE_string(ur_kinematics_output, "",
              "With a URDF --model of a Universal Robots arm (joints shoulder_pan_joint .. "
              "wrist_3_joint): also write the calibrated joint origins in the format of "
              "ROS-Industrial's ur_description kinematics YAML.");
DEFINE_string(report, "", "Write a machine-readable JSON report here (schema in docs/report.md).");
DEFINE_string(html_report, "",
              "Write a self-contained HTML report here (verdict, statistics, plots, parameters; "
              "no scripts, inline SVG). Nothing is written on failure.");
DEFINE_string(plots_dir, "lpoe_plots",
              "Directory for the PNG plots (convergence, per-axis errors, histogram); created if "
              "missing. Empty: no plots.");
DEFINE_string(solver, LPOE_TEXT(solver), LPOE_HELP(solver));
DEFINE_string(joint_errors, LPOE_TEXT(joint_errors), LPOE_HELP(joint_errors));
DEFINE_string(residual_model, LPOE_TEXT(residual_model), LPOE_HELP(residual_model));
DEFINE_string(loss, LPOE_TEXT(loss), LPOE_HELP(loss));
DEFINE_double(loss_scale, LPOE_DEFAULT(loss_scale), LPOE_HELP(loss_scale));
DEFINE_double(sigma, LPOE_DEFAULT(sigma), LPOE_HELP(sigma));
DEFINE_int32(threads, static_cast<int32_t>(LPOE_DEFAULT(threads)), LPOE_HELP(threads));
DEFINE_string(parameterization, LPOE_TEXT(parameterization), LPOE_HELP(parameterization));
DEFINE_string(data_kind, LPOE_TEXT(data_kind), LPOE_HELP(data_kind));
DEFINE_bool(register, LPOE_FLAG(register), LPOE_HELP(register));
DEFINE_double(outlier_threshold, LPOE_DEFAULT(outlier_threshold), LPOE_HELP(outlier_threshold));
DEFINE_int32(max_iterations, static_cast<int32_t>(LPOE_DEFAULT(max_iterations)),
             LPOE_HELP(max_iterations));
DEFINE_double(step_tolerance, LPOE_DEFAULT(step_tolerance), LPOE_HELP(step_tolerance));
DEFINE_double(sd_fraction, LPOE_DEFAULT(sd_fraction), LPOE_HELP(sd_fraction));
DEFINE_double(noise_sigma, LPOE_DEFAULT(noise_sigma), LPOE_HELP(noise_sigma));
DEFINE_string(prior, "",
              "Recalibration (docs/recalibration.md): a calibrated model with its covariance block "
              "(lpoe_calibrate --output, or lpoe_prior's fleet prior) as the prior; the start "
              "model unless --model is given. Groups the new data show changed (a joint's zero, a "
              "joint's frame, a tool) are freed and named.");
DEFINE_double(prior_scale, LPOE_DEFAULT(prior_scale), LPOE_HELP(prior_scale));
DEFINE_double(prior_translation, LPOE_DEFAULT(prior_translation), LPOE_HELP(prior_translation));
DEFINE_double(prior_rotation, LPOE_DEFAULT(prior_rotation), LPOE_HELP(prior_rotation));
DEFINE_double(prior_tool_translation, LPOE_DEFAULT(prior_tool_translation),
              LPOE_HELP(prior_tool_translation));
DEFINE_double(prior_joint_terms, LPOE_DEFAULT(prior_joint_terms), LPOE_HELP(prior_joint_terms));
DEFINE_bool(force, false,
            "Write the outputs even when the plausibility verdict fails; the exit code is still 8, "
            "so that a script can tell a forced result.");
DEFINE_string(fixed_tools, LPOE_TEXT(fixed_tools), LPOE_HELP(fixed_tools));
DEFINE_double(max_condition, LPOE_DEFAULT(max_condition), LPOE_HELP(max_condition));
#undef LPOE_DEFAULT
#undef LPOE_TEXT
#undef LPOE_FLAG
#undef LPOE_HELP

namespace lpoe {
namespace {

using tools::kExitInput;
using tools::kExitOk;
using tools::kExitOutput;
using tools::kExitUsage;

constexpr char kUsage[] =
    "Calibrates the local frames of a serial robot (Local Product of Exponentials, Gao et al. "
    "2022) from measured tool positions.\n\n"
    "  lpoe_calibrate                          # the shipped section-4 data set\n"
    "  lpoe_calibrate --model=robot.yaml --measurements=points.csv --angle_unit=deg \\\n"
    "                 --holdout=0.3 --output=calibrated.yaml --report=report.json\n\n"
    "Units: mm and rad (joint values may be given in degrees with --angle_unit=deg). The\n"
    "measurements may be in any rigid frame (e.g. the tracker's): the calibrated model is\n"
    "expressed in the measurement frame.\n"
    "--model: the nominal model (default: the shipped cobot6); --output: the calibrated model "
    "(YAML; nothing is written on failure).\n"
    "Exit codes: 0 converged, 1 bad flags, 2 bad input file, 3 data cannot identify the model,\n"
    "4 iteration limit reached, 5 numerical failure, 6 output not written, 8 the result is not\n"
    "plausible (residual, scale, units or parameter changes; see the verdict; --force writes it).";

// The pipeline's options from the flags (validated in Run()).
PipelineOptions PipelineOptionsFromFlags(ParameterizationKind kind, bool use_orientation,
                                         AngleUnit unit) {
  PipelineOptions o;
  o.solver = FLAGS_solver == "ceres" ? SolverKind::kCeres : SolverKind::kLinear;
  o.parameterization = kind;
  o.use_orientation = use_orientation;
  o.register_frames = FLAGS_register;
  std::vector<std::string> kinds;
  o.joint_errors_auto = FLAGS_joint_errors == "auto";
  o.joint_error_folds = FLAGS_kfold >= 2 ? FLAGS_kfold : 5;
  std::vector<std::string> effects;
  if (std::string error; ParseJointErrorList(FLAGS_joint_errors, &kinds, &effects, &error)) {
    // In registry order, compliance first (docs/joint_errors.md): it keeps the combinations both
    // terms could explain; the bilinear effects (the tilt) after them.
    o.joint_errors = InRegistryOrder(kinds);
    o.joint_errors.insert(o.joint_errors.end(), effects.begin(), effects.end());
  }
  o.kfold = FLAGS_kfold;
  ParseResidualModelKind(FLAGS_residual_model, &o.residual_model);  // checked in Run()
  o.residual_layer.seed = FLAGS_split_seed;
  // URDF and UR kinematics carry geometry only: with joint-space terms they get a geometry-only
  // re-fit of the same data.
  o.refit_geometry = !FLAGS_urdf_output.empty() || !FLAGS_ur_kinematics_output.empty();
  o.split_seed = FLAGS_split_seed;
  ParseSplitKind(FLAGS_split, &o.split);  // checked by ParseInputFlags
  o.outlier_threshold = FLAGS_outlier_threshold;
  if (FLAGS_prior_scale > 0) {
    auto prior = std::make_shared<ParameterPrior>();
    prior->scale = FLAGS_prior_scale;
    prior->scales.frame_translation_mm = FLAGS_prior_translation;
    prior->scales.frame_rotation_mrad = FLAGS_prior_rotation;
    prior->scales.tool_translation_mm = FLAGS_prior_tool_translation;
    prior->scales.joint_term_mrad = FLAGS_prior_joint_terms;
    o.prior = prior;
  } else {
    o.prior = nullptr;
  }
  o.plausibility.noise_sigma = FLAGS_noise_sigma;
  o.plausibility.joint_values_in_degrees = unit == AngleUnit::kDegrees;
  o.linear.max_iterations = FLAGS_max_iterations;
  o.linear.step_tolerance = FLAGS_step_tolerance;
  o.linear.max_condition_number = FLAGS_max_condition;
  o.linear.convergence.sd_fraction = FLAGS_sd_fraction;
  CeresSolverOptions& c = o.ceres;
  c.max_iterations = FLAGS_max_iterations;
  c.max_condition_number = FLAGS_max_condition;
  c.loss = FLAGS_loss;
  c.loss_scale = FLAGS_loss_scale;
  c.sigma = FLAGS_sigma;
  c.convergence.sd_fraction = FLAGS_sd_fraction;
  // Without a stated noise level, estimate it from the residuals (as the linear solver does).
  c.a_posteriori_covariance = gflags::GetCommandLineFlagInfoOrDie("sigma").is_default;
  if (FLAGS_threads > 0) c.num_threads = FLAGS_threads;
  return o;
}

// `num_frame_parameters`: the identified directions before it are the frames' (rad or mm); the
// joint-space combinations after them have their terms' scaled units and are not ranked with them.
void PrintIdentifiability(const IdentifiabilityReport& id, int num_frame_parameters) {
  std::cout << "identifiability: " << id.num_parameters << " parameters, rank " << id.rank
            << ", condition number of the column-scaled Jacobian " << id.condition_number << "\n";
  if (id.singular_values.size() > 0) {
    const auto& s = id.singular_values;
    std::cout << "  singular values: largest " << s(0) << ", smallest " << s(s.size() - 1) << "\n";
  }
  // The fixed tools' directions are held by the user, not unidentifiable: counted apart.
  std::vector<std::string> held;
  for (const Direction& d : id.unidentifiable) {
    if (IsHeldFixedTool(d)) held.push_back(d.name);
  }
  std::cout << "  not identifiable from this data kind (" << id.unidentifiable.size() - held.size()
            << " directions, left out):\n";
  // One name: "name: reason". Several names with one reason: the reason, then the names wrapped
  // under it (the joint-space terms alone can leave out 60 combinations).
  std::string last_reason;
  std::vector<std::string> names;
  auto flush = [&]() {
    if (names.size() == 1) {
      std::cout << "    " << names[0] << ": " << last_reason << "\n";
    } else if (names.size() > 1) {
      std::cout << "    " << last_reason << ":\n";
      tools::PrintWrapped(std::cout, names, ", ", 6);
    }
    names.clear();
  };
  for (const Direction& d : id.unidentifiable) {
    if (IsHeldFixedTool(d)) continue;
    if (d.reason != last_reason) {
      flush();
      last_reason = d.reason;
    }
    names.push_back(d.name);
  }
  flush();
  if (!held.empty()) {
    std::cout << "  held (fixed tools): " << held.size()
              << " directions, as given, not calibrated:\n";
    tools::PrintWrapped(std::cout, held, ", ", 6);
  }
  if (id.standard_deviation.size() > 0) {
    // The least certain parameters, as a quick read; all of them are in the JSON report.
    const int n = static_cast<int>(id.standard_deviation.size());
    const bool joint_space = num_frame_parameters < n;
    std::vector<int> order(static_cast<size_t>(std::min(n, num_frame_parameters)));
    for (size_t k = 0; k < order.size(); ++k) order[k] = static_cast<int>(k);
    std::sort(order.begin(), order.end(), [&](int a, int b) {
      return id.standard_deviation(a) > id.standard_deviation(b);
    });
    std::vector<std::string> items;
    for (int k = 0; k < std::min<int>(4, static_cast<int>(order.size())); ++k) {
      std::ostringstream item;
      item << id.parameter_names[order[k]] << " " << id.standard_deviation(order[k]);
      items.push_back(item.str());
    }
    std::cout << "  largest standard deviations" << (joint_space ? " of the frames" : "")
              << " (rad or mm" << (joint_space ? "; the joint-space terms': JSON report" : "")
              << "):\n";
    tools::PrintWrapped(std::cout, items, ", ", 6);
    items.clear();
    for (const CorrelatedPair& c : id.most_correlated) {
      std::ostringstream item;
      item << c.a << "/" << c.b << " " << c.correlation;
      items.push_back(item.str());
    }
    std::cout << "  most correlated pairs:\n";
    tools::PrintWrapped(std::cout, items, "; ", 6);
  }
  if (id.data_share.size() == static_cast<Eigen::Index>(id.parameter_names.size()) &&
      id.data_share.size() > 0) {
    // The prior (docs/identifiability.md, "The prior"): what it held.
    std::cout << "  prior: weighed against " << id.prior_data_sigma
              << " mm per axis (the residuals');\n    ";
    if (id.weakly_determined.empty()) {
      std::cout << "every direction determined by the data (data share >= "
                << 100 * kWeaklyDeterminedShare << " %)\n";
    } else {
      std::cout << id.weakly_determined.size()
                << " weakly determined, held near the start model by the prior (data share):\n";
      std::vector<std::string> items;
      for (size_t k = 0; k < id.parameter_names.size(); ++k) {
        if (!(id.data_share(k) < kWeaklyDeterminedShare)) continue;
        std::ostringstream item;
        item << id.parameter_names[k] << " " << std::setprecision(2) << 100 * id.data_share(k)
             << " %";
        items.push_back(item.str());
      }
      tools::PrintWrapped(std::cout, items, ", ", 6);
    }
  }
  for (const std::string& w : id.warnings) std::cout << "  warning: " << w << "\n";
}

// Flag combinations: a bad one gives exit 1 with a message naming the flag.
Status CheckFlags() {
  // The ranges of the option table (lpoe/options.h) were checked by InitTool.
  if (FLAGS_kfold != 0 && !(FLAGS_kfold >= 2 && FLAGS_kfold <= 100)) {
    return Status::Error("--kfold must be 0 (off) or between 2 and 100, got " +
                         std::to_string(FLAGS_kfold));
  }
  return Status::Ok();
}

// What the steps of a calibration run share: the inputs, the outputs and the result.
struct CalibrationRun {
  tools::InputPaths paths;
  tools::InputSettings settings;
  std::vector<std::string> fixed_tools;
  UrdfOptions urdf_options;
  tools::OutputSet outputs;
  std::string plot_dir;  // with its '/'; empty: no plots
  tools::Inputs in;
  bool use_orientation = false;
  tools::RunSummary summary;
  RecalibrationResult recalibration;
};

// The flags, each alone and in combination: exit 1 with a message naming the flag.
int CheckCalibrateFlags(CalibrationRun* r) {
  // --prior without --model: the prior's model is the start.
  if (!FLAGS_prior.empty() && gflags::GetCommandLineFlagInfoOrDie("model").is_default) {
    r->paths.model = FLAGS_prior;
  }
  if (!FLAGS_prior.empty() && !(FLAGS_prior_scale > 0)) {
    std::cerr << "error: --prior needs --prior_scale > 0\n";
    return kExitUsage;
  }
  if (FLAGS_solver != "linear" && FLAGS_solver != "ceres") {
    std::cerr << "error: --solver must be linear or ceres, got '" << FLAGS_solver << "'\n";
    return kExitUsage;
  }
  if (Status s = CheckFlags(); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitUsage;
  }
  if (Status s = ValidateCeresSolverOptions(
          PipelineOptionsFromFlags(r->settings.parameterization, false, r->settings.angle_unit)
              .ceres);
      !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitUsage;
  }
  if (std::vector<std::string> kinds, effects; FLAGS_joint_errors != "auto") {
    std::string error;
    if (!ParseJointErrorList(FLAGS_joint_errors, &kinds, &effects, &error)) {
      std::cerr << "error: --joint_errors='" << FLAGS_joint_errors << "': " << error
                << " (expected none, a comma-separated list of " << JointTermNameList() << ", "
                << BilinearEffectsHelp(/*example=*/true) << ", or auto)\n";
      return kExitUsage;
    }
  }
  if (ResidualModelKind kind; !ParseResidualModelKind(FLAGS_residual_model, &kind)) {
    std::cerr << "error: --residual_model must be none, gp or auto, got '" << FLAGS_residual_model
              << "'\n";
    return kExitUsage;
  }
  if (Status s = ParseNameList(FLAGS_fixed_tools, &r->fixed_tools); !s.ok()) {
    std::cerr << "error: --fixed_tools: " << s.message() << "\n";
    return kExitUsage;
  }
  if (FLAGS_solver == "linear" && FLAGS_loss != "none") {
    std::cerr << "error: --loss needs --solver=ceres (the linear solver is plain least squares)\n";
    return kExitUsage;
  }
  if (FLAGS_data_kind != "auto" && FLAGS_data_kind != "position" && FLAGS_data_kind != "pose") {
    std::cerr << "error: --data_kind must be auto, position or pose, got '" << FLAGS_data_kind
              << "'\n";
    return kExitUsage;
  }
  if (!tools::UrdfOptionsFromFlags(r->paths.model, &r->urdf_options) ||
      (!FLAGS_ur_kinematics_output.empty() && !IsUrdfPath(r->paths.model))) {
    std::cerr << "error: --base_link, --tip_link, --tool_links and --ur_kinematics_output need a "
                 "URDF --model (a name ending in .urdf)\n";
    return kExitUsage;
  }
  return kExitOk;
}

// Every output against every input and every other output (plots included), by identity.
int CheckOutputs(CalibrationRun* r) {
  tools::OutputSet& outputs = r->outputs;
  tools::AddInputs(r->paths, &outputs);
  if (!FLAGS_prior.empty()) outputs.AddInput("--prior", FLAGS_prior);
  outputs.AddOutput("--output", FLAGS_output);
  outputs.AddOutput("--urdf_output", FLAGS_urdf_output);
  outputs.AddOutput("--ur_kinematics_output", FLAGS_ur_kinematics_output);
  outputs.AddOutput("--report", FLAGS_report);
  outputs.AddOutput("--html_report", FLAGS_html_report);
  r->plot_dir = FLAGS_plots_dir.empty() ? "" : FLAGS_plots_dir + "/";
  if (!r->plot_dir.empty()) {
    struct stat st;
    if (::stat(FLAGS_plots_dir.c_str(), &st) == 0 && !S_ISDIR(st.st_mode)) {
      std::cerr << "error: --plots_dir=" << FLAGS_plots_dir << " is not a directory\n";
      return kExitUsage;
    }
    // Created (with its parents) only when the plots are written.
    for (const char* name : tools::kPlotFileNames) {
      outputs.AddOutput("--plots_dir", r->plot_dir + name, true);
    }
  }
  if (Status s = outputs.Check(); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitUsage;
  }
  if (!FLAGS_html_report.empty() && (tools::SameFile(FLAGS_html_report, FLAGS_report) ||
                                     tools::SameFile(FLAGS_html_report, FLAGS_output))) {
    std::cerr << "error: --html_report names the same file as --report or --output\n";
    return kExitUsage;
  }
  return kExitOk;
}

// The model and the measurements read, split and checked against the flags.
int LoadCalibrationInputs(CalibrationRun* r, tools::Progress* progress) {
  const tools::InputPaths& paths = r->paths;
  tools::Inputs& in = r->in;
  if (Status s = tools::LoadInputs(paths.model, paths.measurements, paths.verify,
                                   r->settings.csv, FLAGS_holdout, FLAGS_split_seed, &in,
                                   r->urdf_options, r->settings.split);
      !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitInput;
  }
  if (Status s = SetFixedTools(r->fixed_tools, &in.nominal); !s.ok()) {
    std::cerr << "error: --fixed_tools: " << paths.model << ": " << s.message() << "\n";
    return kExitUsage;
  }
  progress->Rows(paths.measurements, in.identification.size() + in.verification.size());
  tools::RunSummary& summary = r->summary;
  summary.skipped = std::move(in.skipped);
  summary.verification_source = in.verification_source;
  summary.split = SplitKindName(r->settings.split);
  if (in.from_urdf) summary.urdf_frames = tools::UrdfFrameElements(in.urdf, in.nominal);
  // The UR file needs a UR arm with z axes: checked on the nominal model before solving.
  if (!FLAGS_ur_kinematics_output.empty()) {
    std::string ur_yaml;
    if (Status s = UrKinematicsYaml(in.urdf, in.nominal, {}, &ur_yaml); !s.ok()) {
      std::cerr << "error: --ur_kinematics_output: " << s.message() << "\n";
      return kExitUsage;
    }
  }
  if (Status s = tools::CheckHoldoutSplit(FLAGS_holdout, in); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitUsage;
  }
  std::vector<int> configuration_of_row;
  const int identification_configurations =
      FLAGS_kfold > 0 ? ConfigurationGroups(in.identification, &configuration_of_row) : 0;
  if (FLAGS_kfold > identification_configurations) {
    std::cerr << "error: --kfold=" << FLAGS_kfold << " is larger than the "
              << identification_configurations
              << " identification configurations: every fold needs held-out configurations\n";
    return kExitUsage;
  }
  r->use_orientation = in.identification.has_orientation();
  if (FLAGS_data_kind == "position") r->use_orientation = false;
  if (FLAGS_data_kind == "pose" && !in.identification.has_orientation()) {
    std::cerr << "error: --data_kind=pose needs quat_x,quat_y,quat_z,quat_w columns in "
              << paths.measurements << "\n";
    return kExitUsage;
  }
  return kExitOk;
}

// What is calibrated from what, printed before solving.
void PrintRunHeader(const CalibrationRun& r) {
  const RobotModel& nominal = r.in.nominal;
  std::cout << "model:          " << r.paths.model << " (" << nominal.num_joints() << " joints, "
            << nominal.num_tools() << " tool" << (nominal.num_tools() > 1 ? "s" : "") << ")\n"
            << "identification: " << r.paths.measurements << " (" << r.in.identification.size()
            << " rows)\n";
  if (!r.in.verification.empty()) {
    std::cout << "verification:   "
              << (r.paths.verify.empty() ? "held out from the identification file"
                                         : r.paths.verify)
              << " (" << r.in.verification.size() << " rows)\n";
  }
  if (nominal.HasFixedTool()) {
    std::string names;
    for (const Tool& t : nominal.tools) {
      if (t.fixed) names += (names.empty() ? "" : ", ") + t.name;
    }
    std::cout << "fixed tools:    " << names
              << " (held as given: the flange frame is identified in full)\n";
  }
  std::cout << "solver:         " << FLAGS_solver << ", "
            << ParameterizationName(r.settings.parameterization) << " parameterization, "
            << MeasurementKind(TrackerKindId(r.use_orientation)).name << " data\n";
}

// --prior: the calibrated model's covariance as the pipeline's prior (its chain checked).
int ReadPriorFlag(const RobotModel& nominal, PipelineOptions* options) {
  RobotModel prior_model;
  ParameterPrior prior;
  if (Status s = ReadPrior(FLAGS_prior, options->prior ? options->prior->scales : PriorScales(),
                           &prior_model, &prior);
      !s.ok()) {
    std::cerr << "error: --prior: " << s.message() << "\n";
    return kExitInput;
  }
  if (prior_model.num_frames() != nominal.num_frames() ||
      prior_model.num_joints() != nominal.num_joints()) {
    std::cerr << "error: --prior=" << FLAGS_prior << ": its chain (" << prior_model.num_joints()
              << " joints, " << prior_model.num_tools() << " tools) is not the model's\n";
    return kExitInput;
  }
  prior.scale = FLAGS_prior_scale;
  options->prior = std::make_shared<const ParameterPrior>(prior);
  std::cout << "prior:          " << FLAGS_prior << " (informative";
  if (FLAGS_prior_scale != 1) std::cout << ", standard deviations x " << FLAGS_prior_scale;
  std::cout << ")\n";
  return kExitOk;
}

// The one library call: register, solve, analyse, cross-validate, judge (nothing is written
// yet); a recalibration against --prior names the groups that changed.
int SolveCalibration(CalibrationRun* r, tools::Progress* progress) {
  const tools::Inputs& in = r->in;
  PipelineOptions options = PipelineOptionsFromFlags(r->settings.parameterization,
                                                     r->use_orientation, r->settings.angle_unit);
  options.on_iteration = [progress](const std::string& stage, const IterationRecord& rec) {
    progress->Iteration(stage, rec);
  };
  options.on_stage = [progress](const std::string& stage) { progress->Stage(stage); };
  if (!FLAGS_prior.empty()) {
    if (int rc = ReadPriorFlag(in.nominal, &options); rc != kExitOk) return rc;
  }
  RecalibrationResult& recalibration = r->recalibration;
  if (!FLAGS_prior.empty()) {
    recalibration = Recalibrate(in.nominal, in.identification, in.verification, options);
  } else {
    recalibration.run =
        RunCalibrationPipeline(in.nominal, in.identification, in.verification, options);
  }
  if (!recalibration.changed.empty()) {
    std::cout << "recalibration: the new data show " << recalibration.changed.size()
              << " group(s) changed against the prior, freed (held by the tolerances only):\n";
    for (const ChangedGroup& g : recalibration.changed) {
      std::cout << "  " << g.name << ": prior discrepancy chi^2 " << g.chi2 << " for " << g.dof
                << " degrees of freedom\n";
    }
  } else if (!FLAGS_prior.empty()) {
    std::cout << "recalibration: no group changed against the prior\n";
  }
  return kExitOk;
}

void PrintRegistration(const PipelineResult& run) {
  const RegistrationReport& reg = run.registration;
  if (reg.moved) {
    std::cout << reg.message << "\n"
              << "(the measurements are not in the model's base frame: 'before calibration' "
                 "below is the nominal model after the rigid fit)\n";
  } else {
    std::cout << "registration: not needed, the data are in the model's base frame (a rigid fit "
                 "would move the base by only "
              << reg.T_measurement_base.t.norm() << " mm and "
              << LogSO3(reg.T_measurement_base.R).norm() << " rad)\n";
  }
}

// Points that do not fit.
void PrintOutliers(const tools::RunSummary& summary, const std::string& meas_path) {
  if (summary.outliers.empty()) return;
  std::cout << "\n" << summary.outliers.size() << " point(s) fit worse than "
            << FLAGS_outlier_threshold << " robust sigmas (" << summary.robust_sigma
            << " mm per axis); they were used, check them:\n";
  for (size_t k = 0; k < std::min<size_t>(summary.outliers.size(), 20); ++k) {
    const Outlier& o = summary.outliers[k];
    std::cout << "  " << meas_path << ":" << o.line << ": error " << o.error << " mm ("
              << o.sigmas << " sigma)\n";
  }
}

// k-fold cross-validation: each fold's held-out errors and the pooled row.
void PrintFolds(const PipelineResult& run, int identification_rows) {
  if (run.folds.empty()) return;
  std::cout << "\n" << FLAGS_kfold
            << "-fold cross-validation by configuration (held-out position error, mm)\n"
            << "  fold  rows   termination        max      mean       rms       p95\n";
  char line[200];
  for (const FoldSummary& f : run.folds) {
    std::snprintf(line, sizeof(line), "  %4d %5d   %-16s %8.4f %9.4f %9.4f %9.4f\n", f.fold,
                  f.identification_rows,
                  f.termination == Termination::kConverged ? "converged" : "FAILED",
                  f.verification_after.norm.max_abs, f.verification_after.norm.mean_abs,
                  f.verification_after.norm.rms, f.verification_after.norm.p95_abs);
    std::cout << line;
  }
  const ErrorStatistics& all = run.folds_pooled;
  std::snprintf(line, sizeof(line), "   all %5d   %-16s %8.4f %9.4f %9.4f %9.4f\n",
                identification_rows, "", all.norm.max_abs, all.norm.mean_abs, all.norm.rms,
                all.norm.p95_abs);
  std::cout << line;
}

// The result into the summary and printed: identifiability, iterations, errors before and
// after, outliers, folds. Exit code when the solve did not converge, else kExitOk.
int ReportResult(CalibrationRun* r) {
  const PipelineResult& run = r->recalibration.run;
  const CalibrationResult& result = run.result;
  tools::RunSummary& summary = r->summary;
  tools::AddPipelineResult(run, &summary);
  summary.joint_errors_requested = FLAGS_joint_errors;
  summary.residual_model_requested = FLAGS_residual_model;
  summary.prior_path = FLAGS_prior;
  summary.changed_groups = r->recalibration.changed;
  if (run.joint_error_selection.ran) {
    std::cerr << tools::JointErrorSelectionTable(run.joint_error_selection);
  }
  if (run.residual_model_selection.ran) {
    std::cerr << tools::ResidualModelSelectionTable(run.residual_model_selection);
  }
  if (run.registered && result.termination != Termination::kNotIdentifiable) {
    PrintRegistration(run);
  }
  std::cout << "\n";
  const std::string& hint = r->in.angle_unit_hint;
  if (result.termination == Termination::kNotIdentifiable) {
    std::cerr << "error: " << result.message << (hint.empty() ? "" : " (" + hint + ")") << "\n";
    return tools::ExitCodeFor(result.termination);
  }
  PrintIdentifiability(summary.identifiability, result.parameterization.num_frame_parameters());
  std::cout << tools::JointTermsIdentifiability(result);
  std::cerr << tools::GravityTiltSummary(result.gravity_tilt);
  std::cout << "\n";
  tools::PrintIterationTable(std::cout, result);
  std::cout << "\n";
  tools::PrintBeforeAfter(std::cout, "identification set", summary.identification_before,
                          summary.identification_after);
  if (run.has_verification) {
    std::cout << "\n";
    tools::PrintBeforeAfter(std::cout, "verification set", summary.verification_before,
                            summary.verification_after);
  }
  if (const std::string layer = tools::ResidualLayerSummaryText(run); !layer.empty()) {
    std::cout << "\n" << layer;
  }
  // Per-point residuals (about 170 bytes a row) only for the outputs that show them.
  if (!FLAGS_report.empty() || !FLAGS_html_report.empty() || !FLAGS_plots_dir.empty()) {
    tools::AddPointResiduals(run.before, result.model, r->in.identification, r->in.verification,
                             &summary);
  }
  PrintOutliers(summary, r->paths.measurements);
  PrintFolds(run, r->in.identification.size());
  std::cout << "\nresult: " << TerminationName(result.termination) << " after "
            << result.iterations << " iteration(s), " << result.wall_time_seconds * 1e3 << " ms ("
            << result.message << ")\n";
  if (!result.converged()) {
    std::cerr << "error: " << result.message << "; no output written"
              << (hint.empty() ? "" : " (" + hint + ")") << "\n";
    return tools::ExitCodeFor(result.termination);
  }
  return kExitOk;
}

// The plausibility verdict printed; exit 8 when it fails without --force.
int JudgeVerdict(const Verdict& verdict) {
  std::cout << "verdict: " << VerdictLevelName(verdict.level) << ": " << verdict.reason << "\n";
  for (const VerdictCheck& c : verdict.checks) {
    if (c.level != VerdictLevel::kPass) {
      std::cerr << (c.level == VerdictLevel::kFail ? "error" : "warning") << ": " << c.name << ": "
                << c.message << "\n";
    }
  }
  if (verdict.level == VerdictLevel::kFail && !FLAGS_force) {
    std::cerr << "error: the calibration is not plausible (" << verdict.reason
              << "); no output written (--force writes it anyway)\n";
    return tools::kExitImplausible;
  }
  return kExitOk;
}

// --output: the calibrated model with its registration and covariance, staged. Exit 5 when it
// is not finite (nothing is committed).
int StageModelYaml(const PipelineResult& run, tools::OutputSet* outputs, Status* staged) {
  // The registration goes with the model: compensation carries nominal poses into its frame.
  const RobotModel calibrated = CalibratedModel(run);
  // Non-finite values are written nowhere (lpoe/model/refusals.h): exit 5, nothing committed.
  if (Status s = CheckModelFinite(calibrated); !s.ok()) {
    std::cerr << "error: --output=" << FLAGS_output << ": " << s.message() << "\n";
    return tools::kExitNumerical;
  }
  // The estimate's covariance goes with it (the prior of a later recalibration, --prior).
  *staged = outputs->Stage(FLAGS_output, CalibratedModelYaml(calibrated, run.result));
  return kExitOk;
}

// URDF and UR kinematics carry geometry only: what they lack, said on stderr.
void WarnGeometryOutputs(const PipelineResult& run) {
  const CalibrationResult& result = run.result;
  if (!result.model.joint_errors.empty()) {
    const auto rms = [](const ErrorStatistics& e) { return e.norm.rms; };
    std::cerr << "warning: URDF and UR kinematics cannot hold the identified joint-error terms ("
              << tools::JointErrorTermNames(result.model) << ")";
    if (run.has_geometry_only) {
      std::cerr << "; they get a geometry-only re-fit of the same data: RMS error "
                << (run.has_verification ? rms(run.geometry_only_verification)
                                         : rms(run.geometry_only_identification))
                << " mm against " << (run.has_verification ? rms(run.verification_after)
                                                           : rms(run.identification_after))
                << " mm for the model with the terms ("
                << (run.has_verification ? "verification" : "identification") << " set)";
    } else {
      std::cerr << "; the geometry-only re-fit did not converge: they carry the geometry "
                   "identified with the terms, which predicts worse without them";
    }
    std::cerr << ". Predict or compensate with the YAML model (--output; lpoe_predict, "
                 "lpoe_compensate), which keeps the terms\n";
  }
  if (result.model.residual_layer) {
    std::cerr << "warning: URDF and UR kinematics cannot carry the residual layer "
                 "(docs/residual_layer.md): they predict without its correction. Predict or "
                 "compensate with the YAML model (--output), which keeps it\n";
  }
}

// Each model written, with what it predicts on its own (the reports' output_models).
void AddOutputModels(const PipelineResult& run, tools::RunSummary* summary) {
  const CalibrationResult& result = run.result;
  const bool v = run.has_verification;
  const auto rms = [](const ErrorStatistics& e) { return e.norm.rms; };
  const double full = v ? rms(run.verification_after) : rms(run.identification_after);
  const char* set = v ? "verification" : "identification";
  double geometry = full;
  std::string lacks;
  if (!result.model.joint_errors.empty()) {
    geometry = run.has_geometry_only ? (v ? rms(run.geometry_only_verification)
                                          : rms(run.geometry_only_identification))
                                     : -1;
    lacks = "the joint-error terms (" + tools::JointErrorTermNames(result.model) +
            "): a geometry-only re-fit";
  }
  if (result.model.residual_layer) {
    lacks += std::string(lacks.empty() ? "" : "; ") + "the residual layer";
  }
  if (!FLAGS_output.empty()) {
    summary->output_models.push_back({"--output", FLAGS_output, full, set, false, ""});
  }
  for (const auto& [flag, path] :
       {std::pair<std::string, std::string>{"--urdf_output", FLAGS_urdf_output},
        {"--ur_kinematics_output", FLAGS_ur_kinematics_output}}) {
    if (path.empty()) continue;
    summary->output_models.push_back(
        {flag, path, geometry >= 0 ? geometry : full, set, !lacks.empty(),
         lacks.empty() ? "" : "it cannot carry " + lacks + "; predict and compensate with the "
                              "YAML model"});
  }
}

// --urdf_output and --ur_kinematics_output: the geometry (with joint-space terms, the
// geometry-only re-fit of the same data) in the YAML's base frame, staged.
Status StageGeometryOutputs(CalibrationRun* r, Status staged) {
  const PipelineResult& run = r->recalibration.run;
  UrdfOverlayOptions overlay;
  overlay.in_measurement_frame = run.registered && run.registration.moved;
  RobotModel geometry_model = run.has_geometry_only ? run.geometry_only.model : run.result.model;
  // With the registration the YAML records: the URDF's base frame is the YAML's (one model).
  if (overlay.in_measurement_frame) {
    geometry_model.T_measurement_base = run.registration.T_measurement_base;
  }
  if (!FLAGS_urdf_output.empty() && staged.ok()) {
    std::string xml;
    if (r->in.from_urdf) {
      staged = CalibratedUrdfOverlay(r->in.urdf, geometry_model, overlay, &xml);
    } else {
      xml = RobotModelToUrdf(geometry_model);
    }
    if (staged.ok()) staged = r->outputs.Stage(FLAGS_urdf_output, xml);
  }
  if (!FLAGS_ur_kinematics_output.empty() && staged.ok()) {
    std::string ur_yaml;
    staged = UrKinematicsYaml(r->in.urdf, geometry_model, overlay, &ur_yaml);
    if (staged.ok()) staged = r->outputs.Stage(FLAGS_ur_kinematics_output, ur_yaml);
  }
  return staged;
}

// The plots, the HTML page and the JSON report, staged; the report last so that it lists
// everything written (the page lists the models and plots, the report every file, itself and
// the page included).
Status StageReports(CalibrationRun* r, bool implausible, Status staged) {
  tools::RunSummary& summary = r->summary;
  summary.model_path = r->paths.model;
  summary.measurements_path = r->paths.measurements;
  summary.solver = FLAGS_solver;
  summary.parameterization = ParameterizationName(r->settings.parameterization);
  summary.data_kind = MeasurementKind(TrackerKindId(r->use_orientation)).name;
  summary.angle_unit = FLAGS_angle_unit;
  const std::string& plot_dir = r->plot_dir;
  if (!plot_dir.empty() && staged.ok()) {
    std::vector<std::pair<std::string, std::string>> plots;
    staged = tools::RenderPlotFiles(summary, &plots);
    for (size_t k = 0; k < plots.size() && staged.ok(); ++k) {
      staged = r->outputs.Stage(plot_dir + plots[k].first, plots[k].second);
    }
  }
  for (const std::string& o : {FLAGS_output, FLAGS_urdf_output, FLAGS_ur_kinematics_output}) {
    if (!o.empty()) summary.outputs.push_back(o);
  }
  if (!plot_dir.empty()) {
    for (const char* name : tools::kPlotFileNames) summary.outputs.push_back(plot_dir + name);
  }
  summary.forced = implausible;
  if (!FLAGS_html_report.empty() && staged.ok()) {
    std::string html;
    staged = tools::RunSummaryToHtml(summary, &html);
    if (staged.ok()) staged = r->outputs.Stage(FLAGS_html_report, html);
  }
  if (!FLAGS_html_report.empty()) summary.outputs.push_back(FLAGS_html_report);
  if (!FLAGS_report.empty()) summary.outputs.push_back(FLAGS_report);
  if (!FLAGS_report.empty() && staged.ok()) {
    staged = r->outputs.Stage(FLAGS_report, tools::RunSummaryToJson(summary));
  }
  return staged;
}

// The outputs: all staged first, then moved into place together.
int WriteOutputs(CalibrationRun* r) {
  const PipelineResult& run = r->recalibration.run;
  const bool implausible = run.verdict.level == VerdictLevel::kFail;
  Status staged = Status::Ok();
  if (!FLAGS_output.empty()) {
    if (int rc = StageModelYaml(run, &r->outputs, &staged); rc != kExitOk) return rc;
  }
  const bool geometry_outputs = !FLAGS_urdf_output.empty() || !FLAGS_ur_kinematics_output.empty();
  if (geometry_outputs && staged.ok()) WarnGeometryOutputs(run);
  AddOutputModels(run, &r->summary);
  staged = StageGeometryOutputs(r, staged);
  staged = StageReports(r, implausible, staged);
  std::vector<std::string> written;
  if (tools::CommitOutputs(staged, &r->outputs, false, &written) != kExitOk) return kExitOutput;
  if (written.empty()) std::cout << "(use --output=FILE to save the calibrated model)\n";
  if (implausible) {  // --force: written, but a script must still tell the result failed
    std::cerr << "error: the calibration is not plausible (" << run.verdict.reason
              << "); outputs written because of --force\n";
    return tools::kExitImplausible;
  }
  return kExitOk;
}

int Run() {
  // Ballbar distances and probe contacts (several files, or a distance or plane file): their own
  // run (lpoe_calibrate_contact.cc, docs/measurements.md).
  if (tools::ContactCalibrationRequested()) return tools::RunContactCalibration();
  CalibrationRun r;
  if (!tools::InputsFromFlags(&r.paths, &r.settings)) return kExitUsage;
  if (int rc = CheckCalibrateFlags(&r); rc != kExitOk) return rc;
  if (int rc = CheckOutputs(&r); rc != kExitOk) return rc;
  tools::Progress progress(FLAGS_quiet, FLAGS_max_iterations);
  if (int rc = LoadCalibrationInputs(&r, &progress); rc != kExitOk) return rc;
  PrintRunHeader(r);
  if (int rc = SolveCalibration(&r, &progress); rc != kExitOk) return rc;
  if (int rc = ReportResult(&r); rc != kExitOk) return rc;
  if (int rc = JudgeVerdict(r.recalibration.run.verdict); rc != kExitOk) return rc;
  return WriteOutputs(&r);
}

}  // namespace
}  // namespace lpoe

int main(int argc, char** argv) {
  lpoe::tools::InitTool(lpoe::kUsage, &argc, &argv);
  return lpoe::Run();
}
