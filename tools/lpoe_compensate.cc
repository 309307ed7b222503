// lpoe_compensate: the joints that make the calibrated robot reach its targets (issue 12).
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
#include <thread>
#include <vector>

#include <gflags/gflags.h>
#include <glog/logging.h>
#include <nlohmann/json.hpp>

#include "lpoe/csv_rules.h"
#include "lpoe/inverse_kinematics.h"
#include "lpoe/residual_layer.h"
#include "lpoe/io.h"
#include "lpoe/kinematics.h"
#include "lpoe/refusals.h"
#include "lpoe/se3.h"
#include "json_text.h"
#include "output_files.h"
#include "lpoe_compensate_program.h"
#include "tool_common.h"

DEFINE_string(model, "", "Calibrated robot model (YAML written by lpoe_calibrate, or URDF).");
DEFINE_string(targets, "",
              "Targets CSV: q1..qN (the seed: the joints the program would use), x,y,z (desired "
              "tool position, mm, model frame), optional target (tool name or index), optional "
              "quat_x,quat_y,quat_z,quat_w (desired tool orientation; empty for a position row).");
DEFINE_string(joints, "",
              "Joint-program CSV (q1..qN, optional target), planned with --nominal: the output "
              "makes the calibrated robot reach the nominal model's tool poses. Instead of "
              "--targets; needs --nominal.");
DEFINE_string(joints_target, "pose",
              "Joint-program mode: reach the nominal tool 'pose' or only its 'position'.");
DEFINE_string(output, "", "Output CSV: q1..qN (input unit), status, residual, sigma_min and, with "
                          "--nominal, corrected_x,y,z (and corrected_quat_*).");
DEFINE_string(nominal, "",
              "Nominal model (YAML or URDF): adds the nominal tool pose at the compensated joints "
              "(the target to send to a controller using nominal kinematics).");
DEFINE_string(angle_unit, "rad", "Unit of revolute joint values in and out: rad | deg.");
DEFINE_string(frame, "base",
              "Frame of the --targets positions and orientations: base (the robot's base frame, "
              "what programs use; carried into the calibrated model's frame by its recorded "
              "registration) | measurement (the frame the calibration's measurements were in, "
              "e.g. the tracker's). The same for a model calibrated in the base frame.");
DEFINE_string(tcp, "",
              "The TCP the targets are for, when it was not measured: a tool of the models, or "
              "x,y,z[,roll,pitch,yaw] (mm, rad; in the last joint's frame, where the models' tools "
              "are) added to both models. Rows without a target column use it.");
DEFINE_string(tool, "", "Tool name or index for rows without a target column (default: tool 0).");
DEFINE_string(report, "", "JSON summary to write (counts per status, largest correction/residual).");
DEFINE_bool(strict, false, "Exit 8 when any row is not 'ok' (the output is written anyway).");
DEFINE_int32(threads, 0, "Worker threads (0: all cores; the output order is the input's).");
DEFINE_int32(max_iterations, 100, "Newton iterations per attempt (1..10000).");
DEFINE_int32(restarts, 8, "Restarts from perturbed seeds when a solve stalls (0..100).");
DEFINE_double(position_tolerance, 1e-7, "Target reached when the position error is below (mm).");
DEFINE_double(orientation_tolerance, 1e-10, "... and the orientation error below (rad).");
DEFINE_double(singular_threshold, 1e-3,
              "Smallest singular value (mm per rad; rotation rows weighted 100 mm/rad) below which "
              "a row is 'singular'.");

