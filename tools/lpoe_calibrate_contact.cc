// lpoe_calibrate for ballbar distances and probe contacts on planes (lpoe_calibrate_contact.h).
#include "lpoe_calibrate_contact.h"

#include <gflags/gflags.h>
#include <sys/stat.h>

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <iostream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "common_flags.h"
#include "lpoe/contact_calibration.h"
#include "lpoe/contact_measurements.h"
#include "lpoe/io.h"
#include "lpoe/measurement_kinds.h"
#include "lpoe/refusals.h"
#include "lpoe/registration.h"
#include "lpoe/urdf.h"
#include "output_files.h"
#include "report/text_safety.h"
#include "tool_common.h"

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
DEFINE_string(hold_scale, "auto",
              "Distance and plane data: auto | on | off. auto holds the robot's scale at the "
              "nominal model's when no file measures a length (probe contacts on planes alone: "
              "the scale is not determined by them; docs/identifiability.md).");

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

struct KindFigures {
  int rows = 0;
  double rms = 0;       // mm
  double max_abs = 0;   // mm
  double sigma = 0;     // median of the rows' noise (mm)
  int held_rows = 0;
  double held_rms = 0;  // mm
};

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

KindFigures Figures(const ContactMeasurementSet& data, const std::vector<double>& errors,
                    MeasurementKindId kind) {
  KindFigures f;
  std::vector<double> sigmas;
  double sum = 0;
  for (int r = 0; r < data.size(); ++r) {
    if (data.rows[r].kind != kind) continue;
    ++f.rows;
    // Position rows: |e| over three axes; the RMS per axis.
    const double e = errors[r];
    sum += kind == MeasurementKindId::kPosition ? e * e / 3 : e * e;
    f.max_abs = std::max(f.max_abs, std::abs(e));
    sigmas.push_back(data.rows[r].sigma);
  }
  f.rms = f.rows > 0 ? std::sqrt(sum / f.rows) : 0;
  f.sigma = Median(sigmas);
  return f;
}

