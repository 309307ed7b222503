// URDF export of a model without a source URDF (see lpoe/io/urdf.h).
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

Eigen::Vector3d Unit(const Eigen::Vector3d& v) {
  const double n = v.norm();
  return n > 0 && std::isfinite(n) ? Eigen::Vector3d(v / n) : Eigen::Vector3d::Zero();
}

void PushOrigin(tinyxml2::XMLPrinter* p, const SE3d& T) {
  p->OpenElement("origin");
  p->PushAttribute("xyz", Triple(T.t * kMmToMetres).c_str());
  p->PushAttribute("rpy", Triple(RpyFromRotation(T.R)).c_str());
  p->CloseElement();
}

}  // namespace

std::string RobotModelToUrdf(const RobotModel& model) {
  const int n = model.num_joints();

  // Link names: base_link, link1..linkN and the tools; generated names give way to tool names.
  std::set<std::string> taken;
  for (const Tool& t : model.tools) taken.insert(t.name);
  std::vector<std::string> link_names;
  link_names.push_back(Unique("base_link", taken));
  taken.insert(link_names.back());
  for (int i = 1; i <= n; ++i) {
    link_names.push_back(Unique("link" + std::to_string(i), taken));
    taken.insert(link_names.back());
  }
  std::set<std::string> joint_names;
  for (const Joint& j : model.joints) joint_names.insert(j.name);

  // r_i: the point of joint i's axis closest to its local frame origin (zero for prismatic joints).
  // The URDF joint frame sits there: origin_i = Trans(-r_{i-1}) T_{i-1,i}(0) Trans(r_i).
  std::vector<Eigen::Vector3d> shift(n, Eigen::Vector3d::Zero());
  for (int i = 0; i < n; ++i) {
    const Joint& j = model.joints[i];
    if (j.type != JointType::kRevolute) continue;
    const Eigen::Vector3d w = j.twist.head<3>();
    const double w2 = w.squaredNorm();
    if (w2 > 0 && std::isfinite(w2)) shift[i] = w.cross(Eigen::Vector3d(j.twist.tail<3>())) / w2;
  }

  tinyxml2::XMLPrinter p;
  p.PushHeader(false, true);
  p.PushComment(
      " Written by lpoe-calib. Lengths in metres, angles in radians. Joint frames are placed on "
      "the "
      "joint axes, so they may differ from the model's local frames; forward kinematics is the "
      "same. ");
  p.OpenElement("robot");
  p.PushAttribute("name", (model.name.empty() ? std::string("robot") : model.name).c_str());
  for (const std::string& l : link_names) {
    p.OpenElement("link");
    p.PushAttribute("name", l.c_str());
    p.CloseElement();
  }
  for (const Tool& t : model.tools) {
    p.OpenElement("link");
    p.PushAttribute("name", t.name.c_str());
    p.CloseElement();
  }
  for (int i = 0; i < n; ++i) {
    const Joint& j = model.joints[i];
    const bool revolute = j.type == JointType::kRevolute;
    SE3d origin = j.origin;
    if (i > 0) origin.t -= shift[i - 1];
    origin.t += origin.R * shift[i];
    p.OpenElement("joint");
    p.PushAttribute("name", j.name.c_str());
    const bool limited = std::isfinite(j.lower) && std::isfinite(j.upper);
    p.PushAttribute("type", revolute ? (limited ? "revolute" : "continuous") : "prismatic");
    p.OpenElement("parent");
    p.PushAttribute("link", link_names[i].c_str());
    p.CloseElement();
    p.OpenElement("child");
    p.PushAttribute("link", link_names[i + 1].c_str());
    p.CloseElement();
    PushOrigin(&p, origin);
    p.OpenElement("axis");
    const Eigen::Vector3d axis =
        Unit(revolute ? Eigen::Vector3d(j.twist.head<3>()) : Eigen::Vector3d(j.twist.tail<3>()));
    p.PushAttribute("xyz", Triple(axis).c_str());
    p.CloseElement();
    if (limited) {
      const double scale = revolute ? 1.0 : kMmToMetres;
      p.OpenElement("limit");
      p.PushAttribute("lower", Number(j.lower * scale).c_str());
      p.PushAttribute("upper", Number(j.upper * scale).c_str());
      p.PushAttribute("effort", "0");
      p.PushAttribute("velocity", "0");
      p.CloseElement();
    } else if (!revolute) {
      p.PushComment(" placeholder: the kinematic model has no joint limits ");
      p.OpenElement("limit");
      p.PushAttribute("lower", Number(-kPlaceholderPrismaticLimit).c_str());
      p.PushAttribute("upper", Number(kPlaceholderPrismaticLimit).c_str());
      p.PushAttribute("effort", "0");
      p.PushAttribute("velocity", "0");
      p.CloseElement();
    }
    p.CloseElement();
  }
  for (const Tool& t : model.tools) {
    SE3d origin = t.origin;
    if (n > 0) origin.t -= shift[n - 1];
    const std::string name = Unique(t.name + "_joint", joint_names);
    joint_names.insert(name);
    p.OpenElement("joint");
    p.PushAttribute("name", name.c_str());
    p.PushAttribute("type", "fixed");
    p.OpenElement("parent");
    p.PushAttribute("link", link_names[n].c_str());
    p.CloseElement();
    p.OpenElement("child");
    p.PushAttribute("link", t.name.c_str());
    p.CloseElement();
    PushOrigin(&p, origin);
    p.CloseElement();
  }
  p.CloseElement();
  return std::string(p.CStr(), p.CStrSize() > 0 ? p.CStrSize() - 1 : 0);
}

Status WriteRobotModelUrdf(const std::string& path, const RobotModel& model) {
  const Status valid = model.Validate();
  if (!valid.ok()) return Status::Error(path + ": not written: " + valid.message());
  try {
    return WriteFileAtomically(path, RobotModelToUrdf(model));
  } catch (const std::exception& e) {  // std::bad_alloc
    return Status::Error(path + ": cannot write: " + e.what());
  }
}


}  // namespace lpoe
