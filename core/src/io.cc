// File formats of DESIGN.md section 5. Every error is a Status whose message reads
//   <file>:<line>: <what is wrong>; expected <what>
// with 1-based line numbers. Nothing here throws out of the API: yaml-cpp exceptions are caught at
// the top of each reader, and the CSV reader is written without exceptions.
#include "parse_util.h"
#include "joint_errors_yaml.h"
#include "lpoe/io.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <initializer_list>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

namespace lpoe {
namespace {

// ---------------------------------------------------------------------------------------------------
// Shared helpers.

// A quaternion in a model file must be unit to this tolerance; it is then normalized.
constexpr double kQuaternionNormTolerance = 1e-3;
// A measured quaternion below this norm is rejected (a lost measurement, not a rotation).
constexpr double kMinMeasuredQuaternionNorm = 1e-3;
// Plausibility bounds on measurement values: positions (mm) and raw joint values (as written).
constexpr double kMaxAbsPositionMm = 1e6;
constexpr double kMaxAbsJointValue = 1e4;
constexpr double kDegreesToRadians = 3.14159265358979323846 / 180.0;

using internal::LineError;

std::string Quote(std::string_view s) { return internal::Quote(s, 40); }

std::string_view Trim(std::string_view s) {
  size_t b = 0, e = s.size();
  while (b < e && (s[b] == ' ' || s[b] == '\t')) ++b;
  while (e > b && (s[e - 1] == ' ' || s[e - 1] == '\t')) --e;
  return s.substr(b, e - b);
}

enum class NumberParse { kOk, kNotANumber, kNonFinite };

// "nan", "NaN", "inf", "-Infinity"...: what trackers write for a lost beam (an overflowing number
// such as 1e999 is not one of these and stays an error).
bool IsNanOrInfText(std::string_view field) {
  std::string t;
  for (char c : field) {
    if (c != '+' && c != '-') t.push_back(static_cast<char>(std::tolower(static_cast<unsigned char>(c))));
  }
  return t == "nan" || t == "inf" || t == "infinity";
}

// Parses a whole (already trimmed) field as a decimal double. Accepts a leading '+'. "nan", "inf",
// YAML's ".inf"/".nan" and overflowing values are reported as non-finite.
NumberParse ParseDouble(std::string_view s, double* out) {
  if (s.empty()) return NumberParse::kNotANumber;
  const char* first = s.data();
  const char* last = s.data() + s.size();
  bool negate = false;
  if (*first == '+' || *first == '-') {
    negate = *first == '-';
    ++first;
    if (first == last || *first == '+' || *first == '-') return NumberParse::kNotANumber;
  }
  // YAML 1.1/1.2 spellings of infinity and NaN.
  if (*first == '.' && last - first == 4) {
    std::string_view t(first, 4);
    if (t == ".inf" || t == ".Inf" || t == ".INF" || t == ".nan" || t == ".NaN" || t == ".NAN")
      return NumberParse::kNonFinite;
  }
  double v = 0;
  const std::from_chars_result r = std::from_chars(first, last, v, std::chars_format::general);
  if (r.ptr != last) return NumberParse::kNotANumber;
  if (r.ec == std::errc::result_out_of_range) {
    // Overflow is non-finite; underflow (tiny values) is fine: let strtod round it.
    const std::string copy(first, last);
    v = std::strtod(copy.c_str(), nullptr);
  } else if (r.ec != std::errc()) {
    return NumberParse::kNotANumber;
  }
  if (!std::isfinite(v)) return NumberParse::kNonFinite;
  *out = negate ? -v : v;
  return NumberParse::kOk;
}

// "%.17g" without the locale and the format-string parsing of printf.
void AppendNumber(double v, std::string* out) {
  char buf[32];
  const std::to_chars_result r =
      std::to_chars(buf, buf + sizeof(buf), v, std::chars_format::general, 17);
  out->append(buf, r.ptr);
}

// Short form for messages.
std::string ShortNumber(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.6g", v);
  return buf;
}

// ---------------------------------------------------------------------------------------------------
// YAML robot model.

const char* const kModelKeys = "name, joints, tools";
const char* const kJointKeys = "name, type, origin, twist";
const char* const kToolKeys = "name, origin";
const char* const kOriginKeys = "xyz and one of rpy or quaternion";

struct MapEntry {
  std::string key;
  YAML::Node value;
  int line = 1;  // line of the key
};

int LineOf(const YAML::Node& node, int fallback) {
  if (!node.IsDefined()) return fallback;
  const YAML::Mark mark = node.Mark();
  return mark.is_null() || mark.line < 0 ? fallback : mark.line + 1;
}

class ModelYamlReader {
 public:
  explicit ModelYamlReader(const std::string& source) : source_(source) {}

