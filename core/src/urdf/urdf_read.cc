// URDF import of serial-chain robot models (see lpoe/io/urdf.h): the document, its link/joint tree,
// the chain from the base link to the tip and its tools, the LPoE model. Errors read
//   <file>:<line>: <what is wrong>; expected <what>
// with the line of the XML element at fault. Nothing throws out of the API.
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
#include "lpoe/model/model_limits.h"
#include "lpoe/kinematics/se3.h"
#include "lpoe/io/urdf.h"
#include "lpoe/version.h"
#include "io/parse_util.h"
#include "urdf/urdf_tree.h"

namespace lpoe {
namespace urdf_internal {

std::string Quote(std::string_view s) { return internal::Quote(s, 60); }

// The shortest text that reads back as the same double (-0 written as 0).
std::string Number(double v) { return internal::FormatNumber(v); }

std::string Triple(const Eigen::Vector3d& v) {
  return Number(v(0)) + " " + Number(v(1)) + " " + Number(v(2));
}

std::string JointContext(const std::string& name) { return "joint " + Quote(name); }



// True when link `a` is `b` or one of its ancestors.
bool IsAncestorOrSelf(const UrdfTree& tree, int a, int b) {
  for (int l = b; l >= 0;) {
    if (l == a) return true;
    const int pj = tree.links[l].parent_joint;
    l = pj >= 0 ? tree.joints[pj].parent : -1;
  }
  return false;
}

// The joints from link `from` down to link `to` (which must descend from it), in order.
std::vector<int> PathBetween(const UrdfTree& tree, int from, int to) {
  std::vector<int> path;
  for (int l = to; l != from;) {
    const int pj = tree.links[l].parent_joint;
    path.push_back(pj);
    l = tree.joints[pj].parent;
  }
  return std::vector<int>(path.rbegin(), path.rend());
}

// The pose of link `l` in the flange frame, through fixed joints.
SE3d PoseInFlange(const UrdfTree& tree, const UrdfChain& chain, int l) {
  SE3d pose;
  for (int ji : PathBetween(tree, chain.flange, l)) pose = pose * tree.joints[ji].origin;
  return pose;
}

}  // namespace urdf_internal

using namespace urdf_internal;  // NOLINT(build/namespaces): the URDF files' shared steps

namespace {

using internal::LineError;

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
    double v = 0;
    switch (internal::ParseNumber(token, &v)) {
      case internal::NumberParse::kOk:
        // Metres and radians: every length of a robot model within kMaxModelLengthMm (100 m),
        // every angle and limit within kMaxModelAngleRad.
        if (!(std::abs(v) <= kMaxModelLengthMm / 1000)) {
          return "has the number " + Quote(token) +
                 ", out of range (lengths within 100 m, angles within 100 rad)";
        }
        break;
      case internal::NumberParse::kNotANumber:
        return "has the non-numeric value " + Quote(token);
      case internal::NumberParse::kNonFinite:
        return "has the non-finite number " + Quote(token);
      case internal::NumberParse::kOutOfRange:
        return "has the out-of-range number " + Quote(token);
    }
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

// The <limit lower upper> of a revolute or prismatic joint in model units. URDF defaults a missing
// attribute to 0; a continuous joint and a joint without <limit> stay unlimited.
Status ReadLimits(const XMLElement* je, const std::string& source, const std::string& context,
                  UrdfJoint* j) {
  const XMLElement* le = je->FirstChildElement("limit");
  if (le == nullptr || j->continuous) return Status::Ok();
  const double scale = j->kind == Kind::kPrismatic ? kMetresToMm : 1.0;
  double lower = 0, upper = 0;
  Status s = ReadNumbers(le, "lower", 1, false, source, context, "a number (rad or m)", &lower);
  if (!s.ok()) return s;
  s = ReadNumbers(le, "upper", 1, false, source, context, "a number (rad or m)", &upper);
  if (!s.ok()) return s;
  if (!(lower <= upper)) {
    return LineError(
        source, le->GetLineNum(),
        context + ": <limit> lower " + Number(lower) + " is above upper " + Number(upper),
        "lower <= upper");
  }
  j->lower = lower * scale;
  j->upper = upper * scale;
  return Status::Ok();
}

Status ParseJoint(XMLElement* je, const std::string& source,
                  const std::map<std::string, int>& link_index, UrdfJoint* j) {
  j->line = je->GetLineNum();
  j->element = je;
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
    j->continuous = t == "continuous";
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
    s = ReadLimits(je, source, context, j);
    if (!s.ok()) return s;
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

// Step 1: the XML document, and its <robot> root element.
Status ParseXml(const std::string& xml, const std::string& source, XMLDocument* doc,
                XMLElement** robot) {
  if (doc->Parse(xml.data(), xml.size()) != tinyxml2::XML_SUCCESS) {
    // ErrorStr() reads "Error=<name> ErrorID=<n> (0x<n>) Line number=<n>[: <detail>]"; the line is
    // ours already, keep the name and the detail.
    std::string what = std::string("malformed XML (") + doc->ErrorName();
    const std::string_view full = doc->ErrorStr() != nullptr ? doc->ErrorStr() : "";
    const size_t at = full.find("Line number=");
    const size_t colon = at == std::string_view::npos ? at : full.find(": ", at);
    if (colon != std::string_view::npos) {
      what += ": ";
      what += full.substr(colon + 2);
    }
    what += ')';
    return LineError(source, doc->ErrorLineNum(), what, "a well-formed URDF document");
  }
  *robot = doc->RootElement();
  if (*robot == nullptr) return LineError(source, 1, "no XML element", "a <robot> element");
  if (std::string_view((*robot)->Name()) != "robot") {
    return LineError(source, (*robot)->GetLineNum(),
                     "the root element is <" + std::string((*robot)->Name()) + ">",
                     "<robot name=\"...\"> (a URDF file; xacro must be expanded first)");
  }
  if (const XMLElement* second = (*robot)->NextSiblingElement(); second != nullptr) {
    return LineError(source, second->GetLineNum(),
                     "a second root element <" + std::string(second->Name()) + ">",
                     "one <robot> element per file");
  }
  return Status::Ok();
}

// Step 2: the links (before the joints, which may precede the links they name).
Status ReadLinks(UrdfTree* tree) {
  for (const XMLElement* e = tree->robot->FirstChildElement("link"); e != nullptr;
       e = e->NextSiblingElement("link")) {
    const char* name = e->Attribute("name");
    if (name == nullptr || name[0] == '\0') {
      return LineError(tree->source, e->GetLineNum(), "<link> without a name",
                       "<link name=\"...\">");
    }
    if (!tree->link_index.emplace(name, static_cast<int>(tree->links.size())).second) {
      return LineError(tree->source, e->GetLineNum(), "duplicate link name " + Quote(name),
                       "unique link names");
    }
    UrdfLink l;
    l.name = name;
    l.line = e->GetLineNum();
    tree->links.push_back(std::move(l));
  }
  if (tree->links.empty()) {
    return LineError(tree->source, tree->robot_line, "the robot has no <link>",
                     "a chain of links and joints");
  }
  return Status::Ok();
}

// Step 3: the joints, each link with at most one parent joint.
Status ReadJoints(UrdfTree* tree) {
  std::set<std::string> joint_names;
  for (XMLElement* e = tree->robot->FirstChildElement("joint"); e != nullptr;
       e = e->NextSiblingElement("joint")) {
    UrdfJoint j;
    if (Status s = ParseJoint(e, tree->source, tree->link_index, &j); !s.ok()) return s;
    if (!joint_names.insert(j.name).second) {
      return LineError(tree->source, j.line, "duplicate joint name " + Quote(j.name),
                       "unique joint names");
    }
    UrdfLink& child = tree->links[j.child];
    if (child.parent_joint >= 0) {
      return LineError(tree->source, j.line,
                       JointContext(j.name) + ": link " + Quote(child.name) +
                           " is already the child of joint " +
                           Quote(tree->joints[child.parent_joint].name),
                       "each link to have at most one parent joint (a tree)");
    }
    const int index = static_cast<int>(tree->joints.size());
    child.parent_joint = index;
    tree->links[j.parent].child_joints.push_back(index);
    tree->joints.push_back(std::move(j));
  }
  return Status::Ok();
}

// Step 4: the root, the one link that is no joint's child.
Status FindRoot(UrdfTree* tree) {
  std::vector<std::string> roots;
  int first = -1;
  for (int l = 0; l < static_cast<int>(tree->links.size()); ++l) {
    if (tree->links[l].parent_joint >= 0) continue;
    if (first < 0) first = l;
    roots.push_back(tree->links[l].name);
  }
  if (roots.empty()) {
    return LineError(tree->source, tree->robot_line,
                     "every link is the child of a joint (the joints form a cycle)",
                     "one root link that is no joint's child");
  }
  if (roots.size() > 1) {
    return LineError(tree->source, tree->links[tree->link_index.at(roots[1])].line,
                     "several root links (no joint's child): " + JoinQuoted(roots),
                     "one root link, all links connected by joints");
  }
  tree->root = first;
  return Status::Ok();
}

Status LinkByName(const UrdfTree& tree, const std::string& name, const char* role, int* link) {
  const auto it = tree.link_index.find(name);
  if (it == tree.link_index.end()) {
    return LineError(tree.source, tree.robot_line,
                     "the " + std::string(role) + " " + Quote(name) + " does not exist",
                     "the name of a <link> of the robot");
  }
  *link = it->second;
  return Status::Ok();
}

// Without a tip link: the leaves below the base that follow a moving joint are the candidate tips.
// Their last moving joints must lie on one path (side branches of fixed joints on an intermediate
// link, a camera on the forearm, do not count); several candidates after the same last moving
// joint (a UR's ee_link and tool0) make its child link, the flange, the tip.
Status FindTip(const UrdfTree& tree, int base, int* tip) {
  struct Leaf {
    int link, last_moving;
  };
  std::vector<Leaf> leaves;
  std::vector<std::pair<int, int>> stack = {{base, -1}};  // link, last moving joint above it
  while (!stack.empty()) {
    const auto [l, last] = stack.back();
    stack.pop_back();
    const std::vector<int>& children = tree.links[l].child_joints;
    if (children.empty() && last >= 0) leaves.push_back({l, last});
    for (auto it = children.rbegin(); it != children.rend(); ++it) {
      const UrdfJoint& j = tree.joints[*it];
      stack.push_back({j.child, j.kind == Kind::kFixed ? last : *it});
    }
  }
  if (leaves.empty()) {
    return LineError(tree.source, tree.robot_line,
                     "no revolute, continuous or prismatic joint below the base link " +
                         Quote(tree.links[base].name),
                     "a chain with at least one moving joint");
  }
  // The last moving joints that no other candidate's last moving joint descends from.
  std::vector<int> ends;
  for (const Leaf& a : leaves) {
    bool dominated = false;
    for (const Leaf& b : leaves) {
      dominated = dominated || (b.last_moving != a.last_moving &&
                                IsAncestorOrSelf(tree, tree.joints[a.last_moving].child,
                                                 tree.joints[b.last_moving].child));
    }
    if (!dominated && std::find(ends.begin(), ends.end(), a.last_moving) == ends.end()) {
      ends.push_back(a.last_moving);
    }
  }
  std::vector<std::string> candidates;
  std::vector<int> candidate_links;
  for (const Leaf& a : leaves) {
    if (std::find(ends.begin(), ends.end(), a.last_moving) == ends.end()) continue;
    candidates.push_back(tree.links[a.link].name);
    candidate_links.push_back(a.link);
  }
  if (ends.size() > 1) {
    // The deepest link above every candidate, where the chain branches.
    int fork = tree.joints[ends[0]].parent;
    while (true) {
      bool above_all = true;
      for (int e : ends)
        above_all = above_all && IsAncestorOrSelf(tree, fork, tree.joints[e].child);
      if (above_all) break;
      fork = tree.joints[tree.links[fork].parent_joint].parent;
    }
    return LineError(tree.source, tree.links[fork].line,
                     "link " + Quote(tree.links[fork].name) +
                         " branches: moving joints lead to several candidate tips " +
                         JoinQuoted(candidates),
                     "a tip link (UrdfOptions::tip_link, --tip_link) naming one of them");
  }
  *tip = candidate_links.size() == 1 ? candidate_links[0] : tree.joints[ends[0]].child;
  return Status::Ok();
}

}  // namespace

Status urdf_internal::ReadTree(const std::string& xml, const std::string& source, XMLDocument* doc,
                UrdfTree* tree) {
  tree->source = source;
  if (Status s = ParseXml(xml, source, doc, &tree->robot); !s.ok()) return s;
  tree->robot_line = tree->robot->GetLineNum();
  if (Status s = ReadLinks(tree); !s.ok()) return s;
  if (Status s = ReadJoints(tree); !s.ok()) return s;
  return FindRoot(tree);
}


// Step 5: the chain from the base link to the tip link, and its tools.
Status urdf_internal::SelectChain(const UrdfTree& tree, const UrdfOptions& options, UrdfChain* chain) {
  chain->base = tree.root;
  if (!options.base_link.empty()) {
    if (Status s = LinkByName(tree, options.base_link, "base link", &chain->base); !s.ok()) {
      return s;
    }
  }
  // A base link fixed beside the arm (ur_description's `base`, base_link turned by pi): the chain
  // climbs from it through fixed joints to the link above the arm.
  int top = chain->base;
  for (int pj = tree.links[top].parent_joint;
       pj >= 0 && tree.joints[pj].kind == Kind::kFixed; pj = tree.links[top].parent_joint) {
    top = tree.joints[pj].parent;
  }
  std::string tip_name = options.tip_link;
  if (tip_name.empty()) {
    // An ambiguous tree with named tools: the first tool link ends the chain.
    const Status s = FindTip(tree, top, &chain->tip);
    if (!s.ok() && options.tool_links.empty()) return s;
    if (!s.ok()) tip_name = options.tool_links[0];
  }
  if (!tip_name.empty()) {
    if (Status s = LinkByName(tree, tip_name, "tip link", &chain->tip); !s.ok()) return s;
    if (!IsAncestorOrSelf(tree, top, chain->tip)) {
      return LineError(tree.source, tree.links[chain->tip].line,
                       "the tip link " + Quote(tip_name) + " is not below the base link " +
                           Quote(tree.links[chain->base].name),
                       "a tip link reached from the base link through joints (or from a link "
                       "the base link is fixed to)");
    }
  }
  int from = chain->base;
  chain->up.clear();
  chain->base_up = SE3d();
  while (!IsAncestorOrSelf(tree, from, chain->tip)) {
    const int pj = tree.links[from].parent_joint;  // fixed: `top` is above the tip
    chain->up.push_back(pj);
    chain->base_up = chain->base_up * tree.joints[pj].origin.Inverse();
    from = tree.joints[pj].parent;
  }
  // Beside the arm's base only: a link fixed to a moving link (a camera on the forearm) is no base.
  bool fixed_to_root = true;
  for (int ji : chain->up.empty() ? std::vector<int>() : PathBetween(tree, tree.root, from)) {
    fixed_to_root = fixed_to_root && tree.joints[ji].kind == Kind::kFixed;
  }
  if (!fixed_to_root) {
    return LineError(tree.source, tree.links[chain->tip].line,
                     "the tip link " + Quote(tree.links[chain->tip].name) +
                         " is not below the base link " + Quote(tree.links[chain->base].name),
                     "a tip link reached from the base link through joints (or from a link "
                     "the base link is fixed to)");
  }
  chain->path = PathBetween(tree, from, chain->tip);
  for (int ji : chain->path) {
    if (tree.joints[ji].kind != Kind::kFixed) chain->moving.push_back(ji);
  }
  if (chain->moving.empty()) {
    return LineError(tree.source, tree.links[chain->tip].line,
                     "no revolute, continuous or prismatic joint between the base link " +
                         Quote(tree.links[chain->base].name) + " and the tip link " +
                         Quote(tree.links[chain->tip].name),
                     "a chain with at least one moving joint");
  }
  for (int ji : chain->moving) {
    const UrdfJoint& j = tree.joints[ji];
    if (j.mimic_line > 0) {
      return LineError(tree.source, j.mimic_line,
                       JointContext(j.name) + " on the chain mimics another joint",
                       "independent joints on the chain from the base to the tip link (a "
                       "<mimic> joint is supported only off the chain)");
    }
  }
  chain->flange = tree.joints[chain->moving.back()].child;
  if (options.tool_links.empty()) {
    chain->tool_links = {chain->tip};
    return Status::Ok();
  }
  const std::string last = tree.joints[chain->moving.back()].name;
  for (const std::string& name : options.tool_links) {
    int l = -1;
    if (Status s = LinkByName(tree, name, "tool link", &l); !s.ok()) return s;
    bool fixed = IsAncestorOrSelf(tree, chain->flange, l);
    for (int ji : fixed ? PathBetween(tree, chain->flange, l) : std::vector<int>()) {
      fixed = fixed && tree.joints[ji].kind == Kind::kFixed;
    }
    if (!fixed) {
      return LineError(
          tree.source, tree.links[l].line,
          "the tool link " + Quote(name) + " is not after the last moving joint " + Quote(last),
          "a link fixed to the last moving link " + Quote(tree.links[chain->flange].name));
    }
    chain->tool_links.push_back(l);
  }
  return Status::Ok();
}


// Step 6: the LPoE model, fixed joints folded into the next moving joint's origin.
Status urdf_internal::BuildModel(const UrdfTree& tree, const UrdfChain& chain, RobotModel* model) {
  RobotModel out;
  const char* robot_name = tree.robot->Attribute("name");
  out.name = robot_name != nullptr && robot_name[0] != '\0' ? robot_name : "robot";
  SE3d folded = chain.base_up;
  for (int ji : chain.path) {
    const UrdfJoint& j = tree.joints[ji];
    folded = folded * j.origin;
    if (j.kind == Kind::kFixed) continue;
    Joint joint;
    joint.name = j.name;
    joint.origin = folded;
    joint.twist.setZero();
    joint.type = j.kind == Kind::kRevolute ? JointType::kRevolute : JointType::kPrismatic;
    (j.kind == Kind::kRevolute ? joint.twist.head<3>() : joint.twist.tail<3>()) = j.axis;
    joint.lower = j.lower;
    joint.upper = j.upper;
    out.joints.push_back(std::move(joint));
    folded = SE3d();
    if (out.num_joints() == static_cast<int>(chain.moving.size())) break;
  }
  for (int l : chain.tool_links) {
    out.tools.push_back(Tool{tree.links[l].name, PoseInFlange(tree, chain, l)});
  }
  // Named frames: the base link itself and the links fixed to it (either way: `world` above it,
  // ur_description's `base` beside it), and the last moving link and the links fixed below it
  // (`tool0`, `flange`), tools excepted; a program's or a target's frame and a TCP's flange are chosen among them by name.
  std::set<int> tool_set(chain.tool_links.begin(), chain.tool_links.end());
  for (const bool on_flange : {false, true}) {
    const int start = on_flange ? chain.flange : chain.base;
    std::vector<std::pair<int, SE3d>> todo = {{start, SE3d()}};
    std::set<int> seen = {start};
    while (!todo.empty()) {
      const auto [l, pose] = todo.back();
      todo.pop_back();
      if (tool_set.count(l) == 0) {
        out.frames.push_back(NamedFrame{tree.links[l].name, on_flange, pose});
      }
      std::vector<std::pair<int, SE3d>> next;
      for (int cj : tree.links[l].child_joints) {
        if (tree.joints[cj].kind == Kind::kFixed) {
          next.push_back({tree.joints[cj].child, pose * tree.joints[cj].origin});
        }
      }
      const int pj = tree.links[l].parent_joint;
      if (!on_flange && pj >= 0 && tree.joints[pj].kind == Kind::kFixed) {
        next.push_back({tree.joints[pj].parent, pose * tree.joints[pj].origin.Inverse()});
      }
      for (auto it = next.rbegin(); it != next.rend(); ++it) {
        if (seen.insert(it->first).second) todo.push_back(*it);
      }
    }
  }
  const Status valid = out.Validate();
  if (!valid.ok()) {
    return LineError(tree.source, tree.robot_line,
                     "the imported model is invalid: " + valid.message(),
                     "a valid serial-chain model");
  }
  *model = std::move(out);
  return Status::Ok();
}

namespace {

Status ParseImpl(const std::string& xml, const std::string& source, RobotModel* model,
                 const UrdfOptions& options) {
  XMLDocument doc;
  UrdfTree tree;
  if (Status s = ReadTree(xml, source, &doc, &tree); !s.ok()) return s;
  UrdfChain chain;
  if (Status s = SelectChain(tree, options, &chain); !s.ok()) return s;
  return BuildModel(tree, chain, model);
}

}  // namespace

Status ParseRobotModelUrdf(const std::string& xml, const std::string& source, RobotModel* model,
                           const UrdfOptions& options, UrdfSource* kept) {
  try {
    if (Status s = ParseImpl(xml, source, model, options); !s.ok()) return s;
    if (kept != nullptr) *kept = UrdfSource{xml, source, options};
    return Status::Ok();
  } catch (const std::exception& e) {  // std::bad_alloc
    return Status::Error(source + ": cannot parse: " + e.what());
  }
}

Status ReadRobotModelUrdf(const std::string& path, RobotModel* model, const UrdfOptions& options,
                          UrdfSource* kept) {
  std::string text;
  const Status s = ReadFile(path, kMaxModelFileBytes, &text);
  if (!s.ok()) return s;
  return ParseRobotModelUrdf(text, path, model, options, kept);
}

}  // namespace lpoe
