// Distance and plane measurements: the set, its CSV reader and writer, and their simulation
// (lpoe/measurements/contact_measurements.h, docs/measurements.md).
#include "lpoe/measurements/contact_measurements.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <random>
#include <string_view>

#include <Eigen/Dense>

#include "io/file_util.h"
#include "lpoe/io/csv_rules.h"
#include "lpoe/measurements/distance_measurement.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/measurements/plane_measurement.h"
#include "io/parse_util.h"

namespace lpoe {

using internal::LineError;
using internal::Quote;

namespace {

constexpr size_t kMaxContactFileBytes = size_t{256} << 20;
constexpr double kPiContact = 3.14159265358979323846;

bool CommentOrBlank(std::string_view line) {
  for (char c : line) {
    if (c == ' ' || c == '\t' || c == '\r') continue;
    return c == '#';
  }
  return true;
}

int ContactTarget(std::string_view field, const RobotModel& model) {
  for (int t = 0; t < model.num_tools(); ++t) {
    if (field == model.tools[t].name) return t;
  }
  if (field.empty() || field.size() > 9) return -1;
  int index = 0;
  const auto r = std::from_chars(field.data(), field.data() + field.size(), index);
  if (r.ec != std::errc() || r.ptr != field.data() + field.size()) return -1;
  return index >= 0 && index < model.num_tools() ? index : -1;
}

// A feature name: printable, at most 64 bytes.
bool ValidFeatureName(std::string_view s) {
  if (s.empty() || s.size() > 64) return false;
  for (char c : s) {
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) return false;
  }
  return true;
}

// Splits text into lines (LF or CRLF), calling f(line, number) until it returns a failed status.
template <typename F>
Status ForEachLine(std::string_view text, F f) {
  int64_t number = 0;
  size_t start = 0;
  if (text.size() >= 3 && static_cast<unsigned char>(text[0]) == 0xEF &&
      static_cast<unsigned char>(text[1]) == 0xBB && static_cast<unsigned char>(text[2]) == 0xBF) {
    start = 3;
  }
  while (start < text.size()) {
    size_t end = text.find('\n', start);
    if (end == std::string_view::npos) end = text.size();
    std::string_view line = text.substr(start, end - start);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    ++number;
    Status s = f(line, number);
    if (!s.ok()) return s;
    start = end + 1;
  }
  return Status::Ok();
}

}  // namespace

int ContactMeasurementSet::Feature(MeasurementKindId kind, const std::string& name) {
  std::vector<std::string>& names = kind == MeasurementKindId::kPlane ? planes : pivots;
  for (size_t i = 0; i < names.size(); ++i) {
    if (names[i] == name) return static_cast<int>(i);
  }
  names.push_back(name);
  return static_cast<int>(names.size()) - 1;
}

int ContactMeasurementSet::Count(MeasurementKindId kind) const {
  int count = 0;
  for (const ContactRow& r : rows) count += r.kind == kind ? 1 : 0;
  return count;
}

void ContactMeasurementSet::Append(const ContactMeasurementSet& other) {
  if (rows.empty() && num_joints == 0) num_joints = other.num_joints;
  const int file_base = static_cast<int>(files.size());
  files.insert(files.end(), other.files.begin(), other.files.end());
  q.insert(q.end(), other.q.begin(), other.q.end());
  for (ContactRow r : other.rows) {
    if (r.kind == MeasurementKindId::kDistance) r.feature = Feature(r.kind, other.pivots[r.feature]);
    if (r.kind == MeasurementKindId::kPlane) r.feature = Feature(r.kind, other.planes[r.feature]);
    r.file += file_base;
    rows.push_back(r);
  }
}

ContactMeasurementSet ContactMeasurementSet::Subset(const std::vector<int>& which) const {
  ContactMeasurementSet out;
  out.num_joints = num_joints;
  out.pivots = pivots;
  out.planes = planes;
  out.files = files;
  for (int r : which) {
    out.rows.push_back(rows[r]);
    out.q.insert(out.q.end(), joints(r), joints(r) + num_joints);
  }
  return out;
}

std::string ContactMeasurementSet::Where(int row) const {
  const ContactRow& r = rows[row];
  const std::string file = r.file < static_cast<int>(files.size()) ? files[r.file] : "(generated)";
  return r.line > 0 ? file + ":" + std::to_string(r.line) : file + " row " + std::to_string(row + 1);
}

