// lpoe_calibrate: identify the local frames of a robot from tracker measurements.
//
// Reads a nominal model (YAML) and measurements (CSV), registers the model to the measurement frame,
// runs the chosen solver, prints the identifiability report, the convergence table and before/after
// errors on the identification and verification sets, and writes the calibrated model, a JSON
// report and plots. With no arguments it calibrates the shipped section-4 data set.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <string>

#include <gflags/gflags.h>
#include <glog/logging.h>

#include "lpoe/analysis.h"
#include "lpoe/ceres_solver.h"
#include "lpoe/io.h"
#include "lpoe/linear_solver.h"
#include "lpoe/registration.h"
#include "lpoe/statistics.h"
#include "lpoe/urdf.h"
#include "plot.h"
#include "report.h"
#include "tool_common.h"

DEFINE_string(model, "",
              "Nominal robot model: YAML, or URDF when the name ends in .urdf (metres converted to "
              "mm, fixed joints folded in). Default: data/cobot6.yaml.");
DEFINE_string(measurements, "",
              "Identification measurements (CSV: q1..qN,x,y,z[,target][,quat_x..quat_w]). "
              "Default: data/section4/identification.csv.");
DEFINE_string(verify, "",
              "Verification measurements (CSV), never used for identification. Default with the "
              "default measurements: data/section4/verification.csv.");
DEFINE_double(holdout, 0.0,
              "Instead of --verify: hold out this fraction of the measurements (0 <= f < 1), "
              "chosen at random with --split_seed, for verification.");
DEFINE_int32(kfold, 0,
             "Also run k-fold cross-validation with this many folds (>= 2; 0 = off) on the "
             "identification set and report each fold's held-out errors.");
DEFINE_uint64(split_seed, 1, "Seed of the --holdout and --kfold splits.");
DEFINE_string(output, "", "Write the calibrated model here (YAML). Nothing is written on failure.");
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
DEFINE_string(report, "", "Write a machine-readable JSON report here (schema in the README).");
DEFINE_string(html_report, "",
              "Write a self-contained HTML report here (verdict, statistics, plots, parameters; "
              "no scripts, inline SVG). Nothing is written on failure.");
DEFINE_string(plots_dir, "lpoe_plots",
              "Directory for the PNG plots (convergence, per-axis errors, histogram); created if "
              "missing. Empty: no plots.");
DEFINE_string(solver, "linear",
              "linear: the paper's iterative least squares; ceres: Levenberg-Marquardt on SE(3) "
              "manifolds (robust losses, a-priori covariance).");
DEFINE_string(loss, "none",
              "Ceres solver: robust loss against gross errors in the data: none | huber | cauchy.");
DEFINE_double(loss_scale, 1.0,
              "Ceres solver: scale of the robust loss in mm (errors above it are down-weighted).");
DEFINE_double(sigma, 1.0,
              "Ceres solver: measurement noise per axis in mm (residual whitening; sets the scale "
              "of the covariance). Not given: the covariance is scaled by the noise estimated "
              "from the residuals, as with the linear solver.");
DEFINE_int32(threads, 0, "Ceres solver: threads (0: all hardware threads).");
DEFINE_string(parameterization, "identifiable",
              "identifiable: only the directions the data can see (27 for a 6R arm with position "
              "data); full: 6 per local frame, solved as a minimum-norm pseudo-inverse (the "
              "paper's 42).");
DEFINE_string(data_kind, "auto",
              "position | pose | auto: pose-based calibration (paper eqs. 17-24) uses the measured "
              "orientations; auto picks pose when the CSV has quat_* columns.");
DEFINE_string(angle_unit, "rad", "Unit of revolute joint values in the CSV files: rad | deg.");
DEFINE_string(length_unit, "mm",
              "Unit of x, y, z (and prismatic joint values) in the CSV files: mm | m.");
DEFINE_bool(register, true,
            "Register the model to the measurement frame first when the measurements are not in "
            "its base frame (a rigid fit that moves the base by more than 50 mm or 0.05 rad): "
            "rigid fit, then base and tool frames, then everything.");
DEFINE_double(outlier_threshold, 5.0,
              "List points whose error after the fit exceeds this many robust sigmas.");