  Status Read(const YAML::Node& root, RobotModel* model) {
    if (!root.IsDefined() || root.IsNull()) {
      return Error(1, "the document is empty",
                   "a mapping with keys name, joints and tools (DESIGN.md section 5)");
    }
    std::vector<MapEntry> top;
    Status s = ReadMap(root, 1, "the robot model", {"name", "joints", "tools"}, kModelKeys, &top);
    if (!s.ok()) return s;
    const int root_line = LineOf(root, 1);

    const MapEntry* name = Find(top, "name");
    const MapEntry* joints = Find(top, "joints");
    const MapEntry* tools = Find(top, "tools");
    if (name == nullptr) return Error(root_line, "missing key 'name'", "name: <robot name>");
    if (joints == nullptr) {
      return Error(root_line, "missing key 'joints'",
                   "a list 'joints:' of revolute/prismatic joints");
    }
    if (tools == nullptr)
      return Error(root_line, "missing key 'tools'", "a list 'tools:' of tool frames");

    RobotModel out;
    s = ReadString(*name, /*allow_empty=*/true, &out.name);
    if (!s.ok()) return s;

    s = ReadList(*joints, "joint", "revolute or prismatic joints, base to tip");
    if (!s.ok()) return s;
    std::vector<int> joint_lines;
    for (const YAML::Node& item : joints->value) {
      Joint joint;
      int line = 0;
      s = ReadJoint(item, LineOf(item, joints->line), &joint, &line);
      if (!s.ok()) return s;
      for (size_t k = 0; k < out.joints.size(); ++k) {
        if (out.joints[k].name == joint.name) {
          return Error(line,
                       "duplicate joint name " + Quote(joint.name) + " (first on line " +
                           std::to_string(joint_lines[k]) + ")",
                       "unique joint names");
        }
      }
      out.joints.push_back(joint);
      joint_lines.push_back(line);
    }

    s = ReadList(*tools, "tool", "tool frames with name and origin");
    if (!s.ok()) return s;
    std::vector<int> tool_lines;
    for (const YAML::Node& item : tools->value) {
      Tool tool;
      int line = 0;
      s = ReadTool(item, LineOf(item, tools->line), &tool, &line);
      if (!s.ok()) return s;
      for (size_t k = 0; k < out.tools.size(); ++k) {
        if (out.tools[k].name == tool.name) {
          return Error(line,
                       "duplicate tool name " + Quote(tool.name) + " (first on line " +
                           std::to_string(tool_lines[k]) + ")",
                       "unique tool names");
        }
      }
      for (size_t k = 0; k < out.joints.size(); ++k) {
        if (out.joints[k].name == tool.name) {
          return Error(line,
                       "tool name " + Quote(tool.name) + " is also the name of the joint on line " +
                           std::to_string(joint_lines[k]),
                       "names unique across joints and tools");
        }
      }
      out.tools.push_back(tool);
      tool_lines.push_back(line);
    }

    s = out.Validate();
    if (!s.ok()) return Status::Error(source_ + ": " + s.message());
    *model = std::move(out);
    return Status::Ok();
  }

 private:
  Status Error(int line, const std::string& what, const std::string& expected) const {
    return LineError(source_, line, what, expected);
  }

  static const MapEntry* Find(const std::vector<MapEntry>& entries, const char* key) {
    for (const MapEntry& e : entries) {
      if (e.key == key) return &e;
    }
    return nullptr;
  }

  // Collects the entries of a mapping, rejecting non-maps, unknown keys and duplicated keys.
  Status ReadMap(const YAML::Node& node, int fallback_line, const std::string& what,
                 std::initializer_list<const char*> allowed, const char* allowed_text,
                 std::vector<MapEntry>* out) const {
    const int line = LineOf(node, fallback_line);
    if (!node.IsMap()) {
      return Error(line, what + " is not a mapping",
                   std::string("a mapping with keys ") + allowed_text);
    }
    out->clear();
    for (YAML::const_iterator it = node.begin(); it != node.end(); ++it) {
      MapEntry e;
      e.line = LineOf(it->first, line);
      if (!it->first.IsScalar()) {
        return Error(e.line, "a key of " + what + " is not a plain name",
                     std::string("keys ") + allowed_text);
      }
      e.key = it->first.Scalar();
      e.value = it->second;
      bool known = false;
      for (const char* a : allowed) known = known || e.key == a;
      if (!known) {
        return Error(e.line, "unknown key " + Quote(e.key) + " in " + what,
                     std::string("only the keys ") + allowed_text);
      }
      for (const MapEntry& prev : *out) {
        if (prev.key == e.key) {
          return Error(e.line,
                       "duplicate key " + Quote(e.key) + " in " + what + " (first on line " +
                           std::to_string(prev.line) + ")",
                       "each key once");
        }
      }
      out->push_back(std::move(e));
    }
    return Status::Ok();
  }

  Status ReadList(const MapEntry& entry, const std::string& item,
                  const std::string& expected) const {
    const int line = LineOf(entry.value, entry.line);
    if (!entry.value.IsSequence()) {
      return Error(line, "'" + entry.key + "' is not a list", "a non-empty list of " + expected);
    }
    if (entry.value.size() == 0) {
      return Error(line, "'" + entry.key + "' is empty", "at least one " + item);
    }
    return Status::Ok();
  }

  Status ReadString(const MapEntry& entry, bool allow_empty, std::string* out) const {
    const int line = LineOf(entry.value, entry.line);
    if (!entry.value.IsScalar()) {
      return Error(line, "'" + entry.key + "' is not a string",
                   "a name such as " + entry.key + ": joint1");
    }
    *out = entry.value.Scalar();
    if (!allow_empty && out->empty()) {
      return Error(line, "'" + entry.key + "' is empty", "a non-empty name");
    }
    return Status::Ok();
  }

  Status ReadNumber(const YAML::Node& node, int line, const std::string& what, double* out) const {
    if (!node.IsScalar()) return Error(line, what + " is not a number", "a finite decimal number");
    const std::string_view text = Trim(node.Scalar());
    switch (ParseDouble(text, out)) {
      case NumberParse::kOk:
        return Status::Ok();
      case NumberParse::kNonFinite:
        return Error(line, what + " is not finite (" + Quote(text) + ")",
                     "a finite decimal number");
      case NumberParse::kNotANumber:
        break;
    }
    return Error(line, what + " " + Quote(text) + " is not a number", "a finite decimal number");
  }

