#include "common/tool_common.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <iomanip>
#include <iostream>
#include <sstream>
#include <sys/stat.h>
#include <unistd.h>

#include <gflags/gflags.h>
#include <glog/logging.h>

#include "lpoe/analysis.h"
#include "lpoe/io/urdf.h"
#include "lpoe/io/csv_rules.h"
#include "lpoe/options.h"
#include "lpoe/version.h"
#include "common/output_files.h"
#include "io/parse_util.h"

DECLARE_bool(help);
DECLARE_bool(helpfull);
DECLARE_bool(helpshort);

namespace lpoe {
namespace tools {

namespace {

// A flag's default as written: a double in its shortest form (0.03, not gflags'
// 0.029999999999999999), a string in quotes.
std::string DefaultText(const gflags::CommandLineFlagInfo& f) {
  if (f.type == "string") return "\"" + f.default_value + "\"";
  if (f.type == "double") {
    double v = 0;
    if (internal::ParseNumber(f.default_value, &v) == internal::NumberParse::kOk) {
      return internal::FormatNumber(v);
    }
  }
  return f.default_value;
}

}  // namespace

void InitTool(const char* usage, int* argc, char*** argv) {
  gflags::SetUsageMessage(usage);
  gflags::SetVersionString(kLpoeVersion);
  gflags::ParseCommandLineNonHelpFlags(argc, argv, /*remove_flags=*/true);
  std::string name = (*argv)[0];
  const size_t slash = name.find_last_of('/');
  if (slash != std::string::npos) name = name.substr(slash + 1);
  if (FLAGS_help || FLAGS_helpfull || FLAGS_helpshort) {
    if (FLAGS_helpfull) {
      gflags::ShowUsageWithFlags((*argv)[0]);
    } else {
      std::cout << gflags::ProgramUsage() << "\n\nFlags:\n";
      std::vector<gflags::CommandLineFlagInfo> flags;
      gflags::GetAllFlags(&flags);
      for (const auto& f : flags) {
        if (f.filename.find(name) == std::string::npos &&
            f.filename.find("common_flags.cc") == std::string::npos) {
          continue;
        }
        const OptionSpec* spec = FindOption(name, f.name);
        const std::string range = spec != nullptr ? OptionRangeText(*spec) : "";
        std::cout << "  --" << f.name << " (" << f.description << ")\n      type: " << f.type
                  << "  default: " << DefaultText(f)
                  << (range.empty() ? "" : "  range: " + range) << "\n";
      }
    }
    std::exit(kExitOk);
  }
  gflags::HandleCommandLineHelpFlags();
  // The ranges of the option table, for the flags this tool has.
  for (const OptionSpec& spec : Options()) {
    if (!spec.has_range || (spec.scope[0] != '\0' && name != spec.scope)) continue;
    gflags::CommandLineFlagInfo info;
    if (!gflags::GetCommandLineFlagInfo(spec.name, &info)) continue;
    double v = 0;
    const internal::NumberParse parsed = internal::ParseNumber(info.current_value, &v);
    if (parsed == internal::NumberParse::kNonFinite) {
      v = std::strtod(info.current_value.c_str(), nullptr);  // inf or nan: out of every range
    } else if (parsed != internal::NumberParse::kOk) {
      continue;  // gflags parsed it: not a number it would accept
    }
    if (Status s = CheckOption(name, spec.name, v); !s.ok()) {
      std::cerr << "error: " << s.message() << "\n";
      std::exit(kExitUsage);
    }
  }
  FLAGS_logtostderr = true;
  google::InitGoogleLogging((*argv)[0]);
}

void ScalePrismaticJoints(const RobotModel& model, LengthUnit unit, std::vector<double>* q,
                          bool to_unit) {
  const double s = MillimetresPer(unit);
  if (s == 1.0) return;
  const size_t n = static_cast<size_t>(model.num_joints());
  for (size_t j = 0; j < n; ++j) {
    if (model.joints[j].type != JointType::kPrismatic) continue;
    for (size_t k = j; k < q->size(); k += n) (*q)[k] = to_unit ? (*q)[k] / s : (*q)[k] * s;
  }
}

std::string DataDir() {
  if (const char* env = std::getenv("LPOE_DATA_DIR"); env != nullptr && env[0] != '\0') return env;
  // An installed program: <prefix>/bin/<tool> and <prefix>/share/lpoe_calib/data.
  char self[4096];
  const ssize_t n = readlink("/proc/self/exe", self, sizeof(self) - 1);
  if (n > 0) {
    std::string dir(self, static_cast<size_t>(n));
    dir = dir.substr(0, dir.find_last_of('/'));                  // <prefix>/bin
    const std::string prefix = dir.substr(0, dir.find_last_of('/'));
    const std::string installed = prefix + "/" LPOE_INSTALL_DATA_DIR;
    struct stat st;
    if (stat((installed + "/cobot6.yaml").c_str(), &st) == 0) return installed;
  }
  return LPOE_DATA_DIR;
}

InputPaths ResolveInputPaths(const std::string& model_flag, const std::string& measurements_flag,
                             const std::string& verify_flag, bool holdout) {
  const std::string data_dir = DataDir();
  const bool default_data = measurements_flag.empty();
  InputPaths p;
  p.model = model_flag.empty() ? data_dir + "/cobot6.yaml" : model_flag;
  p.measurements = default_data ? data_dir + "/section4/identification.csv" : measurements_flag;
  p.verify = verify_flag;
  if (default_data && p.verify.empty() && !holdout) {
    p.verify = data_dir + "/section4/verification.csv";
  }
  return p;
}

Status LoadInputs(const std::string& model_path, const std::string& measurements_path,
                  const std::string& verify_path, const CsvOptions& csv, double holdout,
                  uint64_t split_seed, Inputs* in, const UrdfOptions& urdf_options,
                  SplitKind split) {
  in->from_urdf = IsUrdfPath(model_path);
  if (Status s = in->from_urdf
                     ? ReadRobotModelUrdf(model_path, &in->nominal, urdf_options, &in->urdf)
                     : ReadRobotModel(model_path, &in->nominal);
      !s.ok()) {
    return s;
  }
  MeasurementSet all;
  if (Status s = ReadMeasurements(measurements_path, in->nominal, csv, &all, &in->skipped);
      !s.ok()) {
    return s;
  }
  std::cerr << CsvReadWarnings(measurements_path, in->skipped);
  const std::string hint = LengthUnitHint(in->nominal, all);
  if (!hint.empty()) std::cerr << "warning: " << measurements_path << ": " << hint << "\n";
  if (csv.angle_unit == AngleUnit::kDegrees) {
    const int n = all.num_joints();
    std::vector<double> max_abs(n, 0.0);
    for (int r = 0; r < all.size(); ++r) {
      for (int j = 0; j < n; ++j) max_abs[j] = std::max(max_abs[j], std::abs(all.q(r)[j]));
    }
    in->angle_unit_hint = DegreesUnitHint(in->nominal, max_abs);
    if (!in->angle_unit_hint.empty()) {
      std::cerr << "warning: " << measurements_path << ": " << in->angle_unit_hint << "\n";
    }
  }
  if (!verify_path.empty()) {
    in->identification = std::move(all);
    in->verification_source = verify_path;
    Status s = ReadMeasurements(verify_path, in->nominal, csv, &in->verification,
                                &in->verification_skipped);
    if (s.ok()) std::cerr << CsvReadWarnings(verify_path, in->verification_skipped);
    return s;
  }
  if (holdout > 0.0) {
    std::vector<int> id_rows, ver_rows;
    HoldoutSplit(all, holdout, split_seed, &id_rows, &ver_rows, split);
    std::vector<bool> held_out(all.size(), false);
    for (int r : ver_rows) held_out[r] = true;
    all.MoveRowsOut(held_out, &in->verification);
    in->identification = std::move(all);
    in->verification_source = "holdout";
    return Status::Ok();
  }
  in->identification = std::move(all);
  return Status::Ok();
}

bool ParseAngleUnit(const std::string& text, AngleUnit* unit) {
  if (text == "rad") {
    *unit = AngleUnit::kRadians;
    return true;
  }
  if (text == "deg") {
    *unit = AngleUnit::kDegrees;
    return true;
  }
  return false;
}

Status ParseInputFlags(const InputFlags& flags, InputSettings* settings) {
  InputSettings out;
  if (!ParseAngleUnit(flags.angle_unit, &out.angle_unit)) {
    return Status::Error("--angle_unit must be rad or deg, got '" + flags.angle_unit + "'");
  }
  out.csv.angle_unit = out.angle_unit;
  if (!ParseLengthUnit(flags.length_unit, &out.csv.length_unit)) {
    return Status::Error("--length_unit must be mm or m, got '" + flags.length_unit + "'");
  }
  if (!ParseParameterization(flags.parameterization, &out.parameterization)) {
    return Status::Error("--parameterization must be identifiable or full, got '" +
                         flags.parameterization + "'");
  }
  if (!ParseSplitKind(flags.split, &out.split)) {
    return Status::Error("--split must be random or sequential, got '" + flags.split + "'");
  }
  if (Status s = CheckRange("holdout", flags.holdout, 0.0, 0.95); !s.ok()) return s;
  if (flags.holdout > 0.0 && !flags.verify.empty()) {
    return Status::Error("give either --verify or --holdout, not both");
  }
  *settings = out;
  return Status::Ok();
}

std::string JsonBeside(const std::string& path) {
  const size_t slash = path.find_last_of('/');
  const size_t dot = path.find_last_of('.');
  const bool extension = dot != std::string::npos && (slash == std::string::npos || dot > slash);
  return (extension ? path.substr(0, dot) : path) + ".json";
}

bool SameFile(const std::string& a, const std::string& b) {
  if (a.empty() || b.empty()) return false;
  if (a == b) return true;
  struct stat sa, sb;
  if (stat(a.c_str(), &sa) != 0 || stat(b.c_str(), &sb) != 0) return false;
  return sa.st_dev == sb.st_dev && sa.st_ino == sb.st_ino;
}

Status CheckRange(const char* name, double value, double lo, double hi, bool lo_open) {
  const bool ok = (lo_open ? value > lo : value >= lo) && value <= hi;
  if (ok) return Status::Ok();
  std::ostringstream os;
  os << "--" << name << " must be in " << (lo_open ? "(" : "[") << lo << ", " << hi << "], got "
     << value;
  return Status::Error(os.str());
}

Status CheckHoldoutSplit(double holdout, int identification_rows, int verification_rows) {
  std::ostringstream os;
  if (verification_rows == 0) {
    os << "--holdout=" << holdout << " holds out no row of the " << identification_rows
       << ": use a larger fraction, or --verify";
    return Status::Error(os.str());
  }
  // Registration's rigid fit needs three points, and every solver needs more rows than that.
  constexpr int kMinIdentificationRows = 10;
  if (identification_rows < kMinIdentificationRows) {
    os << "--holdout=" << holdout << " leaves only " << identification_rows
       << " identification row(s) of " << identification_rows + verification_rows
       << ": use a smaller fraction";
    return Status::Error(os.str());
  }
  return Status::Ok();
}

int ExitCodeFor(Termination t) {
  switch (t) {
    case Termination::kConverged:
      return kExitOk;
    case Termination::kMaxIterations:
      return kExitNotConverged;
    case Termination::kNotIdentifiable:
      return kExitNotIdentifiable;
    case Termination::kNumericalFailure:
      return kExitNumerical;
  }
  return kExitNumerical;
}

void PrintWrapped(std::ostream& os, const std::vector<std::string>& items,
                  const std::string& separator, int indent, int width) {
  const std::string pad(static_cast<size_t>(std::max(indent, 0)), ' ');
  std::string line;
  for (size_t k = 0; k < items.size(); ++k) {
    const std::string item = items[k] + (k + 1 < items.size() ? separator : "");
    // The separator's trailing spaces do not count against the width at the end of a line.
    const std::string shown = item.substr(0, item.find_last_not_of(' ') + 1);
    if (!line.empty() && pad.size() + line.size() + shown.size() > static_cast<size_t>(width)) {
      os << pad << line.substr(0, line.find_last_not_of(' ') + 1) << "\n";
      line.clear();
    }
    line += item;
  }
  if (!line.empty()) os << pad << line.substr(0, line.find_last_not_of(' ') + 1) << "\n";
}

void PrintIterationTable(std::ostream& os, const CalibrationResult& result) {
  char line[160];
  os << "iteration   max error [mm]   mean error [mm]        cost        |x|\n";
  int subsample = 0;
  for (const IterationRecord& r : result.history) {
    // The linear solver's warm start (linear_solver.h): records on a subsample are marked.
    std::snprintf(line, sizeof(line), "%9d%c%16.6f %17.6f %11.4e %10.3e\n", r.iteration,
                  r.rows > 0 ? '*' : ' ', r.max_error, r.mean_error, r.cost, r.step_norm);
    if (r.rows > 0) subsample = r.rows;
    os << line;
  }
  if (subsample > 0) {
    os << "        * warm start: on " << subsample
       << " evenly spaced rows (errors and cost of those rows only)\n";
  }
}

void PrintBeforeAfter(std::ostream& os, const std::string& title, const ErrorStatistics& before,
                      const ErrorStatistics& after) {
  char line[200];
  os << title << " (" << after.count << " points), |measured - predicted| in mm\n";
  os << "        |        before calibration          |         after calibration\n";
  os << "  axis  |    max      mean       rms      p95  |    max      mean       rms      p95\n";
  const char* names[4] = {"x", "y", "z", "norm"};
  for (int a = 0; a < 4; ++a) {
    const AxisStatistics& b = a < 3 ? before.axis[a] : before.norm;
    const AxisStatistics& c = a < 3 ? after.axis[a] : after.norm;
    std::snprintf(line, sizeof(line),
                  "  %-5s | %8.4f %8.4f %8.4f %8.4f | %8.4f %8.4f %8.4f %8.4f\n", names[a],
                  b.max_abs, b.mean_abs, b.rms, b.p95_abs, c.max_abs, c.mean_abs, c.rms,
                  c.p95_abs);
    os << line;
  }
}

int CommitOutputs(const Status& staged, OutputSet* outputs, bool quiet,
                  std::vector<std::string>* written) {
  std::cout << std::flush;
  std::vector<std::string> paths;
  if (Status s = staged.ok() ? outputs->Commit(&paths) : staged; !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitOutput;
  }
  if (!quiet) {
    for (const std::string& path : paths) std::cout << "wrote " << path << "\n";
  }
  if (written != nullptr) *written = std::move(paths);
  return kExitOk;
}

Status ResolveInputs(const std::string& model_flag, const std::string& measurements_flag,
                     const InputFlags& flags, InputPaths* paths, InputSettings* settings) {
  *paths = ResolveInputPaths(model_flag, measurements_flag, flags.verify, flags.holdout != 0.0);
  return ParseInputFlags(flags, settings);
}

void AddInputs(const InputPaths& paths, OutputSet* outputs) {
  outputs->AddInput("--model", paths.model);
  outputs->AddInput("--measurements", paths.measurements);
  outputs->AddInput("--verify", paths.verify);
}

Status CheckHoldoutSplit(double holdout, const Inputs& in) {
  if (!(holdout > 0.0)) return Status::Ok();
  return CheckHoldoutSplit(holdout, in.identification.size(), in.verification.size());
}

}  // namespace tools
}  // namespace lpoe