// pass: within twice the expected noise; check: within five times; fail beyond.
const char* KindVerdict(const KindFigures& f) {
  if (f.rows == 0) return "none";
  const double ratio = f.sigma > 0 ? f.rms / f.sigma : 0;
  return ratio <= 2 ? "pass" : ratio <= 5 ? "check" : "fail";
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

int RunContactCalibration() {
  // ---- Flags.
  struct Unsupported {
    bool set;
    const char* flag;
  };
  for (const Unsupported& u :
       {Unsupported{FLAGS_joint_errors != "none", "--joint_errors"},
        Unsupported{FLAGS_residual_model != "none", "--residual_model"},
        Unsupported{FLAGS_loss != "none", "--loss"},
        Unsupported{!FLAGS_fixed_tools.empty(), "--fixed_tools"},
        Unsupported{FLAGS_parameterization != "identifiable", "--parameterization"}}) {
    if (u.set) {
      std::cerr << "error: " << u.flag
                << " is not available with distance or plane data yet (docs/measurements.md)\n";
      return kExitUsage;
    }
  }
  if (FLAGS_solver != "linear" && FLAGS_solver != "ceres") {
    std::cerr << "error: --solver must be linear or ceres, got '" << FLAGS_solver << "'\n";
    return kExitUsage;
  }
  ContactCalibrationOptions options;
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
  UrdfOptions urdf_options;
  if (!UrdfOptionsFromFlags(FLAGS_model, &urdf_options) ||
      (!FLAGS_ur_kinematics_output.empty() && !IsUrdfPath(FLAGS_model))) {
    std::cerr << "error: --base_link, --tip_link, --tool_links and --ur_kinematics_output need a "
                 "URDF --model (a name ending in .urdf)\n";
    return kExitUsage;
  }
  const MeasurementKindInfo* forced = nullptr;
  if (FLAGS_data_kind != "auto") {
    forced = FindMeasurementKind(FLAGS_data_kind);
    if (forced == nullptr) {
      std::cerr << "error: --data_kind must be auto or one of " << MeasurementKindNames()
                << ", got '" << FLAGS_data_kind << "'\n";
      return kExitUsage;
    }
  }
  const std::vector<std::string> files = SplitList(FLAGS_measurements);
  for (const std::string& f : files) {
    if (f.empty()) {
      std::cerr << "error: --measurements has an empty file name\n";
      return kExitUsage;
    }
  }
  std::vector<double> sigmas(files.size(), SigmaGiven() ? FLAGS_sigma : 0.0);
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
  AngleUnit angle;
  LengthUnit length;
  if (!UnitsFromFlags(&angle, &length, nullptr)) return kExitUsage;
  if (FLAGS_model.empty()) {
    std::cerr << "error: --model is required with distance or plane data\n";
    return kExitUsage;
  }
  OutputSet outputs;
  outputs.AddInput("--model", FLAGS_model);
  for (const std::string& f : files) outputs.AddInput("--measurements", f);
  const std::vector<std::string> verify_files =
      FLAGS_verify.empty() ? std::vector<std::string>() : SplitList(FLAGS_verify);
  for (const std::string& f : verify_files) {
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

  // ---- Inputs.
  RobotModel nominal;
  UrdfSource urdf_source;  // a URDF --model, for the URDF and UR write-back
  const bool from_urdf = IsUrdfPath(FLAGS_model);
  if (from_urdf) {
    if (Status s = ReadRobotModelUrdf(FLAGS_model, &nominal, urdf_options, &urdf_source); !s.ok()) {
      std::cerr << "error: " << s.message() << "\n";
      return kExitInput;
    }
  } else if (int code = ReadModelFlag(&nominal); code != kExitOk) {
    return code;
  }
  // The UR file needs a UR arm with z axes: checked on the nominal model before solving.
  if (!FLAGS_ur_kinematics_output.empty()) {
    std::string ur_yaml;
    if (Status s = UrKinematicsYaml(urdf_source, nominal, {}, &ur_yaml); !s.ok()) {
      std::cerr << "error: --ur_kinematics_output: " << s.message() << "\n";
      return kExitUsage;
    }
  }
  CsvOptions csv;
  csv.angle_unit = angle;
  csv.length_unit = length;
  ContactMeasurementSet data;
  data.num_joints = nominal.num_joints();
  MeasurementSet tracker(nominal.num_joints());
  std::vector<std::string> kinds_of_files;
  for (size_t i = 0; i < files.size(); ++i) {
    const MeasurementKindInfo* kind = nullptr;
    if (Status s = DetectMeasurementFileKind(files[i], &kind); !s.ok()) {
      std::cerr << "error: " << s.message() << "\n";
      return kExitInput;
    }
    if (forced != nullptr && forced != kind) {
      std::cerr << "error: " << files[i] << ": --data_kind=" << forced->name
                << " but its columns are a " << kind->name << " file's (" << kind->columns
                << ")\n";
      return kExitInput;
    }
    kinds_of_files.push_back(kind->name);
    ContactMeasurementSet part;
    if (kind->id == MeasurementKindId::kDistance || kind->id == MeasurementKindId::kPlane) {
      ContactCsvOptions o;
      o.units = csv;
      o.kind = kind;
      o.sigma = sigmas[i];
      if (Status s = ReadContactMeasurements(files[i], nominal, o, &part); !s.ok()) {
        std::cerr << "error: " << s.message() << "\n";
        return kExitInput;
      }
    } else {
      if (!(sigmas[i] > 0)) {
        std::cerr << "error: " << files[i]
                  << ": a tracker file has no sigma column; give its noise with --sigmas (one "
                     "value per file) or --sigma\n";
        return kExitUsage;
      }
      MeasurementSet positions;
      if (Status s = ReadMeasurements(files[i], nominal, csv, &positions, nullptr); !s.ok()) {
        std::cerr << "error: " << s.message() << "\n";
        return kExitInput;
      }
      tracker.Append(positions);
      part = ContactSetFromPositions(positions, sigmas[i], files[i]);
    }
    data.Append(part);
  }
  if (data.Count(MeasurementKindId::kDistance) + data.Count(MeasurementKindId::kPlane) == 0) {
    std::cerr << "error: no distance or plane file among --measurements (tracker data alone: "
                 "give one file, as always)\n";
    return kExitUsage;
  }
  // ---- --verify: distance and plane files of the calibration's pivots and planes, evaluated with
  // the features it estimates.
  ContactMeasurementSet verification;
  if (!verify_files.empty()) {
    ContactMeasurementSet combined = data;
    for (const std::string& f : verify_files) {
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
      o.units = csv;
      o.kind = kind;
      o.sigma = SigmaGiven() ? FLAGS_sigma : 0.0;
      ContactMeasurementSet part;
      if (Status s = ReadContactMeasurements(f, nominal, o, &part); !s.ok()) {
        std::cerr << "error: " << s.message() << "\n";
        return kExitInput;
      }
      combined.Append(part);
    }
    if (combined.pivots.size() != data.pivots.size() ||
        combined.planes.size() != data.planes.size()) {
      std::cerr << "error: --verify names a pivot or plane that --measurements does not (its "
                   "position is estimated from the calibration's rows): "
                << (combined.pivots.size() != data.pivots.size()
                        ? combined.pivots[data.pivots.size()]
                        : combined.planes[data.planes.size()])
                << "\n";
      return kExitInput;
    }
    std::vector<int> rows;
    for (int r = data.size(); r < combined.size(); ++r) rows.push_back(r);
    verification = combined.Subset(rows);
  }
  RobotModel start = nominal;
  if (tracker.size() > 0) {
    if (!FLAGS_urdf_output.empty() || !FLAGS_ur_kinematics_output.empty()) {
      std::cerr << "error: --urdf_output and --ur_kinematics_output are not available with "
                   "tracker files among distance or plane files yet (docs/measurements.md)\n";
      return kExitUsage;
    }
    // The tracker's frame: the model is registered to it first, so that the pivots and planes are
    // estimated in the tracker's frame and the base is seen.
    RegistrationReport report;
    if (Status s = RegisterToMeasurements(nominal, tracker, &start, &report); !s.ok()) {
      std::cerr << "error: registration to the tracker data: " << s.message() << "\n";
      return kExitNumerical;
    }
  }
  // ---- Hold-out rows.
  ContactMeasurementSet identification = data, held = verification;
  if (FLAGS_holdout > 0) {
    std::mt19937_64 rng(FLAGS_split_seed);
    std::vector<int> order(data.size());
    for (int i = 0; i < data.size(); ++i) order[i] = i;
    std::shuffle(order.begin(), order.end(), rng);
    const int count = static_cast<int>(std::floor(FLAGS_holdout * data.size()));
    std::vector<int> train(order.begin() + count, order.end()), test(order.begin(), order.begin() + count);
    std::sort(train.begin(), train.end());
    std::sort(test.begin(), test.end());
    identification = data.Subset(train);
    held = data.Subset(test);
  }

  // ---- Calibration.
  const ContactCalibrationResult result =
      FLAGS_solver == "ceres" ? CalibrateContactsCeres(start, identification, options)
                              : CalibrateContactsLinear(start, identification, options);
  if (!result.ok) {
    std::cerr << "error: " << (result.iterations == 0 ? "not identifiable: " : "") << result.message
              << "\n";
    return ExitFor(result);
  }
  std::vector<double> held_errors;
  if (held.size() > 0) held_errors = ContactErrors(result.model, result.features, held);
  // ---- --kfold: the identification rows in k folds (shuffled by --split_seed); each fold's rows
  // predicted by the calibration of the others, with the same options.
  std::vector<double> fold_errors;
  if (FLAGS_kfold > 0) {
    if (FLAGS_kfold > identification.size()) {
      std::cerr << "error: --kfold=" << FLAGS_kfold << " is larger than the "
                << identification.size() << " identification rows\n";
      return kExitUsage;
    }
    std::mt19937_64 rng(FLAGS_split_seed + 1);
    std::vector<int> order(identification.size());
    for (int i = 0; i < identification.size(); ++i) order[i] = i;
    std::shuffle(order.begin(), order.end(), rng);
    fold_errors.assign(identification.size(), 0.0);
    for (int fold = 0; fold < FLAGS_kfold; ++fold) {
      std::vector<int> train, test;
      for (int i = 0; i < identification.size(); ++i) {
        (i % FLAGS_kfold == fold ? test : train).push_back(order[i]);
      }
      std::sort(train.begin(), train.end());
      std::sort(test.begin(), test.end());
      const ContactMeasurementSet fold_data = identification.Subset(train);
      const ContactCalibrationResult f =
          FLAGS_solver == "ceres" ? CalibrateContactsCeres(start, fold_data, options)
                                  : CalibrateContactsLinear(start, fold_data, options);
      if (!f.ok) {
        std::cerr << "error: --kfold: fold " << fold + 1 << " of " << FLAGS_kfold << ": "
                  << f.message << "\n";
        return ExitFor(f);
      }
      const std::vector<double> e =
          ContactErrors(f.model, f.features, identification.Subset(test));
      for (size_t i = 0; i < test.size(); ++i) fold_errors[test[i]] = e[i];
    }
  }
  const char* verify_label = FLAGS_verify.empty() ? "held-out RMS" : "verify RMS";
  if (Status s = CheckModelFinite(result.model); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitNumerical;
  }

  // ---- Summary.
  std::ostream& out = std::cout;
  const ContactParameterization& p = result.parameterization;
  out << "lpoe_calibrate: " << identification.size() << " rows (";
  for (size_t i = 0; i < files.size(); ++i) {
    out << (i ? ", " : "") << files[i] << ": " << kinds_of_files[i];
  }
  out << "), solver " << result.solver << ", " << result.iterations << " iterations, cost "
      << result.initial_cost << " -> " << result.cost << "\n";
  nlohmann::json kinds_json = nlohmann::json::array();
  std::string html_rows;
  out << std::left << std::setw(10) << "kind" << std::right << std::setw(7) << "rows"
      << std::setw(14) << "RMS (mm)" << std::setw(14) << "max (mm)" << std::setw(16)
      << "expected (mm)" << std::setw(9) << "verdict" << std::setw(16) << verify_label
      << (FLAGS_kfold > 0 ? "     k-fold RMS" : "") << "\n";
  for (const MeasurementKindInfo& kind : MeasurementKinds()) {
    if (kind.id == MeasurementKindId::kPose) continue;  // tracker rows are position rows here
    KindFigures f = Figures(identification, result.errors, kind.id);
    if (f.rows == 0) continue;
    KindFigures h;
    if (held.size() > 0) {
      h = Figures(held, held_errors, kind.id);
      f.held_rows = h.rows;
      f.held_rms = h.rms;
    }
    KindFigures cv;
    if (FLAGS_kfold > 0) cv = Figures(identification, fold_errors, kind.id);
    out << std::left << std::setw(10) << kind.name << std::right << std::setw(7) << f.rows
        << std::setw(14) << f.rms << std::setw(14) << f.max_abs << std::setw(16) << f.sigma
        << std::setw(9) << KindVerdict(f) << std::setw(16)
        << (f.held_rows > 0 ? std::to_string(f.held_rms) : std::string("-"));
    if (FLAGS_kfold > 0) out << std::setw(15) << cv.rms;
    out << "\n";
    nlohmann::json k = {{"kind", kind.name},          {"table", kind.report_table},
                        {"rows", f.rows},             {"rms_mm", f.rms},
                        {"max_abs_mm", f.max_abs},    {"expected_noise_mm", f.sigma},
                        {"verdict", KindVerdict(f)}};
    if (f.held_rows > 0) {
      k["held_out_rows"] = f.held_rows;
      k["held_out_rms_mm"] = f.held_rms;
      // The verification table (--verify or --holdout): the kind's figures on rows not fitted.
      k["verification"] = {{"source", FLAGS_verify.empty() ? "holdout" : "verify"},
                           {"rows", h.rows},
                           {"rms_mm", h.rms},
                           {"max_abs_mm", h.max_abs},
                           {"expected_noise_mm", h.sigma},
                           {"verdict", KindVerdict(h)}};
    }
    if (FLAGS_kfold > 0) {
      k["kfold"] = {{"folds", FLAGS_kfold}, {"rows", cv.rows}, {"rms_mm", cv.rms},
                    {"max_abs_mm", cv.max_abs}};
    }
    kinds_json.push_back(k);
    std::ostringstream row;
    row << "<tr><td>" << kind.report_table << "</td><td>" << f.rows << "</td><td>" << f.rms
        << "</td><td>" << f.max_abs << "</td><td>" << f.sigma << "</td><td>" << KindVerdict(f)
        << "</td><td>" << (f.held_rows > 0 ? std::to_string(f.held_rms) : "-") << "</td></tr>\n";
    html_rows += row.str();
  }
  nlohmann::json pivots = nlohmann::json::array(), planes = nlohmann::json::array();
  for (size_t k = 0; k < result.features.pivots.size(); ++k) {
    const Eigen::Vector3d& c = result.features.pivots[k];
    out << "pivot " << ValidUtf8(identification.pivots[k]) << ": " << c.transpose() << " mm\n";
    pivots.push_back({{"name", ValidUtf8(identification.pivots[k])}, {"xyz_mm", {c(0), c(1), c(2)}}});
  }
  for (size_t k = 0; k < result.features.planes.size(); ++k) {
    const Eigen::Vector4d& pl = result.features.planes[k];
    out << "plane " << ValidUtf8(identification.planes[k]) << ": normal " << pl.head<3>().transpose()
        << ", n.x = " << pl(3) << " mm\n";
    planes.push_back({{"name", ValidUtf8(identification.planes[k])},
                      {"normal", {pl(0), pl(1), pl(2)}},
                      {"offset_mm", pl(3)}});
  }
  out << "parameters: " << p.frames.num_parameters << " of the robot, " << 3 * p.num_pivots
      << " of pivots, " << 3 * p.num_planes << " of planes\n";
  if (p.num_base_directions > 0) {
    out << "not identified (" << p.num_base_directions << " directions of the base): "
        << p.base_reason << "\n";
  }
  out << "scale: " << p.scale_reason << " (S = " << result.scale << ")\n";
  nlohmann::json left_out = nlohmann::json::array();
  for (const Direction& d : p.frames.unidentifiable) {
    left_out.push_back({{"name", ValidUtf8(d.name)}, {"reason", d.reason}});
  }

  // ---- Outputs (nothing is written unless every one is staged).
  Status staged;
  if (!FLAGS_output.empty()) {
    RobotModel calibrated = result.model;
    staged = outputs.Stage(FLAGS_output, RobotModelToYaml(calibrated));
  }
  // The URDF and UR outputs: the calibrated model is an ordinary one, in the robot's own base
  // frame (the base is left out and kept as given), so joint 1 keeps its URDF origin.
  if (staged.ok() && !FLAGS_urdf_output.empty()) {
    std::string xml;
    if (from_urdf) {
      staged = CalibratedUrdfOverlay(urdf_source, result.model, UrdfOverlayOptions(), &xml);
    } else {
      xml = RobotModelToUrdf(result.model);
    }
    if (staged.ok()) staged = outputs.Stage(FLAGS_urdf_output, xml);
  }
  if (staged.ok() && !FLAGS_ur_kinematics_output.empty()) {
    std::string ur_yaml;
    staged = UrKinematicsYaml(urdf_source, result.model, UrdfOverlayOptions(), &ur_yaml);
    if (staged.ok()) staged = outputs.Stage(FLAGS_ur_kinematics_output, ur_yaml);
  }
  if (staged.ok() && !FLAGS_report.empty()) {
    nlohmann::json j = {
        {"tool", "lpoe_calibrate"},
        {"measurements", files},
        {"file_kinds", kinds_of_files},
        {"solver", result.solver},
        {"iterations", result.iterations},
        {"cost_before", result.initial_cost},
        {"cost_after", result.cost},
        {"measurement_kinds", kinds_json},
        {"features", {{"pivots", pivots}, {"planes", planes}}},
        {"parameters", p.frames.num_parameters + 3 * p.num_pivots + 3 * p.num_planes},
        {"base", {{"directions_left_out", p.num_base_directions}, {"reason", p.base_reason}}},
        {"scale", {{"held", p.scale_held}, {"reason", p.scale_reason}, {"value", result.scale}}},
        {"left_out", left_out},
    };
    staged = outputs.Stage(FLAGS_report, j.dump(2) + "\n");
  }
  if (staged.ok() && !FLAGS_html_report.empty()) {
    std::string html =
        "<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>lpoe_calibrate</title></head>"
        "<body>\n<h1>Calibration from distances and planes</h1>\n<table border=\"1\">\n"
        "<tr><th>table</th><th>rows</th><th>RMS (mm)</th><th>max (mm)</th><th>expected noise "
        "(mm)</th><th>verdict</th><th>" + std::string(verify_label) + " (mm)</th></tr>\n" +
        html_rows + "</table>\n<p>" + HtmlEscape(p.base_reason) + "</p>\n<p>Scale: " +
        HtmlEscape(p.scale_reason) + "</p>\n</body></html>\n";
    staged = outputs.Stage(FLAGS_html_report, html);
  }
  return CommitOutputs(staged, &outputs, FLAGS_quiet);
}

}  // namespace tools
}  // namespace lpoe
