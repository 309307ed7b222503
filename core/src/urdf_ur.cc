// ROS-Industrial's UR kinematics file from the calibrated URDF overlay (see lpoe/urdf.h).
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

#include "lpoe/io.h"
#include "lpoe/se3.h"
#include "lpoe/urdf.h"
#include "lpoe/version.h"
#include "parse_util.h"
#include "urdf_tree.h"

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
    uint64_t hash = 1469598103934665603ull;  // FNV-1a of the numbers, to name this calibration
    for (int i = 0; i < 6; ++i) {
      if ((joints[i].axis - Eigen::Vector3d::UnitZ()).norm() > 1e-9) {
        return Status::Error(source.source + ": " + JointContext(joints[i].name) +
                             " has the axis " + Triple(joints[i].axis) +
                             "; the UR kinematics file needs every joint turning about its z axis");
      }
      const Eigen::Vector3d xyz = joints[i].origin.t * kMmToMetres;
      const Eigen::Vector3d rpy = RpyFromRotation(joints[i].origin.R);
      const double values[6] = {xyz(0), xyz(1), xyz(2), rpy(0), rpy(1), rpy(2)};
      const char* names[6] = {"x", "y", "z", "roll", "pitch", "yaw"};
      out += "  " + std::string(kUrKeys[i]) + ":\n";
      for (int k = 0; k < 6; ++k) {
        const std::string number = Number(values[k]);
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
