// The physical joint-error terms of joint_errors.h, compliance under gravity and payload and the
// harmonic transmission errors, as registry entries (joint_term_kind.h, joint_term_registry.inc):
// layout, regressor, prediction, YAML block and simulated truth of each.
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include <glog/logging.h>

#include "io/joint_errors_yaml.h"
#include "terms/joint_term_kind.h"
#include "lpoe/terms/joint_errors.h"
#include "io/parse_util.h"

namespace lpoe {
namespace internal {
namespace {

// ---- compliance

class ComplianceKind : public JointTermKind {
 public:
  const char* name() const override { return "compliance"; }
  int NumParameters(const RobotModel& model) const override {
    return NumComplianceParameters(model.num_joints());
  }
  std::vector<std::string> ParameterNames(const RobotModel& model) const override {
    const int n = model.num_joints();
    std::vector<std::string> names;
    for (int j = 0; j < n; ++j) {
      const std::string& joint = model.joints[j].name;
      for (int k = j; k < n; ++k) {
        const std::string& link = model.joints[k].name;
        for (const char* s : {".c*m_", ".c*hx_", ".c*hy_", ".c*hz_"}) {
          names.push_back(joint + s + link);
        }
      }
      names.push_back(joint + ".c");
    }
    return names;
  }
  // Per joint j the 4 products of every link k >= j, then c_j: each moves joint j only.
  std::vector<int> ParameterJoints(const RobotModel& model) const override {
    const int n = model.num_joints();
    std::vector<int> joints;
    for (int j = 0; j < n; ++j) joints.insert(joints.end(), 4 * (n - j) + 1, j);
    return joints;
  }
  void Regressor(const RobotModel& model, const double* q, Eigen::MatrixXd* Y) const override {
    ComplianceRegressor(model, q, Y);
    ZeroJointErrorRoundingNoise(Y);
  }
  bool RegressorValues(const RobotModel& model, const double* q, double* y) const override {
    ComplianceRegressorValues(model, q, y);
    return true;
  }
  void AddOffsets(const RobotModel& model, const std::vector<double>& theta, const double* q,
                  double* dq) const override {
    const int n = model.num_joints();
    const std::vector<SE3d>& origins = model.joint_errors.regressor_origins;
    thread_local std::vector<double> y;  // no allocation per call
    y.resize(theta.size());
    // On the stored reference geometry (the calibration's start model), as the solver did.
    ComplianceRegressorValues(model, q, y.data(), origins.empty() ? nullptr : &origins);
    for (int j = 0; j < n; ++j) {
      double sum = 0;
      for (int c = ComplianceLinkIndex(n, j, j); c <= CompliancePayloadIndex(n, j); ++c) {
        sum += y[c] * theta[c];
      }
      dq[j] += sum;
    }
  }

