// lpoe_calibrate for ballbar distances and probe contacts on planes (lpoe_calibrate_contact.h).
#include "lpoe_calibrate_contact.h"

#include <gflags/gflags.h>
#include <sys/stat.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iomanip>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "common/common_flags.h"
#include "lpoe/contact_calibration.h"
#include "lpoe/measurements/contact_measurements.h"
#include "lpoe/contact_pipeline.h"
#include "lpoe/io/io.h"
#include "lpoe/measurements/measurement_kinds.h"
#include "lpoe/options.h"
#include "lpoe/model/refusals.h"
#include "lpoe/registration.h"
#include "lpoe/io/urdf.h"
#include "common/output_files.h"
#include "report/contact_layer_report.h"
#include "report/plot.h"
#include "report/report.h"
#include "report/text_safety.h"
#include "common/tool_common.h"

DECLARE_string(measurements);
DECLARE_string(data_kind);
DECLARE_double(sigma);
DECLARE_string(solver);
DECLARE_double(holdout);
DECLARE_uint64(split_seed);
DECLARE_int32(max_iterations);
DECLARE_string(report);
DECLARE_string(html_report);
DECLARE_string(joint_errors);
DECLARE_string(residual_model);
DECLARE_string(loss);
DECLARE_string(verify);
DECLARE_int32(kfold);
DECLARE_string(fixed_tools);
DECLARE_string(urdf_output);
DECLARE_string(ur_kinematics_output);
DECLARE_string(parameterization);

DEFINE_string(sigmas, "",
              "One noise (mm, standard deviation) per --measurements file, comma-separated, for "
              "files without a sigma column (ballbar distances, probe contacts, tracker positions "
              "per axis). Default: --sigma when given, else each file's sigma column.");
DEFINE_string(hold_scale, lpoe::OptionDefaultText("lpoe_calibrate", "hold_scale"),
              lpoe::OptionHelp("lpoe_calibrate", "hold_scale"));