ContactMeasurementSet ContactSetFromPositions(const MeasurementSet& data, double sigma,
                                              const std::string& source) {
  ContactMeasurementSet out;
  out.num_joints = data.num_joints();
  out.files.push_back(source);
  for (int r = 0; r < data.size(); ++r) {
    ContactRow row;
    row.kind = MeasurementKindId::kPosition;
    row.target = data.target(r);
    row.sigma = sigma;
    row.position = data.position(r);
    row.line = data.source_line(r);
    out.rows.push_back(row);
    out.q.insert(out.q.end(), data.q(r), data.q(r) + data.num_joints());
  }
  return out;
}

namespace {

// The rows of one distance or plane CSV file: the header picks the kind and the columns, every
// row after it one ContactRow (its joints in set.q).
class ContactCsvParser {
 public:
  ContactCsvParser(const std::string& source, const RobotModel& model,
                   const ContactCsvOptions& options)
      : source_(source), model_(model), options_(options), n_(model.num_joints()),
        joint_column_(n_, -1) {
    set.num_joints = n_;
    set.files.push_back(source);
  }

  Status Line(std::string_view line, int64_t number) {
    if (line.find('\0') != std::string_view::npos) {
      return LineError(source_, number, "a NUL byte", "CSV text");
    }
    if (CommentOrBlank(line)) return Status::Ok();
    const std::vector<std::string_view> fields = internal::SplitFields(line);
    if (!have_header) return Header(fields, number);
    return Row(fields, number);
  }

  ContactMeasurementSet set;
  CsvHeader header;
  bool have_header = false;

 private:
  Status Header(const std::vector<std::string_view>& fields, int64_t number) {
    Status s = ParseCsvHeader(fields, source_, number, &header);
    if (!s.ok()) return s;
    have_header = true;
    std::string ambiguous;
    const MeasurementKindInfo* detected = DetectMeasurementKind(header.names, &ambiguous);
    if (detected == nullptr && !ambiguous.empty()) {
      return LineError(source_, number, ambiguous, "one of " + MeasurementKindNames());
    }
    kind_ = options_.kind != nullptr ? options_.kind : detected;
    if (kind_ == nullptr || (kind_->id != MeasurementKindId::kDistance &&
                             kind_->id != MeasurementKindId::kPlane)) {
      return LineError(source_, number,
                       "no 'distance' or 'plane' column" +
                           (detected != nullptr ? std::string(" (a ") + detected->name + " file)"
                                                : std::string()),
                       "q1..qN,distance[,pivot][,target][,sigma] or "
                       "q1..qN,plane[,offset][,target][,sigma]");
    }
    if (detected != kind_) {
      return LineError(source_, number,
                       std::string("--data_kind=") + kind_->name + " but the columns are " +
                           (detected != nullptr ? std::string("a ") + detected->name + " file's"
                                                : std::string("of no known kind")),
                       std::string("the columns ") + kind_->columns);
    }
    for (int j = 0; j < n_; ++j) {
      joint_column_[j] = header.Find("q" + std::to_string(j + 1));
      if (joint_column_[j] < 0) joint_column_[j] = header.Find(model_.joints[j].name);
      if (joint_column_[j] < 0) {
        return LineError(source_, number, "no column for joint " + std::to_string(j + 1),
                         "q" + std::to_string(j + 1) + " or " + Quote(model_.joints[j].name));
      }
    }
    // The feature's column (pivot, plane) from the kind's line of the table; the measured value's
    // (a distance, required; a probe's offset, optional) and its checks are the kind's (Value).
    feature_column_ = header.Find(kind_->feature_column);
    if (kind_->id == MeasurementKindId::kDistance) {
      value_column_ = header.Find("distance");
    } else {
      offset_column_ = header.Find("offset");
    }
    target_column_ = header.Find("target");
    sigma_column_ = header.Find("sigma");
    if (sigma_column_ < 0 && !(options_.sigma > 0)) {
      return LineError(source_, number, "no 'sigma' column and no noise given",
                       "a 'sigma' column (mm) or --sigma for this file");
    }
    return Status::Ok();
  }