  //     compliance:                        # one entry per joint with a non-zero product
  //       - joint: joint2
  //         c: 5e-05                       # c_j, rad/(N m) (payload column)
  //         links:                         # link k >= j: [c m, c h_x, c h_y, c h_z]
  //           joint2: [1.5e-4, 0.02, 0, 0.001]
  Status ReadYaml(const JointErrorsYamlReader& reader, const YAML::Node& node, int line,
                  std::vector<double>* theta) const override {
    const RobotModel& model = reader.model();
    const int n = model.num_joints();
    theta->assign(NumComplianceParameters(n), 0.0);
    using Entries = std::vector<std::pair<std::string, YAML::Node>>;
    return reader.Entries(node, line, "compliance", [&](const YAML::Node& item, int l, int* j) {
      Entries entry;
      Status t = reader.Map(item, l, "a compliance entry", {"joint", "c", "links"}, &entry);
      if (!t.ok()) return t;
      const YAML::Node* joint = reader.Find(entry, "joint");
      if (joint == nullptr) {
        return reader.Error(item, l, "compliance entry has no 'joint'", "joint: <name>");
      }
      t = reader.JointIndex(*joint, l, "'joint'", j);
      if (!t.ok()) return t;
      if (const YAML::Node* c = reader.Find(entry, "c")) {
        t = reader.Number(*c, l, "'c'", &(*theta)[CompliancePayloadIndex(n, *j)]);
        if (!t.ok()) return t;
      }
      const YAML::Node* links = reader.Find(entry, "links");
      if (links == nullptr) return Status::Ok();
      std::vector<std::string> names;
      for (int k = *j; k < n; ++k) names.push_back(model.joints[k].name);
      Entries rows;
      t = reader.Map(*links, l,
                     "'links' of joint " + Quote(model.joints[*j].name) + " (the links it moves)",
                     names, &rows);
      if (!t.ok()) return t;
      for (const auto& row : rows) {
        int k = 0;
        reader.JointIndex(YAML::Node(row.first), l, "link", &k);
        t = reader.Numbers(row.second, l, "link " + Quote(row.first), 4,
                           "[c*m, c*hx, c*hy, c*hz]", &(*theta)[ComplianceLinkIndex(n, *j, k)]);
        if (!t.ok()) return t;
      }
      return Status::Ok();
    });
  }
  std::string WriteYaml(const RobotModel& model, const std::vector<double>& theta) const override {
    const int n = model.num_joints();
    std::string entries;
    for (int j = 0; j < n; ++j) {
      const double* block = theta.data() + ComplianceLinkIndex(n, j, j);
      if (AllZero(block, 4 * (n - j) + 1)) continue;
      entries += "    - joint: " + YamlQuotedName(model.joints[j].name) + "\n      c: ";
      AppendYamlNumber(theta[CompliancePayloadIndex(n, j)], &entries);
      entries += "\n      links:\n";
      for (int k = j; k < n; ++k) {
        const double* row = theta.data() + ComplianceLinkIndex(n, j, k);
        if (AllZero(row, 4)) continue;
        entries += "        " + YamlQuotedName(model.joints[k].name) + ": ";
        AppendYamlList(row, 4, &entries);
        entries += '\n';
      }
    }
    std::string out;
    out += "  # c in rad/(N m) (mm/N prismatic); links: [c*m, c*hx, c*hy, c*hz] (kg, kg mm in the\n";
    out += "  # link's frame)\n";
    out += entries.empty() ? "  compliance: []\n" : "  compliance:\n" + entries;
    return out;
  }

  std::vector<double> Simulate(const RobotModel& model,
                               const JointErrorPhysics& physics) const override {
    CHECK_EQ(static_cast<int>(physics.stiffness.size()), model.num_joints());
    return CompliancePhysicsParameters(physics);
  }
};

// ---- harmonics

class HarmonicsKind : public JointTermKind {
 public:
  const char* name() const override { return "harmonics"; }
  int NumParameters(const RobotModel& model) const override {
    return NumHarmonicsParameters(model.num_joints());
  }
  std::vector<std::string> ParameterNames(const RobotModel& model) const override {
    std::vector<std::string> names;
    for (const Joint& joint : model.joints) {
      for (const char* s : {".sin1", ".cos1", ".sin2", ".cos2"}) names.push_back(joint.name + s);
    }
    return names;
  }
  std::vector<int> ParameterJoints(const RobotModel& model) const override {
    std::vector<int> joints;
    for (int j = 0; j < model.num_joints(); ++j) joints.insert(joints.end(), kHarmonicsPerJoint, j);
    return joints;
  }
  void Regressor(const RobotModel& model, const double* q, Eigen::MatrixXd* Y) const override {
    HarmonicsRegressor(model, q, Y);
    ZeroJointErrorRoundingNoise(Y);
  }
  bool RegressorValues(const RobotModel& model, const double* q, double* y) const override {
    HarmonicsRegressorValues(model, q, y);
    return true;
  }
  void AddOffsets(const RobotModel& model, const std::vector<double>& theta, const double* q,
                  double* dq) const override {
    const int n = model.num_joints();
    thread_local std::vector<double> y;  // no allocation per call
    y.resize(theta.size());
    HarmonicsRegressorValues(model, q, y.data());
    for (int j = 0; j < n; ++j) {
      double sum = 0;
      for (int c = kHarmonicsPerJoint * j; c < kHarmonicsPerJoint * (j + 1); ++c) {
        sum += y[c] * theta[c];
      }
      dq[j] += sum;
    }
  }

