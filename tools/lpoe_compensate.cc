// lpoe_compensate: the joints that make the calibrated robot reach its targets.
//
//   lpoe_compensate --model=CAL.yaml --targets=T.csv --output=OUT.csv [--nominal=NOM.yaml]
//   lpoe_compensate --model=CAL.yaml --joints=PROGRAM.csv --nominal=NOM.yaml --output=OUT.csv
//
// Every input row gives a seed (the program's joints) and a target: a tool position, or a pose
// when the quaternion is given, in the calibrated model's frame (targets mode) or the nominal
// model's tool pose at the program's joints carried into that frame by the calibration's
// registration T_measurement_base (joints mode). Inverse kinematics on the calibrated model
// (solvers/include/lpoe/inverse_kinematics.h) finds the compensated joints. Every row is written
// with its status; see docs/compensation.md.
#include <algorithm>
#include <charconv>
#include <cstdint>
#include <functional>
#include <cmath>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

#include <gflags/gflags.h>
#include <glog/logging.h>
#include <nlohmann/json.hpp>

#include "lpoe/compensation.h"
#include "lpoe/io/csv_rules.h"
#include "lpoe/options.h"
#include "lpoe/inverse_kinematics.h"
#include "lpoe/model/residual_layer.h"
#include "lpoe/io/io.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/model/refusals.h"
#include "lpoe/kinematics/se3.h"
#include "report/json_text.h"
#include "common/output_files.h"
#include "lpoe_compensate_program.h"
#include "io/parse_util.h"
#include "common/common_flags.h"
#include "common/tool_common.h"

// Defaults and help of the options lpoe.compensate shares from the option table (lpoe/options.h).
#define LPOE_DEFAULT(name) lpoe::OptionDefault("lpoe_compensate", #name)
#define LPOE_DEFAULT_TEXT(name) lpoe::OptionDefaultText("lpoe_compensate", #name)
#define LPOE_HELP(name) lpoe::OptionHelp("lpoe_compensate", #name)
DEFINE_string(targets, "",
              "Targets CSV: q1..qN (the seed: the joints the program would use), x,y,z (desired "
              "tool position in --length_unit, in --frame), optional target (tool name or index), optional "
              "quat_x,quat_y,quat_z,quat_w (desired tool orientation; empty for a position row).");
DEFINE_string(joints, "",
              "Joint-program CSV (q1..qN, optional target), planned with --nominal: the output "
              "makes the calibrated robot reach the nominal model's tool poses. Instead of "
              "--targets; needs --nominal.");
DEFINE_string(joints_target, LPOE_DEFAULT_TEXT(joints_target), LPOE_HELP(joints_target));
DEFINE_string(nominal, "",
              "Nominal model (YAML or URDF): adds the nominal tool pose at the compensated joints "
              "(the target to send to a controller using nominal kinematics).");
DEFINE_string(frame, LPOE_DEFAULT_TEXT(frame), LPOE_HELP(frame));
DEFINE_string(tcp, "",
              "The TCP the targets are for, when it was not measured: a tool of the models, or "
              "x,y,z[,roll,pitch,yaw] (mm, rad) relative to the flange (--flange), as a "
              "controller's TCP is; added to both models. Rows without a target column use it.");
DEFINE_string(tool, "", "Tool name or index for rows without a target column (default: tool 0).");
DEFINE_string(report, "", "JSON summary to write (counts per status, largest correction/residual).");
DEFINE_bool(strict, false, "Exit 8 when any row is not 'ok' (the output is written anyway).");
// The IK options: defaults, ranges and help from the option table (lpoe/options.h), shared with
// lpoe.compensate.
DEFINE_int32(threads, static_cast<int>(LPOE_DEFAULT(threads)), LPOE_HELP(threads));
DEFINE_int32(max_iterations, static_cast<int>(LPOE_DEFAULT(max_iterations)),
             LPOE_HELP(max_iterations));
