// URDF import and export of serial-chain robot models (see lpoe/urdf.h). Errors read
//   <file>:<line>: <what is wrong>; expected <what>
// with the line of the XML element at fault. Nothing throws out of the API.
#include "lpoe/urdf.h"

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
#include "lpoe/version.h"
#include "parse_util.h"

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
    double v = 0;
    switch (internal::ParseNumber(token, &v)) {
      case internal::NumberParse::kOk:
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

// The shortest text that reads back as the same double (-0 written as 0).
std::string Number(double v) { return internal::FormatNumber(v); }

std::string Triple(const Eigen::Vector3d& v) {
  return Number(v(0)) + " " + Number(v(1)) + " " + Number(v(2));
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
  bool continuous = false;
  int line = 0;
  int parent = -1, child = -1;                      // link indices
  SE3d origin;                                      // mm
  Eigen::Vector3d axis = Eigen::Vector3d::UnitX();  // unit
  int mimic_line = 0;                               // line of a <mimic> element, 0 if none
  // <limit lower upper> in model units (rad or mm); infinite without a <limit> or for continuous.
  double lower = -std::numeric_limits<double>::infinity();
  double upper = std::numeric_limits<double>::infinity();
  XMLElement* element = nullptr;
};

// The link/joint tree of a parsed URDF document (the document owns the elements).
struct UrdfTree {
  std::string source;
  XMLElement* robot = nullptr;
  int robot_line = 0;
  std::vector<UrdfLink> links;
  std::vector<UrdfJoint> joints;
  std::map<std::string, int> link_index;
  int root = -1;
};

// The serial chain chosen from the tree, and the tools on it.
struct UrdfChain {
  int base = -1;                // link: the model's base frame
  int tip = -1;                 // link: the end of the chain
  std::vector<int> path;        // joints from base to tip, in order
  std::vector<int> moving;      // the moving joints of `path`, in order
  int flange = -1;              // the child link of the last moving joint
  std::vector<int> tool_links;  // link indices, fixed to the flange
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

Status ReadTree(const std::string& xml, const std::string& source, XMLDocument* doc,
                UrdfTree* tree) {
  tree->source = source;
  if (Status s = ParseXml(xml, source, doc, &tree->robot); !s.ok()) return s;
  tree->robot_line = tree->robot->GetLineNum();
  if (Status s = ReadLinks(tree); !s.ok()) return s;
  if (Status s = ReadJoints(tree); !s.ok()) return s;
  return FindRoot(tree);
}

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

// Step 5: the chain from the base link to the tip link, and its tools.
Status SelectChain(const UrdfTree& tree, const UrdfOptions& options, UrdfChain* chain) {
  chain->base = tree.root;
  if (!options.base_link.empty()) {
    if (Status s = LinkByName(tree, options.base_link, "base link", &chain->base); !s.ok()) {
      return s;
    }
  }
  std::string tip_name = options.tip_link;
  if (tip_name.empty()) {
    // An ambiguous tree with named tools: the first tool link ends the chain.
    const Status s = FindTip(tree, chain->base, &chain->tip);
    if (!s.ok() && options.tool_links.empty()) return s;
    if (!s.ok()) tip_name = options.tool_links[0];
  }
  if (!tip_name.empty()) {
    if (Status s = LinkByName(tree, tip_name, "tip link", &chain->tip); !s.ok()) return s;
    if (!IsAncestorOrSelf(tree, chain->base, chain->tip)) {
      return LineError(tree.source, tree.links[chain->tip].line,
                       "the tip link " + Quote(tip_name) + " is not below the base link " +
                           Quote(tree.links[chain->base].name),
                       "a tip link reached from the base link through joints");
    }
  }
  chain->path = PathBetween(tree, chain->base, chain->tip);
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

// The pose of link `l` in the flange frame, through fixed joints.
SE3d PoseInFlange(const UrdfTree& tree, const UrdfChain& chain, int l) {
  SE3d pose;
  for (int ji : PathBetween(tree, chain.flange, l)) pose = pose * tree.joints[ji].origin;
  return pose;
}

// Step 6: the LPoE model, fixed joints folded into the next moving joint's origin.
Status BuildModel(const UrdfTree& tree, const UrdfChain& chain, RobotModel* model) {
  RobotModel out;
  const char* robot_name = tree.robot->Attribute("name");
  out.name = robot_name != nullptr && robot_name[0] != '\0' ? robot_name : "robot";
  SE3d folded;
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
  const Status valid = out.Validate();
  if (!valid.ok()) {
    return LineError(tree.source, tree.robot_line,
                     "the imported model is invalid: " + valid.message(),
                     "a valid serial-chain model");
  }
  *model = std::move(out);
  return Status::Ok();
}

Status ParseImpl(const std::string& xml, const std::string& source, RobotModel* model,
                 const UrdfOptions& options) {
  XMLDocument doc;
  UrdfTree tree;
  if (Status s = ReadTree(xml, source, &doc, &tree); !s.ok()) return s;
  UrdfChain chain;
  if (Status s = SelectChain(tree, options, &chain); !s.ok()) return s;
  return BuildModel(tree, chain, model);
}

// ---------------------------------------------------------------------------------------------------
// Overlay: the source document with the calibrated origins written into it.

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

std::string Unique(std::string name, const std::set<std::string>& taken) {
  while (taken.count(name) > 0) name += '_';
  return name;
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

// The calibrated URDF origin of each moving joint of the chain (mm), for the UR kinematics file.
struct OverlayJoint {
  std::string name;
  SE3d origin;
  Eigen::Vector3d axis;
};

Status OverlayImpl(const UrdfSource& src, const RobotModel& cal, const UrdfOverlayOptions& options,
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

// The UR joints in chain order, and the keys of ROS-Industrial's UR kinematics file.
constexpr const char* kUrJoints[6] = {"shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint",
                                      "wrist_1_joint",      "wrist_2_joint",       "wrist_3_joint"};
constexpr const char* kUrKeys[6] = {"shoulder", "upper_arm", "forearm",
                                    "wrist_1",  "wrist_2",   "wrist_3"};

bool EndsWith(const std::string& s, const std::string& suffix) {
  return s.size() >= suffix.size() &&
         s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

// ---------------------------------------------------------------------------------------------------
// Export of a model without a source URDF.

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

Status CalibratedUrdfOverlay(const UrdfSource& source, const RobotModel& calibrated,
                             const UrdfOverlayOptions& options, std::string* xml) {
  try {
    return OverlayImpl(source, calibrated, options, xml, nullptr);
  } catch (const std::exception& e) {  // std::bad_alloc
    return Status::Error(source.source + ": cannot write the overlay: " + e.what());
  }
}

namespace {

// Writes the text `make` produces to `path` atomically; nothing is written when it fails.
template <typename Make>
Status WriteMade(const std::string& path, Make make) {
  std::string text;
  if (Status s = make(&text); !s.ok()) return Status::Error(path + ": not written: " + s.message());
  return WriteFileAtomically(path, text);
}

}  // namespace

Status WriteCalibratedUrdf(const std::string& path, const UrdfSource& source,
                           const RobotModel& calibrated, const UrdfOverlayOptions& options) {
  return WriteMade(path, [&](std::string* xml) {
    return CalibratedUrdfOverlay(source, calibrated, options, xml);
  });
}

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
