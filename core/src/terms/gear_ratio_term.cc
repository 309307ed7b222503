// The `gear_ratio` joint-space term (docs/joint_errors.md, "Gear ratio"): an error s_j of joint j's
// transmission ratio (a revolute joint: the gearbox's ratio; a prismatic joint: the lead-screw's
// pitch) scales the joint's travel,
//
//   dq_j = s_j q_j,          Y(q) = diag(q_1 .. q_n),   s_j dimensionless (rad/rad, mm/mm).
//
// One parameter per joint, moving that joint only. Where q_j stays constant s_j q_j is a joint
// offset and the solvers' rank logic drops it; with q_j spanning a range it is separable from the
// offset (the geometry's joint zero) and from the harmonics (sin q, cos q, sin 2q, cos 2q).
//
// YAML, under `joint_errors` (joints left out have s = 0):
//
//   gear_ratio:
//     - joint: joint2
//       s: 0.00025
//
// Simulation: |s_j| uniform in [1e-4, 1e-3], random sign, from the physics' seed.
#include <cmath>
#include <cstdint>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "io/joint_errors_yaml.h"
#include "terms/joint_term_kind.h"

namespace lpoe {
namespace internal {
namespace {

class GearRatioKind : public JointTermKind {
 public:
  const char* name() const override { return "gear_ratio"; }
  int NumParameters(const RobotModel& model) const override { return model.num_joints(); }
  std::vector<std::string> ParameterNames(const RobotModel& model) const override {
    std::vector<std::string> names;
    for (const Joint& joint : model.joints) names.push_back(joint.name + ".s");
    return names;
  }
  std::vector<int> ParameterJoints(const RobotModel& model) const override {
    std::vector<int> joints(model.num_joints());
    for (int j = 0; j < model.num_joints(); ++j) joints[j] = j;
    return joints;
  }
  void Regressor(const RobotModel& model, const double* q, Eigen::MatrixXd* Y) const override {
    const int n = model.num_joints();
    Y->setZero(n, n);
    for (int j = 0; j < n; ++j) (*Y)(j, j) = q[j];
    ZeroJointErrorRoundingNoise(Y);
  }
  bool RegressorValues(const RobotModel& model, const double* q, double* y) const override {
    const int n = model.num_joints();
    for (int j = 0; j < n; ++j) y[j] = q[j];
    ZeroJointErrorRoundingNoise(y, n);
    return true;
  }
  void AddOffsets(const RobotModel& model, const std::vector<double>& theta, const double* q,
                  double* dq) const override {
    const int n = model.num_joints();
    thread_local std::vector<double> y;  // no allocation per call
    y.resize(n);
    RegressorValues(model, q, y.data());
    for (int j = 0; j < n; ++j) dq[j] += y[j] * theta[j];
  }

  Status ReadYaml(const JointErrorsYamlReader& reader, const YAML::Node& node, int line,
                  std::vector<double>* theta) const override {
    theta->assign(reader.model().num_joints(), 0.0);
    return reader.Entries(node, line, name(), [&](const YAML::Node& item, int l, int* j) {
      std::vector<std::pair<std::string, YAML::Node>> entry;
      Status t = reader.Map(item, l, "a gear_ratio entry", {"joint", "s"}, &entry);
      if (!t.ok()) return t;
      const YAML::Node* joint = reader.Find(entry, "joint");
      const YAML::Node* s = reader.Find(entry, "s");
      if (joint == nullptr) {
        return reader.Error(item, l, "gear_ratio entry has no 'joint'", "joint: <name>");
      }
      t = reader.JointIndex(*joint, l, "'joint'", j);
      if (!t.ok()) return t;
      if (s == nullptr) {
        return reader.Error(item, l, "gear_ratio entry has no 's'",
                            "s: <ratio error, dimensionless>");
      }
      return reader.Number(*s, l, "'s'", &(*theta)[*j]);
    });
  }
  std::string WriteYaml(const RobotModel& model, const std::vector<double>& theta) const override {
    std::string entries;
    for (int j = 0; j < model.num_joints(); ++j) {
      if (theta[j] == 0) continue;
      entries += "    - joint: " + YamlQuotedName(model.joints[j].name) + "\n      s: ";
      AppendYamlNumber(theta[j], &entries);
      entries += '\n';
    }
    std::string out =
        "  # dimensionless: dq = s q (transmission-ratio error; lead-screw pitch error if "
        "prismatic)\n";
    out += entries.empty() ? "  gear_ratio: []\n" : "  gear_ratio:\n" + entries;
    return out;
  }

  std::vector<double> Simulate(const RobotModel& model,
                               const JointErrorPhysics& physics) const override {
    // A stream of its own, so that the other terms' draws do not depend on this term's.
    std::mt19937_64 engine(physics.seed ^ 0x9e3779b97f4a7c15ULL);
    auto uniform = [&engine] { return static_cast<double>(engine() >> 11) * 0x1.0p-53; };
    constexpr double kSmallest = 1e-4, kLargest = 1e-3;
    std::vector<double> theta(model.num_joints());
    for (double& s : theta) {
      const double magnitude = kSmallest + (kLargest - kSmallest) * uniform();
      s = uniform() < 0.5 ? -magnitude : magnitude;
    }
    return theta;
  }
  // The robot moves to (q + z) + s (q + z) = q + s q + (1 + s) z: s z more of joint offset.
  void FoldJointZeros(const RobotModel& model, const std::vector<double>& joint_zero,
                      std::vector<double>* theta, std::vector<double>* extra_zero) const override {
    for (int j = 0; j < model.num_joints(); ++j) (*extra_zero)[j] += (*theta)[j] * joint_zero[j];
  }
};

}  // namespace

const JointTermKind& GearRatioJointTermKind() {
  static const GearRatioKind kind;
  return kind;
}

}  // namespace internal
}  // namespace lpoe