  // A flow or block list of exactly `n` numbers.
  Status ReadNumbers(const MapEntry& entry, int n, const std::string& expected, double* out) const {
    const int line = LineOf(entry.value, entry.line);
    const std::string what = "'" + entry.key + "'";
    if (!entry.value.IsSequence() || static_cast<int>(entry.value.size()) != n) {
      const std::string got = entry.value.IsSequence()
                                  ? "a list of " + std::to_string(entry.value.size())
                                  : std::string("not a list");
      return Error(line, what + " is " + got,
                   "a list of " + std::to_string(n) + " numbers " + expected);
    }
    for (int i = 0; i < n; ++i) {
      const YAML::Node item = entry.value[i];
      Status s =
          ReadNumber(item, LineOf(item, line), what + " entry " + std::to_string(i + 1), &out[i]);
      if (!s.ok()) return s;
    }
    return Status::Ok();
  }

  Status ReadOrigin(const MapEntry& entry, SE3d* origin) const {
    const int line = LineOf(entry.value, entry.line);
    std::vector<MapEntry> keys;
    Status s =
        ReadMap(entry.value, line, "'origin'", {"xyz", "rpy", "quaternion"}, kOriginKeys, &keys);
    if (!s.ok()) return s;
    const MapEntry* xyz = Find(keys, "xyz");
    const MapEntry* rpy = Find(keys, "rpy");
    const MapEntry* quat = Find(keys, "quaternion");
    if (xyz == nullptr) return Error(line, "'origin' has no 'xyz'", "xyz: [x, y, z] in mm");
    if (rpy != nullptr && quat != nullptr) {
      return Error(quat->line, "'origin' gives both 'rpy' and 'quaternion'",
                   "one orientation, rpy: [roll, pitch, yaw] or quaternion: [x, y, z, w]");
    }
    double t[3];
    s = ReadNumbers(*xyz, 3, "[x, y, z] in mm", t);
    if (!s.ok()) return s;
    SE3d out;
    out.t = Eigen::Vector3d(t[0], t[1], t[2]);
    if (rpy != nullptr) {
      double a[3];
      s = ReadNumbers(*rpy, 3, "[roll, pitch, yaw] in rad", a);
      if (!s.ok()) return s;
      out.R = RotationFromRpy(a[0], a[1], a[2]);
    } else if (quat != nullptr) {
      Eigen::Vector4d q;
      s = ReadNumbers(*quat, 4, "[x, y, z, w]", q.data());
      if (!s.ok()) return s;
      const double norm = q.norm();
      if (!(std::abs(norm - 1.0) <= kQuaternionNormTolerance)) {
        return Error(LineOf(quat->value, quat->line), "'quaternion' has norm " + ShortNumber(norm),
                     "a unit quaternion [x, y, z, w] (norm within " +
                         ShortNumber(kQuaternionNormTolerance) + " of 1)");
      }
      out.R = QuaternionToRotation<double>(q / norm);
    } else {
      return Error(line, "'origin' has no orientation",
                   "rpy: [roll, pitch, yaw] in rad or quaternion: [x, y, z, w]");
    }
    *origin = out;
    return Status::Ok();
  }

  Status CheckTwist(const Vector6d& s, JointType type, int line) const {
    const Eigen::Vector3d w = s.head<3>();
    const Eigen::Vector3d v = s.tail<3>();
    if (type == JointType::kRevolute) {
      if (std::abs(w.norm() - 1.0) > kTwistTolerance ||
          std::abs(w.dot(v)) > kTwistTolerance * std::max(1.0, v.norm())) {
        return Error(line,
                     "the twist of a revolute joint has |omega| = " + ShortNumber(w.norm()) +
                         " and omega . v = " + ShortNumber(w.dot(v)),
                     "|omega| = 1 and omega . v = 0 (twist is [omega, v])");
      }
    } else {
      if (w.norm() > kTwistTolerance || std::abs(v.norm() - 1.0) > kTwistTolerance) {
        return Error(line,
                     "the twist of a prismatic joint has |omega| = " + ShortNumber(w.norm()) +
                         " and |v| = " + ShortNumber(v.norm()),
                     "omega = 0 and |v| = 1 (twist is [omega, v])");
      }
    }
    return Status::Ok();
  }

  Status ReadJoint(const YAML::Node& node, int fallback_line, Joint* joint, int* joint_line) const {
    const int line = LineOf(node, fallback_line);
    *joint_line = line;
    std::vector<MapEntry> keys;
    Status s =
        ReadMap(node, line, "a joint", {"name", "type", "origin", "twist"}, kJointKeys, &keys);
    if (!s.ok()) return s;
    const MapEntry* name = Find(keys, "name");
    const MapEntry* type = Find(keys, "type");
    const MapEntry* origin = Find(keys, "origin");
    const MapEntry* twist = Find(keys, "twist");
    if (name == nullptr) return Error(line, "joint has no 'name'", "name: <joint name>");
    s = ReadString(*name, /*allow_empty=*/false, &joint->name);
    if (!s.ok()) return s;
    const std::string who = "joint " + Quote(joint->name);
    if (type == nullptr) return Error(line, who + " has no 'type'", "type: revolute | prismatic");
    if (origin == nullptr) {
      return Error(line, who + " has no 'origin'", "origin: {xyz: [x, y, z], rpy: [r, p, y]}");
    }
    const int type_line = LineOf(type->value, type->line);
    if (!type->value.IsScalar())
      return Error(type_line, who + ": 'type' is not a name", "revolute or prismatic");
    const std::string& t = type->value.Scalar();
    if (t == "revolute") {
      joint->type = JointType::kRevolute;
    } else if (t == "prismatic") {
      joint->type = JointType::kPrismatic;
    } else {
      return Error(type_line, who + ": unknown joint type " + Quote(t), "revolute or prismatic");
    }
    s = ReadOrigin(*origin, &joint->origin);
    if (!s.ok()) return s;
    if (twist != nullptr) {
      Vector6d xi;
      s = ReadNumbers(*twist, 6, "[wx, wy, wz, vx, vy, vz]", xi.data());
      if (!s.ok()) return s;
      s = CheckTwist(xi, joint->type, LineOf(twist->value, twist->line));
      if (!s.ok()) return s;
      joint->twist = xi;
    } else {
      joint->twist = DefaultTwist(joint->type);
    }
    return Status::Ok();
  }