  //     harmonics:                         # rad
  //       - joint: joint2
  //         coefficients: [a1, b1, a2, b2] # a1 sin q + b1 cos q + a2 sin 2q + b2 cos 2q
  Status ReadYaml(const JointErrorsYamlReader& reader, const YAML::Node& node, int line,
                  std::vector<double>* theta) const override {
    theta->assign(NumHarmonicsParameters(reader.model().num_joints()), 0.0);
    return reader.Entries(node, line, "harmonics", [&](const YAML::Node& item, int l, int* j) {
      std::vector<std::pair<std::string, YAML::Node>> entry;
      Status t = reader.Map(item, l, "a harmonics entry", {"joint", "coefficients"}, &entry);
      if (!t.ok()) return t;
      const YAML::Node* joint = reader.Find(entry, "joint");
      const YAML::Node* coefficients = reader.Find(entry, "coefficients");
      if (joint == nullptr) {
        return reader.Error(item, l, "harmonics entry has no 'joint'", "joint: <name>");
      }
      t = reader.JointIndex(*joint, l, "'joint'", j);
      if (!t.ok()) return t;
      if (coefficients == nullptr) {
        return reader.Error(item, l, "harmonics entry has no 'coefficients'",
                            "coefficients: [a1, b1, a2, b2]");
      }
      return reader.Numbers(*coefficients, l, "'coefficients'", 4, "[a1, b1, a2, b2] in rad",
                            &(*theta)[kHarmonicsPerJoint * *j]);
    });
  }
  std::string WriteYaml(const RobotModel& model, const std::vector<double>& theta) const override {
    std::string entries;
    for (int j = 0; j < model.num_joints(); ++j) {
      const double* row = theta.data() + kHarmonicsPerJoint * j;
      if (AllZero(row, kHarmonicsPerJoint)) continue;
      entries += "    - joint: " + YamlQuotedName(model.joints[j].name) + "\n      coefficients: ";
      AppendYamlList(row, kHarmonicsPerJoint, &entries);
      entries += '\n';
    }
    std::string out = "  # rad: a1 sin q + b1 cos q + a2 sin 2q + b2 cos 2q\n";
    out += entries.empty() ? "  harmonics: []\n" : "  harmonics:\n" + entries;
    return out;
  }

  std::vector<double> Simulate(const RobotModel& model,
                               const JointErrorPhysics& physics) const override {
    const int n = model.num_joints();
    CHECK_EQ(static_cast<int>(physics.harmonics.size()), n);
    std::vector<double> theta(NumHarmonicsParameters(n), 0.0);
    for (int j = 0; j < n; ++j) {
      for (int c = 0; c < kHarmonicsPerJoint; ++c) {
        theta[kHarmonicsPerJoint * j + c] = physics.harmonics[j](c);
      }
    }
    return theta;
  }
  // a sin(q + z) + b cos(q + z) = a' sin q + b' cos q for each order.
  void FoldJointZeros(const RobotModel& model, const std::vector<double>& joint_zero,
                      std::vector<double>* theta, std::vector<double>* extra_zero) const override {
    (void)extra_zero;
    for (int i = 0; i < model.num_joints(); ++i) {
      if (model.joints[i].type != JointType::kRevolute) continue;
      for (int order = 1; order <= 2; ++order) {
        double* ab = &(*theta)[kHarmonicsPerJoint * i + 2 * (order - 1)];
        const double s = std::sin(order * joint_zero[i]), c = std::cos(order * joint_zero[i]);
        const double a = ab[0], b = ab[1];
        ab[0] = a * c - b * s;
        ab[1] = a * s + b * c;
      }
    }
  }
};

}  // namespace

const JointTermKind& ComplianceJointTermKind() {
  static const ComplianceKind kind;
  return kind;
}

const JointTermKind& HarmonicsJointTermKind() {
  static const HarmonicsKind kind;
  return kind;
}

}  // namespace internal
}  // namespace lpoe
