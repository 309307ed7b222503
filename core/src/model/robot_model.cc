#include "lpoe/model/robot_model.h"

#include "lpoe/terms/joint_errors.h"
#include "lpoe/model/residual_layer.h"

#include <cmath>
#include <limits>
#include <set>
#include <sstream>

namespace lpoe {
namespace {

constexpr double kRotationTolerance = 1e-9;

SE3d Translation(double x, double y, double z) {
  return SE3d(Eigen::Matrix3d::Identity(), Eigen::Vector3d(x, y, z));
}

SE3d Rx(double a) { return SE3d(RotationFromRpy(a, 0.0, 0.0), Eigen::Vector3d::Zero()); }
SE3d Rz(double a) { return SE3d(RotationFromRpy(0.0, 0.0, a), Eigen::Vector3d::Zero()); }

bool IsFinite(const SE3d& X) { return X.R.allFinite() && X.t.allFinite(); }

std::string CheckRotation(const Eigen::Matrix3d& R) {
  const double orth = (R.transpose() * R - Eigen::Matrix3d::Identity()).norm();
  if (orth > kRotationTolerance || R.determinant() < 0) {
    std::ostringstream os;
    os << "rotation is not orthonormal (|R^T R - I| = " << orth << ", det = " << R.determinant()
       << ")";
    return os.str();
  }
  return "";
}

}  // namespace

const char* JointTypeName(JointType type) {
  return type == JointType::kRevolute ? "revolute" : "prismatic";
}

Vector6d DefaultTwist(JointType type) {
  Vector6d s = Vector6d::Zero();
  if (type == JointType::kRevolute) {
    s(2) = 1;
  } else {
    s(5) = 1;
  }
  return s;
}

Status ValidateTwist(JointType type, const Vector6d& twist) {
  const Eigen::Vector3d w = twist.head<3>();
  const Eigen::Vector3d v = twist.tail<3>();
  std::ostringstream os;
  if (!twist.allFinite()) {
    os << "non-finite number in the twist";
  } else if (type == JointType::kRevolute) {
    if (std::abs(w.norm() - 1.0) > kTwistTolerance) {
      os << "revolute twist needs a unit rotation axis, |omega| = " << w.norm();
    } else if (std::abs(w.dot(v)) > kTwistTolerance * std::max(1.0, v.norm())) {
      os << "revolute twist must have omega . v = 0 (no pitch), got " << w.dot(v);
    }
  } else {
    if (w.norm() > kTwistTolerance) {
      os << "prismatic twist needs omega = 0, |omega| = " << w.norm();
    } else if (std::abs(v.norm() - 1.0) > kTwistTolerance) {
      os << "prismatic twist needs a unit direction, |v| = " << v.norm();
    }
  }
  const std::string what = os.str();
  return what.empty() ? Status::Ok() : Status::Error(what);
}

Status ValidateLimits(double lower, double upper) {
  if (lower == std::numeric_limits<double>::infinity() ||
      upper == -std::numeric_limits<double>::infinity()) {
    std::ostringstream ls;
    ls << "limits [" << lower << ", " << upper << "] are open the wrong way (only the lower limit "
       << "may be -inf and only the upper +inf)";
    return Status::Error(ls.str());
  }
  if (std::isnan(lower) || std::isnan(upper) || !(lower <= upper)) {
    std::ostringstream ls;
    ls << "limits [" << lower << ", " << upper << "] must satisfy lower <= upper";
    return Status::Error(ls.str());
  }
  return Status::Ok();
}

const NamedFrame* RobotModel::FindFrame(const std::string& frame_name, bool on_flange) const {
  for (const NamedFrame& f : frames) {
    if (f.name == frame_name && f.on_flange == on_flange) return &f;
  }
  return nullptr;
}

int RobotModel::FindTool(const std::string& tool_name) const {
  for (int k = 0; k < num_tools(); ++k) {
    if (tools[k].name == tool_name) return k;
  }
  return -1;
}

bool RobotModel::HasFixedTool() const {
  for (const Tool& t : tools) {
    if (t.fixed) return true;
  }
  return false;
}

Status RobotModel::Validate() const {
  if (joints.empty()) return Status::Error("the model has no joints; expected at least one");
  if (tools.empty()) {
    return Status::Error("the model has no tools; expected at least one measured point");
  }
  std::set<std::string> names;
  for (int i = 0; i < num_joints(); ++i) {
    const Joint& j = joints[i];
    const std::string where = "joint " + std::to_string(i + 1) + " ('" + j.name + "')";
    if (j.name.empty()) return Status::Error(where + ": empty name");
    if (!names.insert(j.name).second) return Status::Error(where + ": duplicate name");
    if (!IsFinite(j.origin) || !j.twist.allFinite()) {
      return Status::Error(where + ": non-finite number in origin or twist");
    }
    const std::string rot = CheckRotation(j.origin.R);
    if (!rot.empty()) return Status::Error(where + ": origin " + rot);
    Status s = ValidateLimits(j.lower, j.upper);
    if (!s.ok()) return Status::Error(where + ": " + s.message());
    s = ValidateTwist(j.type, j.twist);
    if (!s.ok()) return Status::Error(where + ": " + s.message());
  }
  for (int k = 0; k < num_tools(); ++k) {
    const Tool& t = tools[k];
    const std::string where = "tool " + std::to_string(k) + " ('" + t.name + "')";
    if (t.name.empty()) return Status::Error(where + ": empty name");
    if (!names.insert(t.name).second) {
      return Status::Error(where + ": name already used by a joint or tool");
    }
    if (!IsFinite(t.origin)) return Status::Error(where + ": non-finite number in origin");
    const std::string rot = CheckRotation(t.origin.R);
    if (!rot.empty()) return Status::Error(where + ": origin " + rot);
  }
  if (residual_layer) {
    if (Status s = residual_layer->Validate(num_joints(), num_tools()); !s.ok()) return s;
  }
  return ValidateJointErrorTerms(*this);
}

const std::vector<double>& JointErrorTerms::Values(const std::string& name) const {
  static const std::vector<double> kNone;
  for (const JointTermEntry& t : terms) {
    if (t.name == name) return t.values;
  }
  return kNone;
}

bool JointErrorTerms::empty() const {
  for (const JointTermEntry& t : terms) {
    if (!t.values.empty()) return false;
  }
  return true;
}

std::vector<double>* JointErrorTerms::MutableValues(const std::string& name) {
  for (JointTermEntry& t : terms) {
    if (t.name == name) return &t.values;
  }
  terms.push_back(JointTermEntry{name, {}});
  return &terms.back().values;
}

void JointErrorTerms::Remove(const std::string& name) {
  for (size_t i = 0; i < terms.size(); ++i) {
    if (terms[i].name == name) {
      terms.erase(terms.begin() + static_cast<std::ptrdiff_t>(i));
      return;
    }
  }
}

RobotModel MakeCobot6(const Eigen::Vector3d& tool_xyz) {
  // Joint frames at q = 0 in base coordinates (docs/conventions.md, paper Table 1).
  const double H1 = 96, W1 = 138, L1 = 418, W2 = 114, L2 = 398, W3 = 98, H2 = 98, W4 = 89;
  const SE3d down = Rx(-kPi / 2);  // local z along base +y
  std::vector<SE3d> F = {
      SE3d(),                                               // base
      Translation(0, 0, H1),                                // joint 1
      Translation(0, W1, H1) * down,                        // joint 2
      Translation(0, W1 - W2, H1 + L1) * down,              // joint 3
      Translation(0, W1 - W2 + W3, H1 + L1 + L2) * down,    // joint 4
      Translation(0, W1 - W2 + W3, H1 + L1 + L2 + H2),      // joint 5
      Translation(0, W1 - W2 + W3 + W4, H1 + L1 + L2 + H2) * down,  // joint 6
  };
  RobotModel m;
  m.name = "cobot6";
  for (int i = 1; i <= 6; ++i) {
    Joint j;
    j.name = "joint" + std::to_string(i);
    j.type = JointType::kRevolute;
    j.origin = F[i - 1].Inverse() * F[i];
    j.twist = DefaultTwist(JointType::kRevolute);
    m.joints.push_back(j);
  }
  m.tools.push_back(Tool{"smr1", Translation(tool_xyz.x(), tool_xyz.y(), tool_xyz.z())});
  return m;
}

RobotModel MakeFromStandardDh(const std::string& name, const std::vector<DhRow>& rows,
                              const SE3d& tool) {
  // Joint i turns about z of DH frame i-1 (A_i = Rz(theta + q) Tz(d) Tx(a) Rx(alpha), or
  // Tz(d + q) for a prismatic joint); the motion commutes with Rz(theta) Tz(d), so
  // A_i(q) = exp(s^ q) * static_i and the local frame of joint i+1 is static_i.
  RobotModel m;
  m.name = name;
  SE3d previous_static;  // identity: the base is DH frame 0 = local frame of joint 1
  for (size_t i = 0; i < rows.size(); ++i) {
    const DhRow& r = rows[i];
    Joint j;
    j.name = "joint" + std::to_string(i + 1);
    j.type = r.type;
    j.twist = DefaultTwist(r.type);
    j.origin = previous_static;
    m.joints.push_back(j);
    previous_static = Rz(r.theta) * Translation(0, 0, r.d) * Translation(r.a, 0, 0) * Rx(r.alpha);
  }
  m.tools.push_back(Tool{"tool", previous_static * tool});
  return m;
}

RobotModel MakeUr5Like() {
  const double h = kPi / 2;
  return MakeFromStandardDh("ur5_like",
                            {{0, h, 89.159, 0},
                             {-425.0, 0, 0, 0},
                             {-392.25, 0, 0, 0},
                             {0, h, 109.15, 0},
                             {0, -h, 94.65, 0},
                             {0, 0, 82.3, 0}},
                            Translation(30, 20, 50));
}

RobotModel MakeSevenJointArm() {
  const double h = kPi / 2;
  // An iiwa-like arm with small link offsets so that no two consecutive axes intersect exactly.
  return MakeFromStandardDh("arm7",
                            {{0, -h, 340, 0},
                             {5, h, 0, 0},
                             {0, h, 400, 0},
                             {-5, -h, 0, 0},
                             {0, -h, 400, 0},
                             {0, h, 0, 0},
                             {0, 0, 126, 0}},
                            Translation(25, -15, 60));
}

RobotModel MakeArmWithPrismatic() {
  const double h = kPi / 2;
  DhRow prismatic{0, h, 250, 0};
  prismatic.type = JointType::kPrismatic;
  return MakeFromStandardDh("arm_prismatic",
                            {{0, -h, 300, 0},
                             prismatic,
                             {200, 0, 50, 0.3},
                             {0, -h, 80, 0},
                             {0, h, 150, 0},
                             {0, 0, 70, 0}},
                            Translation(35, 10, 40));
}

}  // namespace lpoe