  Status ReadTool(const YAML::Node& node, int fallback_line, Tool* tool, int* tool_line) const {
    const int line = LineOf(node, fallback_line);
    *tool_line = line;
    std::vector<MapEntry> keys;
    Status s = ReadMap(node, line, "a tool", {"name", "origin"}, kToolKeys, &keys);
    if (!s.ok()) return s;
    const MapEntry* name = Find(keys, "name");
    const MapEntry* origin = Find(keys, "origin");
    if (name == nullptr) return Error(line, "tool has no 'name'", "name: <tool name>");
    s = ReadString(*name, /*allow_empty=*/false, &tool->name);
    if (!s.ok()) return s;
    if (origin == nullptr) {
      return Error(line, "tool " + Quote(tool->name) + " has no 'origin'",
                   "origin: {xyz: [x, y, z], rpy: [r, p, y]}");
    }
    return ReadOrigin(*origin, &tool->origin);
  }

  const std::string& source_;
};

// A name written bare when YAML reads it back as the same string, double-quoted otherwise.
std::string YamlName(const std::string& name) {
  bool plain = !name.empty();
  for (const char c : name) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
                    c == '_' || c == '-' || c == '.';
    plain = plain && ok;
  }
  if (plain) {
    // Words YAML would read as null, booleans or special floats, and leading characters that start
    // other tokens.
    static const char* const kSpecial[] = {
        "null", "Null", "NULL", "true", "True", "TRUE", "false", "False", "FALSE",
        "yes",  "Yes",  "YES",  "no",   "No",   "NO",   "on",    "On",    "ON",
        "off",  "Off",  "OFF",  "y",    "Y",    "n",    "N"};
    for (const char* w : kSpecial) plain = plain && name != w;
    plain = plain && name[0] != '-' && name[0] != '.';
  }
  if (plain) return name;
  std::string out = "\"";
  for (const char c : name) {
    const unsigned char u = static_cast<unsigned char>(c);
    if (c == '"' || c == '\\') {
      out += '\\';
      out += c;
    } else if (u < 0x20 || u == 0x7f) {
      char buf[8];
      std::snprintf(buf, sizeof(buf), "\\x%02x", u);
      out += buf;
    } else {
      out += c;
    }
  }
  out += '"';
  return out;
}

void AppendList(const double* v, int n, std::string* out) {
  *out += '[';
  for (int i = 0; i < n; ++i) {
    if (i > 0) *out += ", ";
    AppendNumber(v[i], out);
  }
  *out += ']';
}

void AppendOrigin(const SE3d& origin, std::string* out) {
  const Eigen::Vector4d q = RotationToQuaternion<double>(origin.R);
  *out += "origin: {xyz: ";
  AppendList(origin.t.data(), 3, out);
  *out += ", quaternion: ";
  AppendList(q.data(), 4, out);
  *out += "}";
  // rpy for humans only; the reader ignores comments and the quaternion is what round-trips.
  const Eigen::Vector3d rpy = RpyFromRotation(origin.R);
  char buf[96];
  std::snprintf(buf, sizeof(buf), "  # rpy: [%.9g, %.9g, %.9g]", rpy(0) + 0.0, rpy(1) + 0.0,
                rpy(2) + 0.0);  // + 0.0 turns -0 into 0
  *out += buf;
  *out += '\n';
}

// ---------------------------------------------------------------------------------------------------
// CSV measurements.

enum class ColumnKind { kQ, kX, kY, kZ, kTarget, kQuatX, kQuatY, kQuatZ, kQuatW };

struct Column {
  ColumnKind kind = ColumnKind::kQ;
  int joint = 0;     // kQ: 0-based joint index
  std::string name;  // as written in the header (trimmed)
};

std::string ExpectedColumns(int num_joints) {
  std::string s = num_joints == 1 ? std::string("q1") : "q1..q" + std::to_string(num_joints);
  s += ", x, y, z, optional target, optional quat_x, quat_y, quat_z, quat_w";
  return s;
}

std::string ToLower(std::string_view s) {
  std::string out(s);
  for (char& c : out) {
    if (c >= 'A' && c <= 'Z') c = static_cast<char>(c - 'A' + 'a');
  }
  return out;
}

// Splits `line` at commas into `fields` (string_views into `line`).
void SplitFields(std::string_view line, std::vector<std::string_view>* fields) {
  fields->clear();
  size_t start = 0;
  while (true) {
    const void* hit = std::memchr(line.data() + start, ',', line.size() - start);
    if (hit == nullptr) {
      fields->push_back(line.substr(start));
      return;
    }
    const size_t pos = static_cast<const char*>(hit) - line.data();
    fields->push_back(line.substr(start, pos - start));
    start = pos + 1;
  }
}

bool IsBlankOrComment(std::string_view line) {
  for (const char c : line) {
    if (c == ' ' || c == '\t') continue;
    return c == '#';
  }
  return true;
}

class CsvHeader {
 public:
  Status Parse(std::string_view line, int line_number, const std::string& source, int num_joints) {
    std::vector<std::string_view> fields;
    SplitFields(line, &fields);
    const std::string expected = "a header with columns " + ExpectedColumns(num_joints);
    std::vector<int> q_column(num_joints, -1);
    int xyz_column[3] = {-1, -1, -1};
    int quat_column[4] = {-1, -1, -1, -1};
    static const char* const kQuatNames[4] = {"quat_x", "quat_y", "quat_z", "quat_w"};
    for (size_t c = 0; c < fields.size(); ++c) {
      const std::string_view raw = Trim(fields[c]);
      Column col;
      col.name = std::string(raw);
      const std::string lower = ToLower(raw);
      if (raw.empty()) {
        return LineError(source, line_number,
                         "header column " + std::to_string(c + 1) + " has an empty name", expected);
      }
      double dummy;
      if (ParseDouble(raw, &dummy) != NumberParse::kNotANumber) {
        return LineError(source, line_number,
                         "the first line is data (" + Quote(raw) + " where a column name belongs)",
                         expected);
      }
      int* slot = nullptr;
      if (lower.size() >= 2 && lower[0] == 'q' && lower[1] >= '1' && lower[1] <= '9' &&
          std::all_of(lower.begin() + 1, lower.end(),
                      [](char ch) { return ch >= '0' && ch <= '9'; })) {
        int k = 0;
        const auto r = std::from_chars(lower.data() + 1, lower.data() + lower.size(), k);
        if (r.ec != std::errc() || k > num_joints) {
          return LineError(source, line_number,
                           "extra joint column " + Quote(raw) + ": the model has " +
                               std::to_string(num_joints) + " joints",
                           expected);
        }
        col.kind = ColumnKind::kQ;
        col.joint = k - 1;
        slot = &q_column[k - 1];
      } else if (lower == "x" || lower == "y" || lower == "z") {
        const int axis = lower[0] - 'x';
        col.kind = static_cast<ColumnKind>(static_cast<int>(ColumnKind::kX) + axis);
        slot = &xyz_column[axis];
      } else if (lower == "target") {
        col.kind = ColumnKind::kTarget;
        slot = &target_column_;
      } else {
        for (int k = 0; k < 4; ++k) {
          if (lower == kQuatNames[k]) {
            col.kind = static_cast<ColumnKind>(static_cast<int>(ColumnKind::kQuatX) + k);
            slot = &quat_column[k];
          }
        }
        if (slot == nullptr) {
          return LineError(source, line_number, "unknown column " + Quote(raw), expected);
        }
      }
      if (*slot >= 0) {
        return LineError(source, line_number,
                         "duplicated column " + Quote(raw) + " (columns " +
                             std::to_string(*slot + 1) + " and " + std::to_string(c + 1) + ")",
                         "each column once");
      }
      *slot = static_cast<int>(c);
      columns_.push_back(std::move(col));
    }
    std::string missing;
    auto add_missing = [&missing](const std::string& name) {
      missing += missing.empty() ? "" : ", ";
      missing += "'" + name + "'";
    };
    for (int k = 0; k < num_joints; ++k) {
      if (q_column[k] < 0) add_missing("q" + std::to_string(k + 1));
    }
    for (int a = 0; a < 3; ++a) {
      if (xyz_column[a] < 0) add_missing(std::string(1, static_cast<char>('x' + a)));
    }
    if (!missing.empty()) {
      return LineError(source, line_number,
                       "missing column" +
                           std::string(missing.find(',') != std::string::npos ? "s " : " ") +
                           missing,
                       expected);
    }
    const int num_quat =
        static_cast<int>(std::count_if(quat_column, quat_column + 4, [](int c) { return c >= 0; }));
    if (num_quat != 0 && num_quat != 4) {
      for (int k = 0; k < 4; ++k) {
        if (quat_column[k] < 0) add_missing(kQuatNames[k]);
      }
      return LineError(source, line_number, "incomplete orientation: missing " + missing,
                       "all four of quat_x, quat_y, quat_z, quat_w, or none");
    }
    has_orientation_ = num_quat == 4;
    return Status::Ok();
  }

