// YAML of the non-geometric terms (docs/joint_errors.md, "YAML format"):
//
//   gravity: [0, 0, -9.80665]                  # m/s^2, base frame; optional
//   payload: {mass: 0.5, com: [0, 0, 40]}      # kg; mm in the last joint's frame; optional
//   joint_errors:                              # optional
//     compliance:                              # one entry per joint with a non-zero product
//       - joint: joint2
//         c: 5e-05                             # c_j, rad/(N m) (payload column)
//         links:                               # link k >= j: [c m, c h_x, c h_y, c h_z]
//           joint2: [1.5e-4, 0.02, 0, 0.001]
//     harmonics:                               # rad
//       - joint: joint2
//         coefficients: [a1, b1, a2, b2]       # a1 sin q + b1 cos q + a2 sin 2q + b2 cos 2q
//
// Joints left out of a list have zero parameters.
#include "joint_errors_yaml.h"

#include <charconv>
#include <cstdio>
#include <cmath>
#include <string_view>
#include <utility>
#include <vector>

#include "lpoe/joint_errors.h"
#include "parse_util.h"

namespace lpoe {
namespace internal {
namespace {

const char* const kGravityExpected = "gravity: [x, y, z] in m/s^2 (finite numbers)";

int LineOf(const YAML::Node& node, int fallback) {
  if (!node.IsDefined()) return fallback;
  const YAML::Mark mark = node.Mark();
  return mark.is_null() || mark.line < 0 ? fallback : mark.line + 1;
}

class Reader {
 public:
  Reader(const std::string& source, const RobotModel& model) : source_(source), model_(model) {}

  Status Error(const YAML::Node& node, int fallback, const std::string& what,
               const std::string& expected) const {
    return LineError(source_, LineOf(node, fallback), what, expected);
  }

  Status Number(const YAML::Node& node, int line, const std::string& what, double* out) const {
    if (!node.IsScalar()) return Error(node, line, what + " is not a number", "a finite number");
    const std::string& text = node.Scalar();
    double v = 0;
    if (ParseNumber(Trim(text), &v) != NumberParse::kOk) {
      return Error(node, line, what + " " + Quote(text) + " is not a finite number",
                   "a finite number");
    }
    *out = v;
    return Status::Ok();
  }

  Status Numbers(const YAML::Node& node, int line, const std::string& what, int count,
                 const std::string& expected, double* out) const {
    if (!node.IsSequence() || static_cast<int>(node.size()) != count) {
      const std::string got = node.IsSequence() ? "a list of " + std::to_string(node.size())
                                                : std::string("not a list");
      return Error(node, line, what + " is " + got, expected);
    }
    for (int i = 0; i < count; ++i) {
      Status s = Number(node[i], LineOf(node, line), what + " entry " + std::to_string(i + 1),
                        &out[i]);
      if (!s.ok()) return s;
    }
    return Status::Ok();
  }

  // The entries of a mapping, each key once and among `allowed`.
  Status Map(const YAML::Node& node, int line, const std::string& what,
             const std::vector<std::string>& allowed,
             std::vector<std::pair<std::string, YAML::Node>>* out) const {
    std::string keys;
    for (const std::string& a : allowed) keys += (keys.empty() ? "" : ", ") + a;
    if (!node.IsMap()) return Error(node, line, what + " is not a mapping", "keys " + keys);
    out->clear();
    for (YAML::const_iterator it = node.begin(); it != node.end(); ++it) {
      const int key_line = LineOf(it->first, line);
      const std::string key = it->first.IsScalar() ? it->first.Scalar() : std::string();
      bool known = false;
      for (const std::string& a : allowed) known = known || key == a;
      if (!known) {
        return LineError(source_, key_line, "unknown key " + Quote(key) + " in " + what,
                         "only the keys " + keys);
      }
      for (const auto& prev : *out) {
        if (prev.first == key) {
          return LineError(source_, key_line, "duplicate key " + Quote(key) + " in " + what,
                           "each key once");
        }
      }
      out->emplace_back(key, it->second);
    }
    return Status::Ok();
  }

  static const YAML::Node* Find(const std::vector<std::pair<std::string, YAML::Node>>& entries,
                                const char* key) {
    for (const auto& e : entries) {
      if (e.first == key) return &e.second;
    }
    return nullptr;
  }