  Status NumberOf(const std::vector<std::string_view>& fields, int64_t number, int column,
                  const char* what, double* v) const {
    const std::string_view f = fields[column];
    const internal::NumberParse p = internal::ParseNumber(f, v);
    if (p != internal::NumberParse::kOk) {
      return LineError(source_, number,
                       std::string("column '") + header.names[column] + "': " + Quote(f) +
                           (p == internal::NumberParse::kNonFinite ? " is not finite" : ""),
                       what);
    }
    return Status::Ok();
  }

  // The row's joint values, in the model's units (rad, mm), appended to set.q.
  Status Joints(const std::vector<std::string_view>& fields, int64_t number) {
    for (int j = 0; j < n_; ++j) {
      double v = 0;
      if (Status s = NumberOf(fields, number, joint_column_[j], "a finite joint value", &v);
          !s.ok()) {
        return s;
      }
      if (std::abs(v) > kMaxAbsCsvJointValue) {
        return LineError(source_, number,
                         "column '" + header.names[joint_column_[j]] + "': " +
                             Quote(fields[joint_column_[j]]) + " is out of range",
                         "a joint value of magnitude at most 1e4");
      }
      if (model_.joints[j].type == JointType::kRevolute &&
          options_.units.angle_unit == AngleUnit::kDegrees) {
        v *= kPiContact / 180.0;
      }
      if (model_.joints[j].type == JointType::kPrismatic &&
          options_.units.length_unit == LengthUnit::kMetres) {
        v *= 1000.0;
      }
      set.q.push_back(v);
    }
    return Status::Ok();
  }

  // The distance (ballbar) or the probe tip's offset (plane) into row->value, in mm.
  Status Value(const std::vector<std::string_view>& fields, int64_t number, double length_scale,
               ContactRow* row) const {
    if (kind_->id == MeasurementKindId::kDistance) {
      Status s = NumberOf(fields, number, value_column_, "a distance (mm), positive", &row->value);
      if (!s.ok()) return s;
      row->value *= length_scale;
      if (!(row->value > 0) || row->value > kMaxAbsCsvPositionMm) {
        return LineError(source_, number,
                         "column 'distance': " + Quote(fields[value_column_]) + " is not a length",
                         "a distance above 0 and at most 1e6 mm");
      }
    } else if (offset_column_ >= 0) {
      Status s = NumberOf(fields, number, offset_column_,
                          "an offset (mm): the probe tip's radius", &row->value);
      if (!s.ok()) return s;
      row->value *= length_scale;
      if (std::abs(row->value) > kMaxAbsCsvPositionMm) {
        return LineError(source_, number, "column 'offset': " + Quote(fields[offset_column_]) +
                                              " is out of range",
                         "an offset of magnitude at most 1e6 mm");
      }
    }
    return Status::Ok();
  }

  // The pivot or plane, the tool and the noise of the row.
  Status FeatureToolSigma(const std::vector<std::string_view>& fields, int64_t number,
                          double length_scale, ContactRow* row) {
    std::string feature = kind_->id == MeasurementKindId::kDistance ? "pivot1" : "";
    if (feature_column_ >= 0) feature = std::string(fields[feature_column_]);
    if (!ValidFeatureName(feature)) {
      return LineError(source_, number,
                       std::string("column '") + kind_->feature_column + "': " + Quote(feature) +
                           " is not a name",
                       std::string("the ") + kind_->feature_noun +
                           "'s name (1 to 64 printable characters)");
    }
    row->feature = set.Feature(kind_->id, feature);
    if (target_column_ >= 0) {
      row->target = ContactTarget(fields[target_column_], model_);
      if (row->target < 0) {
        return LineError(source_, number,
                         "column 'target': unknown tool " + Quote(fields[target_column_]),
                         "a tool of the model (name or 0-based index)");
      }
    }
    row->sigma = options_.sigma;
    if (sigma_column_ >= 0) {
      Status s = NumberOf(fields, number, sigma_column_, "a noise (mm), positive", &row->sigma);
      if (!s.ok()) return s;
      row->sigma *= length_scale;
      if (!(row->sigma > 0) || row->sigma > 1e3) {
        return LineError(source_, number,
                         "column 'sigma': " + Quote(fields[sigma_column_]) + " is not a noise",
                         "a standard deviation above 0 and at most 1000 mm");
      }
    }
    return Status::Ok();
  }