namespace lpoe {
namespace tools {
namespace {

std::vector<std::string> SplitList(const std::string& text) {
  std::vector<std::string> out;
  std::stringstream ss(text);
  for (std::string item; std::getline(ss, item, ',');) out.push_back(item);
  return out;
}

bool SigmaGiven() {
  gflags::CommandLineFlagInfo info;
  return gflags::GetCommandLineFlagInfo("sigma", &info) && !info.is_default;
}

std::string HtmlEscape(const std::string& text) {
  std::string out;
  for (char c : ValidUtf8(text)) {
    switch (c) {
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '&': out += "&amp;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

// The figures of one pivot or plane as JSON (the kind's table per feature).
// Okabe-Ito colours for the pivots' and planes' series (after the held-out grey).
const uint32_t kContactFeatureColors[] = {0x0072B2, 0xD55E00, 0x009E73, 0xCC79A7,
                                          0xE69F00, 0x56B4E9, 0x000000};

// One panel per kind: each row's error (distance, plane: signed; tracker: |e|) against its index
// among the kind's rows, a series per pivot or plane, the held-out or verification rows after
// them in grey.
Figure ContactErrorFigure(const ContactPipelineResult& run, const std::string& held_label) {
  Figure figure;
  for (const ContactKindSummary& summary : run.kinds) {
    const MeasurementKindId id = summary.kind->id;
    // From the kind's line of the table: a kind with a feature (a pivot, a plane) has one signed
    // residual per row and a series per feature; a tracker kind (no feature) the length of its
    // error, one series.
    const bool per_feature = summary.kind->feature_size > 0;
    Panel panel;
    panel.title = summary.kind->report_table;
    panel.x_label = "row";
    panel.y_label = per_feature ? "error [mm]" : "|error| [mm]";
    panel.zero_line = per_feature;
    panel.integer_x = true;
    const int num_features = per_feature ? static_cast<int>(summary.features.size()) : 1;
    std::vector<Series> series(num_features);
    Series held;
    held.label = held_label;
    held.rgb = 0x999999;
    const auto add = [&](const ContactMeasurementSet& set, const std::vector<double>& errors,
                         bool is_held, int* index) {
      for (int r = 0; r < set.size(); ++r) {
        if (set.rows[r].kind != id) continue;
        ++*index;
        Series* target = &held;
        if (!is_held) {
          // The feature's series (features with identification rows, in the summary's order).
          int k = 0;
          if (per_feature) {
            // The set keeps each feature kind's names apart (pivots, planes).
            const std::vector<std::string>& names =
                id == MeasurementKindId::kDistance ? set.pivots : set.planes;
            while (k < num_features && summary.features[k].name != names[set.rows[r].feature]) ++k;
            if (k == num_features) continue;
          }
          target = &series[k];
        }
        target->x.push_back(*index);
        target->y.push_back(errors[r]);
      }
    };
    int index = 0;
    add(run.identification, run.calibration.errors, false, &index);
    if (!run.held_errors.empty()) add(run.held, run.held_errors, true, &index);
    for (int k = 0; k < num_features; ++k) {
      series[k].label = per_feature ? std::string(summary.kind->feature_noun) + " " +
                                          ValidUtf8(summary.features[k].name)
                                    : std::string("tracker");
      series[k].rgb = kContactFeatureColors[k % (sizeof(kContactFeatureColors) /
                                                  sizeof(kContactFeatureColors[0]))];
    }
    if (!held.y.empty()) series.push_back(held);
    for (Series& one : series) {
      one.markers = true;
      one.lines = false;
      // Large sets: the per-bucket extremes (the same picture, fewer points).
      const std::vector<int> keep = DecimatedIndices(one.y, 2000);
      if (keep.size() < one.y.size()) {
        Series d = one;
        d.x.clear();
        d.y.clear();
        for (int i : keep) {
          d.x.push_back(one.x[i]);
          d.y.push_back(one.y[i]);
        }
        one = d;
      }
      if (!one.y.empty()) panel.series.push_back(one);
    }
    figure.panels.push_back(panel);
  }
  figure.columns = 1;
  figure.width = 900;
  figure.height = std::max(300, 280 * static_cast<int>(figure.panels.size()));
  return figure;
}

int ExitFor(const ContactCalibrationResult& r) {
  if (r.ok) return kExitOk;
  if (r.iterations == 0) return kExitNotIdentifiable;
  return r.message.find("iteration") != std::string::npos ? kExitNotConverged : kExitNumerical;
}

}  // namespace

bool ContactCalibrationRequested() {
  const MeasurementKindInfo* flag_kind = FindMeasurementKind(FLAGS_data_kind);
  if (flag_kind != nullptr && (flag_kind->id == MeasurementKindId::kDistance ||
                               flag_kind->id == MeasurementKindId::kPlane)) {
    return true;
  }
  if (FLAGS_measurements.find(',') != std::string::npos) return true;
  if (FLAGS_measurements.empty()) return false;
  // Only a regular file is looked at first (a pipe read for its header would be consumed).
  struct stat st;
  if (::stat(FLAGS_measurements.c_str(), &st) != 0 || !S_ISREG(st.st_mode)) return false;
  const MeasurementKindInfo* kind = nullptr;
  if (!DetectMeasurementFileKind(FLAGS_measurements, &kind).ok() || kind == nullptr) return false;
  return kind->id == MeasurementKindId::kDistance || kind->id == MeasurementKindId::kPlane;
}

namespace {

// What the steps of a contact calibration share: the options and files from the flags, the inputs
// read, the run, and the tables and JSON the summary builds for the outputs.
struct ContactRun {
  ContactCalibrationOptions options;
  UrdfOptions urdf_options;
  const MeasurementKindInfo* forced = nullptr;  // --data_kind (null: auto)
  std::vector<std::string> files, verify_files;
  std::vector<double> sigmas;
  AngleUnit angle;
  LengthUnit length;
  OutputSet outputs;
  RobotModel nominal;
  UrdfSource urdf_source;  // a URDF --model, for the URDF and UR write-back
  bool from_urdf = false;
  CsvOptions csv;
  ContactInputs inputs;
  ContactMeasurementSet verification;
  RobotModel start;
  ContactPipelineResult run;
  ResidualModelKind residual_model = ResidualModelKind::kNone;  // --residual_model
  std::string layer_text;  // the residual layer's lines of the summary (empty without one)
  const char* verify_label = "held-out RMS";
  // Built by the summary for the HTML page.
  std::string html_rows, html_feature_rows;
};

// The options of the calibration from the flags; what these kinds do not take refused.
int ContactOptionsFromFlags(ContactRun* job) {
  struct Unsupported {
    bool set;
    const char* flag;
  };
  for (const Unsupported& u :
       {Unsupported{FLAGS_loss != "none", "loss"},
        Unsupported{!FLAGS_fixed_tools.empty(), "fixed_tools"},
        Unsupported{FLAGS_parameterization != "identifiable", "parameterization"}}) {
    if (u.set) {
      std::cerr << "error: --" << u.flag << " is not available with distance or plane data: "
                << ContactRefusalReason(u.flag) << " (docs/measurements.md)\n";
      return kExitUsage;
    }
  }
  if (!ParseResidualModelKind(FLAGS_residual_model, &job->residual_model)) {
    std::cerr << "error: --residual_model must be none, gp or auto, got '" << FLAGS_residual_model
              << "'\n";
    return kExitUsage;
  }
  if (FLAGS_solver != "linear" && FLAGS_solver != "ceres") {
    std::cerr << "error: --solver must be linear or ceres, got '" << FLAGS_solver << "'\n";
    return kExitUsage;
  }
  ContactCalibrationOptions& options = job->options;
  if (!ParseScaleHold(FLAGS_hold_scale, &options.hold_scale)) {
    std::cerr << "error: --hold_scale must be auto, on or off, got '" << FLAGS_hold_scale << "'\n";
    return kExitUsage;
  }
  if (FLAGS_max_iterations < 1 || FLAGS_max_iterations > 10000) {
    std::cerr << "error: --max_iterations must be in [1, 10000]\n";
    return kExitUsage;
  }
  options.max_iterations = std::max(FLAGS_max_iterations, 30);
  if (!(FLAGS_holdout >= 0 && FLAGS_holdout < 1)) {
    std::cerr << "error: --holdout must be in [0, 1)\n";
    return kExitUsage;
  }
  if (FLAGS_kfold != 0 && !(FLAGS_kfold >= 2 && FLAGS_kfold <= 100)) {
    std::cerr << "error: --kfold must be 0 (off) or in [2, 100], got " << FLAGS_kfold << "\n";
    return kExitUsage;
  }
  if (!FLAGS_verify.empty() && FLAGS_holdout > 0) {
    std::cerr << "error: give either --verify or --holdout, not both\n";
    return kExitUsage;
  }
  if (!UrdfOptionsFromFlags(FLAGS_model, &job->urdf_options) ||
      (!FLAGS_ur_kinematics_output.empty() && !IsUrdfPath(FLAGS_model))) {
    std::cerr << "error: --base_link, --tip_link, --tool_links and --ur_kinematics_output need a "
                 "URDF --model (a name ending in .urdf)\n";
    return kExitUsage;
  }
  if (FLAGS_data_kind != "auto") {
    job->forced = FindMeasurementKind(FLAGS_data_kind);
    if (job->forced == nullptr) {
      std::cerr << "error: --data_kind must be auto or one of " << MeasurementKindNames()
                << ", got '" << FLAGS_data_kind << "'\n";
      return kExitUsage;
    }
  }
  job->verify_label = FLAGS_verify.empty() ? "held-out RMS" : "verify RMS";
  return kExitOk;
}

// The files and their noise, the units, and every output checked against the inputs and each
// other before any work.
int ContactFilesFromFlags(ContactRun* job) {
  std::vector<std::string>& files = job->files;
  files = SplitList(FLAGS_measurements);
  for (const std::string& f : files) {
    if (f.empty()) {
      std::cerr << "error: --measurements has an empty file name\n";
      return kExitUsage;
    }
  }
  std::vector<double>& sigmas = job->sigmas;
  sigmas.assign(files.size(), SigmaGiven() ? FLAGS_sigma : 0.0);
  if (!FLAGS_sigmas.empty()) {
    const std::vector<std::string> items = SplitList(FLAGS_sigmas);
    if (items.size() != files.size()) {
      std::cerr << "error: --sigmas has " << items.size() << " values for " << files.size()
                << " --measurements files\n";
      return kExitUsage;
    }
    for (size_t i = 0; i < items.size(); ++i) {
      char* end = nullptr;
      sigmas[i] = std::strtod(items[i].c_str(), &end);
      if (end == items[i].c_str() || *end != '\0' || !(sigmas[i] > 0 && sigmas[i] <= 1e3)) {
        std::cerr << "error: --sigmas: '" << items[i] << "' is not a noise in (0, 1000] mm\n";
        return kExitUsage;
      }
    }
  }
  if (SigmaGiven() && !(FLAGS_sigma > 0 && FLAGS_sigma <= 1e3)) {
    std::cerr << "error: --sigma must be in (0, 1000] mm\n";
    return kExitUsage;
  }
  if (!UnitsFromFlags(&job->angle, &job->length, nullptr)) return kExitUsage;
  if (FLAGS_model.empty()) {
    std::cerr << "error: --model is required with distance or plane data\n";
    return kExitUsage;
  }
  OutputSet& outputs = job->outputs;
  outputs.AddInput("--model", FLAGS_model);
  for (const std::string& f : files) outputs.AddInput("--measurements", f);
  job->verify_files =
      FLAGS_verify.empty() ? std::vector<std::string>() : SplitList(FLAGS_verify);
  for (const std::string& f : job->verify_files) {
    if (f.empty()) {
      std::cerr << "error: --verify has an empty file name\n";
      return kExitUsage;
    }
    outputs.AddInput("--verify", f);
  }
  outputs.AddOutput("--output", FLAGS_output);
  outputs.AddOutput("--urdf_output", FLAGS_urdf_output);
  outputs.AddOutput("--ur_kinematics_output", FLAGS_ur_kinematics_output);
  outputs.AddOutput("--report", FLAGS_report);
  outputs.AddOutput("--html_report", FLAGS_html_report);
  if (Status s = outputs.Check(); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitUsage;
  }
  return kExitOk;
}

// The model (checked for the UR file before solving) and the measurement files.
int ReadContactModelAndData(ContactRun* job) {
  job->from_urdf = IsUrdfPath(FLAGS_model);
  if (job->from_urdf) {
    if (Status s = ReadRobotModelUrdf(FLAGS_model, &job->nominal, job->urdf_options,
                                      &job->urdf_source);
        !s.ok()) {
      std::cerr << "error: " << s.message() << "\n";
      return kExitInput;
    }
  } else if (int code = ReadModelFlag(&job->nominal); code != kExitOk) {
    return code;
  }
  // The UR file needs a UR arm with z axes: checked on the nominal model before solving.
  if (!FLAGS_ur_kinematics_output.empty()) {
    std::string ur_yaml;
    if (Status s = UrKinematicsYaml(job->urdf_source, job->nominal, {}, &ur_yaml); !s.ok()) {
      std::cerr << "error: --ur_kinematics_output: " << s.message() << "\n";
      return kExitUsage;
    }
  }
  job->csv.angle_unit = job->angle;
  job->csv.length_unit = job->length;
  ContactInputOptions input_options;
  input_options.units = job->csv;
  input_options.forced_kind = job->forced;
  input_options.sigmas = job->sigmas;
  bool usage_error = false;
  if (Status s = ReadContactInputs(job->files, job->nominal, input_options, &job->inputs,
                                   &usage_error);
      !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return usage_error ? kExitUsage : kExitInput;
  }
  const ContactMeasurementSet& data = job->inputs.data;
  if (data.Count(MeasurementKindId::kDistance) + data.Count(MeasurementKindId::kPlane) == 0) {
    std::cerr << "error: no distance or plane file among --measurements (tracker data alone: "
                 "give one file, as always)\n";
    return kExitUsage;
  }
  return kExitOk;
}

// --verify: distance and plane files of the calibration's pivots and planes, evaluated with the
// features it estimates.
int ReadContactVerification(ContactRun* job) {
  if (job->verify_files.empty()) return kExitOk;
  std::vector<ContactMeasurementSet> parts;
  for (const std::string& f : job->verify_files) {
    const MeasurementKindInfo* kind = nullptr;
    if (Status s = DetectMeasurementFileKind(f, &kind); !s.ok()) {
      std::cerr << "error: " << s.message() << "\n";
      return kExitInput;
    }
    if (kind->id != MeasurementKindId::kDistance && kind->id != MeasurementKindId::kPlane) {
      std::cerr << "error: --verify " << f << ": a " << kind->name
                << " file; with distance or plane data --verify takes distance or plane files "
                   "(tracker rows: use --holdout)\n";
      return kExitUsage;
    }
    ContactCsvOptions o;
    o.units = job->csv;
    o.kind = kind;
    o.sigma = SigmaGiven() ? FLAGS_sigma : 0.0;
    ContactMeasurementSet part;
    if (Status s = ReadContactMeasurements(f, job->nominal, o, &part); !s.ok()) {
      std::cerr << "error: " << s.message() << "\n";
      return kExitInput;
    }
    parts.push_back(std::move(part));
  }
  if (Status s = ContactVerificationSet(job->inputs.data, parts, &job->verification); !s.ok()) {
    std::cerr << "error: --verify names a pivot or plane that --measurements does not (its "
                 "position is estimated from the calibration's rows): "
              << s.message() << "\n";
    return kExitInput;
  }
  return kExitOk;
}

// The start model (registered to the tracker's frame when tracker files are among the files)
// and the joint-space terms built on it.
int ContactStartAndTerms(ContactRun* job) {
  job->start = job->nominal;
  if (!FLAGS_joint_errors.empty() && FLAGS_joint_errors != "none" &&
      (!FLAGS_urdf_output.empty() || !FLAGS_ur_kinematics_output.empty())) {
    std::cerr << "error: --urdf_output and --ur_kinematics_output are not available with "
                 "--joint_errors and distance or plane data: URDF and UR kinematics cannot hold "
                 "the joint-space terms, and no geometry-only re-fit is made for these rows; "
                 "calibrate the geometry alone for them (docs/measurements.md)\n";
    return kExitUsage;
  }
  if (job->inputs.tracker.size() > 0) {
    if (!FLAGS_urdf_output.empty() || !FLAGS_ur_kinematics_output.empty()) {
      std::cerr << "error: --urdf_output and --ur_kinematics_output are not available with "
                   "tracker files among distance or plane files: "
                << ContactRefusalReason("urdf_with_tracker") << " (docs/measurements.md)\n";
      return kExitUsage;
    }
    // The tracker's frame: the model is registered to it first, so that the pivots and planes are
    // estimated in the tracker's frame and the base is seen.
    RegistrationReport report;
    if (Status s = RegisterToMeasurements(job->nominal, job->inputs.tracker, &job->start, &report);
        !s.ok()) {
      std::cerr << "error: registration to the tracker data: " << s.message() << "\n";
      return kExitNumerical;
    }
  }
  // --joint_errors: the registry's terms, built on the start model (their regressors' geometry);
  // auto: chosen by cross-validation on the identification rows (SelectContactJointErrors).
  const std::string terms = FLAGS_joint_errors == "auto" ? "none" : FLAGS_joint_errors;
  if (Status s = ContactJointTerms(terms, job->start, &job->options.joint_terms); !s.ok()) {
    std::cerr << "error: --joint_errors=" << s.message() << " (docs/measurements.md)\n";
    return kExitUsage;
  }
  return kExitOk;
}

// The run: hold-out rows (or --verify's), calibration, --kfold (the identification rows in k
// folds, shuffled by --split_seed + 1; each fold's rows predicted by the calibration of the
// others, with the same options), the figures per kind (lpoe/contact_pipeline.h).
int RunContactJob(ContactRun* job) {
  ContactPipelineOptions run_options;
  run_options.joint_errors_auto = FLAGS_joint_errors == "auto";
  run_options.solver = FLAGS_solver;
  run_options.calibration = job->options;
  run_options.holdout = FLAGS_holdout;
  run_options.split_seed = FLAGS_split_seed;
  run_options.kfold = FLAGS_kfold;
  run_options.residual_model = job->residual_model;
  job->run = RunContactPipeline(job->start, job->inputs.data, job->verification, run_options);
  const ContactPipelineResult& run = job->run;
  if (run.joint_error_selection.ran && !FLAGS_quiet) {
    std::cerr << JointErrorSelectionTable(run.joint_error_selection,
                                          "distance and plane errors (mm)");
  }
  const ContactCalibrationResult& result = run.calibration;
  if (!result.ok) {
    std::cerr << "error: " << (result.iterations == 0 ? "not identifiable: " : "") << result.message
              << "\n";
    return ExitFor(result);
  }
  if (run.kfold_too_large) {
    std::cerr << "error: --kfold=" << FLAGS_kfold << " " << run.message << "\n";
    return kExitUsage;
  }
  if (run.failed_fold >= 0) {
    std::cerr << "error: --kfold: fold " << run.failed_fold + 1 << " of " << FLAGS_kfold << ": "
              << run.message << "\n";
    return ExitFor(run.fold_failure);
  }
  if (Status s = CheckModelFinite(result.model); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitNumerical;
  }
  return kExitOk;
}

// The table per kind (printed, and as HTML rows for the page; the report's JSON:
// ContactReportJsonText).
void ContactKindTables(ContactRun* job, std::ostream& out) {
  const ContactPipelineResult& run = job->run;
  const ContactCalibrationResult& result = run.calibration;
  out << "lpoe_calibrate: " << run.identification.size() << " rows (";
  for (size_t i = 0; i < job->files.size(); ++i) {
    out << (i ? ", " : "") << job->files[i] << ": " << job->inputs.kinds[i];
  }
  out << "), solver " << result.solver << ", " << result.iterations << " iterations, cost "
      << result.initial_cost << " -> " << result.cost << "\n";
  out << std::left << std::setw(10) << "kind" << std::right << std::setw(7) << "rows"
      << std::setw(14) << "RMS (mm)" << std::setw(14) << "max (mm)" << std::setw(16)
      << "expected (mm)" << std::setw(9) << "verdict" << std::setw(16) << job->verify_label
      << (FLAGS_kfold > 0 ? "     k-fold RMS" : "") << "\n";
  for (const ContactKindSummary& summary : run.kinds) {
    const MeasurementKindInfo& kind = *summary.kind;
    const ContactKindFigures& f = summary.fit;
    const ContactKindFigures& h = summary.held;
    const ContactKindFigures& cv = summary.kfold;
    out << std::left << std::setw(10) << kind.name << std::right << std::setw(7) << f.rows
        << std::setw(14) << f.rms << std::setw(14) << f.max_abs << std::setw(16) << f.sigma
        << std::setw(9) << ContactKindVerdict(f) << std::setw(16)
        << (h.rows > 0 ? std::to_string(h.rms) : std::string("-"));
    if (FLAGS_kfold > 0) out << std::setw(15) << cv.rms;
    out << "\n";
    // The kind's table per pivot (distance) or per plane (plane).
    for (const ContactFeatureSummary& fs : summary.features) {
      std::ostringstream frow;
      frow << "<tr><td>" << kind.feature_noun << "</td><td>" << HtmlEscape(fs.name)
           << "</td><td>" << fs.fit.rows << "</td><td>" << fs.fit.rms << "</td><td>"
           << fs.fit.max_abs << "</td><td>" << fs.fit.sigma << "</td><td>"
           << ContactKindVerdict(fs.fit) << "</td><td>"
           << (fs.held.rows > 0 ? std::to_string(fs.held.rms) : "-") << "</td></tr>\n";
      job->html_feature_rows += frow.str();
    }
    std::ostringstream row;
    row << "<tr><td>" << kind.report_table << "</td><td>" << f.rows << "</td><td>" << f.rms
        << "</td><td>" << f.max_abs << "</td><td>" << f.sigma << "</td><td>"
        << ContactKindVerdict(f) << "</td><td>" << (h.rows > 0 ? std::to_string(h.rms) : "-")
        << "</td></tr>\n";
    job->html_rows += row.str();
  }
}

// The pivots and planes, the parameters, the joint-space terms, the base and the scale (printed).
void ContactEstimates(ContactRun* job, std::ostream& out) {
  const ContactCalibrationResult& result = job->run.calibration;
  const ContactMeasurementSet& identification = job->run.identification;
  const ContactParameterization& p = result.parameterization;
  for (size_t k = 0; k < result.features.pivots.size(); ++k) {
    const Eigen::Vector3d& c = result.features.pivots[k];
    out << "pivot " << ValidUtf8(identification.pivots[k]) << ": " << c.transpose() << " mm\n";
  }
  for (size_t k = 0; k < result.features.planes.size(); ++k) {
    const Eigen::Vector4d& pl = result.features.planes[k];
    out << "plane " << ValidUtf8(identification.planes[k]) << ": normal " << pl.head<3>().transpose()
        << ", n.x = " << pl(3) << " mm\n";
  }
  const int joint_parameters = p.frames.num_joint_parameters();
  out << "parameters: " << p.frames.num_parameters - joint_parameters << " of the robot, "
      << 3 * p.num_pivots << " of pivots, " << 3 * p.num_planes << " of planes";
  if (!p.frames.joint_blocks.empty()) out << ", " << joint_parameters << " of joint-space terms";
  out << "\n";
  // The joint-space terms' values (what the YAML's joint_errors carries).
  for (size_t b = 0; b < result.joint_terms.size(); ++b) {
    const JointTermValues& t = result.joint_terms[b];
    const int kept = static_cast<int>(p.frames.joint_blocks[b].basis.cols());
    out << "joint-space term " << t.term->name() << ": " << kept << " of "
        << t.term->num_parameters() << " combinations identified; values:";
    for (int k = 0; k < t.theta.size(); ++k) {
      out << " " << t.term->ParameterName(k) << "=" << t.theta(k);
    }
    out << "\n";
  }
  job->layer_text = ContactLayerText(job->run, FLAGS_kfold);
  out << job->layer_text;
  if (p.num_base_directions > 0) {
    out << "not identified (" << p.num_base_directions << " directions of the base): "
        << p.base_reason << "\n";
  }
  out << "scale: " << p.scale_reason << " (S = " << result.scale << ")\n";
}

// The model, its URDF and UR kinematics files and the JSON report, staged.
Status StageContactModelAndReport(ContactRun* job) {
  const ContactPipelineResult& run = job->run;
  const ContactCalibrationResult& result = run.calibration;
  OutputSet& outputs = job->outputs;
  Status staged;
  if (!FLAGS_output.empty()) {
    RobotModel calibrated = result.model;
    staged = outputs.Stage(FLAGS_output, RobotModelToYaml(calibrated));
  }
  // The URDF and UR outputs: the calibrated model is an ordinary one, in the robot's own base
  // frame (the base is left out and kept as given), so joint 1 keeps its URDF origin.
  if (staged.ok() && !FLAGS_urdf_output.empty()) {
    std::string xml;
    if (job->from_urdf) {
      staged = CalibratedUrdfOverlay(job->urdf_source, result.model, UrdfOverlayOptions(), &xml);
    } else {
      xml = RobotModelToUrdf(result.model);
    }
    if (staged.ok()) staged = outputs.Stage(FLAGS_urdf_output, xml);
  }
  if (staged.ok() && !FLAGS_ur_kinematics_output.empty()) {
    std::string ur_yaml;
    staged = UrKinematicsYaml(job->urdf_source, result.model, UrdfOverlayOptions(), &ur_yaml);
    if (staged.ok()) staged = outputs.Stage(FLAGS_ur_kinematics_output, ur_yaml);
  }
  if (staged.ok() && !FLAGS_report.empty()) {
    // The report's body as lpoe.calibrate writes it (report/contact_layer_report.h); the keys
    // sorted, as the rest of the tool's reports.
    nlohmann::json j = nlohmann::json::parse(
        ContactReportJsonText(run, !FLAGS_verify.empty(), FLAGS_kfold, FLAGS_residual_model));
    j["tool"] = "lpoe_calibrate";
    j["measurements"] = job->files;
    j["file_kinds"] = job->inputs.kinds;
    staged = outputs.Stage(FLAGS_report, j.dump(2) + "\n");
  }
  return staged;
}

// The HTML page: the table per kind, per pivot and plane, the plot and the terms' values.
Status StageContactHtml(ContactRun* job) {
  const ContactPipelineResult& run = job->run;
  const ContactCalibrationResult& result = run.calibration;
  const ContactParameterization& p = result.parameterization;
  const std::string verify_label = job->verify_label;
  std::string errors_html;
  // The errors per pivot and plane, and their plot.
  if (!job->html_feature_rows.empty()) {
    errors_html = "<h2>Errors per pivot and plane</h2>\n<table border=\"1\">\n<tr><th>feature</th>"
                  "<th>name</th><th>rows</th><th>RMS (mm)</th><th>max (mm)</th><th>expected "
                  "noise (mm)</th><th>verdict</th><th>" + verify_label +
                  " (mm)</th></tr>\n" + job->html_feature_rows + "</table>\n";
  }
  std::string svg;
  Status staged = RenderFigure(
      ContactErrorFigure(run, FLAGS_verify.empty() ? "held out" : "verify"), ImageFormat::kSvg,
      &svg);
  if (!staged.ok()) return staged;
  errors_html += "<h2>Plots</h2>\n<figure>" + svg + "</figure>\n";
  // The joint-space terms' values (the YAML's joint_errors).
  std::string joint_html;
  for (const JointTermValues& t : result.joint_terms) {
    std::ostringstream h;
    h << "<p>Joint-space term " << HtmlEscape(t.term->name()) << ":";
    for (int k = 0; k < t.theta.size(); ++k) {
      h << " " << HtmlEscape(t.term->ParameterName(k)) << " = " << t.theta(k);
    }
    h << "</p>\n";
    joint_html += h.str();
  }
  const std::string html =
      "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>lpoe_calibrate</title></head>"
      "<body>\n<h1>Calibration from distances and planes</h1>\n<table border=\"1\">\n"
      "<tr><th>table</th><th>rows</th><th>RMS (mm)</th><th>max (mm)</th><th>expected noise "
      "(mm)</th><th>verdict</th><th>" + verify_label + " (mm)</th></tr>\n" +
      job->html_rows + "</table>\n<p>" + HtmlEscape(p.base_reason) + "</p>\n<p>Scale: " +
      HtmlEscape(p.scale_reason) + "</p>\n" + joint_html +
      (job->layer_text.empty()
           ? ""
           : "<h2>Residual layer</h2>\n<pre>" + HtmlEscape(job->layer_text) + "</pre>\n") +
      errors_html + "</body></html>\n";
  return job->outputs.Stage(FLAGS_html_report, html);
}

}  // namespace

int RunContactCalibration() {
  ContactRun job;
  if (int rc = ContactOptionsFromFlags(&job); rc != kExitOk) return rc;
  if (int rc = ContactFilesFromFlags(&job); rc != kExitOk) return rc;
  if (int rc = ReadContactModelAndData(&job); rc != kExitOk) return rc;
  if (int rc = ReadContactVerification(&job); rc != kExitOk) return rc;
  if (int rc = ContactStartAndTerms(&job); rc != kExitOk) return rc;
  if (int rc = RunContactJob(&job); rc != kExitOk) return rc;
  ContactKindTables(&job, std::cout);
  ContactEstimates(&job, std::cout);
  // Nothing is written unless every output is staged.
  Status staged = StageContactModelAndReport(&job);
  if (staged.ok() && !FLAGS_html_report.empty()) staged = StageContactHtml(&job);
  if (staged.ok() && job.run.calibration.model.residual_layer &&
      (!FLAGS_urdf_output.empty() || !FLAGS_ur_kinematics_output.empty())) {
    std::cerr << "warning: URDF and UR kinematics cannot carry the residual layer "
                 "(docs/residual_layer.md): they predict without its correction. Predict or "
                 "compensate with the YAML model (--output), which keeps it\n";
  }
  return CommitOutputs(staged, &job.outputs, FLAGS_quiet);
}

}  // namespace tools
}  // namespace lpoe
