// YAML of the non-geometric terms (docs/joint_errors.md, "YAML format"):
//
//   gravity: [0, 0, -9.80665]                  # m/s^2, base frame; optional
//   payload: {mass: 0.5, com: [0, 0, 40]}      # kg; mm in the last joint's frame; optional
//   joint_errors:                              # optional
//     <term>: ...                              # one key per registry term the model carries
//     regressor_origins: ...                   # optional
//
// Each term's block is read and written by its registry entry (joint_term_kind.h); a key that is
// not a registry name is an error naming its line. Terms are written in registry order.
#include "io/joint_errors_yaml.h"

#include <charconv>
#include <cstdio>
#include <algorithm>
#include <cmath>
#include <string_view>
#include <utility>
#include <vector>

#include "terms/joint_term_kind.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/model/model_limits.h"
#include "io/parse_util.h"

namespace lpoe {
namespace internal {
namespace {

const char* const kGravityExpected = "gravity: [x, y, z] in m/s^2 (finite numbers)";

}  // namespace

int JointErrorsYamlReader::LineOf(const YAML::Node& node, int fallback) {
  if (!node.IsDefined()) return fallback;
  const YAML::Mark mark = node.Mark();
  return mark.is_null() || mark.line < 0 ? fallback : mark.line + 1;
}

Status JointErrorsYamlReader::Error(const YAML::Node& node, int fallback, const std::string& what,
                                    const std::string& expected) const {
  return LineError(source_, LineOf(node, fallback), what, expected);
}

Status JointErrorsYamlReader::Number(const YAML::Node& node, int line, const std::string& what,
                                     double* out) const {
  if (!node.IsScalar()) return Error(node, line, what + " is not a number", "a finite number");
  const std::string& text = node.Scalar();
  double v = 0;
  if (ParseNumber(Trim(text), &v) != NumberParse::kOk) {
    return Error(node, line, what + " " + Quote(text) + " is not a finite number",
                 "a finite number");
  }
  if (!(std::abs(v) <= kMaxJointTermValue)) {
    return Error(node, line, what + " " + Quote(text) + " is out of range",
                 "a number within +-" + ShortNumber(kMaxJointTermValue));
  }
  *out = v;
  return Status::Ok();
}

Status JointErrorsYamlReader::Numbers(const YAML::Node& node, int line, const std::string& what,
                                      int count, const std::string& expected, double* out) const {
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

Status JointErrorsYamlReader::Map(const YAML::Node& node, int line, const std::string& what,
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

const YAML::Node* JointErrorsYamlReader::Find(
    const std::vector<std::pair<std::string, YAML::Node>>& entries, const char* key) {
  for (const auto& e : entries) {
    if (e.first == key) return &e.second;
  }
  return nullptr;
}

Status JointErrorsYamlReader::JointIndex(const YAML::Node& node, int line, const std::string& what,
                                         int* index) const {
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

Status JointErrorsYamlReader::TwiceError(int line, int joint, const std::string& what) const {
  return LineError(source_, line,
                   "joint " + Quote(model_.joints[joint].name) + " appears twice in '" + what + "'",
                   "one entry per joint");
}

namespace {

class Reader : public JointErrorsYamlReader {
 public:
  using JointErrorsYamlReader::JointErrorsYamlReader;

  Status Gravity(const YAML::Node& node, int line, Eigen::Vector3d* g) const {
    Status s = Numbers(node, line, "'gravity'", 3, kGravityExpected, g->data());
    if (s.ok() && !(g->norm() <= kMaxModelGravity)) {
      return Error(node, line, "'gravity' has magnitude " + ShortNumber(g->norm()) + " m/s^2",
                   "a gravity vector of at most " + ShortNumber(kMaxModelGravity) + " m/s^2");
    }
    return s;
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
    if (payload->mass < 0 || payload->mass > kMaxModelPayloadKg) {
      return Error(*mass, line, "'mass' is out of range",
                   "a payload mass in [0, " + ShortNumber(kMaxModelPayloadKg) + "] kg");
    }
    payload->com.setZero();
    if (com != nullptr) {
      s = Numbers(*com, line, "'com'", 3, "com: [x, y, z] in mm in the last joint's frame",
                  payload->com.data());
      if (s.ok() && !(payload->com.cwiseAbs().maxCoeff() <= kMaxModelLengthMm)) {
        return Error(*com, line, "'com' is out of range",
                     "a centre of mass within +-" + ShortNumber(kMaxModelLengthMm) + " mm");
      }
    }
    return s;
  }

  // `joint_errors`: one key per registry term (read by the term's entry), and regressor_origins.
  Status ReadJointErrors(const YAML::Node& node, int line, JointErrorTerms* terms) const {
    std::vector<std::string> allowed;
    for (const JointTermKind* kind : JointTermKinds()) allowed.push_back(kind->name());
    allowed.push_back("regressor_origins");
    std::vector<std::pair<std::string, YAML::Node>> keys;
    Status s = Map(node, line, "'joint_errors'", allowed, &keys);
    if (!s.ok()) return s;
    if (const YAML::Node* origins = Find(keys, "regressor_origins")) {
      s = ReadRegressorOrigins(*origins, line, &terms->regressor_origins);
      if (!s.ok()) return s;
    }
    // In registry order, as the file is written (the stored order does not matter otherwise).
    for (const JointTermKind* kind : JointTermKinds()) {
      const YAML::Node* value = Find(keys, kind->name());
      if (value == nullptr) continue;
      std::vector<double> theta;
      s = kind->ReadYaml(*this, *value, line, &theta);
      if (!s.ok()) return s;
      *terms->MutableValues(kind->name()) = std::move(theta);
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

};

}  // namespace

void AppendYamlNumber(double v, std::string* out) { AppendNumber(v, out); }

void AppendYamlList(const double* v, int n, std::string* out) {
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

// The joint offsets the model's joint-space terms add, at configurations spread over the joint
// limits (+-pi or +-1000 mm where a side is open), must be finite and plausible: a joint-space
// error is a small correction (arc seconds to tenths of a degree), never radians.
Status CheckJointErrorOffsets(const std::string& source, int line, const RobotModel& model) {
  const int n = model.num_joints();
  if (model.joint_errors.empty() || n == 0) return Status::Ok();
  std::vector<double> q(n), dq(n);
  constexpr int kSamples = 64;
  for (int k = 0; k <= kSamples; ++k) {
    for (int j = 0; j < n; ++j) {
      const Joint& joint = model.joints[j];
      const double open = joint.type == JointType::kRevolute ? kPi : 1000.0;
      const double lo = std::isfinite(joint.lower) ? joint.lower : -open;
      const double hi = std::isfinite(joint.upper) ? joint.upper : open;
      // Corners first (k = 0: all lower, 1: all upper), then a low-discrepancy spread.
      const double u = k < 2 ? k : std::fmod(0.5 + (k * (j + 1)) * 0.6180339887498949, 1.0);
      q[j] = lo + (hi - lo) * u;
    }
    std::fill(dq.begin(), dq.end(), 0.0);
    JointErrorOffsets(model, q.data(), dq.data());
    for (int j = 0; j < n; ++j) {
      const bool revolute = model.joints[j].type == JointType::kRevolute;
      const double bound = revolute ? kMaxJointTermOffset : kMaxJointTermOffsetMm;
      if (!(std::abs(dq[j]) <= bound)) {
        return LineError(source, line,
                         "'joint_errors' move joint " + Quote(model.joints[j].name) + " by " +
                             ShortNumber(dq[j]) + (revolute ? " rad" : " mm") +
                             " within its range: not a plausible joint-space error",
                         "terms that move every joint by at most " + ShortNumber(bound) +
                             (revolute ? " rad" : " mm"));
      }
    }
  }
  return Status::Ok();
}

std::string YamlQuotedName(const std::string& name) { return internal::YamlDoubleQuoted(name); }

Status ReadModelWithJointErrors(
    const std::string& source, const YAML::Node& root, RobotModel* model,
    const std::function<Status(const YAML::Node&, RobotModel*)>& read_geometry) {
  // The keys of this file: value, line of the key (0 when absent).
  struct Key {
    const char* name;
    YAML::Node value;
    int line = 0;
  } keys[] = {{"gravity", {}, 0}, {"payload", {}, 0}, {"joint_errors", {}, 0}, {"residual_layer", {}, 0}};
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
        return LineError(source, JointErrorsYamlReader::LineOf(it->first, 1),
                         "duplicate key '" + name + "' in the robot model (first on line " +
                             std::to_string(key->line) + ")",
                         "each key once");
      }
      key->value = it->second;
      key->line = JointErrorsYamlReader::LineOf(it->first, 1);
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
    if (s.ok()) s = CheckJointErrorOffsets(source, keys[2].line, out);
  }
  if (s.ok() && keys[3].line > 0) {
    s = ReadResidualLayerYaml(reader, keys[3].value, keys[3].line, &out.residual_layer);
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
    AppendYamlList(model.gravity.data(), 3, &out);
    out += "  # m/s^2 in the base frame\n";
  }
  if (model.payload.mass != 0 || !model.payload.com.isZero(0)) {
    out += "payload: {mass: ";
    AppendNumber(model.payload.mass, &out);
    out += ", com: ";
    AppendYamlList(model.payload.com.data(), 3, &out);
    out += "}  # kg; mm in the last joint's frame\n";
  }
  const JointErrorTerms& terms = model.joint_errors;
  if (terms.empty()) return out;
  out += "joint_errors:  # docs/joint_errors.md\n";
  for (const JointTermKind* kind : JointTermKinds()) {
    if (!terms.Has(kind->name())) continue;
    out += kind->WriteYaml(model, terms.Values(kind->name()));
  }
  if (!terms.regressor_origins.empty()) {
    out += "  # the joint origins the regressors were identified on: [x, y, z, qx, qy, qz, qw]\n";
    out += "  regressor_origins:\n";
    for (int j = 0; j < n; ++j) {
      const SE3d& o = terms.regressor_origins[j];
      const Eigen::Vector4d quat = RotationToQuaternion(o.R);
      const double v[7] = {o.t(0), o.t(1), o.t(2), quat(0), quat(1), quat(2), quat(3)};
      out += "    " + YamlQuotedName(model.joints[j].name) + ": ";
      AppendYamlList(v, 7, &out);
      out += '\n';
    }
  }
  return out;
}

}  // namespace internal
}  // namespace lpoe