  Status Row(const std::vector<std::string_view>& fields, int64_t number) {
    Status s = CheckCsvRowFields(fields.size(), header, source_, number);
    if (!s.ok()) return s;
    if (set.size() >= (1 << 30)) return LineError(source_, number, "too many rows", "at most 2^30");
    ContactRow row;
    row.kind = kind_->id;
    row.file = 0;
    row.line = number;
    if (s = Joints(fields, number); !s.ok()) return s;
    const double length_scale = options_.units.length_unit == LengthUnit::kMetres ? 1000.0 : 1.0;
    if (s = Value(fields, number, length_scale, &row); !s.ok()) return s;
    if (s = FeatureToolSigma(fields, number, length_scale, &row); !s.ok()) return s;
    set.rows.push_back(row);
    return Status::Ok();
  }

  const std::string& source_;
  const RobotModel& model_;
  const ContactCsvOptions& options_;
  const int n_;
  const MeasurementKindInfo* kind_ = nullptr;
  std::vector<int> joint_column_;
  int value_column_ = -1, feature_column_ = -1, offset_column_ = -1, target_column_ = -1,
      sigma_column_ = -1;
};

}  // namespace

Status ParseContactMeasurementsCsv(const std::string& text, const std::string& source,
                                   const RobotModel& model, const ContactCsvOptions& options,
                                   ContactMeasurementSet* out) {
  ContactCsvParser parser(source, model, options);
  const Status status = ForEachLine(text, [&](std::string_view line, int64_t number) -> Status {
    return parser.Line(line, number);
  });
  if (!status.ok()) return status;
  if (!parser.have_header) {
    return LineError(source, 1, "no header", "a header naming q1..qN and 'distance' or 'plane'");
  }
  if (parser.set.rows.empty()) {
    return LineError(source, parser.header.line > 0 ? parser.header.line : 1, "no data rows",
                     "at least one measurement");
  }
  *out = std::move(parser.set);
  return Status::Ok();
}

Status ReadContactMeasurements(const std::string& path, const RobotModel& model,
                               const ContactCsvOptions& options, ContactMeasurementSet* out) {
  std::string text;
  Status s = internal::ReadFileBounded(path, kMaxContactFileBytes, &text);
  if (!s.ok()) return s;
  return ParseContactMeasurementsCsv(text, path, model, options, out);
}

namespace {

// Whether `text` holds a complete line (ended by '\n') that is neither blank nor a comment, from
// *scanned on; *scanned moves past the complete lines looked at.
bool HasHeaderLine(const std::string& text, size_t* scanned) {
  while (true) {
    const size_t end = text.find('\n', *scanned);
    if (end == std::string::npos) return false;
    const std::string_view line(text.data() + *scanned, end - *scanned);
    *scanned = end + 1;
    if (!CommentOrBlank(line)) return true;
  }
}

// The file's text up to its header line (all of it when it has none): a tracker file of 10^6 rows
// is not read whole to learn its kind. Bounded by kMaxContactFileBytes like the readers.
Status ReadUpToHeader(const std::string& path, std::string* text) {
  try {
    internal::InputFile file;
    if (Status s = file.Open(path); !s.ok()) return s;
    char buf[1 << 16];
    size_t scanned = 0;
    while (!HasHeaderLine(*text, &scanned)) {
      size_t got = 0;
      if (Status s = file.Read(buf, sizeof(buf), &got); !s.ok()) return s;
      if (got == 0) break;
      if (text->size() + got > kMaxContactFileBytes) {
        return Status::Error(path + ": no header in the first " +
                             std::to_string(kMaxContactFileBytes) + " bytes");
      }
      text->append(buf, got);
    }
    return Status::Ok();
  } catch (const std::exception& e) {  // std::bad_alloc
    return Status::Error(path + ": cannot read: " + e.what());
  }
}

}  // namespace

Status DetectMeasurementFileKind(const std::string& path, const MeasurementKindInfo** kind) {
  *kind = nullptr;
  std::string text;
  Status s = ReadUpToHeader(path, &text);
  if (!s.ok()) return s;
  const MeasurementKindInfo* found = nullptr;
  bool done = false;
  s = ForEachLine(text, [&](std::string_view line, int64_t number) -> Status {
    if (done || CommentOrBlank(line)) return Status::Ok();
    done = true;
    std::vector<std::string> names;
    for (std::string_view f : internal::SplitFields(line)) names.emplace_back(f);
    std::string ambiguous;
    found = DetectMeasurementKind(names, &ambiguous);
    if (found == nullptr) {
      return LineError(path, number, ambiguous.empty() ? "a header of no measurement kind" : ambiguous,
                       "the columns of one of " + MeasurementKindNames() +
                           " (docs/file_formats.md)");
    }
    return Status::Ok();
  });
  if (!s.ok()) return s;
  if (found == nullptr) return LineError(path, 1, "no header", "a CSV header");
  *kind = found;
  return Status::Ok();
}