namespace lpoe {
namespace {

constexpr char kUsage[] =
    "Compensates robot targets with a calibrated model (inverse kinematics).\n\n"
    "  lpoe_compensate --model=calibrated.yaml --targets=targets.csv --output=joints.csv\n"
    "  lpoe_compensate --model=calibrated.yaml --joints=program.csv --nominal=nominal.yaml \\\n"
    "      --output=joints.csv --report=summary.json\n\n"
    "Exit codes: 0 file processed (rows may carry a status other than ok), 1 bad flags or outputs "
    "(one names an input or the other output, or its directory is missing or not writable: "
    "checked before any row is read), 2 bad input file, 6 output not written (then neither is), "
    "8 --strict and some row not ok.";

constexpr int kExitNotAllOk = 8;
constexpr int kMaxJointsRead = InverseKinematics::kMaxJoints;
constexpr double kDegreesPerRadian = 180.0 / 3.14159265358979323846;

// Targets this far (mm) from anything the robot reaches are in another frame (--frame).
constexpr double kWrongFrameMm = 1000.0;

struct Row {
  IkTarget target;
  int line = 0;
};

int ResolveTool(const RobotModel& model, std::string_view field) {
  for (int t = 0; t < model.num_tools(); ++t) {
    if (field == model.tools[t].name) return t;
  }
  int index = -1;
  const auto [p, ec] = std::from_chars(field.data(), field.data() + field.size(), index);
  if (ec != std::errc() || p != field.data() + field.size()) return -1;
  return index >= 0 && index < model.num_tools() ? index : -1;
}

std::string_view Trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t' || s.front() == '\r')) {
    s.remove_prefix(1);
  }
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) {
    s.remove_suffix(1);
  }
  return s;
}

bool ParseNumber(std::string_view s, double* x) {
  s = Trim(s);
  if (!s.empty() && s.front() == '+') s.remove_prefix(1);
  const auto [p, ec] = std::from_chars(s.data(), s.data() + s.size(), *x);
  return ec == std::errc() && p == s.data() + s.size() && std::isfinite(*x);
}

// Reads the targets or joint-program CSV in chunks of rows (streamed: memory bounded by the chunk):
// seeds (radians/mm) and targets (positions and orientations only in targets mode).
class RowReader {
 public:
  RowReader(const std::string& path, const RobotModel& model, AngleUnit unit, bool need_position,
            int default_tool)
      : path_(path), model_(model), unit_(unit), need_position_(need_position),
        default_tool_(default_tool), col_q_(model.num_joints(), -1) {}