  const std::vector<Column>& columns() const { return columns_; }
  bool has_orientation() const { return has_orientation_; }
  bool has_target() const { return target_column_ >= 0; }

 private:
  std::vector<Column> columns_;
  bool has_orientation_ = false;
  int target_column_ = -1;
};

// Tool index for a target field: a tool name first, else a 0-based index. -1 when neither.
int ResolveTarget(std::string_view field, const RobotModel& model) {
  for (int t = 0; t < model.num_tools(); ++t) {
    if (field == model.tools[t].name) return t;
  }
  if (field.empty() || field.size() > 9) return -1;
  int index = 0;
  const auto r = std::from_chars(field.data(), field.data() + field.size(), index);
  if (r.ec != std::errc() || r.ptr != field.data() + field.size()) return -1;
  return index >= 0 && index < model.num_tools() ? index : -1;
}

std::string ToolList(const RobotModel& model) {
  std::string s;
  for (int t = 0; t < model.num_tools(); ++t) {
    if (t > 0) s += ", ";
    s += Quote(model.tools[t].name);
  }
  return s;
}

// A target name the reader maps back to the same tool; otherwise the index is written.
bool TargetNameRoundTrips(const RobotModel& model, int tool) {
  const std::string& name = model.tools[tool].name;
  if (name.empty() || Trim(name).size() != name.size()) return false;
  if (name.find_first_of(",\r\n\"") != std::string::npos) return false;
  return ResolveTarget(name, model) == tool;
}

}  // namespace