DEFINE_int32(max_iterations, 30, "Iteration limit.");
DEFINE_double(step_tolerance, 1e-10, "Convergence: stop when |x| falls below this.");
DEFINE_double(max_condition, 1e8,
              "Refuse data whose column-scaled Jacobian has a larger condition number.");

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
    "Exit codes: 0 converged, 1 bad flags, 2 bad input file, 3 data cannot identify the model,\n"
    "4 iteration limit reached, 5 numerical failure, 6 output not written.";

struct Job {
  RobotModel nominal;
  MeasurementSet identification, verification;
  bool use_orientation = false;
  ParameterizationKind kind = ParameterizationKind::kIdentifiable;
};

// Prints a progress line to stderr once a run has taken more than a second.
class Progress {
 public:
  explicit Progress(std::string what) : what_(std::move(what)) {}
  ~Progress() {
    if (shown_) std::cerr << "\n";
  }
  void Update(const IterationRecord& r) {
    const double t = std::chrono::duration<double>(Clock::now() - start_).count();
    if (t < 1.0) return;
    shown_ = true;
    char line[160];
    std::snprintf(line, sizeof(line), "\r%s: iteration %d, max error %.4f mm, %.1f s", what_.c_str(),
                  r.iteration, r.max_error, t);
    std::cerr << line << std::flush;
  }

 private:
  using Clock = std::chrono::steady_clock;
  std::string what_;
  Clock::time_point start_ = Clock::now();
  bool shown_ = false;
};

// The Ceres solver's options from the flags (validated in Run()).
CeresSolverOptions CeresOptionsFromFlags(const Job& job) {
  CeresSolverOptions options;
  options.parameterization = job.kind;
  options.use_orientation = job.use_orientation;
  options.max_iterations = FLAGS_max_iterations;
  options.max_condition_number = FLAGS_max_condition;
  options.loss = FLAGS_loss;
  options.loss_scale = FLAGS_loss_scale;
  options.sigma = FLAGS_sigma;
  // Without a stated noise level, estimate it from the residuals (as the linear solver does).
  options.a_posteriori_covariance = gflags::GetCommandLineFlagInfoOrDie("sigma").is_default;
  if (FLAGS_threads > 0) options.num_threads = FLAGS_threads;
  return options;
}

// Registration (optional) then the chosen solver. `registration` may be null.
CalibrationResult Solve(const Job& job, const MeasurementSet& data, const std::string& what,
                        RegistrationReport* registration, RobotModel* rigid_nominal) {
  RobotModel start = job.nominal;
  if (rigid_nominal) *rigid_nominal = job.nominal;
  if (FLAGS_register) {
    RegistrationReport local;
    RegistrationReport& rep = registration ? *registration : local;
    if (Status s = RegisterToMeasurements(job.nominal, data, &start, &rep); !s.ok()) {
      CalibrationResult failed;
      failed.model = job.nominal;
      failed.termination = Termination::kNotIdentifiable;
      failed.message = s.message();
      return failed;
    }
    if (!rep.moved) {
      // The data are in the base frame already: start from the nominal model, as the paper does.
      start = job.nominal;
    } else if (rigid_nominal) {
      rigid_nominal->joints[0].origin = rep.T_measurement_base * job.nominal.joints[0].origin;
    }
  }
  Progress progress(what);
  if (FLAGS_solver == "ceres") {
    CeresSolverOptions options = CeresOptionsFromFlags(job);
    options.on_iteration = [&](const IterationRecord& r) { progress.Update(r); };
    return CalibrateCeres(start, data, options);
  }
  LinearSolverOptions options;
  options.parameterization = job.kind;
  options.use_orientation = job.use_orientation;
  options.max_iterations = FLAGS_max_iterations;
  options.step_tolerance = FLAGS_step_tolerance;
  options.max_condition_number = FLAGS_max_condition;
  options.on_iteration = [&](const IterationRecord& r) { progress.Update(r); };
  CalibrationResult result = CalibrateLinear(start, data, options);
  // The history starts from the registered model; errors before calibration are reported
  // separately against the nominal model.
  return result;
}

