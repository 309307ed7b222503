// The calibrated URDF overlay (see lpoe/urdf.h): the source document with the calibrated origins
// (and limits) written into it, every other byte of markup as it was.
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
namespace urdf_internal {

std::string Unique(std::string name, const std::set<std::string>& taken) {
  while (taken.count(name) > 0) name += '_';
  return name;
}

}  // namespace urdf_internal

using namespace urdf_internal;  // NOLINT(build/namespaces): the URDF files' shared steps

namespace {

using internal::LineError;

// Text for an XML comment: a comment may not contain "--" nor end with '-' (a name such as
// "a-->b" would otherwise close it early and leave the rest as markup).
std::string CommentText(const std::string& text) {
  std::string out;
  out.reserve(text.size());
  for (char c : text) {
    if (c == '-' && !out.empty() && out.back() == '-') out += ' ';
    out += c;
  }
  if (!out.empty() && out.back() == '-') out += ' ';
  return out;
}

void SetOrigin(XMLDocument* doc, XMLElement* parent, const SE3d& T) {
  XMLElement* o = parent->FirstChildElement("origin");
  if (o == nullptr) {
    o = doc->NewElement("origin");
    parent->InsertFirstChild(o);
  }
  o->SetAttribute("xyz", Triple(T.t * kMmToMetres).c_str());
  o->SetAttribute("rpy", Triple(RpyFromRotation(T.R)).c_str());
}

XMLElement* AppendFixedJoint(XMLDocument* doc, XMLElement* robot, const std::string& name,
                             const std::string& parent, const std::string& child, const SE3d& T) {
  XMLElement* link = doc->NewElement("link");
  link->SetAttribute("name", child.c_str());
  robot->InsertEndChild(link);
  XMLElement* joint = doc->NewElement("joint");
  joint->SetAttribute("name", name.c_str());
  joint->SetAttribute("type", "fixed");
  robot->InsertEndChild(joint);
  XMLElement* p = doc->NewElement("parent");
  p->SetAttribute("link", parent.c_str());
  joint->InsertEndChild(p);
  XMLElement* c = doc->NewElement("child");
  c->SetAttribute("link", child.c_str());
  joint->InsertEndChild(c);
  SetOrigin(doc, joint, T);
  return joint;
}

// The model's limits written into the joint's <limit> where they differ from the file's.
void SetLimits(XMLDocument* doc, const Joint& joint, const UrdfJoint& j) {
  if (j.continuous || !std::isfinite(joint.lower) || !std::isfinite(joint.upper)) return;
  if (joint.lower == j.lower && joint.upper == j.upper) return;
  const double scale = j.kind == Kind::kPrismatic ? kMmToMetres : 1.0;
  XMLElement* le = j.element->FirstChildElement("limit");
  if (le == nullptr) {
    le = doc->NewElement("limit");
    le->SetAttribute("effort", "0");
    le->SetAttribute("velocity", "0");
    j.element->InsertEndChild(le);
  }
  le->SetAttribute("lower", Number(joint.lower * scale).c_str());
  le->SetAttribute("upper", Number(joint.upper * scale).c_str());
}

// Indents by two spaces per level, as URDF files usually are, so that a diff against the source
// shows the changed lines only.
class TwoSpacePrinter : public tinyxml2::XMLPrinter {
 protected:
  void PrintSpace(int depth) override {
    for (int i = 0; i < depth; ++i) Write("  ");
  }
};

Status Mismatch(const UrdfSource& src, const std::string& what) {
  return Status::Error(src.source + ": the calibrated model does not match this URDF: " + what);
}

}  // namespace