DEFINE_int32(restarts, static_cast<int>(LPOE_DEFAULT(restarts)), LPOE_HELP(restarts));
DEFINE_double(position_tolerance, LPOE_DEFAULT(position_tolerance), LPOE_HELP(position_tolerance));
DEFINE_double(orientation_tolerance, LPOE_DEFAULT(orientation_tolerance),
              LPOE_HELP(orientation_tolerance));
DEFINE_double(singular_threshold, LPOE_DEFAULT(singular_threshold), LPOE_HELP(singular_threshold));
#undef LPOE_DEFAULT
#undef LPOE_DEFAULT_TEXT
#undef LPOE_HELP

namespace lpoe {

IkOptions tools::IkOptionsFromFlags() {
  IkOptions o;
  o.max_iterations = FLAGS_max_iterations;
  o.restarts = FLAGS_restarts;
  o.position_tolerance = FLAGS_position_tolerance;
  o.orientation_tolerance = FLAGS_orientation_tolerance;
  o.singular_threshold = FLAGS_singular_threshold;
  return o;
}

namespace {

constexpr char kUsage[] =
    "Compensates robot targets with a calibrated model (inverse kinematics).\n\n"
    "  lpoe_compensate --model=calibrated.yaml --targets=targets.csv --output=joints.csv\n"
    "  lpoe_compensate --model=calibrated.yaml --joints=program.csv --nominal=nominal.yaml \\\n"
    "      --output=joints.csv --report=summary.json\n\n"
    "Exit codes: 0 file processed (rows may carry a status other than ok), 1 bad flags or outputs "
    "(one names an input or the other output, or its directory is missing or not writable: "
    "checked before any row is read), 2 bad input file, 5 a compensation that is not finite "
    "(nothing written), 6 output not written (then neither is), "
    "8 --strict and some row not ok.";

constexpr int kExitNotAllOk = 8;
constexpr int kMaxJointsRead = InverseKinematics::kMaxJoints;
constexpr double kDegreesPerRadian = 180.0 / 3.14159265358979323846;

using internal::AppendNumber;
using internal::NumberParse;
using internal::Trim;

bool ParseFinite(std::string_view s, double* x) {
  return internal::ParseNumber(s, x) == NumberParse::kOk;
}

// Reads the targets or joint-program CSV in chunks of rows (streamed: memory bounded by the chunk):
// seeds (radians/mm) and targets (positions and orientations only in targets mode, in mm).
class RowReader {
 public:
  RowReader(const std::string& path, const Compensator& compensator, AngleUnit unit,
            LengthUnit length_unit, bool need_position)
      : path_(path), compensator_(compensator), model_(compensator.model()), unit_(unit),
        mm_per_unit_(tools::MillimetresPer(length_unit)), need_position_(need_position),
        col_q_(model_.num_joints(), -1) {}

  // Opens the file and reads up to its header line.
  Status Open() {
    if (Status s = reader_.Open(path_); !s.ok()) return s;
    const int n = model_.num_joints();
    std::string_view l;
    while (NextLine(&l)) {
      // The header by the rules every reader shares (lpoe/io/csv_rules.h): no column twice.
      if (Status s = ParseCsvHeader(internal::SplitFields(l), path_, line_, &header_); !s.ok()) {
        return s;
      }
      col_x_ = header_.Find("x");
      col_y_ = header_.Find("y");
      col_z_ = header_.Find("z");
      col_target_ = header_.Find("target");
      const char* quat[4] = {"quat_x", "quat_y", "quat_z", "quat_w"};
      for (int k = 0; k < 4; ++k) col_quat_[k] = header_.Find(quat[k]);
      for (int j = 0; j < n; ++j) col_q_[j] = header_.Find("q" + std::to_string(j + 1));
      for (int j = 0; j < n; ++j) {
        if (col_q_[j] < 0) {
          return Error("the header has no column q" + std::to_string(j + 1) + "; expected q1..q" +
                       std::to_string(n) + " (the model has " + std::to_string(n) + " joints)");
        }
      }
      if (need_position_ && (col_x_ < 0 || col_y_ < 0 || col_z_ < 0)) {
        return Error("the header has no x, y, z columns; expected the target position (" +
                     std::string(mm_per_unit_ == 1.0 ? "mm" : "m") + ")");
      }
      const int quats = (col_quat_[0] >= 0) + (col_quat_[1] >= 0) + (col_quat_[2] >= 0) +
                        (col_quat_[3] >= 0);
      if (quats != 0 && quats != 4) {
        return Error("the header has only some of quat_x, quat_y, quat_z, quat_w");
      }
      return Status::Ok();
    }
    if (!reader_.status().ok()) return reader_.status();
    line_ = std::max(line_, 1);
    return Error("no header line; expected q1..qN, x, y, z");
  }