std::string ContactMeasurementsCsv(const RobotModel& model, const ContactMeasurementSet& data,
                                   MeasurementKindId kind) {
  const int n = model.num_joints();
  std::string out;
  for (int j = 0; j < n; ++j) out += "q" + std::to_string(j + 1) + ",";
  out += kind == MeasurementKindId::kDistance ? "distance,pivot,target,sigma\n"
                                              : "plane,offset,target,sigma\n";
  for (int r = 0; r < data.size(); ++r) {
    const ContactRow& row = data.rows[r];
    if (row.kind != kind) continue;
    for (int j = 0; j < n; ++j) {
      internal::AppendNumber(data.joints(r)[j], &out);
      out += ',';
    }
    if (kind == MeasurementKindId::kDistance) {
      internal::AppendNumber(row.value, &out);
      out += ',' + data.pivots[row.feature];
    } else {
      out += data.planes[row.feature] + ',';
      internal::AppendNumber(row.value, &out);
    }
    out += ',' + std::to_string(row.target) + ',';
    internal::AppendNumber(row.sigma, &out);
    out += '\n';
  }
  return out;
}

namespace {

// Joint values in the model's limits (and within [-pi, pi] for revolute joints without them).
bool WithinLimits(const RobotModel& model, const std::vector<double>& q) {
  for (int j = 0; j < model.num_joints(); ++j) {
    const Joint& joint = model.joints[j];
    const double lo = std::isfinite(joint.lower) ? joint.lower : -1e9;
    const double hi = std::isfinite(joint.upper) ? joint.upper : 1e9;
    if (q[j] < lo || q[j] > hi) return false;
  }
  return true;
}

// Moves q by Gauss-Newton (minimum-norm steps) until the tool's origin is at `target` (to 1e-9
// mm); false when it does not converge in 50 steps.
bool MoveToolTo(const RobotModel& model, int tool, const Eigen::Vector3d& target,
                std::vector<double>* q) {
  Eigen::Matrix<double, 3, Eigen::Dynamic> J;
  for (int it = 0; it < 50; ++it) {
    const Eigen::Vector3d P = ToolPositionJointJacobian(model, q->data(), tool, &J);
    const Eigen::Vector3d e = target - P;
    if (e.norm() < 1e-9) return true;
    Eigen::VectorXd dq = J.transpose() * (J * J.transpose()).ldlt().solve(e);
    const double largest = dq.cwiseAbs().maxCoeff();
    if (!std::isfinite(largest)) return false;
    if (largest > 0.3) dq *= 0.3 / largest;
    for (int j = 0; j < model.num_joints(); ++j) (*q)[j] += dq(j);
  }
  return false;
}

// Where the truth's tool really is at commanded joints q: at its effective joint values when it
// carries joint-space terms (lpoe_simulate --joint_errors), else FK(q).
Eigen::Vector3d TrueContactPoint(const RobotModel& truth, const std::vector<double>& q, int tool) {
  if (truth.joint_errors.empty()) return ToolPosition(truth, q.data(), tool);
  std::vector<double> q_eff(q.size());
  EffectiveJoints(truth, q.data(), q_eff.data());
  return ToolPosition(truth, q_eff.data(), tool);
}

// The probe stops where the truth's tip (at its effective joint values) touches: moves the
// commanded joints q along the normal n until the true point's height n.P is the target's (the
// geometric target shifted by the joint terms' displacement, a few micrometres; a few rounds).
bool ContactWithJointErrors(const RobotModel& truth, int tool, const Eigen::Vector3d& n,
                            const Eigen::Vector3d& target, std::vector<double>* q) {
  Eigen::Vector3d aim = target;
  for (int it = 0; it < 10; ++it) {
    const double off = n.dot(TrueContactPoint(truth, *q, tool) - target);
    if (std::abs(off) < 1e-10) return true;
    aim -= off * n;
    if (!MoveToolTo(truth, tool, aim, q)) return false;
  }
  return false;
}

class ContactRandom {
 public:
  explicit ContactRandom(uint64_t seed) : engine_(seed) {}
  double Uniform(double lo, double hi) {
    return lo + (hi - lo) * static_cast<double>(engine_() >> 11) * 0x1.0p-53;
  }
  double Normal() {
    // Box-Muller on the raw engine (the same draws on every standard library).
    const double u1 = Uniform(1e-300, 1.0);
    const double u2 = Uniform(0.0, 1.0);
    return std::sqrt(-2.0 * std::log(u1)) * std::cos(2.0 * kPiContact * u2);
  }
  Eigen::Vector3d UnitVector() {
    Eigen::Vector3d v;
    do {
      const double x = Uniform(-1, 1);
      const double y = Uniform(-1, 1);
      const double z = Uniform(-1, 1);
      v = Eigen::Vector3d(x, y, z);
    } while (v.norm() < 0.1 || v.norm() > 1.0);
    return v.normalized();
  }
  // A configuration around q0: the first three joints within +-arm rad, the others within +-wrist.
  std::vector<double> Around(const std::vector<double>& q0, double arm, double wrist) {
    std::vector<double> q = q0;
    for (size_t j = 0; j < q.size(); ++j) {
      const double a = j < 3 ? arm : wrist;
      q[j] += Uniform(-a, a);
    }
    return q;
  }