Status urdf_internal::OverlayImpl(const UrdfSource& src, const RobotModel& cal, const UrdfOverlayOptions& options,
                                 std::string* xml, std::vector<OverlayJoint>* moved) {
  XMLDocument doc;
  UrdfTree tree;
  if (Status s = ReadTree(src.xml, src.source, &doc, &tree); !s.ok()) return s;
  UrdfChain chain;
  if (Status s = SelectChain(tree, src.options, &chain); !s.ok()) return s;
  RobotModel nominal;
  if (Status s = BuildModel(tree, chain, &nominal); !s.ok()) return s;
  if (Status s = cal.Validate(); !s.ok()) return Mismatch(src, s.message());
  if (cal.num_joints() != nominal.num_joints()) {
    return Mismatch(src, std::to_string(cal.num_joints()) + " joints instead of " +
                             std::to_string(nominal.num_joints()));
  }
  for (int i = 0; i < cal.num_joints(); ++i) {
    if (cal.joints[i].name != nominal.joints[i].name ||
        cal.joints[i].type != nominal.joints[i].type) {
      return Mismatch(src, "joint " + std::to_string(i + 1) + " is " + Quote(cal.joints[i].name) +
                               " (" + JointTypeName(cal.joints[i].type) + "), the URDF's " +
                               Quote(nominal.joints[i].name) + " (" +
                               JointTypeName(nominal.joints[i].type) + ")");
    }
  }
  std::set<std::string> link_names, joint_names;
  for (const UrdfLink& l : tree.links) link_names.insert(l.name);
  for (const UrdfJoint& j : tree.joints) joint_names.insert(j.name);

  // The calibrated base frame is the measurement frame: joint 1 keeps its URDF origin and the
  // measurement frame takes T_measurement_base = C_1 N_1^-1 (the two are not separable).
  SE3d T_measurement_base;
  if (options.in_measurement_frame) {
    T_measurement_base = cal.joints[0].origin * nominal.joints[0].origin.Inverse();
  }

  // Moving joints: origin = (fixed joints folded before it)^-1 * calibrated local frame.
  SE3d folded;
  int k = 0;
  for (int ji : chain.path) {
    UrdfJoint& j = tree.joints[ji];
    if (j.kind == Kind::kFixed) {
      folded = folded * j.origin;
      continue;
    }
    const Joint& c = cal.joints[k];
    const SE3d local = k == 0 ? T_measurement_base.Inverse() * c.origin : c.origin;
    const bool revolute = c.type == JointType::kRevolute;
    const Eigen::Vector3d w = c.twist.head<3>(), v = c.twist.tail<3>();
    if (revolute && v.norm() > 1e-9) {
      return Mismatch(src, JointContext(c.name) +
                               ": the axis does not pass through the joint "
                               "frame's origin (twist v = " +
                               Triple(v) +
                               "), which a URDF joint "
                               "cannot express");
    }
    const Eigen::Vector3d axis = (revolute ? w : v).normalized();
    j.origin = folded.Inverse() * local;
    SetOrigin(&doc, j.element, j.origin);
    if ((axis - j.axis).norm() > 1e-12) {
      XMLElement* ae = j.element->FirstChildElement("axis");
      if (ae == nullptr) {
        ae = doc.NewElement("axis");
        j.element->InsertEndChild(ae);
      }
      ae->SetAttribute("xyz", Triple(axis).c_str());
      j.axis = axis;
    }
    SetLimits(&doc, c, j);
    if (moved != nullptr) moved->push_back({j.name, j.origin, axis});
    folded = SE3d();
    if (++k == cal.num_joints()) break;
  }

  // Tools that are links fixed after the flange take the calibrated pose in their own fixed joint
  // (ancestors first); the others become new links on the tip.
  std::vector<std::pair<int, int>> link_tools;  // depth below the flange, tool index
  std::vector<int> new_tools;
  for (int t = 0; t < cal.num_tools(); ++t) {
    const auto it = tree.link_index.find(cal.tools[t].name);
    bool fixed = it != tree.link_index.end() && it->second != chain.flange &&
                 IsAncestorOrSelf(tree, chain.flange, it->second);
    const std::vector<int> path =
        fixed ? PathBetween(tree, chain.flange, it->second) : std::vector<int>();
    for (int ji : path) fixed = fixed && tree.joints[ji].kind == Kind::kFixed;
    if (fixed) {
      link_tools.push_back({static_cast<int>(path.size()), t});
    } else {
      new_tools.push_back(t);
    }
  }
  std::sort(link_tools.begin(), link_tools.end());
  for (const auto& [depth, t] : link_tools) {
    UrdfJoint& j = tree.joints[tree.links[tree.link_index.at(cal.tools[t].name)].parent_joint];
    j.origin = PoseInFlange(tree, chain, j.parent).Inverse() * cal.tools[t].origin;
    SetOrigin(&doc, j.element, j.origin);
  }
  const SE3d tip_in_flange = PoseInFlange(tree, chain, chain.tip);
  const std::string tip = tree.links[chain.tip].name;
  tree.robot->InsertEndChild(doc.NewComment(
      " Added by lpoe-calib: the measurement (tracker) frame and the measured tools (SMRs) "));
  for (int t : new_tools) {
    const std::string link =
        Unique(link_names.count(cal.tools[t].name) ? cal.tools[t].name + "_smr" : cal.tools[t].name,
               link_names);
    link_names.insert(link);
    const std::string joint = Unique(link + "_joint", joint_names);
    joint_names.insert(joint);
    AppendFixedJoint(&doc, tree.robot, joint, tip, link,
                     tip_in_flange.Inverse() * cal.tools[t].origin);
  }
  const std::string frame = Unique(options.measurement_link, link_names);
  AppendFixedJoint(&doc, tree.robot, Unique(frame + "_joint", joint_names),
                   tree.links[chain.base].name, frame, T_measurement_base.Inverse());

  std::string changed;
  for (int ji : chain.moving) changed += (changed.empty() ? "" : ", ") + tree.joints[ji].name;
  const std::string note = " Calibrated by lpoe-calib " + std::string(kLpoeVersion) +
                           ": the origins (and axes) of the joints " + changed +
                           " and the tool frames changed; everything else as in the source. ";
  tree.robot->InsertFirstChild(doc.NewComment(CommentText(note).c_str()));
  // Text or elements beside <robot> at the document level (which tinyxml2 reads but would not read
  // back once printed) are no part of a URDF: dropped.
  for (tinyxml2::XMLNode* n = doc.FirstChild(); n != nullptr;) {
    tinyxml2::XMLNode* next = n->NextSibling();
    if (n != tree.robot && (n->ToElement() != nullptr || n->ToText() != nullptr)) doc.DeleteNode(n);
    n = next;
  }
  TwoSpacePrinter printer;
  doc.Print(&printer);
  *xml = std::string(printer.CStr(), printer.CStrSize() > 0 ? printer.CStrSize() - 1 : 0);
  return Status::Ok();
}

Status CalibratedUrdfOverlay(const UrdfSource& source, const RobotModel& calibrated,
                             const UrdfOverlayOptions& options, std::string* xml) {
  try {
    return OverlayImpl(source, calibrated, options, xml, nullptr);
  } catch (const std::exception& e) {  // std::bad_alloc
    return Status::Error(source.source + ": cannot write the overlay: " + e.what());
  }
}

Status WriteCalibratedUrdf(const std::string& path, const UrdfSource& source,
                           const RobotModel& calibrated, const UrdfOverlayOptions& options) {
  return WriteMade(path, [&](std::string* xml) {
    return CalibratedUrdfOverlay(source, calibrated, options, xml);
  });
}

}  // namespace lpoe