  bool has_quaternion() const { return col_quat_[0] >= 0; }
  // Largest magnitude per joint of the seeds read so far (as read, before unit conversion).
  const std::vector<double>& max_abs() const { return max_abs_; }

  // Appends up to `max_rows` rows; fewer only at the end of the file.
  Status Read(int max_rows, std::vector<double>* seeds, std::vector<IkTarget>* targets,
              std::vector<int>* lines) {
    const int n = model_.num_joints();
    std::string_view l;
    for (int count = 0; count < max_rows && NextLine(&l); ++count) {
      const std::vector<std::string_view> f = internal::SplitFields(l);
      // Every field the header names, no more (a decimal comma), no fewer ("no q6").
      if (Status s = CheckCsvRowFields(f.size(), header_, path_, line_); !s.ok()) return s;
      const size_t base = seeds->size();
      seeds->resize(base + n);
      for (int j = 0; j < n; ++j) {
        double v;
        if (!ParseFinite(f[col_q_[j]], &v) || std::abs(v) > kMaxAbsCsvJointValue) {
          return Error("q" + std::to_string(j + 1) + " " + internal::Quote(f[col_q_[j]]) +
                       " is not a joint value; expected a finite number of magnitude at most 1e4");
        }
        max_abs_[j] = std::max(max_abs_[j], std::abs(v));
        if (model_.joints[j].type == JointType::kRevolute) {
          if (unit_ == AngleUnit::kDegrees) v /= kDegreesPerRadian;
        } else {
          v *= mm_per_unit_;
        }
        (*seeds)[base + j] = v;
      }
      IkTarget target;
      target.tool = compensator_.default_tool();
      if (col_target_ >= 0 && !f[col_target_].empty()) {
        target.tool = compensator_.ResolveTool(std::string(f[col_target_]));
        if (target.tool < 0) {
          return Error("target " + internal::Quote(f[col_target_]) +
                       " is neither a tool name nor an index below " +
                       std::to_string(model_.num_tools()));
        }
      }
      if (need_position_) {
        const int xyz[3] = {col_x_, col_y_, col_z_};
        for (int k = 0; k < 3; ++k) {
          double v;
          if (!ParseFinite(f[xyz[k]], &v) || std::abs(v * mm_per_unit_) > kMaxAbsCsvPositionMm) {
            // A finite value read in metres beyond the limit is most likely millimetres: say
            // which flag read it so.
            const bool metres = mm_per_unit_ != 1.0 && ParseFinite(f[xyz[k]], &v);
            return Error(std::string("xyz").substr(k, 1) + " " + internal::Quote(f[xyz[k]]) +
                         " is not a position; expected a finite number of magnitude at most "
                         "1e6 mm" +
                         (metres ? std::string(" (read in metres, --length_unit=m; millimetres "
                                               "are --length_unit=mm)")
                                 : std::string()));
          }
          target.position(k) = v * mm_per_unit_;
        }
        if (col_quat_[0] >= 0) {
          int given = 0;
          for (int k = 0; k < 4; ++k) given += !f[col_quat_[k]].empty();
          if (given == 4) {
            Eigen::Vector4d qv;
            for (int k = 0; k < 4; ++k) {
              if (!ParseFinite(f[col_quat_[k]], &qv(k))) {
                return Error("quaternion component is not a finite number");
              }
            }
            if (std::abs(qv.norm() - 1) > 1e-3) {
              return Error("the quaternion is not unit (norm within 1e-3 expected)");
            }
            target.has_orientation = true;
            target.rotation = QuaternionToRotation<double>(qv / qv.norm());
          } else if (given != 0) {
            return Error("give all four quat_* values (a pose row) or none (a position row)");
          }
        }
      }
      targets->push_back(target);
      lines->push_back(line_);
    }
    return reader_.status();
  }