 private:
  std::mt19937_64 engine_;
};

// A seed configuration for feature k of `count`: joint 1 spread over 120 degrees, the arm bent
// (shoulder and elbow), the wrist turned, so that the features sit apart in the workspace in front
// of the robot.
std::vector<double> SeedConfiguration(const RobotModel& model, int k, int count) {
  std::vector<double> q(model.num_joints(), 0.0);
  const double spread = count > 1 ? (2.0 * kPiContact / 3.0) * (k / double(count - 1) - 0.5) : 0;
  if (!q.empty()) q[0] = spread;
  if (q.size() > 1) q[1] = -0.4;
  if (q.size() > 2) q[2] = 1.0;
  if (q.size() > 4) q[4] = 0.8;
  for (int j = 0; j < model.num_joints(); ++j) {
    const Joint& joint = model.joints[j];
    if (joint.type == JointType::kPrismatic) q[j] = 0;
    if (std::isfinite(joint.lower)) q[j] = std::max(q[j], joint.lower);
    if (std::isfinite(joint.upper)) q[j] = std::min(q[j], joint.upper);
  }
  return q;
}

}  // namespace

Status SimulateBallbar(const RobotModel& truth, const BallbarSimulationOptions& options,
                       ContactMeasurementSet* out, std::vector<Eigen::Vector3d>* pivots_out) {
  if (options.count < 1 || !(options.bar_length > 0) || !(options.stroke >= 0) ||
      !(options.noise >= 0) || options.target < 0 || options.target >= truth.num_tools()) {
    return Status::Error("ballbar simulation: bad options (count, bar length, stroke, noise, tool)");
  }
  ContactRandom rng(options.seed);
  std::vector<Eigen::Vector3d> pivots = options.pivots;
  const int num_pivots = pivots.empty() ? std::max(1, options.num_pivots) : int(pivots.size());
  std::vector<std::vector<double>> seeds;
  for (int k = 0; k < num_pivots; ++k) {
    std::vector<double> q0 = SeedConfiguration(truth, k, num_pivots);
    if (options.pivots.empty()) {
      // The pivot below the ball at the seed configuration, one bar length away.
      const Eigen::Vector3d P = ToolPosition(truth, q0.data(), options.target);
      pivots.push_back(P - options.bar_length * Eigen::Vector3d(0, 0, 1));
    }
    seeds.push_back(q0);
  }
  ContactMeasurementSet set;
  set.num_joints = truth.num_joints();
  set.files.push_back("(simulated ballbar)");
  for (int k = 0; k < num_pivots; ++k) set.Feature(MeasurementKindId::kDistance, "pivot" + std::to_string(k + 1));
  int attempts = 0;
  for (int i = 0; i < options.count; ++i) {
    const int k = i % num_pivots;
    for (;;) {
      if (++attempts > 100 * options.count + 1000) {
        return Status::Error("ballbar simulation: the ball does not reach the sphere around " +
                             set.pivots[k] + " within the joint limits");
      }
      std::vector<double> q = rng.Around(seeds[k], 0.5, 1.2);
      Eigen::Vector3d u = rng.UnitVector();
      if (u(2) < -0.2) u(2) = -u(2);  // the ball above the pivot's equator, mostly
      const double length = options.bar_length + rng.Uniform(-options.stroke, options.stroke);
      if (!MoveToolTo(truth, options.target, pivots[k] + length * u, &q)) continue;
      if (!WithinLimits(truth, q)) continue;
      ContactRow row;
      row.kind = MeasurementKindId::kDistance;
      row.feature = k;
      row.target = options.target;
      row.sigma = options.noise > 0 ? options.noise : 0.001;
      row.value = DistanceMeasurement::Simulate(TrueContactPoint(truth, q, options.target),
                                                pivots[k]) +
                  options.noise * rng.Normal();
      set.rows.push_back(row);
      set.q.insert(set.q.end(), q.begin(), q.end());
      break;
    }
  }
  *out = std::move(set);
  if (pivots_out != nullptr) *pivots_out = pivots;
  return Status::Ok();
}