// -----------------------------------------------------------------------------------------------------
// Robot model.

Status ParseRobotModelYaml(const std::string& text, const std::string& source, RobotModel* model) {
  try {
    YAML::Node root;
    try {
      root = YAML::Load(text);
    } catch (const YAML::Exception& e) {
      const int line = e.mark.is_null() ? 1 : e.mark.line + 1;
      return LineError(source, line, "YAML syntax error: " + e.msg,
                       "a YAML robot model (DESIGN.md section 5)");
    }
    return internal::ReadModelWithJointErrors(source, root, model, [&](const YAML::Node& r, RobotModel* m) { return ModelYamlReader(source).Read(r, m); });
  } catch (const YAML::Exception& e) {
    const int line = e.mark.is_null() ? 1 : e.mark.line + 1;
    return LineError(source, line, "cannot read the model: " + e.msg,
                     "a YAML robot model (DESIGN.md section 5)");
  } catch (const std::exception& e) {
    return LineError(source, 1, std::string("cannot read the model: ") + e.what(),
                     "a YAML robot model (DESIGN.md section 5)");
  }
}

Status ReadRobotModel(const std::string& path, RobotModel* model) {
  std::string text;
  Status s = ReadFile(path, &text);
  if (!s.ok()) return s;
  return ParseRobotModelYaml(text, path, model);
}

std::string RobotModelToYaml(const RobotModel& model) {
  std::string out;
  out += "# lpoe-calib robot model (DESIGN.md section 5): lengths in mm, angles in rad.\n";
  out += "# origin = T_{i-1,i}(0) of each joint / T_{n,tool} of each tool; twist = (omega, v).\n";
  out += "name: " + YamlName(model.name) + "\n";
  out += "joints:\n";
  for (const Joint& joint : model.joints) {
    out += "  - name: " + YamlName(joint.name) + "\n";
    out += "    type: ";
    out += joint.type == JointType::kPrismatic ? "prismatic" : "revolute";
    out += "\n    ";
    AppendOrigin(joint.origin, &out);
    out += "    twist: ";
    AppendList(joint.twist.data(), 6, &out);
    out += '\n';
  }
  out += "tools:\n";
  for (const Tool& tool : model.tools) {
    out += "  - name: " + YamlName(tool.name) + "\n    ";
    AppendOrigin(tool.origin, &out);
  }
  out += internal::JointErrorsToYaml(model);
  return out;
}

Status WriteRobotModel(const std::string& path, const RobotModel& model) {
  return WriteFileAtomically(path, RobotModelToYaml(model));
}

// -----------------------------------------------------------------------------------------------------
// Measurements.

Status ParseMeasurementsCsv(const std::string& text, const std::string& source,
                            const RobotModel& model, AngleUnit unit, MeasurementSet* data) {
  return ParseMeasurementsCsv(text, source, model, unit, data, nullptr);
}