 private:
  Status Error(const std::string& what) const {
    return Status::Error(path_ + ":" + std::to_string(line_) + ": " + what);
  }
  // The next non-empty line that is not a comment (a UTF-8 BOM at the start removed).
  bool NextLine(std::string_view* out) {
    while (reader_.Next(&text_)) {
      ++line_;
      std::string_view l(text_);
      if (line_ == 1 && l.compare(0, 3, "\xEF\xBB\xBF") == 0) l.remove_prefix(3);
      while (!l.empty() && l.back() == '\r') l.remove_suffix(1);
      l = Trim(l);
      if (l.empty() || l.front() == '#') continue;
      *out = l;
      return true;
    }
    return false;
  }

  const std::string path_;
  const Compensator& compensator_;
  const RobotModel& model_;
  const AngleUnit unit_;
  const double mm_per_unit_;
  const bool need_position_;
  LineReader reader_;
  std::string text_;
  int line_ = 0;
  std::vector<int> col_q_;
  std::vector<double> max_abs_ = std::vector<double>(kMaxJointsRead, 0.0);
  CsvHeader header_;
  int col_x_ = -1, col_y_ = -1, col_z_ = -1, col_target_ = -1, col_quat_[4] = {-1, -1, -1, -1};
};

using tools::kExitInput;
using tools::kExitOk;
using tools::kExitOutput;
using tools::kExitUsage;

// What the steps of a compensation share: the request, the units, the files and the solver.
struct Compensation {
  bool joints_mode = false;
  AngleUnit unit;
  LengthUnit length_unit;
  double mm_per_unit = 1;
  CompensationRequest request;
  tools::OutputSet outputs;
  std::unique_ptr<Compensator> compensator;
  std::string in_path;  // --joints or --targets
  bool orientation_columns = false;
};

// The workflow's request (lpoe/compensation.h) from the flags, the models not read yet; the
// outputs checked against the inputs.
int RequestFromFlags(Compensation* c) {
  c->joints_mode = !FLAGS_joints.empty();
  if (FLAGS_model.empty() || FLAGS_output.empty() || c->joints_mode == !FLAGS_targets.empty()) {
    std::cerr << "error: need --model, --output and one of --targets or --joints (see --help)\n";
    return kExitUsage;
  }
  if (FLAGS_joints_target != "pose" && FLAGS_joints_target != "position") {
    std::cerr << "error: --joints_target must be pose or position\n";
    return kExitUsage;
  }
  if (!tools::UnitsFromFlags(&c->unit, &c->length_unit, &c->mm_per_unit)) return kExitUsage;
  CompensationRequest& request = c->request;
  request.has_nominal = !FLAGS_nominal.empty();
  request.joints_mode = c->joints_mode;
  request.joints_target_pose = FLAGS_joints_target == "pose";
  if (!ParseTargetFrame(FLAGS_frame, &request.frame, &request.frame_link)) {
    std::cerr << "error: --frame must be base, measurement or link:NAME, got '" << FLAGS_frame
              << "'\n";
    return kExitUsage;
  }
  request.tcp = FLAGS_tcp;
  request.flange = FLAGS_flange;
  request.tool = FLAGS_tool;
  request.ik = tools::IkOptionsFromFlags();
  request.threads = FLAGS_threads;
  if (Status s = CheckCompensationRequest(request); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitUsage;
  }
  // Every output against every input and the other output, and its directory writable, before
  // any work (tools/common/output_files.h); both are committed together at the end or neither.
  tools::OutputSet& outputs = c->outputs;
  outputs.AddInput("--model", FLAGS_model);
  outputs.AddInput("--targets", FLAGS_targets);
  outputs.AddInput("--joints", FLAGS_joints);
  outputs.AddInput("--nominal", FLAGS_nominal);
  outputs.AddOutput("--output", FLAGS_output);
  outputs.AddOutput("--report", FLAGS_report);
  if (Status s = outputs.Check(); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitUsage;
  }
  return kExitOk;
}

// The models read and the compensator made from them.
int MakeCompensator(Compensation* c) {
  CompensationRequest& request = c->request;
  if (Status s = tools::CheckUrdfFlagsHaveAUrdf({FLAGS_model, FLAGS_nominal}); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitUsage;
  }
  if (Status s = tools::ReadModelWithUrdfFlags(FLAGS_model, &request.model, /*other_urdf=*/true);
      !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitInput;
  }
  if (request.has_nominal) {
    if (Status s = tools::ReadModelWithUrdfFlags(FLAGS_nominal, &request.nominal,
                                                 /*other_urdf=*/true);
        !s.ok()) {
      std::cerr << "error: " << s.message() << "\n";
      return kExitInput;
    }
  }
  bool input_error = false;
  if (Status s = Compensator::Create(request, &c->compensator, &input_error); !s.ok()) {
    std::cerr << "error: "
              << (input_error ? (s.message().rfind("nominal: ", 0) == 0
                                     ? FLAGS_nominal + ": " + s.message().substr(9)
                                     : FLAGS_model + ": " + s.message())
                              : s.message())
              << "\n";
    return input_error ? kExitInput : kExitUsage;
  }
  return kExitOk;
}

// The output CSV's comment and header lines.
std::string OutputHeader(const Compensation& c) {
  const bool joints_mode = c.joints_mode;
  const bool with_nominal = c.request.has_nominal;
  std::string header = "# lpoe_compensate: model " + tools::CommentText(FLAGS_model) + ", " +
                       (joints_mode ? "joints " : "targets ") + tools::CommentText(c.in_path) +
                       (joints_mode ? std::string()
                                    : ", targets in the " +
                                          std::string(c.request.frame == TargetFrame::kBase
                                                          ? "robot's base"
                                                          : "measurement") +
                                          " frame") +
                       ", angles in " + FLAGS_angle_unit +
                       (c.length_unit == LengthUnit::kMillimetres ? "" : ", lengths in m") +
                       (with_nominal ? "; corrected_* in the nominal model's base frame" : "") +
                       "\n";
  const int n = c.compensator->model().num_joints();
  for (int j = 0; j < n; ++j) header += "q" + std::to_string(j + 1) + ",";
  header += "status,residual,sigma_min";
  if (with_nominal) {
    header += ",corrected_x,corrected_y,corrected_z";
    if (c.orientation_columns) {
      header += ",corrected_quat_x,corrected_quat_y,corrected_quat_z,corrected_quat_w";
    }
  }
  header += "\n";
  return header;
}

// Formats rows [begin, end) of a solved chunk into `text`.
void FormatRows(const Compensation& c, const std::vector<IkTarget>& targets,
                const CompensatedRows& solved, int begin, int end, std::string* text) {
  const RobotModel& model = c.compensator->model();
  const int n = model.num_joints();
  std::string& out = *text;
  for (int k = begin; k < end; ++k) {
    const double* q = &solved.q[size_t(k) * n];
    const IkResult& r = solved.results[k];
    for (int j = 0; j < n; ++j) {
      const bool revolute = model.joints[j].type == JointType::kRevolute;
      AppendNumber(revolute ? (c.unit == AngleUnit::kDegrees ? q[j] * kDegreesPerRadian : q[j])
                            : q[j] / c.mm_per_unit,
                   &out);
      out += ',';
    }
    out += IkStatusName(r.status);
    out += ',';
    AppendNumber(r.position_error / c.mm_per_unit, &out);
    out += ',';
    AppendNumber(r.sigma_min, &out);
    if (c.request.has_nominal) {
      const SE3d& T = solved.corrected[k];
      for (int col = 0; col < 3; ++col) {
        out += ',';
        AppendNumber(T.t(col) / c.mm_per_unit, &out);
      }
      if (c.orientation_columns) {
        const Eigen::Vector4d qv = RotationToQuaternion<double>(T.R);
        for (int col = 0; col < 4; ++col) {
          out += ',';
          if (targets[k].has_orientation) AppendNumber(qv(col), &out);
        }
      }
    }
    out += '\n';
  }
}

// How streaming the rows failed: a bad row (exit 2), a compensation that is not finite (exit 5),
// else an unwritable output (exit 6).
struct StreamFailure {
  bool input = false;
  bool numerical = false;
};

// Streams the rows into the staged output at `temporary`: read a chunk, solve it on all threads
// (each a contiguous block, so the output keeps the input's order), format it the same way,
// write it.
Status StreamRows(const Compensation& c, RowReader* reader, const std::string& temporary,
                  CompensationSummary* total, StreamFailure* failure) {
  tools::StagedFile out;
  if (Status s = out.Create(temporary); !s.ok()) return s;
  if (Status s = out.Append(OutputHeader(c)); !s.ok()) return s;
  constexpr int kChunkRows = 1 << 15;
  Compensator& compensator = *c.compensator;
  std::vector<double> seeds;
  std::vector<IkTarget> targets;
  std::vector<int> lines;
  CompensatedRows solved;
  std::vector<std::string> texts;
  while (true) {
    seeds.clear();
    targets.clear();
    lines.clear();
    if (Status s = reader->Read(kChunkRows, &seeds, &targets, &lines); !s.ok()) {
      failure->input = true;
      return s;
    }
    const int chunk = static_cast<int>(targets.size());
    if (chunk == 0) break;
    compensator.Solve(seeds.data(), &targets, &solved);
    if (Status s = CheckCompensatedFinite(solved, lines.data(), 0, c.in_path); !s.ok()) {
      failure->numerical = true;
      return s;
    }
    texts.assign(compensator.Blocks(chunk), std::string());
    compensator.ForEachBlock(chunk, [&](int block, int begin, int end) {
      FormatRows(c, targets, solved, begin, end, &texts[block]);
    });
    for (const std::string& text : texts) {
      if (Status s = out.Append(text); !s.ok()) return s;
    }
    total->Add(solved, lines.data());
  }
  return out.Close();
}

// Warnings on the rows read: joint values that look like degrees, rows far from the layer's data.
void WarnAboutRows(const Compensation& c, const RowReader& reader,
                   const CompensationSummary& total) {
  const RobotModel& model = c.compensator->model();
  if (c.unit == AngleUnit::kRadians) {
    std::vector<double> max_abs = reader.max_abs();
    max_abs.resize(model.num_joints());
    const std::string hint = JointUnitHint(model, max_abs);
    if (!hint.empty()) std::cerr << "warning: " << c.in_path << ": " << hint << "\n";
  }
  if (total.layer_far_rows > 0) {
    std::cerr << "warning: " << c.in_path << ": " << total.layer_far_rows << " of " << total.rows
              << " row(s) are far from every configuration the residual layer was identified on "
                 "(kernel distance above "
              << kLayerFarDistance << " length scales; first on line " << total.layer_far_line
              << "): there its correction fades and the parametric model's accuracy applies "
                 "(docs/residual_layer.md)\n";
  }
}

// The summary: printed (unless --quiet), checked against the frame, and as the JSON report.
int Summarize(const Compensation& c, const CompensationSummary& total, nlohmann::json* report) {
  const int count = total.rows;
  nlohmann::json& r = *report;
  r["model"] = FLAGS_model;
  r["input"] = c.in_path;
  r["mode"] = c.joints_mode ? "joints" : "targets";
  r["rows"] = count;
  r["residual_layer_far_rows"] = total.layer_far_rows;
  nlohmann::json counts;
  std::ostringstream summary;
  summary << "lpoe_compensate: " << count << " rows:";
  for (int s = 0; s < 5; ++s) {
    const char* name = IkStatusName(static_cast<IkStatus>(s));
    counts[name] = total.per_status[s];
    summary << " " << name << " " << total.per_status[s];
  }
  summary << "\n  largest correction " << total.max_correction << " (rad/mm, Euclidean; line "
          << total.max_correction_line << ")\n  largest residual " << total.max_residual
          << " mm (line " << total.max_residual_line << "), orientation "
          << total.max_orientation_residual << " rad\n";
  if (!FLAGS_quiet) std::cerr << summary.str();
  // Most targets metres from anything the robot reaches are in another frame: an error that
  // says which frame was assumed; nothing is written.
  if (Status s = total.CheckFrame(c.request, c.in_path); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitInput;
  }
  r["frame"] = c.joints_mode ? "nominal program" : FLAGS_frame;
  r["status_counts"] = counts;
  r["largest_correction"] = {{"value", total.max_correction},
                             {"line", total.max_correction_line}};
  r["largest_residual_mm"] = {{"value", total.max_residual}, {"line", total.max_residual_line}};
  r["largest_orientation_residual_rad"] = total.max_orientation_residual;
  r["output"] = FLAGS_output;
  return kExitOk;
}

int Run() {
  Compensation c;
  if (int rc = RequestFromFlags(&c); rc != kExitOk) return rc;
  if (int rc = MakeCompensator(&c); rc != kExitOk) return rc;
  c.in_path = c.joints_mode ? FLAGS_joints : FLAGS_targets;
  RowReader reader(c.in_path, *c.compensator, c.unit, c.length_unit, !c.joints_mode);
  if (Status s = reader.Open(); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitInput;
  }
  c.orientation_columns = c.joints_mode ? c.request.joints_target_pose : reader.has_quaternion();
  // The output, streamed into its staged temporary (committed with the report at the end).
  CompensationSummary total;
  StreamFailure failure;
  Status staged = c.outputs.StageWith(FLAGS_output, [&](const std::string& temporary) {
    return StreamRows(c, &reader, temporary, &total, &failure);
  });
  if (!staged.ok()) {
    std::cerr << "error: " << staged.message() << "\n";
    return failure.numerical ? tools::kExitNumerical : failure.input ? kExitInput : kExitOutput;
  }
  WarnAboutRows(c, reader, total);
  nlohmann::json report;
  if (int rc = Summarize(c, total, &report); rc != kExitOk) return rc;
  if (!FLAGS_report.empty()) staged = c.outputs.Stage(FLAGS_report, tools::JsonText(report));
  if (tools::CommitOutputs(staged, &c.outputs, true) != kExitOk) return kExitOutput;
  if (FLAGS_strict && total.per_status[static_cast<int>(IkStatus::kOk)] != total.rows) {
    return kExitNotAllOk;
  }
  return kExitOk;
}

}  // namespace
}  // namespace lpoe

int main(int argc, char** argv) {
  lpoe::tools::InitTool(lpoe::kUsage, &argc, &argv);
  if (lpoe::tools::ProgramModeRequested()) return lpoe::tools::RunProgramMode();
  return lpoe::Run();
}