  // Opens the file and reads up to its header line.
  Status Open() {
    if (Status s = reader_.Open(path_); !s.ok()) return s;
    const int n = model_.num_joints();
    std::string_view l;
    while (NextLine(&l)) {
      // The header by the rules every reader shares (lpoe/csv_rules.h): no column twice.
      if (Status s = ParseCsvHeader(Fields(l), path_, line_, &header_); !s.ok()) return s;
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
        return Error("the header has no x, y, z columns; expected the target position (mm)");
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
  Status Read(int max_rows, std::vector<double>* seeds, std::vector<Row>* rows) {
    const int n = model_.num_joints();
    std::string_view l;
    for (int count = 0; count < max_rows && NextLine(&l); ++count) {
      const int nf = Split(l);
      // Every field the header names, no more (a decimal comma), no fewer ("no q6").
      if (Status s = CheckCsvRowFields(static_cast<size_t>(nf), header_, path_, line_); !s.ok()) {
        return s;
      }
      auto field = [&](int c) { return f_[c]; };
      const size_t base = seeds->size();
      seeds->resize(base + n);
      for (int j = 0; j < n; ++j) {
        double v;
        if (!ParseNumber(field(col_q_[j]), &v) || std::abs(v) > kMaxAbsCsvJointValue) {
          return Error("q" + std::to_string(j + 1) + " '" +
                       std::string(field(col_q_[j]).substr(0, 40)) +
                       "' is not a joint value; expected a finite number of magnitude at most 1e4");
        }
        max_abs_[j] = std::max(max_abs_[j], std::abs(v));
        if (unit_ == AngleUnit::kDegrees && model_.joints[j].type == JointType::kRevolute) {
          v /= kDegreesPerRadian;
        }
        (*seeds)[base + j] = v;
      }
      Row row;
      row.line = line_;
      row.target.tool = default_tool_;
      if (col_target_ >= 0 && !field(col_target_).empty()) {
        row.target.tool = ResolveTool(model_, field(col_target_));
        if (row.target.tool < 0) {
          return Error("target '" + std::string(field(col_target_)) +
                       "' is neither a tool name nor an index below " +
                       std::to_string(model_.num_tools()));
        }
      }
      if (need_position_) {
        const int xyz[3] = {col_x_, col_y_, col_z_};
        for (int k = 0; k < 3; ++k) {
          if (!ParseNumber(field(xyz[k]), &row.target.position(k)) ||
              std::abs(row.target.position(k)) > kMaxAbsCsvPositionMm) {
            return Error(std::string("xyz").substr(k, 1) + " '" +
                         std::string(field(xyz[k]).substr(0, 40)) +
                         "' is not a position; expected a finite number of magnitude at most "
                         "1e6 mm");
          }
        }
        if (col_quat_[0] >= 0) {
          int given = 0;
          for (int k = 0; k < 4; ++k) given += !field(col_quat_[k]).empty();
          if (given == 4) {
            Eigen::Vector4d qv;
            for (int k = 0; k < 4; ++k) {
              if (!ParseNumber(field(col_quat_[k]), &qv(k))) {
                return Error("quaternion component is not a finite number");
              }
            }
            if (std::abs(qv.norm() - 1) > 1e-3) {
              return Error("the quaternion is not unit (norm within 1e-3 expected)");
            }
            row.target.has_orientation = true;
            row.target.rotation = QuaternionToRotation<double>(qv / qv.norm());
          } else if (given != 0) {
            return Error("give all four quat_* values (a pose row) or none (a position row)");
          }
        }
      }
      rows->push_back(row);
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
      l = Trim(l);
      if (l.empty() || l.front() == '#') continue;
      *out = l;
      return true;
    }
    return false;
  }
  std::vector<std::string_view> Fields(std::string_view l) {
    Split(l);
    return f_;
  }
  int Split(std::string_view l) {
    f_.clear();
    size_t a = 0;
    while (true) {
      const size_t b = l.find(',', a);
      f_.push_back(Trim(l.substr(a, b == std::string_view::npos ? std::string_view::npos : b - a)));
      if (b == std::string_view::npos) break;
      a = b + 1;
    }
    return static_cast<int>(f_.size());
  }

  const std::string path_;
  const RobotModel& model_;
  const AngleUnit unit_;
  const bool need_position_;
  const int default_tool_;
  LineReader reader_;
  std::string text_;
  int line_ = 0;
  std::vector<std::string_view> f_;
  std::vector<int> col_q_;
  std::vector<double> max_abs_ = std::vector<double>(kMaxJointsRead, 0.0);
  CsvHeader header_;
  int col_x_ = -1, col_y_ = -1, col_z_ = -1, col_target_ = -1, col_quat_[4] = {-1, -1, -1, -1};
};

void AppendNumber(double x, std::string* out) {
  char buf[32];
  const auto [p, ec] = std::to_chars(buf, buf + sizeof(buf), x);
  out->append(buf, p);
}

// A solution farther than this from every inducing configuration of the model's residual layer
// (in length-scale units) gets less than exp(-3^2 / 2) = 1 % of the kernel's weight there.
constexpr double kLayerFarDistance = 3.0;

int Run() {
  using tools::kExitInput;
  using tools::kExitOk;
  using tools::kExitOutput;
  using tools::kExitUsage;
  // ---- Flags.
  const bool joints_mode = !FLAGS_joints.empty();
  if (FLAGS_model.empty() || FLAGS_output.empty() || joints_mode == !FLAGS_targets.empty()) {
    std::cerr << "error: need --model, --output and one of --targets or --joints (see --help)\n";
    return kExitUsage;
  }
  if (joints_mode && FLAGS_nominal.empty()) {
    std::cerr << "error: --joints needs --nominal (the model the program was planned with)\n";
    return kExitUsage;
  }
  if (FLAGS_joints_target != "pose" && FLAGS_joints_target != "position") {
    std::cerr << "error: --joints_target must be pose or position\n";
    return kExitUsage;
  }
  AngleUnit unit;
  if (!tools::ParseAngleUnit(FLAGS_angle_unit, &unit)) {
    std::cerr << "error: --angle_unit must be rad or deg\n";
    return kExitUsage;
  }
  if (FLAGS_frame != "base" && FLAGS_frame != "measurement") {
    std::cerr << "error: --frame must be base or measurement, got '" << FLAGS_frame << "'\n";
    return kExitUsage;
  }
  // --tcp as numbers: x,y,z[,roll,pitch,yaw].
  std::vector<double> tcp_numbers;
  {
    std::stringstream ss(FLAGS_tcp);
    bool numeric = !FLAGS_tcp.empty();
    for (std::string item; numeric && std::getline(ss, item, ',');) {
      char* end = nullptr;
      const double v = std::strtod(item.c_str(), &end);
      if (item.empty() || *end != '\0' || !std::isfinite(v)) numeric = false;
      tcp_numbers.push_back(v);
    }
    if (!numeric) tcp_numbers.clear();
    if (numeric && tcp_numbers.size() != 3 && tcp_numbers.size() != 6) {
      std::cerr << "error: --tcp=" << FLAGS_tcp
                << ": expected x,y,z or x,y,z,roll,pitch,yaw (mm, rad), or a tool name\n";
      return kExitUsage;
    }
  }
  if (!FLAGS_tcp.empty() && !FLAGS_tool.empty()) {
    std::cerr << "error: give --tcp or --tool, not both\n";
    return kExitUsage;
  }
  if (FLAGS_threads < 0 || FLAGS_threads > 256 || FLAGS_max_iterations < 1 ||
      FLAGS_max_iterations > 10000 || FLAGS_restarts < 0 || FLAGS_restarts > 100 ||
      !(FLAGS_position_tolerance > 0) || !(FLAGS_orientation_tolerance > 0) ||
      !(FLAGS_singular_threshold >= 0)) {
    std::cerr << "error: need 0 <= --threads <= 256, 1 <= --max_iterations <= 10000, "
                 "0 <= --restarts <= 100, positive tolerances, --singular_threshold >= 0\n";
    return kExitUsage;
  }
  // Every output against every input and the other output, and its directory writable, before
  // any work (tools/output_files.h); both are committed together at the end or neither.
  tools::OutputSet outputs;
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

  // ---- Inputs.
  RobotModel model, nominal;
  if (Status s = tools::CheckUrdfFlagsHaveAUrdf({FLAGS_model, FLAGS_nominal}); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitUsage;
  }
  if (Status s = tools::ReadModelWithUrdfFlags(FLAGS_model, &model, /*other_urdf=*/true);
      !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitInput;
  }
  if (Status s = InverseKinematics::CheckModel(model); !s.ok()) {
    std::cerr << "error: " << FLAGS_model << ": " << s.message() << "\n";
    return kExitInput;
  }
  const bool with_nominal = !FLAGS_nominal.empty();
  if (with_nominal) {
    if (Status s = tools::ReadModelWithUrdfFlags(FLAGS_nominal, &nominal, /*other_urdf=*/true);
        !s.ok()) {
      std::cerr << "error: " << s.message() << "\n";
      return kExitInput;
    }
    if (Status s = CheckNominalMatches(model, nominal); !s.ok()) {
      std::cerr << "error: " << FLAGS_nominal << ": " << s.message() << "\n";
      return kExitInput;
    }
  }
  int default_tool = 0;
  if (!tcp_numbers.empty()) {
    // A TCP given by its offset: one more tool of both models (the same place on the flange).
    const bool rpy = tcp_numbers.size() == 6;
    const Eigen::Matrix3d R = RotationFromRpy(rpy ? tcp_numbers[3] : 0.0, rpy ? tcp_numbers[4] : 0.0,
                                              rpy ? tcp_numbers[5] : 0.0);
    const Tool tcp{"tcp", SE3d(R, Eigen::Vector3d(tcp_numbers[0], tcp_numbers[1], tcp_numbers[2]))};
    model.tools.push_back(tcp);
    if (with_nominal) nominal.tools.push_back(tcp);
    default_tool = model.num_tools() - 1;
  } else if (!FLAGS_tcp.empty()) {
    default_tool = model.FindTool(FLAGS_tcp);
    if (default_tool < 0 || (with_nominal && nominal.FindTool(FLAGS_tcp) != default_tool)) {
      std::cerr << "error: --tcp=" << FLAGS_tcp << " is not a tool of "
                << (default_tool < 0 ? FLAGS_model : FLAGS_nominal)
                << " (at the same index in both models) nor x,y,z[,roll,pitch,yaw]; with a URDF, "
                   "name its link in --tool_links\n";
      return kExitUsage;
    }
  }
  if (!FLAGS_tool.empty()) {
    default_tool = ResolveTool(model, FLAGS_tool);
    if (default_tool < 0) {
      std::cerr << "error: --tool=" << FLAGS_tool << " is neither a tool name of "
                << FLAGS_model << " nor an index below " << model.num_tools() << "\n";
      return kExitUsage;
    }
  }
  const std::string& in_path = joints_mode ? FLAGS_joints : FLAGS_targets;
  RowReader reader(in_path, model, unit, !joints_mode, default_tool);
  if (Status s = reader.Open(); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitInput;
  }
  const int n = model.num_joints();
  IkOptions options;
  options.max_iterations = FLAGS_max_iterations;
  options.restarts = FLAGS_restarts;
  options.position_tolerance = FLAGS_position_tolerance;
  options.orientation_tolerance = FLAGS_orientation_tolerance;
  options.singular_threshold = FLAGS_singular_threshold;
  const InverseKinematics ik(model, options);  // with the model's joint-error terms
  const KinematicChain nominal_chain(with_nominal ? nominal : model);
  const bool orientation_columns =
      joints_mode ? FLAGS_joints_target == "pose" : reader.has_quaternion();
  const int threads = FLAGS_threads > 0
                          ? FLAGS_threads
                          : std::max(1, static_cast<int>(std::thread::hardware_concurrency()));

  std::string header = "# lpoe_compensate: model " + tools::CommentText(FLAGS_model) + ", " +
                       (joints_mode ? "joints " : "targets ") + tools::CommentText(in_path) +
                       (joints_mode ? std::string()
                                    : ", targets in the " +
                                          std::string(FLAGS_frame == "base" ? "robot's base"
                                                                            : "measurement") +
                                          " frame") +
                       ", angles in " + FLAGS_angle_unit +
                       (with_nominal ? "; corrected_* in the nominal model's base frame" : "") +
                       "\n";
  for (int j = 0; j < n; ++j) header += "q" + std::to_string(j + 1) + ",";
  header += "status,residual,sigma_min";
  if (with_nominal) {
    header += ",corrected_x,corrected_y,corrected_z";
    if (orientation_columns) {
      header += ",corrected_quat_x,corrected_quat_y,corrected_quat_z,corrected_quat_w";
    }
  }
  header += "\n";

  // Per worker: its rows' output text and summary.
  struct Part {
    std::string text;
    int per_status[5] = {};
    double max_correction = 0, max_residual = 0, max_orientation_residual = 0;
    int max_correction_line = 0, max_residual_line = 0;
    int far_rows = 0;  // rows metres from anything the robot reaches (kWrongFrameMm)
    // Rows whose solution is far from every identification configuration of the model's residual
    // layer (kLayerFarDistance): there its correction fades to the parametric model's.
    int layer_far_rows = 0, layer_far_line = 0;
  };
  // Solves rows [begin, end) of a chunk and formats them into `part`.
  auto solve_rows = [&](const std::vector<Row>& rows, const std::vector<double>& seeds, int begin,
                        int end, Part* part) {
    double q[InverseKinematics::kMaxJoints];
    for (int k = begin; k < end; ++k) {
      const Row& row = rows[k];
      const IkResult r = ik.Solve(row.target, &seeds[size_t(k) * n], q);
      std::string& out = part->text;
      for (int j = 0; j < n; ++j) {
        const bool deg =
            unit == AngleUnit::kDegrees && model.joints[j].type == JointType::kRevolute;
        AppendNumber(deg ? q[j] * kDegreesPerRadian : q[j], &out);
        out += ',';
      }
      out += IkStatusName(r.status);
      out += ',';
      AppendNumber(r.position_error, &out);
      out += ',';
      AppendNumber(r.sigma_min, &out);
      if (with_nominal) {
        const SE3d T = nominal_chain.Pose(q, row.target.tool);
        for (int c = 0; c < 3; ++c) {
          out += ',';
          AppendNumber(T.t(c), &out);
        }
        if (orientation_columns) {
          const Eigen::Vector4d qv = RotationToQuaternion<double>(T.R);
          for (int c = 0; c < 4; ++c) {
            out += ',';
            if (row.target.has_orientation) AppendNumber(qv(c), &out);
          }
        }
      }
      out += '\n';
      ++part->per_status[static_cast<int>(r.status)];
      if (r.correction > part->max_correction) {
        part->max_correction = r.correction;
        part->max_correction_line = row.line;
      }
      if (r.position_error > kWrongFrameMm) ++part->far_rows;
      if (model.residual_layer && model.residual_layer->KernelDistance(q) > kLayerFarDistance) {
        if (part->layer_far_rows++ == 0) part->layer_far_line = row.line;
      }
      if (r.position_error > part->max_residual) {
        part->max_residual = r.position_error;
        part->max_residual_line = row.line;
      }
      part->max_orientation_residual =
          std::max(part->max_orientation_residual, r.orientation_error);
    }
  };

  // ---- The output, streamed into its staged temporary (committed with the report at the end).
  Part total;
  int count = 0;
  bool input_failed = false;  // a bad row (exit 2), not an unwritable output (exit 6)
  Status staged = outputs.StageWith(FLAGS_output, [&](const std::string& temporary) -> Status {
    tools::StagedFile out;
    if (Status s = out.Create(temporary); !s.ok()) return s;
    if (Status s = out.Append(header); !s.ok()) return s;
    // ---- Stream: read a chunk, solve it on all threads (each a contiguous share, so the output
    // keeps the input's order), write it.
    constexpr int kChunkRows = 1 << 15;
    std::vector<double> seeds;
    std::vector<Row> rows;
    std::vector<Part> parts(threads);
    while (true) {
      seeds.clear();
      rows.clear();
      if (Status s = reader.Read(kChunkRows, &seeds, &rows); !s.ok()) {
        input_failed = true;
        return s;
      }
      const int chunk = static_cast<int>(rows.size());
      if (chunk == 0) break;
      // Targets in the base frame: carried into the calibrated model's (measurement) frame.
      if (!joints_mode && FLAGS_frame == "base") {
        for (int k = 0; k < chunk; ++k) {
          IkTarget& t = rows[k].target;
          t.position = model.T_measurement_base * t.position;
          t.rotation = model.T_measurement_base.R * t.rotation;
        }
      }
      // Joint-program mode: the nominal tool pose at the program's joints, in the calibrated
      // model's (measurement) frame.
      if (joints_mode) {
        for (int k = 0; k < chunk; ++k) {
          IkTarget& t = rows[k].target;
          const SE3d T = model.T_measurement_base * nominal_chain.Pose(&seeds[size_t(k) * n], t.tool);
          t.position = T.t;
          t.rotation = T.R;
          t.has_orientation = FLAGS_joints_target == "pose";
        }
      }
      const int workers = std::max(1, std::min(threads, chunk / 256));
      std::vector<std::thread> pool;
      for (int t = 0; t < workers; ++t) {
        parts[t].text.clear();
        const int begin = static_cast<int>(int64_t{chunk} * t / workers);
        const int end = static_cast<int>(int64_t{chunk} * (t + 1) / workers);
        if (t + 1 < workers) {
          pool.emplace_back(solve_rows, std::cref(rows), std::cref(seeds), begin, end, &parts[t]);
        } else {
          solve_rows(rows, seeds, begin, end, &parts[t]);
        }
      }
      for (std::thread& th : pool) th.join();
      // Worker t's rows precede worker t+1's: in order.
      for (int t = 0; t < workers; ++t) {
        if (Status s = out.Append(parts[t].text); !s.ok()) return s;
        Part& p = parts[t];
        for (int c = 0; c < 5; ++c) total.per_status[c] += p.per_status[c];
        if (p.max_correction > total.max_correction) {
          total.max_correction = p.max_correction;
          total.max_correction_line = p.max_correction_line;
        }
        if (p.max_residual > total.max_residual) {
          total.max_residual = p.max_residual;
          total.max_residual_line = p.max_residual_line;
        }
        total.max_orientation_residual =
            std::max(total.max_orientation_residual, p.max_orientation_residual);
        total.far_rows += p.far_rows;
        if (total.layer_far_rows == 0) total.layer_far_line = p.layer_far_line;
        total.layer_far_rows += p.layer_far_rows;
        p = Part();
      }
      count += chunk;
    }
    return out.Close();
  });
  if (!staged.ok()) {
    std::cerr << "error: " << staged.message() << "\n";
    return input_failed ? kExitInput : kExitOutput;
  }
  if (unit == AngleUnit::kRadians) {
    std::vector<double> max_abs = reader.max_abs();
    max_abs.resize(n);
    const std::string hint = JointUnitHint(model, max_abs);
    if (!hint.empty()) std::cerr << "warning: " << in_path << ": " << hint << "\n";
  }
  const int* per_status = total.per_status;
  const double max_correction = total.max_correction, max_residual = total.max_residual;
  const double max_orientation_residual = total.max_orientation_residual;
  const int max_correction_line = total.max_correction_line;
  const int max_residual_line = total.max_residual_line;

  if (total.layer_far_rows > 0) {
    std::cerr << "warning: " << in_path << ": " << total.layer_far_rows << " of " << count
              << " row(s) are far from every configuration the residual layer was identified on "
                 "(kernel distance above "
              << kLayerFarDistance << " length scales; first on line " << total.layer_far_line
              << "): there its correction fades and the parametric model's accuracy applies "
                 "(docs/residual_layer.md)\n";
  }
  // ---- Summary.
  nlohmann::json report;
  report["model"] = FLAGS_model;
  report["input"] = in_path;
  report["mode"] = joints_mode ? "joints" : "targets";
  report["rows"] = count;
  report["residual_layer_far_rows"] = total.layer_far_rows;
  nlohmann::json counts;
  std::cerr << "lpoe_compensate: " << count << " rows:";
  for (int s = 0; s < 5; ++s) {
    const char* name = IkStatusName(static_cast<IkStatus>(s));
    counts[name] = per_status[s];
    std::cerr << " " << name << " " << per_status[s];
  }
  std::cerr << "\n  largest correction " << max_correction << " (rad/mm, Euclidean; line "
            << max_correction_line << ")\n  largest residual " << max_residual << " mm (line "
            << max_residual_line << "), orientation " << max_orientation_residual << " rad\n";
  // Most targets metres from anything the robot reaches are in another frame, not beyond the
  // robot's reach: an error that says which frame was assumed; nothing is written. (One far row
  // is an unreachable target, written with its status.)
  if (!joints_mode && count > 0 && 2 * total.far_rows > count) {
    std::cerr << "error: " << in_path << ": " << total.far_rows << " of " << count
              << " targets are more than " << kWrongFrameMm
              << " mm from any pose the calibrated robot reaches (line " << max_residual_line
              << ": " << max_residual << " mm): the targets were read in the " << (FLAGS_frame == "base" ? "robot's base" : "measurement")
              << " frame (--frame=" << FLAGS_frame << "); if they are in the "
              << (FLAGS_frame == "base" ? "measurement (tracker)" : "robot's base")
              << " frame, use --frame=" << (FLAGS_frame == "base" ? "measurement" : "base")
              << "; no output written\n";
    return kExitInput;
  }
  report["frame"] = joints_mode ? "nominal program" : FLAGS_frame;
  report["status_counts"] = counts;
  report["largest_correction"] = {{"value", max_correction}, {"line", max_correction_line}};
  report["largest_residual_mm"] = {{"value", max_residual}, {"line", max_residual_line}};
  report["largest_orientation_residual_rad"] = max_orientation_residual;
  report["output"] = FLAGS_output;
  if (!FLAGS_report.empty()) staged = outputs.Stage(FLAGS_report, tools::JsonText(report));
  if (Status s = staged.ok() ? outputs.Commit(nullptr) : staged; !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitOutput;
  }
  if (FLAGS_strict && per_status[static_cast<int>(IkStatus::kOk)] != count) return kExitNotAllOk;
  return kExitOk;
}

}  // namespace
}  // namespace lpoe

int main(int argc, char** argv) {
  lpoe::tools::InitTool(lpoe::kUsage, &argc, &argv);
  if (lpoe::tools::ProgramModeRequested()) return lpoe::tools::RunProgramMode();  // issue 32
  return lpoe::Run();
}