namespace {

Status ParseMeasurementsCsvImpl(const std::string& text, const std::string& source,
                                const RobotModel& model, AngleUnit unit, MeasurementSet* data,
                                CsvReadReport* report) {
  const int n = model.num_joints();
  std::string_view rest(text);
  if (rest.size() >= 3 && rest.substr(0, 3) == "\xEF\xBB\xBF") rest.remove_prefix(3);

  // Revolute joints get the degree factor; prismatic joints are in mm either way.
  std::vector<double> scale(n, 1.0);
  if (unit == AngleUnit::kDegrees) {
    for (int j = 0; j < n; ++j) {
      if (model.joints[j].type == JointType::kRevolute) scale[j] = kDegreesToRadians;
    }
  }

  CsvHeader header;
  bool have_header = false;
  int header_line = 0;
  int line_number = 0;
  MeasurementSet out(n);
  // One row per line at most, and a row has at least n + 3 one-character fields and their commas:
  // the second bound keeps a file of blank lines from reserving gigabytes.
  const size_t max_rows = std::min<size_t>(std::count(rest.begin(), rest.end(), '\n') + 1,
                                           rest.size() / (2 * static_cast<size_t>(n + 3)) + 1);
  out.Reserve(static_cast<int>(std::min<size_t>(max_rows, static_cast<size_t>(1) << 30)));
  CsvReadReport local_report;

  std::vector<std::string_view> fields;
  std::vector<double> q(n);
  Eigen::Vector3d position;
  Eigen::Vector4d quat;

  while (!rest.empty()) {
    const size_t nl = rest.find('\n');
    std::string_view line = rest.substr(0, nl);
    rest.remove_prefix(nl == std::string_view::npos ? rest.size() : nl + 1);
    ++line_number;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    if (IsBlankOrComment(line)) continue;

    if (!have_header) {
      Status s = header.Parse(line, line_number, source, n);
      if (!s.ok()) return s;
      have_header = true;
      header_line = line_number;
      continue;
    }

    SplitFields(line, &fields);
    const std::vector<Column>& columns = header.columns();
    if (fields.size() != columns.size()) {
      return LineError(source, line_number, std::to_string(fields.size()) + " fields",
                       std::to_string(columns.size()) + " as in the header on line " +
                           std::to_string(header_line));
    }
    int target = 0;
    bool lost_beam = false;
    for (size_t c = 0; c < fields.size(); ++c) {
      const Column& col = columns[c];
      const std::string_view field = Trim(fields[c]);
      if (col.kind == ColumnKind::kTarget) {
        target = ResolveTarget(field, model);
        if (target < 0) {
          return LineError(source, line_number, "column 'target': unknown tool " + Quote(field),
                           "a tool name (" + ToolList(model) + ") or an index from 0 to " +
                               std::to_string(model.num_tools() - 1));
        }
        continue;
      }
      double v = 0;
      const NumberParse r = ParseDouble(field, &v);
      const bool is_position = col.kind == ColumnKind::kX || col.kind == ColumnKind::kY ||
                               col.kind == ColumnKind::kZ;
      if (r == NumberParse::kNonFinite && is_position && IsNanOrInfText(field)) {
        // A tracker that lost the beam may export NaN/Inf: the row is skipped like a row of zeros.
        lost_beam = true;
        continue;
      }
      if (r != NumberParse::kOk) {
        const std::string what =
            field.empty() ? "column " + Quote(col.name) + " is empty"
            : r == NumberParse::kNonFinite
                ? "column " + Quote(col.name) + ": non-finite value " + Quote(field)
                : "column " + Quote(col.name) + ": " + Quote(field) + " is not a number";
        return LineError(source, line_number, what, "a finite decimal number");
      }
      switch (col.kind) {
        case ColumnKind::kQ:
          if (std::abs(v) > kMaxAbsJointValue) {
            return LineError(
                source, line_number,
                "column " + Quote(col.name) + ": value " + Quote(field) + " is out of range",
                "a joint value of magnitude at most " + ShortNumber(kMaxAbsJointValue));
          }
          q[col.joint] = v * scale[col.joint];
          break;
        case ColumnKind::kX:
        case ColumnKind::kY:
        case ColumnKind::kZ:
          if (std::abs(v) > kMaxAbsPositionMm) {
            return LineError(
                source, line_number,
                "column " + Quote(col.name) + ": value " + Quote(field) + " is out of range",
                "a position of magnitude at most " + ShortNumber(kMaxAbsPositionMm) + " mm");
          }
          position(static_cast<int>(col.kind) - static_cast<int>(ColumnKind::kX)) = v;
          break;
        case ColumnKind::kQuatX:
        case ColumnKind::kQuatY:
        case ColumnKind::kQuatZ:
        case ColumnKind::kQuatW:
          quat(static_cast<int>(col.kind) - static_cast<int>(ColumnKind::kQuatX)) = v;
          break;
        case ColumnKind::kTarget:
          break;
      }
    }
    if (lost_beam || (position(0) == 0.0 && position(1) == 0.0 && position(2) == 0.0)) {
      // Lost beam (zeros or non-finite x, y, z): skipped and reported, not an error.
      ++local_report.skipped_zero_rows;
      local_report.skipped_lines.push_back(line_number);
      continue;
    }
    if (header.has_orientation()) {
      const double norm = quat.norm();
      if (!(norm >= kMinMeasuredQuaternionNorm) || !std::isfinite(norm)) {
        return LineError(source, line_number, "quat_x..quat_w have norm " + ShortNumber(norm),
                         "a unit quaternion (norm near 1)");
      }
      out.AddPose(q.data(), SE3d(QuaternionToRotation<double>(quat / norm), position), target,
                  line_number);
    } else {
      out.Add(q.data(), position, target, line_number);
    }
  }

  if (!have_header) {
    return LineError(
        source, std::max(line_number, 1), "no header line (the file is empty)",
        "a header with columns " + ExpectedColumns(n) + ", then one row per measurement");
  }
  if (out.empty()) {
    const std::string skipped =
        local_report.skipped_zero_rows > 0
            ? " (" + std::to_string(local_report.skipped_zero_rows) + " rows without a measurement skipped)"
            : std::string();
    return LineError(source, header_line, "no measurement rows after the header" + skipped,
                     "at least one row of measurements");
  }
  *data = std::move(out);
  if (report != nullptr) *report = std::move(local_report);
  return Status::Ok();
}

}  // namespace

Status ParseMeasurementsCsv(const std::string& text, const std::string& source,
                            const RobotModel& model, AngleUnit unit, MeasurementSet* data,
                            CsvReadReport* report) {
  try {
    return ParseMeasurementsCsvImpl(text, source, model, unit, data, report);
  } catch (const std::exception& e) {  // std::bad_alloc on absurdly large input
    return LineError(source, 1, std::string("cannot read the measurements: ") + e.what(),
                     "a measurements CSV that fits in memory");
  }
}

Status ReadMeasurements(const std::string& path, const RobotModel& model, AngleUnit unit,
                        MeasurementSet* data) {
  return ReadMeasurements(path, model, unit, data, nullptr);
}

Status ReadMeasurements(const std::string& path, const RobotModel& model, AngleUnit unit,
                        MeasurementSet* data, CsvReadReport* report) {
  std::string text;
  Status s = ReadFile(path, &text);
  if (!s.ok()) return s;
  return ParseMeasurementsCsv(text, path, model, unit, data, report);
}

