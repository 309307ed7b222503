// The robot model as YAML (docs/file_formats.md; lpoe/io/io.h). Every error is a Status whose message
// reads "<file>:<line>: <what is wrong>; expected <what>" with 1-based line numbers; yaml-cpp
// exceptions are caught at the top of the reader.
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <initializer_list>
#include <limits>
#include <string>
#include <string_view>
#include <unordered_map>
#include <utility>
#include <vector>

#include "lpoe/io/io.h"
#include "lpoe/model/model_limits.h"
#include "lpoe/io/urdf.h"
#include "io/joint_errors_yaml.h"
#include "lpoe/model/refusals.h"
#include "io/parse_util.h"

namespace lpoe {
namespace {

// A quaternion in a model file must be unit to this tolerance; it is then normalized.
constexpr double kQuaternionNormTolerance = 1e-3;

using internal::AppendNumber;
using internal::LineError;
using internal::NumberParse;
using internal::ParseNumber;
using internal::Quote;
using internal::ShortNumber;
using internal::Trim;

// ---------------------------------------------------------------------------------------------------
// YAML robot model.

const char* const kModelKeys = "name, joints, tools, registration, frames, covariance";
const char* const kJointKeys = "name, type, origin, twist, limits";
const char* const kToolKeys = "name, origin, fixed";
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
                   "a mapping with keys name, joints and tools (docs/file_formats.md)");
    }
    std::vector<MapEntry> top;
    Status s = ReadMap(root, 1, "the robot model",
                       {"name", "joints", "tools", "registration", "frames", "covariance"},
                       kModelKeys, &top);
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
    // First line of each name, joints and tools alike (hashing keeps the check linear).
    std::unordered_map<std::string, int> joint_lines, tool_lines;
    out.joints.reserve(joints->value.size());
    for (const YAML::Node& item : joints->value) {
      Joint joint;
      int line = 0;
      s = ReadJoint(item, LineOf(item, joints->line), &joint, &line);
      if (!s.ok()) return s;
      const auto [it, inserted] = joint_lines.emplace(joint.name, line);
      if (!inserted) {
        return Error(line,
                     "duplicate joint name " + Quote(joint.name) + " (first on line " +
                         std::to_string(it->second) + ")",
                     "unique joint names");
      }
      out.joints.push_back(std::move(joint));
    }

    s = ReadList(*tools, "tool", "tool frames with name and origin");
    if (!s.ok()) return s;
    out.tools.reserve(tools->value.size());
    for (const YAML::Node& item : tools->value) {
      Tool tool;
      int line = 0;
      s = ReadTool(item, LineOf(item, tools->line), &tool, &line);
      if (!s.ok()) return s;
      const auto [it, inserted] = tool_lines.emplace(tool.name, line);
      if (!inserted) {
        return Error(line,
                     "duplicate tool name " + Quote(tool.name) + " (first on line " +
                         std::to_string(it->second) + ")",
                     "unique tool names");
      }
      const auto joint = joint_lines.find(tool.name);
      if (joint != joint_lines.end()) {
        return Error(line,
                     "tool name " + Quote(tool.name) + " is also the name of the joint on line " +
                         std::to_string(joint->second),
                     "names unique across joints and tools");
      }
      out.tools.push_back(std::move(tool));
    }

    // Optional model sections (gravity, payload, joint errors) are read here, one call each.
    // registration: T_measurement_base of a registered calibration (compensation).
    if (const MapEntry* reg = Find(top, "registration"); reg != nullptr) {
      s = ReadOrigin(*reg, &out.T_measurement_base);
      if (!s.ok()) return s;
    }

    // frames: named base and flange frames (robot_model.h, NamedFrame).
    if (const MapEntry* frames = Find(top, "frames"); frames != nullptr) {
      s = ReadList(*frames, "frame", "frames {name, on: base or flange, origin}");
      if (!s.ok()) return s;
      for (const YAML::Node& item : frames->value) {
        const int line = LineOf(item, frames->line);
        std::vector<MapEntry> keys;
        s = ReadMap(item, line, "a frame", {"name", "on", "origin"}, "name, on, origin", &keys);
        if (!s.ok()) return s;
        const MapEntry* fname = Find(keys, "name");
        const MapEntry* on = Find(keys, "on");
        const MapEntry* origin = Find(keys, "origin");
        if (fname == nullptr || on == nullptr || origin == nullptr) {
          return Error(line, "a frame needs name, on and origin",
                       "{name: base, on: base, origin: {xyz: [x, y, z], rpy: [r, p, y]}}");
        }
        NamedFrame f;
        s = ReadString(*fname, /*allow_empty=*/false, &f.name);
        if (!s.ok()) return s;
        std::string where;
        s = ReadString(*on, /*allow_empty=*/false, &where);
        if (!s.ok()) return s;
        if (where != "base" && where != "flange") {
          return Error(LineOf(on->value, on->line), "frame " + Quote(f.name) + ": on is " + Quote(where),
                       "on: base (fixed to the robot's base) or on: flange (fixed to the last link)");
        }
        f.on_flange = where == "flange";
        if (out.FindFrame(f.name, f.on_flange) != nullptr) {
          return Error(line, "duplicate frame " + Quote(f.name) + " on the " + where,
                       "unique frame names");
        }
        s = ReadOrigin(*origin, &f.pose);
        if (!s.ok()) return s;
        out.frames.push_back(std::move(f));
      }
    }

    // Whole-model checks; the per-joint ones (twists, limits) were made above with their lines.
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
    if (out->find('\0') != std::string::npos) {
      return Error(line, "'" + entry.key + "' " + Quote(*out) + " contains a NUL byte",
                   "a name without NUL bytes");
    }
    return Status::Ok();
  }

  // A number within +-max_abs (kMaxModelLengthMm unless said: every length of the file).
  Status ReadNumber(const YAML::Node& node, int line, const std::string& what, double* out,
                    double max_abs = kMaxModelLengthMm) const {
    if (!node.IsScalar()) return Error(line, what + " is not a number", "a finite decimal number");
    const std::string_view text = Trim(node.Scalar());
    switch (ParseNumber(text, out)) {
      case NumberParse::kOk:
        if (!(std::abs(*out) <= max_abs)) {
          return Error(line, what + " " + Quote(text) + " is out of range",
                       "a number within +-" + ShortNumber(max_abs) +
                           " (mm or rad: a physically plausible robot model)");
        }
        return Status::Ok();
      case NumberParse::kNonFinite:
      case NumberParse::kOutOfRange:
        return Error(line, what + " is not finite (" + Quote(text) + ")",
                     "a finite decimal number");
      case NumberParse::kNotANumber:
        break;
    }
    return Error(line, what + " " + Quote(text) + " is not a number", "a finite decimal number");
  }

  // A flow or block list of exactly `n` numbers.
  Status ReadNumbers(const MapEntry& entry, int n, const std::string& expected, double* out,
                     double max_abs = kMaxModelLengthMm) const {
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
          ReadNumber(item, LineOf(item, line), what + " entry " + std::to_string(i + 1), &out[i],
                     max_abs);
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
      s = ReadNumbers(*rpy, 3, "[roll, pitch, yaw] in rad", a, kMaxModelAngleRad);
      if (!s.ok()) return s;
      out.R = RotationFromRpy(a[0], a[1], a[2]);
    } else if (quat != nullptr) {
      Eigen::Vector4d q;
      s = ReadNumbers(*quat, 4, "[x, y, z, w]", q.data(), 2.0);
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

  // `limits: [lower, upper]` (rad for revolute, mm for prismatic joints); an open side is written
  // -.inf / .inf.
  Status ReadLimits(const MapEntry& entry, Joint* joint) const {
    const int line = LineOf(entry.value, entry.line);
    const char* const expected = "[lower, upper] in rad (revolute) or mm (prismatic)";
    if (!entry.value.IsSequence() || entry.value.size() != 2) {
      return Error(line, "'limits' is not a list of 2", std::string("a list of 2 numbers ") + expected);
    }
    double v[2];
    for (int i = 0; i < 2; ++i) {
      const YAML::Node item = entry.value[i];
      const int item_line = LineOf(item, line);
      const std::string what = std::string("'limits' ") + (i == 0 ? "lower" : "upper") + " value";
      if (item.IsScalar()) {
        std::string_view t = Trim(item.Scalar());
        const bool negative = !t.empty() && t[0] == '-';
        if (!t.empty() && (t[0] == '-' || t[0] == '+')) t.remove_prefix(1);
        if (t == ".inf" || t == ".Inf" || t == ".INF") {
          if (negative != (i == 0)) {
            return Error(item_line, what + " is " + (negative ? "-" : "+") + "infinity",
                         "-.inf only as the lower and .inf only as the upper limit");
          }
          v[i] = negative ? -std::numeric_limits<double>::infinity()
                          : std::numeric_limits<double>::infinity();
          continue;
        }
      }
      Status s = ReadNumber(item, item_line, what, &v[i]);
      if (!s.ok()) return s;
    }
    const Status s = ValidateLimits(v[0], v[1]);
    if (!s.ok()) return Error(line, "joint " + Quote(joint->name) + ": " + s.message(), expected);
    joint->lower = v[0];
    joint->upper = v[1];
    return Status::Ok();
  }

  Status ReadJoint(const YAML::Node& node, int fallback_line, Joint* joint, int* joint_line) const {
    const int line = LineOf(node, fallback_line);
    *joint_line = line;
    std::vector<MapEntry> keys;
    Status s =
        ReadMap(node, line, "a joint", {"name", "type", "origin", "twist", "limits"}, kJointKeys,
                &keys);
    if (!s.ok()) return s;
    const MapEntry* name = Find(keys, "name");
    const MapEntry* type = Find(keys, "type");
    const MapEntry* origin = Find(keys, "origin");
    const MapEntry* twist = Find(keys, "twist");
    const MapEntry* limits = Find(keys, "limits");
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
      s = ValidateTwist(joint->type, xi);
      if (!s.ok()) {
        return Error(LineOf(twist->value, twist->line), who + ": " + s.message(),
                     "a twist [omega, v] of the joint's type");
      }
      joint->twist = xi;
    } else {
      joint->twist = DefaultTwist(joint->type);
    }
    if (limits != nullptr) return ReadLimits(*limits, joint);
    return Status::Ok();
  }

  Status ReadTool(const YAML::Node& node, int fallback_line, Tool* tool, int* tool_line) const {
    const int line = LineOf(node, fallback_line);
    *tool_line = line;
    std::vector<MapEntry> keys;
    Status s = ReadMap(node, line, "a tool", {"name", "origin", "fixed"}, kToolKeys, &keys);
    if (!s.ok()) return s;
    const MapEntry* name = Find(keys, "name");
    const MapEntry* origin = Find(keys, "origin");
    const MapEntry* fixed = Find(keys, "fixed");
    if (name == nullptr) return Error(line, "tool has no 'name'", "name: <tool name>");
    s = ReadString(*name, /*allow_empty=*/false, &tool->name);
    if (!s.ok()) return s;
    if (origin == nullptr) {
      return Error(line, "tool " + Quote(tool->name) + " has no 'origin'",
                   "origin: {xyz: [x, y, z], rpy: [r, p, y]}");
    }
    if (fixed != nullptr) {
      // A known SMR nest (robot_model.h, Tool::fixed): held as given by a calibration.
      const int fixed_line = LineOf(fixed->value, fixed->line);
      const std::string value = fixed->value.IsScalar() ? fixed->value.Scalar() : std::string();
      if (value != "true" && value != "false") {
        return Error(fixed_line,
                     "tool " + Quote(tool->name) + ": 'fixed' is " +
                         (fixed->value.IsScalar() ? Quote(value) : std::string("not a scalar")),
                     "fixed: true (a known tool frame, held as given) or fixed: false");
      }
      tool->fixed = value == "true";
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
  return plain ? name : internal::YamlDoubleQuoted(name);
}

void AppendList(const double* v, int n, std::string* out) {
  *out += '[';
  for (int i = 0; i < n; ++i) {
    if (i > 0) *out += ", ";
    AppendNumber(v[i], out);
  }
  *out += ']';
}

// A joint limit; an open side as YAML's infinity.
void AppendLimit(double v, std::string* out) {
  if (std::isinf(v)) {
    *out += v < 0 ? "-.inf" : ".inf";
  } else {
    AppendNumber(v, out);
  }
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

// The line (1-based) where a second YAML document starts, or 0: a "---" line after content, or
// content after a "..." line (comments and blank lines are not content). Block scalars cannot hold
// such a line at column 0, so the markers are unambiguous.
int SecondDocumentLine(const std::string& text) {
  bool content = false, ended = false;
  int line = 0;
  size_t pos = 0;
  while (pos < text.size()) {
    size_t end = text.find('\n', pos);
    if (end == std::string::npos) end = text.size();
    ++line;
    std::string_view l(text.data() + pos, end - pos);
    if (!l.empty() && l.back() == '\r') l.remove_suffix(1);
    auto marker = [&](const char* m) {
      return l.substr(0, 3) == m && (l.size() == 3 || l[3] == ' ' || l[3] == '\t');
    };
    const size_t first = l.find_first_not_of(" \t");
    const bool blank = first == std::string_view::npos || l[first] == '#';
    if (marker("---")) {
      if (content || ended) return line;
      const size_t rest = l.find_first_not_of(" \t", 3);
      if (rest != std::string_view::npos && l[rest] != '#') content = true;  // "--- {...}"
    } else if (marker("...")) {
      if (content) ended = true;
    } else if (!blank) {
      if (ended) return line;
      content = true;
    }
    pos = end + 1;
  }
  return 0;
}

}  // namespace

// -----------------------------------------------------------------------------------------------------
// Robot model.

Status ParseRobotModelYaml(const std::string& text, const std::string& source, RobotModel* model) {
  try {
    // A second document is found from its markers, not with YAML::LoadAll, which loops forever on
    // some malformed input (found by fuzz_yaml); Load reads the first document only.
    if (const int second = SecondDocumentLine(text); second > 0) {
      return LineError(source, second, "a second YAML document (documents are separated by '---')",
                       "one robot model per file");
    }
    YAML::Node root;
    try {
      root = YAML::Load(text);
    } catch (const YAML::Exception& e) {
      const int line = e.mark.is_null() ? 1 : e.mark.line + 1;
      return LineError(source, line, "YAML syntax error: " + e.msg,
                       "a YAML robot model (docs/file_formats.md)");
    }
    return internal::ReadModelWithJointErrors(source, root, model, [&](const YAML::Node& r, RobotModel* m) { return ModelYamlReader(source).Read(r, m); });
  } catch (const YAML::Exception& e) {
    const int line = e.mark.is_null() ? 1 : e.mark.line + 1;
    return LineError(source, line, "cannot read the model: " + e.msg,
                     "a YAML robot model (docs/file_formats.md)");
  } catch (const std::exception& e) {
    return LineError(source, 1, std::string("cannot read the model: ") + e.what(),
                     "a YAML robot model (docs/file_formats.md)");
  }
}

Status ReadRobotModel(const std::string& path, RobotModel* model) {
  std::string text;
  Status s = ReadFile(path, kMaxModelFileBytes, &text);
  if (!s.ok()) return s;
  return ParseRobotModelYaml(text, path, model);
}

std::string RobotModelToYaml(const RobotModel& model) {
  std::string out;
  out += "# lpoe-calib robot model (docs/file_formats.md): lengths in mm, angles in rad.\n";
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
    if (joint.has_limits()) {
      out += "    limits: [";
      AppendLimit(joint.lower, &out);
      out += ", ";
      AppendLimit(joint.upper, &out);
      out += "]\n";
    }
  }
  out += "tools:\n";
  for (const Tool& tool : model.tools) {
    out += "  - name: " + YamlName(tool.name) + "\n    ";
    AppendOrigin(tool.origin, &out);
    if (tool.fixed) out += "    fixed: true\n";
  }
  // Optional model sections (gravity, payload, joint errors) are written here, one call each.
  if (!model.T_measurement_base.R.isIdentity(0) || !model.T_measurement_base.t.isZero(0)) {
    std::string origin;
    AppendOrigin(model.T_measurement_base, &origin);
    out += "# registration = T_measurement_base: the measurement frame from the nominal base frame.\n";
    out += "registration: " + origin.substr(origin.find('{'));
  }
  if (!model.frames.empty()) {
    out += "# frames: named base frames (in the nominal base frame) and flange frames (in the last "
           "joint's frame)\nframes:\n";
    for (const NamedFrame& f : model.frames) {
      out += "  - name: " + YamlName(f.name) + "\n    on: " + (f.on_flange ? "flange" : "base") +
             "\n    ";
      AppendOrigin(f.pose, &out);
    }
  }
  out += internal::JointErrorsToYaml(model);
  out += internal::ResidualLayerToYaml(model);
  return out;
}

bool IsUrdfPath(const std::string& path) {
  constexpr std::string_view kExtension = ".urdf";
  if (path.size() < kExtension.size()) return false;
  const std::string_view tail(path.data() + path.size() - kExtension.size(), kExtension.size());
  for (size_t i = 0; i < tail.size(); ++i) {
    const char c = tail[i] >= 'A' && tail[i] <= 'Z' ? static_cast<char>(tail[i] - 'A' + 'a') : tail[i];
    if (c != kExtension[i]) return false;
  }
  return true;
}

Status ReadRobotModelFile(const std::string& path, RobotModel* model) {
  return IsUrdfPath(path) ? ReadRobotModelUrdf(path, model) : ReadRobotModel(path, model);
}

Status WriteRobotModel(const std::string& path, const RobotModel& model) {
  if (Status s = CheckModelFinite(model); !s.ok()) return Status::Error(path + ": " + s.message());
  return WriteFileAtomically(path, RobotModelToYaml(model));
}

}  // namespace lpoe