  Status JointIndex(const YAML::Node& node, int line, const std::string& what, int* index) const {
    if (!node.IsScalar()) return Error(node, line, what + " is not a joint name", "a joint name");
    for (int j = 0; j < model_.num_joints(); ++j) {
      if (model_.joints[j].name == node.Scalar()) {
        *index = j;
        return Status::Ok();
      }
    }
    return Error(node, line, what + " " + Quote(node.Scalar()) + " is not a joint of the model",
                 "the name of one of the model's joints");
  }

  Status Gravity(const YAML::Node& node, int line, Eigen::Vector3d* g) const {
    return Numbers(node, line, "'gravity'", 3, kGravityExpected, g->data());
  }

  Status ReadPayload(const YAML::Node& node, int line, Payload* payload) const {
    std::vector<std::pair<std::string, YAML::Node>> keys;
    Status s = Map(node, line, "'payload'", {"mass", "com"}, &keys);
    if (!s.ok()) return s;
    const YAML::Node* mass = Find(keys, "mass");
    const YAML::Node* com = Find(keys, "com");
    if (mass == nullptr) return Error(node, line, "'payload' has no 'mass'", "mass: <kg>");
    s = Number(*mass, line, "'mass'", &payload->mass);
    if (!s.ok()) return s;
    if (payload->mass < 0) {
      return Error(*mass, line, "'mass' is negative", "a payload mass >= 0 in kg");
    }
    payload->com.setZero();
    if (com != nullptr) {
      s = Numbers(*com, line, "'com'", 3, "com: [x, y, z] in mm in the last joint's frame",
                  payload->com.data());
    }
    return s;
  }

  // A list of per-joint entries; `read` fills the parameters of one joint.
  template <typename ReadEntry>
  Status Entries(const YAML::Node& node, int line, const std::string& what,
                 const ReadEntry& read) const {
    if (!node.IsSequence()) {
      return Error(node, line, "'" + what + "' is not a list", "a list of per-joint entries");
    }
    std::vector<int> seen;
    for (const YAML::Node& item : node) {
      int joint = -1;
      const int item_line = LineOf(item, line);
      Status s = read(item, item_line, &joint);
      if (!s.ok()) return s;
      for (int prev : seen) {
        if (prev == joint) {
          return LineError(source_, item_line,
                           "joint " + Quote(model_.joints[joint].name) + " appears twice in '" +
                               what + "'",
                           "one entry per joint");
        }
      }
      seen.push_back(joint);
    }
    return Status::Ok();
  }

  Status ReadJointErrors(const YAML::Node& node, int line, JointErrorTerms* terms) const {
    const int n = model_.num_joints();
    std::vector<std::pair<std::string, YAML::Node>> keys;
    Status s = Map(node, line, "'joint_errors'", {"compliance", "harmonics", "regressor_origins"},
                   &keys);
    if (!s.ok()) return s;
    if (const YAML::Node* origins = Find(keys, "regressor_origins")) {
      s = ReadRegressorOrigins(*origins, line, &terms->regressor_origins);
      if (!s.ok()) return s;
    }
    if (const YAML::Node* compliance = Find(keys, "compliance")) {
      terms->compliance.assign(NumComplianceParameters(n), 0.0);
      s = Entries(*compliance, line, "compliance", [&](const YAML::Node& item, int l, int* j) {
        std::vector<std::pair<std::string, YAML::Node>> entry;
        Status t = Map(item, l, "a compliance entry", {"joint", "c", "links"}, &entry);
        if (!t.ok()) return t;
        const YAML::Node* joint = Find(entry, "joint");
        if (joint == nullptr) return Error(item, l, "compliance entry has no 'joint'", "joint: <name>");
        t = JointIndex(*joint, l, "'joint'", j);
        if (!t.ok()) return t;
        if (const YAML::Node* c = Find(entry, "c")) {
          t = Number(*c, l, "'c'", &terms->compliance[CompliancePayloadIndex(n, *j)]);
          if (!t.ok()) return t;
        }
        const YAML::Node* links = Find(entry, "links");
        if (links == nullptr) return Status::Ok();
        std::vector<std::string> names;
        for (int k = *j; k < n; ++k) names.push_back(model_.joints[k].name);
        std::vector<std::pair<std::string, YAML::Node>> rows;
        t = Map(*links, l, "'links' of joint " + Quote(model_.joints[*j].name) +
                               " (the links it moves)",
                names, &rows);
        if (!t.ok()) return t;
        for (const auto& row : rows) {
          int k = 0;
          JointIndex(YAML::Node(row.first), l, "link", &k);
          t = Numbers(row.second, l, "link " + Quote(row.first), 4, "[c*m, c*hx, c*hy, c*hz]",
                      &terms->compliance[ComplianceLinkIndex(n, *j, k)]);
          if (!t.ok()) return t;
        }
        return Status::Ok();
      });
      if (!s.ok()) return s;
    }
    if (const YAML::Node* harmonics = Find(keys, "harmonics")) {
      terms->harmonics.assign(NumHarmonicsParameters(n), 0.0);
      s = Entries(*harmonics, line, "harmonics", [&](const YAML::Node& item, int l, int* j) {
        std::vector<std::pair<std::string, YAML::Node>> entry;
        Status t = Map(item, l, "a harmonics entry", {"joint", "coefficients"}, &entry);
        if (!t.ok()) return t;
        const YAML::Node* joint = Find(entry, "joint");
        const YAML::Node* coefficients = Find(entry, "coefficients");
        if (joint == nullptr) return Error(item, l, "harmonics entry has no 'joint'", "joint: <name>");
        t = JointIndex(*joint, l, "'joint'", j);
        if (!t.ok()) return t;
        if (coefficients == nullptr) {
          return Error(item, l, "harmonics entry has no 'coefficients'", "coefficients: [a1, b1, a2, b2]");
        }
        return Numbers(*coefficients, l, "'coefficients'", 4, "[a1, b1, a2, b2] in rad",
                       &terms->harmonics[kHarmonicsPerJoint * *j]);
      });
    }
    return s;
  }

