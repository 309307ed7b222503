// ROS-Industrial's UR kinematics file from the calibrated URDF overlay (see lpoe/io/urdf.h).
#include <tinyxml2.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <limits>
#include <map>
#include <set>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "lpoe/io/io.h"
#include "lpoe/kinematics/se3.h"
#include "lpoe/io/urdf.h"
#include "lpoe/version.h"
#include "io/parse_util.h"
#include "urdf/urdf_tree.h"

namespace lpoe {
using namespace urdf_internal;  // NOLINT(build/namespaces): the URDF files' shared steps

namespace {

using internal::LineError;

// The UR joints in chain order, and the keys of ROS-Industrial's UR kinematics file.
constexpr const char* kUrJoints[6] = {"shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint",
                                      "wrist_1_joint",      "wrist_2_joint",       "wrist_3_joint"};
constexpr const char* kUrKeys[6] = {"shoulder", "upper_arm", "forearm",
                                    "wrist_1",  "wrist_2",   "wrist_3"};

bool EndsWith(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() &&
         s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

}  // namespace

bool IsUrModel(const RobotModel& model) {
  if (model.num_joints() != 6) return false;
  const std::string& first = model.joints[0].name;
  if (!EndsWith(first, kUrJoints[0])) return false;
  const std::string prefix = first.substr(0, first.size() - std::string(kUrJoints[0]).size());
  for (int i = 0; i < 6; ++i) {
    if (model.joints[i].name != prefix + kUrJoints[i]) return false;
  }
  return true;
}

Status UrKinematicsYaml(const UrdfSource& source, const RobotModel& calibrated,
                        const UrdfOverlayOptions& options, std::string* yaml) {
  if (!IsUrModel(calibrated)) {
    return Status::Error(source.source +
                         ": not a UR robot (its six joints are not shoulder_pan_joint, "
                         "shoulder_lift_joint, elbow_joint, wrist_1_joint, wrist_2_joint, "
                         "wrist_3_joint): no UR kinematics file");
  }
  try {
    std::string xml;
    std::vector<OverlayJoint> joints;
    if (Status s = OverlayImpl(source, calibrated, options, &xml, &joints); !s.ok()) return s;
    std::string out =
        "# Calibrated by lpoe-calib " + std::string(kLpoeVersion) + " from " + source.source +
        ": the origin of each joint in its parent link (metres, radians,\n# R = Rz(yaw) Ry(pitch) "
        "Rx(roll)), in the format of ROS-Industrial's ur_description kinematics files.\n"
        "kinematics:\n";
    bool along_z = true;
    for (int i = 0; i < 6; ++i) {
      along_z = along_z && (joints[i].axis - Eigen::Vector3d::UnitZ()).norm() <= 1e-9;
    }
    // The classic ur_description layout (ur5.urdf.xacro before the e-Series: joints turning about
    // y, shoulder_pan_joint on base_link, tool0 fixed to wrist_3_link) converted to the current
    // one (every joint about its z, shoulder_pan_joint on base_link_inertia, which is UR's Base
    // frame `base`, tool0 = wrist_3_link): link frame i becomes L_i A_i with A_i turning z onto
    // the joint's axis (A_6: tool0's pose, which must turn z onto wrist_3's axis and lie on it),
    // so that origin_i = A_{i-1}^-1 O_i A_i, A_0 the pose of `base` in shoulder_pan_joint's
    // parent link. Forward kinematics to tool0 is unchanged.
    std::vector<SE3d> origins;
    for (const OverlayJoint& j : joints) origins.push_back(j.origin);
    if (!along_z) {
      const char* kLayout =
          "; the UR kinematics file is written from the current ur_description layout (every "
          "joint turning about its z axis) or converted from the classic one, which needs a link "
          "`base` (UR's Base frame) fixed to shoulder_pan_joint's parent and a link `tool0` fixed "
          "to wrist_3_link on its axis";
      RobotModel nominal;
      if (Status s = ParseRobotModelUrdf(source.xml, source.source, &nominal, source.options);
          !s.ok()) {
        return s;
      }
      // shoulder_pan_joint's parent link in the model's base frame, and `base` in it.
      XMLDocument doc;
      UrdfTree tree;
      if (Status s = ReadTree(source.xml, source.source, &doc, &tree); !s.ok()) return s;
      const UrdfJoint* first = nullptr;
      for (const UrdfJoint& j : tree.joints) {
        if (j.name == joints[0].name) first = &j;
      }
      const NamedFrame* base = nominal.FindFrame("base", false);
      const NamedFrame* tool0 = nominal.FindFrame("tool0", true);
      if (first == nullptr || base == nullptr || tool0 == nullptr) {
        return Status::Error(source.source + ": " + JointContext(joints[0].name) +
                             " and the others do not all turn about their z axes" + kLayout);
      }
      const SE3d parent = nominal.joints[0].origin * first->origin.Inverse();
      std::vector<SE3d> A(7);
      A[0] = parent.Inverse() * base->pose;
      for (int i = 1; i <= 6; ++i) {
        const Eigen::Vector3d a = joints[i - 1].axis;
        if (i == 6) {
          A[6] = tool0->pose;
          const Eigen::Vector3d along = A[6].t - a * a.dot(A[6].t);
          if ((A[6].R * Eigen::Vector3d::UnitZ() - a).norm() > 1e-6 || along.norm() > 1e-6) {
            return Status::Error(source.source + ": tool0 is not on wrist_3_joint's axis turned "
                                 "onto it" + kLayout);
          }
          continue;
        }
        // The smallest rotation turning z onto a (a half turn about x for -z).
        const Eigen::Vector3d z = Eigen::Vector3d::UnitZ();
        const Eigen::Vector3d w = z.cross(a);
        const double c = z.dot(a);
        A[i].R = w.norm() < 1e-12
                     ? (c > 0 ? Eigen::Matrix3d::Identity()
                              : Eigen::Matrix3d(Eigen::Vector3d(1, -1, -1).asDiagonal()))
                     : ExpSO3(Eigen::Vector3d(w.normalized() * std::atan2(w.norm(), c)));
      }
      for (int i = 0; i < 6; ++i) origins[i] = A[i].Inverse() * joints[i].origin * A[i + 1];
    }
    uint64_t hash = 1469598103934665603ull;  // FNV-1a of the numbers, to name this calibration
    for (int i = 0; i < 6; ++i) {
      const Eigen::Vector3d xyz = origins[i].t * kMmToMetres;
      const Eigen::Vector3d rpy = RpyFromRotation(origins[i].R);
      const double values[6] = {xyz(0), xyz(1), xyz(2), rpy(0), rpy(1), rpy(2)};
      const char* names[6] = {"x", "y", "z", "roll", "pitch", "yaw"};
      out += "  " + std::string(kUrKeys[i]) + ":\n";
      for (int k = 0; k < 6; ++k) {
        // The URDF's own text where no conversion was needed (the two agree to the digit).
        const std::string number = along_z ? joints[i].text[k] : Number(values[k]);
        out += "    " + std::string(names[k]) + ": " + number + "\n";
        for (char ch : number) hash = (hash ^ static_cast<unsigned char>(ch)) * 1099511628211ull;
      }
    }
    char tag[40];
    std::snprintf(tag, sizeof(tag), "lpoe_calib_%016llx", static_cast<unsigned long long>(hash));
    out += "  hash: " + std::string(tag) + "\n";
    *yaml = std::move(out);
    return Status::Ok();
  } catch (const std::exception& e) {  // std::bad_alloc
    return Status::Error(source.source + ": cannot write the UR kinematics: " + e.what());
  }
}

Status WriteUrKinematicsYaml(const std::string& path, const UrdfSource& source,
                             const RobotModel& calibrated, const UrdfOverlayOptions& options) {
  return WriteMade(
      path, [&](std::string* yaml) { return UrKinematicsYaml(source, calibrated, options, yaml); });
}

}  // namespace lpoe