void PrintIdentifiability(const IdentifiabilityReport& id) {
  std::cout << "identifiability: " << id.num_parameters << " parameters, rank " << id.rank
            << ", condition number of the column-scaled Jacobian " << id.condition_number << "\n";
  if (id.singular_values.size() > 0) {
    const auto& s = id.singular_values;
    std::cout << "  singular values: largest " << s(0) << ", smallest " << s(s.size() - 1) << "\n";
  }
  std::cout << "  not identifiable from this data kind (" << id.unidentifiable.size()
            << " directions, left out):\n";
  std::string last_reason;
  std::string names;
  auto flush = [&]() {
    if (!names.empty()) std::cout << "    " << names << ": " << last_reason << "\n";
    names.clear();
  };
  for (const Direction& d : id.unidentifiable) {
    if (d.reason != last_reason) {
      flush();
      last_reason = d.reason;
    }
    names += (names.empty() ? "" : ", ") + d.name;
  }
  flush();
  if (id.standard_deviation.size() > 0) {
    // The least certain parameters, as a quick read; all of them are in the JSON report.
    std::vector<int> order(id.standard_deviation.size());
    for (size_t k = 0; k < order.size(); ++k) order[k] = static_cast<int>(k);
    std::sort(order.begin(), order.end(), [&](int a, int b) {
      return id.standard_deviation(a) > id.standard_deviation(b);
    });
    std::cout << "  largest standard deviations (rad or mm):";
    for (int k = 0; k < std::min<int>(4, static_cast<int>(order.size())); ++k) {
      std::cout << " " << id.parameter_names[order[k]] << " " << id.standard_deviation(order[k]);
    }
    std::cout << "\n  most correlated pairs:";
    for (const CorrelatedPair& c : id.most_correlated) {
      std::cout << " " << c.a << "/" << c.b << " " << c.correlation << ";";
    }
    std::cout << "\n";
  }
  for (const std::string& w : id.warnings) std::cout << "  warning: " << w << "\n";
}