  // regressor_origins: {joint name: [x, y, z, qx, qy, qz, qw]} for every joint.
  Status ReadRegressorOrigins(const YAML::Node& node, int line, std::vector<SE3d>* origins) const {
    const int n = model_.num_joints();
    std::vector<std::string> names;
    for (int j = 0; j < n; ++j) names.push_back(model_.joints[j].name);
    std::vector<std::pair<std::string, YAML::Node>> rows;
    Status s = Map(node, line, "'regressor_origins'", names, &rows);
    if (!s.ok()) return s;
    if (static_cast<int>(rows.size()) != n) {
      return Error(node, line, "'regressor_origins' has " + std::to_string(rows.size()) +
                                   " joints", "one entry per joint of the model");
    }
    origins->assign(n, SE3d());
    for (const auto& row : rows) {
      int j = 0;
      JointIndex(YAML::Node(row.first), line, "joint", &j);
      double v[7];
      s = Numbers(row.second, line, "regressor origin " + Quote(row.first), 7,
                  "[x, y, z, qx, qy, qz, qw] (mm; a unit quaternion)", v);
      if (!s.ok()) return s;
      const Eigen::Vector4d quat(v[3], v[4], v[5], v[6]);
      if (!(std::abs(quat.norm() - 1) < 1e-6)) {
        return Error(row.second, line,
                     "regressor origin " + Quote(row.first) + " has a quaternion of norm " +
                         std::to_string(quat.norm()),
                     "a unit quaternion (x, y, z, w)");
      }
      (*origins)[j].t = Eigen::Vector3d(v[0], v[1], v[2]);
      (*origins)[j].R = QuaternionToRotation(quat);
    }
    return Status::Ok();
  }