Status SimulatePlaneContacts(const RobotModel& truth, const PlaneSimulationOptions& options,
                             ContactMeasurementSet* out, std::vector<Eigen::Vector4d>* planes_out) {
  if (options.count < 1 || !(options.probe_radius >= 0) || !(options.noise >= 0) ||
      !(options.cube_size > 0) || options.target < 0 || options.target >= truth.num_tools()) {
    return Status::Error("plane simulation: bad options (count, probe radius, noise, cube, tool)");
  }
  ContactRandom rng(options.seed);
  const double h = 0.5 * options.cube_size;
  const std::vector<double> q0 = SeedConfiguration(truth, 0, 1);
  Eigen::Vector3d centre = options.cube_centre;
  if (!options.cube_given) {
    // The cube's +x, +y, +z corner just below and behind the tool at the seed configuration.
    centre = ToolPosition(truth, q0.data(), options.target) - Eigen::Vector3d(h, h, h) -
             Eigen::Vector3d(options.probe_radius, options.probe_radius, options.probe_radius);
  }
  std::vector<Eigen::Vector4d> planes;
  ContactMeasurementSet set;
  set.num_joints = truth.num_joints();
  set.files.push_back("(simulated touch probe)");
  const char* names[3] = {"face_x", "face_y", "face_z"};
  for (int k = 0; k < 3; ++k) {
    const Eigen::Vector3d n = Eigen::Vector3d::Unit(k);
    planes.emplace_back(n(0), n(1), n(2), n.dot(centre) + h);
    set.Feature(MeasurementKindId::kPlane, names[k]);
  }
  int attempts = 0;
  for (int i = 0; i < options.count; ++i) {
    const int k = i % 3;
    const Eigen::Vector3d n = planes[k].head<3>();
    for (;;) {
      if (++attempts > 100 * options.count + 1000) {
        return Status::Error(std::string("plane simulation: the probe does not reach ") + names[k] +
                             " within the joint limits");
      }
      std::vector<double> q = rng.Around(q0, 0.4, 1.2);
      const double e = options.noise * rng.Normal();
      // A point of the face (within 90 % of it) plus the tip's radius along the normal.
      Eigen::Vector3d target = centre + h * n + (options.probe_radius + e) * n;
      for (int a = 0; a < 3; ++a) {
        if (a != k) target(a) += rng.Uniform(-0.9 * h, 0.9 * h);
      }
      if (!MoveToolTo(truth, options.target, target, &q)) continue;
      if (!truth.joint_errors.empty() &&
          !ContactWithJointErrors(truth, options.target, n, target, &q)) {
        continue;
      }
      if (!WithinLimits(truth, q)) continue;
      ContactRow row;
      row.kind = MeasurementKindId::kPlane;
      row.feature = k;
      row.target = options.target;
      row.sigma = options.noise > 0 ? options.noise : 0.001;
      row.value = options.probe_radius;
      set.rows.push_back(row);
      set.q.insert(set.q.end(), q.begin(), q.end());
      break;
    }
  }
  *out = std::move(set);
  if (planes_out != nullptr) *planes_out = planes;
  return Status::Ok();
}

}  // namespace lpoe