std::string MeasurementsToCsv(const RobotModel& model, const MeasurementSet& data,
                              const std::string& comment) {
  std::string out;
  if (!comment.empty()) {
    size_t start = 0;
    while (start <= comment.size()) {
      size_t end = comment.find('\n', start);
      if (end == std::string::npos) end = comment.size();
      std::string_view line(comment.data() + start, end - start);
      if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
      out += "# ";
      out += line;
      out += '\n';
      start = end + 1;
    }
  }
  const int n = data.num_joints();
  for (int j = 0; j < n; ++j) {
    out += 'q';
    out += std::to_string(j + 1);
    out += ',';
  }
  out += "x,y,z,target";
  const bool pose = data.has_orientation();
  if (pose) out += ",quat_x,quat_y,quat_z,quat_w";
  out += '\n';

  std::vector<std::string> target_text(std::max(model.num_tools(), 0));
  for (int t = 0; t < model.num_tools(); ++t) {
    target_text[t] = TargetNameRoundTrips(model, t) ? model.tools[t].name : std::to_string(t);
  }
  out.reserve(out.size() + static_cast<size_t>(data.size()) * (n + 3 + (pose ? 4 : 0)) * 24);
  for (int row = 0; row < data.size(); ++row) {
    const double* q = data.q(row);
    for (int j = 0; j < n; ++j) {
      AppendNumber(q[j], &out);
      out += ',';
    }
    const Eigen::Vector3d& p = data.position(row);
    for (int a = 0; a < 3; ++a) {
      AppendNumber(p(a), &out);
      out += ',';
    }
    const int t = data.target(row);
    out += t >= 0 && t < model.num_tools() ? target_text[t] : std::to_string(t);
    if (pose) {
      const Eigen::Vector4d quat = RotationToQuaternion<double>(data.orientation(row));
      for (int k = 0; k < 4; ++k) {
        out += ',';
        AppendNumber(quat(k), &out);
      }
    }
    out += '\n';
  }
  return out;
}

Status WriteMeasurements(const std::string& path, const RobotModel& model,
                         const MeasurementSet& data, const std::string& comment) {
  return WriteFileAtomically(path, MeasurementsToCsv(model, data, comment));
}

// -----------------------------------------------------------------------------------------------------
// Files.

Status WriteFileAtomically(const std::string& path, const std::string& contents) {
  if (path.empty()) return Status::Error("cannot write a file with an empty path");
  std::string tmp = path + ".tmp.XXXXXX";
  const int fd = ::mkstemp(&tmp[0]);
  if (fd < 0) {
    const int err = errno;
    return Status::Error(path + ": cannot create a temporary file " + tmp + ": " +
                         std::strerror(err));
  }
  auto fail = [&](const char* what, int err) {
    ::close(fd);
    ::unlink(tmp.c_str());
    return Status::Error(path + ": " + what + " " + tmp + ": " + std::strerror(err));
  };
  // mkstemp creates mode 0600; give the result the mode of the file it replaces, or 0644.
  struct stat st;
  const mode_t mode = ::stat(path.c_str(), &st) == 0 ? (st.st_mode & 07777) : 0644;
  if (::fchmod(fd, mode) != 0) return fail("cannot set the mode of", errno);
  const char* p = contents.data();
  size_t left = contents.size();
  while (left > 0) {
    const ssize_t w = ::write(fd, p, left);
    if (w < 0) {
      if (errno == EINTR) continue;
      return fail("cannot write", errno);
    }
    p += w;
    left -= static_cast<size_t>(w);
  }
  if (::fsync(fd) != 0) return fail("cannot flush", errno);
  if (::close(fd) != 0) {
    const int err = errno;
    ::unlink(tmp.c_str());
    return Status::Error(path + ": cannot close " + tmp + ": " + std::strerror(err));
  }
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    const int err = errno;
    ::unlink(tmp.c_str());
    return Status::Error(path + ": cannot rename " + tmp + " to it: " + std::strerror(err));
  }
  // Make the rename itself durable (best effort: some file systems refuse to open directories).
  const size_t slash = path.rfind('/');
  const std::string dir = slash == std::string::npos ? "."
                          : slash == 0               ? "/"
                                                     : path.substr(0, slash);
  const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dfd >= 0) {
    ::fsync(dfd);
    ::close(dfd);
  }
  return Status::Ok();
}

namespace {

// Closes a descriptor on every path out, exceptions included.
class FileDescriptor {
 public:
  explicit FileDescriptor(int fd) : fd_(fd) {}
  ~FileDescriptor() {
    if (fd_ >= 0) ::close(fd_);
  }
  FileDescriptor(const FileDescriptor&) = delete;
  FileDescriptor& operator=(const FileDescriptor&) = delete;
  int get() const { return fd_; }

 private:
  int fd_;
};

Status ReadFileImpl(const std::string& path, std::string* contents) {
  const FileDescriptor fd(::open(path.c_str(), O_RDONLY | O_CLOEXEC));
  if (fd.get() < 0) {
    const int err = errno;
    return Status::Error(path + ": cannot open: " + std::strerror(err));
  }
  std::string text;
  struct stat st;
  if (::fstat(fd.get(), &st) == 0 && S_ISREG(st.st_mode) && st.st_size > 0) {
    text.reserve(static_cast<size_t>(st.st_size));
  }
  char buf[1 << 16];
  while (true) {
    const ssize_t r = ::read(fd.get(), buf, sizeof(buf));
    if (r < 0) {
      if (errno == EINTR) continue;
      const int err = errno;
      return Status::Error(path + ": cannot read: " + std::strerror(err));
    }
    if (r == 0) break;
    text.append(buf, static_cast<size_t>(r));
  }
  *contents = std::move(text);
  return Status::Ok();
}

}  // namespace

Status ReadFile(const std::string& path, std::string* contents) {
  try {
    return ReadFileImpl(path, contents);
  } catch (const std::exception& e) {  // std::bad_alloc on a file larger than memory
    return Status::Error(path + ": cannot read: " + e.what());
  }
}

}  // namespace lpoe