 private:
  const std::string& source_;
  const RobotModel& model_;
};

void AppendList(const double* v, int n, std::string* out) {
  *out += '[';
  for (int i = 0; i < n; ++i) {
    if (i > 0) *out += ", ";
    AppendNumber(v[i], out);
  }
  *out += ']';
}

bool AllZero(const double* v, int n) {
  for (int i = 0; i < n; ++i) {
    if (v[i] != 0) return false;
  }
  return true;
}

std::string QuotedName(const std::string& name) { return internal::YamlDoubleQuoted(name); }

}  // namespace

Status ReadModelWithJointErrors(
    const std::string& source, const YAML::Node& root, RobotModel* model,
    const std::function<Status(const YAML::Node&, RobotModel*)>& read_geometry) {
  // The keys of this file: value, line of the key (0 when absent).
  struct Key {
    const char* name;
    YAML::Node value;
    int line = 0;
  } keys[] = {{"gravity", {}, 0}, {"payload", {}, 0}, {"joint_errors", {}, 0}};
  // The other keys, with their own nodes (and so their line numbers), go to the model reader.
  // (Assigning to a YAML::Node would overwrite the node it refers to: `filtered` is built apart.)
  YAML::Node filtered(YAML::NodeType::Map);
  if (root.IsMap()) {
    for (YAML::const_iterator it = root.begin(); it != root.end(); ++it) {
      const std::string name = it->first.IsScalar() ? it->first.Scalar() : std::string();
      Key* key = nullptr;
      for (Key& k : keys) key = name == k.name ? &k : key;
      if (key == nullptr) {
        filtered.force_insert(it->first, it->second);
        continue;
      }
      if (key->line > 0) {
        return LineError(source, LineOf(it->first, 1),
                         "duplicate key '" + name + "' in the robot model (first on line " +
                             std::to_string(key->line) + ")",
                         "each key once");
      }
      key->value = it->second;
      key->line = LineOf(it->first, 1);
    }
  }
  RobotModel out;
  Status s = read_geometry(root.IsMap() ? filtered : root, &out);
  if (!s.ok()) return s;
  Reader reader(source, out);
  if (keys[0].line > 0) s = reader.Gravity(keys[0].value, keys[0].line, &out.gravity);
  if (s.ok() && keys[1].line > 0) s = reader.ReadPayload(keys[1].value, keys[1].line, &out.payload);
  if (s.ok() && keys[2].line > 0) {
    s = reader.ReadJointErrors(keys[2].value, keys[2].line, &out.joint_errors);
  }
  if (!s.ok()) return s;
  s = out.Validate();
  if (!s.ok()) return Status::Error(source + ": " + s.message());
  *model = std::move(out);
  return Status::Ok();
}

std::string JointErrorsToYaml(const RobotModel& model) {
  std::string out;
  const int n = model.num_joints();
  if (model.gravity != RobotModel().gravity) {
    out += "gravity: ";
    AppendList(model.gravity.data(), 3, &out);
    out += "  # m/s^2 in the base frame\n";
  }
  if (model.payload.mass != 0 || !model.payload.com.isZero(0)) {
    out += "payload: {mass: ";
    AppendNumber(model.payload.mass, &out);
    out += ", com: ";
    AppendList(model.payload.com.data(), 3, &out);
    out += "}  # kg; mm in the last joint's frame\n";
  }
  const JointErrorTerms& terms = model.joint_errors;
  if (terms.empty()) return out;
  out += "joint_errors:  # docs/joint_errors.md\n";
  if (!terms.compliance.empty()) {
    std::string entries;
    for (int j = 0; j < n; ++j) {
      const double* block = terms.compliance.data() + ComplianceLinkIndex(n, j, j);
      if (AllZero(block, 4 * (n - j) + 1)) continue;
      entries += "    - joint: " + QuotedName(model.joints[j].name) + "\n      c: ";
      AppendNumber(terms.compliance[CompliancePayloadIndex(n, j)], &entries);
      entries += "\n      links:\n";
      for (int k = j; k < n; ++k) {
        const double* row = terms.compliance.data() + ComplianceLinkIndex(n, j, k);
        if (AllZero(row, 4)) continue;
        entries += "        " + QuotedName(model.joints[k].name) + ": ";
        AppendList(row, 4, &entries);
        entries += '\n';
      }
    }
    out += "  # c in rad/(N m) (mm/N prismatic); links: [c*m, c*hx, c*hy, c*hz] (kg, kg mm in the\n";
    out += "  # link's frame)\n";
    out += entries.empty() ? "  compliance: []\n" : "  compliance:\n" + entries;
  }
  if (!terms.harmonics.empty()) {
    std::string entries;
    for (int j = 0; j < n; ++j) {
      const double* row = terms.harmonics.data() + kHarmonicsPerJoint * j;
      if (AllZero(row, kHarmonicsPerJoint)) continue;
      entries += "    - joint: " + QuotedName(model.joints[j].name) + "\n      coefficients: ";
      AppendList(row, kHarmonicsPerJoint, &entries);
      entries += '\n';
    }
    out += "  # rad: a1 sin q + b1 cos q + a2 sin 2q + b2 cos 2q\n";
    out += entries.empty() ? "  harmonics: []\n" : "  harmonics:\n" + entries;
  }
  if (!terms.regressor_origins.empty()) {
    out += "  # the joint origins the regressors were identified on: [x, y, z, qx, qy, qz, qw]\n";
    out += "  regressor_origins:\n";
    for (int j = 0; j < n; ++j) {
      const SE3d& o = terms.regressor_origins[j];
      const Eigen::Vector4d quat = RotationToQuaternion(o.R);
      const double v[7] = {o.t(0), o.t(1), o.t(2), quat(0), quat(1), quat(2), quat(3)};
      out += "    " + QuotedName(model.joints[j].name) + ": ";
      AppendList(v, 7, &out);
      out += '\n';
    }
  }
  return out;
}

}  // namespace internal
}  // namespace lpoe
