// URDF import and export of serial-chain robot models (see lpoe/urdf.h). Errors read
//   <file>:<line>: <what is wrong>; expected <what>
// with the line of the XML element at fault. Nothing throws out of the API.
#include "parse_util.h"
#include "lpoe/urdf.h"

#include <tinyxml2.h>

#include <charconv>
#include <cmath>
#include <cstdio>
#include <exception>
#include <map>
#include <set>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

#include "lpoe/io.h"
#include "lpoe/se3.h"

namespace lpoe {
namespace {

using tinyxml2::XMLDocument;
using tinyxml2::XMLElement;

constexpr double kMetresToMm = 1000.0;
constexpr double kMmToMetres = 1e-3;
// An axis shorter than this cannot be normalized meaningfully.
constexpr double kMinAxisNorm = 1e-9;
// Placeholder prismatic limit written on export (metres); the model carries no limits.
constexpr double kPlaceholderPrismaticLimit = 1.0;

using internal::LineError;

std::string Quote(std::string_view s) { return internal::Quote(s, 60); }

bool IsSpace(char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r'; }

// Parses exactly `count` whitespace-separated numbers from `text` into `out`. Returns an empty
// string on success, else what is wrong (the caller adds where and what was expected).
std::string ParseNumbers(std::string_view text, int count, double* out) {
  int n = 0;
  size_t i = 0;
  while (true) {
    while (i < text.size() && IsSpace(text[i])) ++i;
    if (i == text.size()) break;
    size_t e = i;
    while (e < text.size() && !IsSpace(text[e])) ++e;
    std::string_view token = text.substr(i, e - i);
    i = e;
    if (n == count) {
      return "has more than " + std::to_string(count) + " numbers";
    }
    std::string_view digits = token;
    if (digits.size() > 1 && digits[0] == '+' && digits[1] != '-') digits.remove_prefix(1);
    double v = 0;
    const auto [ptr, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), v);
    if (ec == std::errc::result_out_of_range) {
      return "has the out-of-range number " + Quote(token);
    }
    if (ec != std::errc() || ptr != digits.data() + digits.size()) {
      return "has the non-numeric value " + Quote(token);
    }
    if (!std::isfinite(v)) return "has the non-finite number " + Quote(token);
    out[n++] = v;
  }
  if (n != count) {
    return "has " + std::to_string(n) + " number" + (n == 1 ? "" : "s");
  }
  return "";
}

// Reads attribute `attr` of `e` as `count` numbers. `present` (may be null) tells whether the
// attribute exists; a missing attribute is an error only when `required`.
Status ReadNumbers(const XMLElement* e, const char* attr, int count, bool required,
                   const std::string& source, const std::string& context, const char* expected,
                   double* out, bool* present = nullptr) {
  const char* value = e->Attribute(attr);
  if (present != nullptr) *present = value != nullptr;
  if (value == nullptr) {
    if (!required) return Status::Ok();
    return LineError(source, e->GetLineNum(),
                     context + ": <" + e->Name() + "> has no attribute " + attr, expected);
  }
  const std::string what = ParseNumbers(value, count, out);
  if (!what.empty()) {
    return LineError(
        source, e->GetLineNum(),
        context + ": <" + e->Name() + "> attribute " + attr + "=" + Quote(value) + " " + what,
        expected);
  }
  return Status::Ok();
}

// The <origin> child of `parent` (optional; identity when absent), lengths converted to mm.
Status ReadOrigin(const XMLElement* parent, const std::string& source, const std::string& context,
                  SE3d* origin) {
  *origin = SE3d();
  const XMLElement* o = parent->FirstChildElement("origin");
  if (o == nullptr) return Status::Ok();
  double xyz[3] = {0, 0, 0}, rpy[3] = {0, 0, 0};
  Status s =
      ReadNumbers(o, "xyz", 3, false, source, context, "three numbers 'x y z' in metres", xyz);
  if (!s.ok()) return s;
  s = ReadNumbers(o, "rpy", 3, false, source, context, "three numbers 'roll pitch yaw' in radians",
                  rpy);
  if (!s.ok()) return s;
  const Eigen::Vector3d t = Eigen::Vector3d(xyz[0], xyz[1], xyz[2]) * kMetresToMm;
  if (!t.allFinite()) {
    return LineError(source, o->GetLineNum(), context + ": <origin> xyz overflows in millimetres",
                     "a translation below 1e300 m");
  }
  origin->R = RotationFromRpy(rpy[0], rpy[1], rpy[2]);
  origin->t = t;
  return Status::Ok();
}

enum class Kind { kFixed, kRevolute, kPrismatic };

struct UrdfLink {
  std::string name;
  int line = 0;
  int parent_joint = -1;          // index into the joints, -1 for a root
  std::vector<int> child_joints;  // in document order
};

struct UrdfJoint {
  std::string name;
  Kind kind = Kind::kFixed;
  int line = 0;
  int parent = -1, child = -1;                      // link indices
  SE3d origin;                                      // mm
  Eigen::Vector3d axis = Eigen::Vector3d::UnitX();  // unit
  int mimic_line = 0;                               // line of a <mimic> element, 0 if none
};

std::string JointContext(const std::string& name) { return "joint " + Quote(name); }

// Reads the <link link="..."> attribute of the <parent>/<child> element `tag` of joint `j`.
Status ReadLinkRef(const XMLElement* je, const char* tag, const std::string& source,
                   const std::string& context, const std::map<std::string, int>& link_index,
                   int* link) {
  const XMLElement* e = je->FirstChildElement(tag);
  if (e == nullptr) {
    return LineError(source, je->GetLineNum(), context + ": no <" + tag + "> element",
                     std::string("<") + tag + " link=\"...\"/>");
  }
  const char* name = e->Attribute("link");
  if (name == nullptr) {
    return LineError(source, e->GetLineNum(), context + ": <" + tag + "> has no attribute link",
                     std::string("<") + tag + " link=\"...\"/>");
  }
  const auto it = link_index.find(name);
  if (it == link_index.end()) {
    return LineError(source, e->GetLineNum(),
                     context + ": <" + tag + "> names the unknown link " + Quote(name),
                     "the name of a <link> of the robot");
  }
  *link = it->second;
  return Status::Ok();
}

Status ParseJoint(const XMLElement* je, const std::string& source,
                  const std::map<std::string, int>& link_index, UrdfJoint* j) {
  j->line = je->GetLineNum();
  const char* name = je->Attribute("name");
  if (name == nullptr || name[0] == '\0') {
    return LineError(source, j->line, "<joint> without a name",
                     "<joint name=\"...\" type=\"...\">");
  }
  j->name = name;
  const std::string context = JointContext(j->name);
  const char* type = je->Attribute("type");
  if (type == nullptr) {
    return LineError(source, j->line, context + " has no attribute type",
                     "type=\"revolute\", \"continuous\", \"prismatic\" or \"fixed\"");
  }
  const std::string_view t = type;
  if (t == "revolute" || t == "continuous") {
    j->kind = Kind::kRevolute;
  } else if (t == "prismatic") {
    j->kind = Kind::kPrismatic;
  } else if (t == "fixed") {
    j->kind = Kind::kFixed;
  } else if (t == "floating" || t == "planar") {
    return LineError(
        source, j->line,
        context + " has type " + Quote(t) + ", which has more than one degree of freedom",
        "a revolute, continuous, prismatic or fixed joint");
  } else {
    return LineError(source, j->line, context + " has the unknown type " + Quote(t),
                     "revolute, continuous, prismatic or fixed");
  }
  Status s = ReadLinkRef(je, "parent", source, context, link_index, &j->parent);
  if (!s.ok()) return s;
  s = ReadLinkRef(je, "child", source, context, link_index, &j->child);
  if (!s.ok()) return s;
  if (j->parent == j->child) {
    return LineError(source, j->line, context + " has the same parent and child link",
                     "a joint between two different links");
  }
  s = ReadOrigin(je, source, context, &j->origin);
  if (!s.ok()) return s;
  if (j->kind != Kind::kFixed) {
    const XMLElement* ae = je->FirstChildElement("axis");
    if (ae != nullptr) {  // absent: (1, 0, 0), the URDF default
      double a[3];
      s = ReadNumbers(ae, "xyz", 3, true, source, context, "three numbers 'x y z' (the joint axis)",
                      a);
      if (!s.ok()) return s;
      const Eigen::Vector3d axis(a[0], a[1], a[2]);
      const double norm = axis.norm();
      if (!(norm >= kMinAxisNorm) || !std::isfinite(norm)) {
        return LineError(
            source, ae->GetLineNum(),
            context + ": <axis> xyz=" + Quote(ae->Attribute("xyz")) + " is a zero vector",
            "a non-zero axis direction");
      }
      j->axis = axis / norm;
    }
    if (const XMLElement* me = je->FirstChildElement("mimic")) j->mimic_line = me->GetLineNum();
  }
  return Status::Ok();
}

std::string JoinQuoted(const std::vector<std::string>& names) {
  std::string out;
  for (size_t i = 0; i < names.size(); ++i) {
    if (i > 0) out += ", ";
    out += Quote(names[i]);
  }
  return out;
}

Status ParseImpl(const std::string& xml, const std::string& source, RobotModel* model,
                 const UrdfOptions& options) {
  XMLDocument doc;
  if (doc.Parse(xml.data(), xml.size()) != tinyxml2::XML_SUCCESS) {
    // ErrorStr() reads "Error=<name> ErrorID=<n> (0x<n>) Line number=<n>[: <detail>]"; the line is
    // ours already, keep the name and the detail.
    std::string what = std::string("malformed XML (") + doc.ErrorName();
    const std::string_view full = doc.ErrorStr() != nullptr ? doc.ErrorStr() : "";
    const size_t at = full.find("Line number=");
    const size_t colon = at == std::string_view::npos ? at : full.find(": ", at);
    if (colon != std::string_view::npos) {
      what += ": ";
      what += full.substr(colon + 2);
    }
    what += ')';
    return LineError(source, doc.ErrorLineNum(), what, "a well-formed URDF document");
  }
  const XMLElement* robot = doc.RootElement();
  if (robot == nullptr) {
    return LineError(source, 1, "no XML element", "a <robot> element");
  }
  if (std::string_view(robot->Name()) != "robot") {
    return LineError(source, robot->GetLineNum(),
                     "the root element is <" + std::string(robot->Name()) + ">",
                     "<robot name=\"...\"> (a URDF file; xacro must be expanded first)");
  }
  const int robot_line = robot->GetLineNum();
  if (const XMLElement* second = robot->NextSiblingElement(); second != nullptr) {
    return LineError(source, second->GetLineNum(),
                     "a second root element <" + std::string(second->Name()) + ">",
                     "one <robot> element per file");
  }

  // Links first (joints may precede the links they name).
  std::vector<UrdfLink> links;
  std::map<std::string, int> link_index;
  for (const XMLElement* e = robot->FirstChildElement("link"); e != nullptr;
       e = e->NextSiblingElement("link")) {
    const char* name = e->Attribute("name");
    if (name == nullptr || name[0] == '\0') {
      return LineError(source, e->GetLineNum(), "<link> without a name", "<link name=\"...\">");
    }
    if (!link_index.emplace(name, static_cast<int>(links.size())).second) {
      return LineError(source, e->GetLineNum(), "duplicate link name " + Quote(name),
                       "unique link names");
    }
    UrdfLink l;
    l.name = name;
    l.line = e->GetLineNum();
    links.push_back(std::move(l));
  }
  if (links.empty()) {
    return LineError(source, robot_line, "the robot has no <link>", "a chain of links and joints");
  }

  std::vector<UrdfJoint> joints;
  std::set<std::string> joint_names;
  for (const XMLElement* e = robot->FirstChildElement("joint"); e != nullptr;
       e = e->NextSiblingElement("joint")) {
    UrdfJoint j;
    Status s = ParseJoint(e, source, link_index, &j);
    if (!s.ok()) return s;
    if (!joint_names.insert(j.name).second) {
      return LineError(source, j.line, "duplicate joint name " + Quote(j.name),
                       "unique joint names");
    }
    UrdfLink& child = links[j.child];
    if (child.parent_joint >= 0) {
      return LineError(source, j.line,
                       JointContext(j.name) + ": link " + Quote(child.name) +
                           " is already the child of joint " +
                           Quote(joints[child.parent_joint].name),
                       "each link to have at most one parent joint (a tree)");
    }
    const int index = static_cast<int>(joints.size());
    child.parent_joint = index;
    links[j.parent].child_joints.push_back(index);
    joints.push_back(std::move(j));
  }

  // The root: the one link that is never a child.
  std::vector<int> roots;
  for (int l = 0; l < static_cast<int>(links.size()); ++l) {
    if (links[l].parent_joint < 0) roots.push_back(l);
  }
  if (roots.empty()) {
    return LineError(source, robot_line,
                     "every link is the child of a joint (the joints form a cycle)",
                     "one root link that is no joint's child");
  }
  if (roots.size() > 1) {
    std::vector<std::string> names;
    for (int r : roots) names.push_back(links[r].name);
    return LineError(source, links[roots[1]].line,
                     "several root links (no joint's child): " + JoinQuoted(names),
                     "one root link, all links connected by joints");
  }
  const int root = roots[0];

  // leads_to_motion[l]: a moving joint descends from link l. Each link has at most one parent, so
  // walking up from every moving joint marks exactly the ancestors; marks stop the walk (and
  // cycles).
  std::vector<char> leads_to_motion(links.size(), 0);
  int num_moving = 0;
  for (const UrdfJoint& j : joints) {
    if (j.kind == Kind::kFixed) continue;
    ++num_moving;
    int l = j.parent;
    while (l >= 0 && !leads_to_motion[l]) {
      leads_to_motion[l] = 1;
      const int pj = links[l].parent_joint;
      l = pj >= 0 ? joints[pj].parent : -1;
    }
  }
  if (num_moving == 0) {
    return LineError(source, robot_line, "the robot has no revolute, continuous or prismatic joint",
                     "a chain with at least one moving joint");
  }

  // Walk the chain from the root, folding fixed joints into the next moving joint's origin.
  RobotModel out;
  const char* robot_name = robot->Attribute("name");
  out.name = robot_name != nullptr && robot_name[0] != '\0' ? robot_name : "robot";
  SE3d folded;
  int link = root;
  int last_moving = -1;
  for (size_t steps = 0; steps <= joints.size(); ++steps) {
    std::vector<int> next;
    for (int ji : links[link].child_joints) {
      const UrdfJoint& j = joints[ji];
      if (j.kind != Kind::kFixed || leads_to_motion[j.child]) next.push_back(ji);
    }
    if (next.empty()) break;
    if (next.size() > 1) {
      return LineError(
          source, links[link].line,
          "link " + Quote(links[link].name) + " branches: moving joints follow both joint " +
              Quote(joints[next[0]].name) + " and joint " + Quote(joints[next[1]].name),
          "a serial chain (one path from the root through all moving joints)");
    }
    const UrdfJoint& j = joints[next[0]];
    folded = folded * j.origin;
    if (j.kind != Kind::kFixed) {
      if (j.mimic_line > 0) {
        return LineError(source, j.mimic_line, JointContext(j.name) + " mimics another joint",
                         "independent joints in the serial chain (no <mimic>)");
      }
      Joint joint;
      joint.name = j.name;
      joint.origin = folded;
      joint.twist.setZero();
      if (j.kind == Kind::kRevolute) {
        joint.type = JointType::kRevolute;
        joint.twist.head<3>() = j.axis;
      } else {
        joint.type = JointType::kPrismatic;
        joint.twist.tail<3>() = j.axis;
      }
      out.joints.push_back(std::move(joint));
      folded = SE3d();
      last_moving = next[0];
    }
    link = j.child;
  }
  if (out.num_joints() != num_moving) {
    for (const UrdfJoint& j : joints) {
      if (j.kind == Kind::kFixed) continue;
      bool in_chain = false;
      for (const Joint& c : out.joints) in_chain = in_chain || c.name == j.name;
      if (!in_chain) {
        return LineError(source, j.line,
                         JointContext(j.name) + " is not on the chain from the root link " +
                             Quote(links[root].name),
                         "all moving joints on one serial chain");
      }
    }
  }

  // Tools: the fixed subtree after the last moving joint, preorder in document order.
  const int tip = joints[last_moving].child;
  std::vector<int> subtree;  // link indices
  std::map<int, SE3d> pose;  // relative to the tip link
  std::vector<int> stack = {tip};
  pose[tip] = SE3d();
  while (!stack.empty()) {
    const int l = stack.back();
    stack.pop_back();
    subtree.push_back(l);
    const std::vector<int>& children = links[l].child_joints;
    for (auto it = children.rbegin(); it != children.rend(); ++it) {
      const UrdfJoint& j = joints[*it];
      pose[j.child] = pose[l] * j.origin;
      stack.push_back(j.child);
    }
  }
  if (options.tool_links.empty()) {
    for (int l : subtree) {
      if (links[l].child_joints.empty()) out.tools.push_back(Tool{links[l].name, pose[l]});
    }
  } else {
    for (const std::string& name : options.tool_links) {
      const auto it = link_index.find(name);
      if (it == link_index.end()) {
        return LineError(
            source, robot_line, "the tool link " + Quote(name) + " does not exist",
            "the name of a <link> after the last moving joint " + Quote(joints[last_moving].name));
      }
      const auto p = pose.find(it->second);
      if (p == pose.end()) {
        return LineError(source, links[it->second].line,
                         "the tool link " + Quote(name) + " is not after the last moving joint " +
                             Quote(joints[last_moving].name),
                         "a link fixed to the last moving link " + Quote(links[tip].name));
      }
      out.tools.push_back(Tool{name, p->second});
    }
  }

  const Status valid = out.Validate();
  if (!valid.ok()) {
    return LineError(source, robot_line, "the imported model is invalid: " + valid.message(),
                     "a valid serial-chain model");
  }
  *model = std::move(out);
  return Status::Ok();
}

// ---------------------------------------------------------------------------------------------------
// Export.

std::string Number(double v) {
  if (v == 0) v = 0;  // no "-0"
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof(buf), v, std::chars_format::general, 17);
  return std::string(buf, r.ptr);
}

std::string Triple(const Eigen::Vector3d& v) {
  return Number(v(0)) + " " + Number(v(1)) + " " + Number(v(2));
}

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

std::string Unique(std::string name, const std::set<std::string>& taken) {
  while (taken.count(name) > 0) name += '_';
  return name;
}

}  // namespace

Status ParseRobotModelUrdf(const std::string& xml, const std::string& source, RobotModel* model,
                           const UrdfOptions& options) {
  try {
    return ParseImpl(xml, source, model, options);
  } catch (const std::exception& e) {  // std::bad_alloc
    return Status::Error(source + ": cannot parse: " + e.what());
  }
}

Status ReadRobotModelUrdf(const std::string& path, RobotModel* model, const UrdfOptions& options) {
  std::string text;
  const Status s = ReadFile(path, kMaxModelFileBytes, &text);
  if (!s.ok()) return s;
  return ParseRobotModelUrdf(text, path, model, options);
}

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
    p.PushAttribute("type", revolute ? "continuous" : "prismatic");
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
    if (!revolute) {
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