int Run() {
  const tools::InputPaths paths =
      tools::ResolveInputPaths(FLAGS_model, FLAGS_measurements, FLAGS_verify, FLAGS_holdout != 0.0);
  const std::string& model_path = paths.model;
  const std::string& meas_path = paths.measurements;
  const std::string& verify_path = paths.verify;

  // ---- Flags.
  AngleUnit unit;
  Job job;
  if (!tools::ParseAngleUnit(FLAGS_angle_unit, &unit)) {
    std::cerr << "error: --angle_unit must be rad or deg, got '" << FLAGS_angle_unit << "'\n";
    return kExitUsage;
  }
  CsvOptions csv;
  csv.angle_unit = unit;
  if (!ParseLengthUnit(FLAGS_length_unit, &csv.length_unit)) {
    std::cerr << "error: --length_unit must be mm or m, got '" << FLAGS_length_unit << "'\n";
    return kExitUsage;
  }
  if (!ParseParameterization(FLAGS_parameterization, &job.kind)) {
    std::cerr << "error: --parameterization must be identifiable or full, got '"
              << FLAGS_parameterization << "'\n";
    return kExitUsage;
  }
  if (FLAGS_solver != "linear" && FLAGS_solver != "ceres") {
    std::cerr << "error: --solver must be linear or ceres, got '" << FLAGS_solver << "'\n";
    return kExitUsage;
  }
  if (FLAGS_threads < 0) {
    std::cerr << "error: --threads must be >= 0, got " << FLAGS_threads << "\n";
    return kExitUsage;
  }
  if (Status s = ValidateCeresSolverOptions(CeresOptionsFromFlags(job)); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
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
  if (!(FLAGS_holdout >= 0.0 && FLAGS_holdout < 1.0)) {
    std::cerr << "error: --holdout must be in [0, 1), got " << FLAGS_holdout << "\n";
    return kExitUsage;
  }
  if (FLAGS_holdout > 0.0 && !FLAGS_verify.empty()) {
    std::cerr << "error: give either --verify or --holdout, not both\n";
    return kExitUsage;
  }
  if (FLAGS_kfold == 1 || FLAGS_kfold < 0 || FLAGS_kfold > 100) {
    std::cerr << "error: --kfold must be 0 (off) or between 2 and 100, got " << FLAGS_kfold << "\n";
    return kExitUsage;
  }
  if (FLAGS_max_iterations < 1 || FLAGS_max_iterations > 100000 ||
      !(FLAGS_step_tolerance > 0) || !(FLAGS_max_condition > 1) ||
      !(FLAGS_outlier_threshold > 0)) {
    std::cerr << "error: --max_iterations must be in [1, 100000], --step_tolerance > 0, "
                 "--max_condition > 1, --outlier_threshold > 0\n";
    return kExitUsage;
  }
  UrdfOptions urdf_options;
  if (!tools::UrdfOptionsFromFlags(model_path, &urdf_options) ||
      (!FLAGS_ur_kinematics_output.empty() && !IsUrdfPath(model_path))) {
    std::cerr << "error: --base_link, --tip_link, --tool_links and --ur_kinematics_output need a "
                 "URDF --model (a name ending in .urdf)\n";
    return kExitUsage;
  }
  for (const std::string& out : {FLAGS_output, FLAGS_report, FLAGS_urdf_output,
                                  FLAGS_ur_kinematics_output, FLAGS_html_report}) {
    for (const std::string& in : {model_path, meas_path, verify_path}) {
      if (!out.empty() && tools::SameFile(out, in)) {
        std::cerr << "error: an output would overwrite the input file " << in << "\n";
        return kExitUsage;
      }
    }
  }
  if (!FLAGS_output.empty() && tools::SameFile(FLAGS_output, FLAGS_report)) {
    std::cerr << "error: --output and --report name the same file\n";
    return kExitUsage;
  }
  if (!FLAGS_html_report.empty() && (tools::SameFile(FLAGS_html_report, FLAGS_report) ||
                                     tools::SameFile(FLAGS_html_report, FLAGS_output))) {
    std::cerr << "error: --html_report names the same file as --report or --output\n";
    return kExitUsage;
  }

  // ---- Inputs.
  tools::RunSummary summary;
  UrdfSource urdf_source;  // the URDF --model, for the overlay write-back
  bool from_urdf = false;
  {
    tools::Inputs in;
    if (Status s = tools::LoadInputs(model_path, meas_path, verify_path, csv, FLAGS_holdout,
                                     FLAGS_split_seed, &in, urdf_options);
        !s.ok()) {
      std::cerr << "error: " << s.message() << "\n";
      return kExitInput;
    }
    from_urdf = in.from_urdf;
    urdf_source = std::move(in.urdf);
    // The UR file needs a UR arm with z axes: checked on the nominal model before solving.
    std::string ur_yaml;
    if (!FLAGS_ur_kinematics_output.empty()) {
      if (Status s = UrKinematicsYaml(urdf_source, in.nominal, {}, &ur_yaml); !s.ok()) {
        std::cerr << "error: --ur_kinematics_output: " << s.message() << "\n";
        return kExitUsage;
      }
    }
    job.nominal = std::move(in.nominal);
    job.identification = std::move(in.identification);
    job.verification = std::move(in.verification);
    summary.skipped = std::move(in.skipped);
    summary.verification_source = std::move(in.verification_source);
  }

  job.use_orientation = job.identification.has_orientation();
  if (FLAGS_data_kind == "position") job.use_orientation = false;
  if (FLAGS_data_kind == "pose" && !job.identification.has_orientation()) {
    std::cerr << "error: --data_kind=pose needs quat_x,quat_y,quat_z,quat_w columns in "
              << meas_path << "\n";
    return kExitUsage;
  }

  std::cout << "model:          " << model_path << " (" << job.nominal.num_joints()
            << " joints, " << job.nominal.num_tools() << " tool"
            << (job.nominal.num_tools() > 1 ? "s" : "") << ")\n"
            << "identification: " << meas_path << " (" << job.identification.size() << " rows)\n";
  if (!job.verification.empty()) {
    std::cout << "verification:   "
              << (verify_path.empty() ? "held out from the identification file" : verify_path)
              << " (" << job.verification.size() << " rows)\n";
  }
  std::cout << "solver:         " << FLAGS_solver << ", " << ParameterizationName(job.kind)
            << " parameterization, " << (job.use_orientation ? "pose" : "position") << " data\n";

  // ---- Solve.
  RobotModel before_model;
  const CalibrationResult result =
      Solve(job, job.identification, "calibrating", &summary.registration, &before_model);
  summary.registered = FLAGS_register;
  if (FLAGS_register && result.termination != Termination::kNotIdentifiable) {
    const RegistrationReport& reg = summary.registration;
    if (reg.moved) {
      std::cout << reg.message << "\n";
    } else {
      std::cout << "registration: not needed, the data are in the model's base frame (a rigid fit "
                   "would move the base by only "
                << reg.T_measurement_base.t.norm() << " mm and "
                << LogSO3(reg.T_measurement_base.R).norm() << " rad)\n";
    }
    if (summary.registration.moved) {
      std::cout << "(the measurements are not in the model's base frame: 'before calibration' "
                   "below is the nominal model after the rigid fit)\n";
    }
  }
  std::cout << "\n";
  if (result.termination == Termination::kNotIdentifiable) {
    std::cerr << "error: " << result.message << "\n";
    return tools::ExitCodeFor(result.termination);
  }
  summary.result = result;
  summary.identifiability = AnalyzeIdentifiability(job.nominal, job.identification, result);
  PrintIdentifiability(summary.identifiability);
  std::cout << "\n";
  tools::PrintIterationTable(std::cout, result);
  std::cout << "\n";
  summary.identification_before = PositionErrorStatistics(before_model, job.identification);
  summary.identification_after = PositionErrorStatistics(result.model, job.identification);
  tools::PrintBeforeAfter(std::cout, "identification set", summary.identification_before,
                          summary.identification_after);
  if (!job.verification.empty()) {
    summary.has_verification = true;
    summary.verification_before = PositionErrorStatistics(before_model, job.verification);
    summary.verification_after = PositionErrorStatistics(result.model, job.verification);
    std::cout << "\n";
    tools::PrintBeforeAfter(std::cout, "verification set", summary.verification_before,
                            summary.verification_after);
  }

  tools::AddPointResiduals(before_model, result.model, job.identification, job.verification,
                           &summary);

  // ---- Points that do not fit.
  summary.outliers = FindOutliers(result.model, job.identification, FLAGS_outlier_threshold,
                                  &summary.robust_sigma);
  if (!summary.outliers.empty()) {
    std::cout << "\n" << summary.outliers.size() << " point(s) fit worse than "
              << FLAGS_outlier_threshold << " robust sigmas (" << summary.robust_sigma
              << " mm per axis); they were used, check them:\n";
    for (size_t k = 0; k < std::min<size_t>(summary.outliers.size(), 20); ++k) {
      const Outlier& o = summary.outliers[k];
      std::cout << "  " << meas_path << ":" << o.line << ": error " << o.error << " mm ("
                << o.sigmas << " sigma)\n";
    }
  }

  // ---- k-fold cross-validation.
  if (FLAGS_kfold >= 2) {
    const auto folds = KFolds(job.identification.size(), FLAGS_kfold, FLAGS_split_seed);
    std::cout << "\n" << FLAGS_kfold << "-fold cross-validation (held-out position error, mm)\n"
              << "  fold  rows   termination        max      mean       rms       p95\n";
    std::vector<Eigen::Vector3d> pooled;
    for (int f = 0; f < FLAGS_kfold; ++f) {
      const MeasurementSet train =
          job.identification.Subset(Complement(job.identification.size(), folds[f]));
      const MeasurementSet test = job.identification.Subset(folds[f]);
      const CalibrationResult r =
          Solve(job, train, "fold " + std::to_string(f + 1), nullptr, nullptr);
      tools::FoldResult fr;
      fr.fold = f + 1;
      fr.identification_rows = train.size();
      fr.termination = TerminationName(r.termination);
      const std::vector<Eigen::Vector3d> e = PositionErrors(r.model, test);
      pooled.insert(pooled.end(), e.begin(), e.end());
      fr.verification_after = ComputeStatistics(e);
      char line[200];
      std::snprintf(line, sizeof(line), "  %4d %5d   %-16s %8.4f %9.4f %9.4f %9.4f\n", fr.fold,
                    fr.identification_rows, r.converged() ? "converged" : "FAILED",
                    fr.verification_after.norm.max_abs, fr.verification_after.norm.mean_abs,
                    fr.verification_after.norm.rms, fr.verification_after.norm.p95_abs);
      std::cout << line;
      summary.folds.push_back(fr);
    }
    const ErrorStatistics all_folds = ComputeStatistics(pooled);
    char line[200];
    std::snprintf(line, sizeof(line), "   all %5d   %-16s %8.4f %9.4f %9.4f %9.4f\n",
                  job.identification.size(), "", all_folds.norm.max_abs,
                  all_folds.norm.mean_abs, all_folds.norm.rms, all_folds.norm.p95_abs);
    std::cout << line;
  }

  std::cout << "\nresult: " << TerminationName(result.termination) << " after "
            << result.iterations << " iteration(s), " << result.wall_time_seconds * 1e3 << " ms\n";
  if (!result.converged()) {
    std::cerr << "error: " << result.message << "; no output written\n";
    return tools::ExitCodeFor(result.termination);
  }

  // ---- Outputs (each written atomically; the model first, the report last so that it lists
  // everything written).
  if (!FLAGS_output.empty()) {
    // The registration goes with the model: compensation carries nominal poses into its frame.
    RobotModel calibrated = result.model;
    if (summary.registered && summary.registration.moved) {
      calibrated.T_measurement_base = summary.registration.T_measurement_base;
    }
    if (Status s = WriteRobotModel(FLAGS_output, calibrated); !s.ok()) {
      std::cerr << "error: " << s.message() << "\n";
      return kExitOutput;
    }
    summary.outputs.push_back(FLAGS_output);
  }
  UrdfOverlayOptions overlay;
  overlay.in_measurement_frame = FLAGS_register && summary.registration.moved;
  if (!FLAGS_urdf_output.empty()) {
    if (Status s = from_urdf ? WriteCalibratedUrdf(FLAGS_urdf_output, urdf_source, result.model,
                                                   overlay)
                             : WriteRobotModelUrdf(FLAGS_urdf_output, result.model);
        !s.ok()) {
      std::cerr << "error: " << s.message() << "\n";
      return kExitOutput;
    }
    summary.outputs.push_back(FLAGS_urdf_output);
  }
  if (!FLAGS_ur_kinematics_output.empty()) {
    if (Status s = WriteUrKinematicsYaml(FLAGS_ur_kinematics_output, urdf_source, result.model,
                                         overlay);
        !s.ok()) {
      std::cerr << "error: " << s.message() << "\n";
      return kExitOutput;
    }
    summary.outputs.push_back(FLAGS_ur_kinematics_output);
  }
  summary.model_path = model_path;
  summary.measurements_path = meas_path;
  summary.solver = FLAGS_solver;
  summary.parameterization = ParameterizationName(job.kind);
  summary.data_kind = job.use_orientation ? "pose" : "position";
  summary.angle_unit = FLAGS_angle_unit;
  if (!FLAGS_plots_dir.empty()) {
    if (Status s = tools::WritePlotFiles(FLAGS_plots_dir, &summary); !s.ok()) {
      std::cerr << "error: " << s.message() << "\n";
      return kExitOutput;
    }
  }
  if (!FLAGS_html_report.empty()) {
    if (Status s = tools::WriteHtmlReport(FLAGS_html_report, &summary); !s.ok()) {
      std::cerr << "error: " << s.message() << "\n";
      return kExitOutput;
    }
  }
  if (!FLAGS_report.empty()) {
    summary.outputs.push_back(FLAGS_report);
    if (Status s = WriteFileAtomically(FLAGS_report, tools::RunSummaryToJson(summary)); !s.ok()) {
      std::cerr << "error: " << s.message() << "\n";
      return kExitOutput;
    }
  }
  if (summary.outputs.empty()) {
    std::cout << "(use --output=FILE to save the calibrated model)\n";
  } else {
    for (const std::string& o : summary.outputs) std::cout << "wrote " << o << "\n";
  }
  return kExitOk;
}

}  // namespace
}  // namespace lpoe

int main(int argc, char** argv) {
  lpoe::tools::InitTool(lpoe::kUsage, &argc, &argv);
  return lpoe::Run();
}
