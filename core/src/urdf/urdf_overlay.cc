// The calibrated URDF overlay (see lpoe/io/urdf.h): the source document with the calibrated origins
// (and limits) written into it, every other byte of markup as it was.
#include <tinyxml2.h>

#include <algorithm>
#include <array>
#include <cstring>
#include <tuple>
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

// ---- The source text, edited in place. tinyxml2 has read the document (so it is well formed);
// this scanner finds the byte ranges of the start tags and their attribute values, so that the
// overlay replaces exactly the numbers it changes and inserts what it adds, every other byte kept.
struct TextAttribute {
  std::string name;
  size_t value_begin = 0, value_end = 0;  // the raw value between the quotes
};
struct TextElement {
  std::string name;
  size_t begin = 0, end = 0;  // the start tag, '<' to '>' inclusive-exclusive
  size_t close_begin = 0;     // the end tag's '<' (== end for a self-closing tag)
  bool self_closing = false;
  int parent = -1;
  std::vector<TextAttribute> attributes;
  const TextAttribute* Attribute(const std::string& n) const {
    for (const TextAttribute& a : attributes) {
      if (a.name == n) return &a;
    }
    return nullptr;
  }
};

bool ScanSpace(char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r'; }

// Every element of `text` in document order; false when the text is not what tinyxml2 accepted.
bool ScanElements(const std::string& text, std::vector<TextElement>* out) {
  std::vector<int> open;
  size_t i = 0;
  const size_t n = text.size();
  auto skip_to = [&](const char* end_mark) {
    const size_t e = text.find(end_mark, i);
    if (e == std::string::npos) return false;
    i = e + std::strlen(end_mark);
    return true;
  };
  while (i < n) {
    if (text[i] != '<') {
      ++i;
      continue;
    }
    if (text.compare(i, 4, "<!--") == 0) {
      if (!skip_to("-->")) return false;
    } else if (text.compare(i, 9, "<![CDATA[") == 0) {
      if (!skip_to("]]>")) return false;
    } else if (text.compare(i, 2, "<?") == 0) {
      if (!skip_to("?>")) return false;
    } else if (text.compare(i, 2, "<!") == 0) {
      if (!skip_to(">")) return false;
    } else if (text.compare(i, 2, "</") == 0) {
      if (open.empty()) return false;
      (*out)[open.back()].close_begin = i;
      open.pop_back();
      if (!skip_to(">")) return false;
    } else {
      TextElement e;
      e.begin = i++;
      while (i < n && !ScanSpace(text[i]) && text[i] != '>' && text[i] != '/') e.name += text[i++];
      while (true) {
        while (i < n && ScanSpace(text[i])) ++i;
        if (i >= n) return false;
        if (text[i] == '>') {
          ++i;
          break;
        }
        if (text[i] == '/') {
          if (i + 1 >= n || text[i + 1] != '>') return false;
          e.self_closing = true;
          i += 2;
          break;
        }
        TextAttribute a;
        while (i < n && !ScanSpace(text[i]) && text[i] != '=') a.name += text[i++];
        while (i < n && ScanSpace(text[i])) ++i;
        if (i >= n || text[i] != '=') return false;
        ++i;
        while (i < n && ScanSpace(text[i])) ++i;
        if (i >= n || (text[i] != '"' && text[i] != '\'')) return false;
        const char quote = text[i++];
        a.value_begin = i;
        const size_t q = text.find(quote, i);
        if (q == std::string::npos) return false;
        a.value_end = q;
        i = q + 1;
        e.attributes.push_back(std::move(a));
      }
      e.end = i;
      e.parent = open.empty() ? -1 : open.back();
      if (e.self_closing) e.close_begin = e.end;
      out->push_back(std::move(e));
      if (!out->back().self_closing) open.push_back(static_cast<int>(out->size()) - 1);
    }
  }
  return open.empty();
}

// Text for an attribute value in double quotes.
std::string EscapeAttribute(const std::string& s) {
  std::string out;
  for (char c : s) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

std::vector<std::string> SplitSpace(std::string_view s) {
  std::vector<std::string> out;
  size_t i = 0;
  while (i < s.size()) {
    while (i < s.size() && ScanSpace(s[i])) ++i;
    size_t e = i;
    while (e < s.size() && !ScanSpace(s[e])) ++e;
    if (e > i) out.emplace_back(s.substr(i, e - i));
    i = e;
  }
  return out;
}

double WrapNear(double a, double near) {
  return a + 2 * kPi * std::round((near - a) / (2 * kPi));
}

}  // namespace

namespace urdf_internal {

// The roll, pitch, yaw of R (R = Rz(yaw) Ry(pitch) Rx(roll)) closest to `old`: of the two
// solutions (r, p, y) and (r + pi, pi - p, y + pi), each angle moved by whole turns towards the
// old one, the nearer; at gimbal lock (pitch at +-pi/2, where only r - y or r + y is defined) the
// change is shared between roll and yaw. Every candidate reproduces R.
Eigen::Vector3d RpyNearest(const Eigen::Matrix3d& R, const Eigen::Vector3d& old) {
  const Eigen::Vector3d a = RpyFromRotation(R);
  Eigen::Vector3d best = a;
  double best_distance = std::numeric_limits<double>::infinity();
  auto consider = [&](const Eigen::Vector3d& c, double tolerance) {
    if ((RotationFromRpy(c(0), c(1), c(2)) - R).norm() > tolerance) return;
    const double distance = (c - old).norm();
    if (distance < best_distance) {
      best_distance = distance;
      best = c;
    }
  };
  for (int branch = 0; branch < 2; ++branch) {
    Eigen::Vector3d c = branch == 0 ? a : Eigen::Vector3d(a(0) + kPi, kPi - a(1), a(2) + kPi);
    for (int k = 0; k < 3; ++k) c(k) = WrapNear(c(k), old(k));
    consider(c, 1e-12);  // exact: both branches reproduce R
    if (std::abs(std::cos(c(1))) < 1e-7) {
      // Gimbal lock: R depends on r - s y only (s = sin(pitch)); keep that, share the change
      // between roll and yaw. Accepted when it reproduces R to 1e-10 (near, not at, the lock the
      // two are still tied by cos(pitch)).
      const double s = std::sin(c(1)) > 0 ? 1.0 : -1.0;
      const double d = (c(0) - s * c(2)) - (old(0) - s * old(2));
      Eigen::Vector3d g = c;
      g(0) = old(0) + d / 2;
      g(2) = old(2) - s * d / 2;
      consider(g, 1e-10);
    }
  }
  return best;
}

}  // namespace urdf_internal

namespace {

// Edits of the source text: byte ranges replaced (or, empty, insertions), applied at the end.
struct TextEdits {
  std::vector<std::pair<std::pair<size_t, size_t>, std::string>> edits;
  void Replace(size_t begin, size_t end, std::string text) {
    edits.push_back({{begin, end}, std::move(text)});
  }
  std::string Apply(const std::string& source) const {
    auto sorted = edits;
    std::stable_sort(sorted.begin(), sorted.end(),
                     [](const auto& a, const auto& b) { return a.first.first < b.first.first; });
    std::string out;
    size_t at = 0;
    for (const auto& [range, text] : sorted) {
      out.append(source, at, range.first - at);
      out += text;
      at = std::max(at, range.second);
    }
    out.append(source, at, std::string::npos);
    return out;
  }
};

// The indentation of the line holding byte `at` of `text`.
std::string IndentOf(const std::string& text, size_t at) {
  size_t line = text.rfind('\n', at == 0 ? 0 : at - 1);
  line = line == std::string::npos ? 0 : line + 1;
  size_t e = line;
  while (e < text.size() && (text[e] == ' ' || text[e] == '\t')) ++e;
  return text.substr(line, e - line);
}

// New text for the numbers of an attribute holding three numbers: an unchanged number keeps its
// text (a change below `tolerance` is no change), a changed one is the shortest text that reads
// back as the new value. `old_text` is the attribute's raw value ("" when absent).
std::string NumbersText(const std::string& old_text, const Eigen::Vector3d& values,
                        double tolerance, bool* changed, std::string out_tokens[3]) {
  const std::vector<std::string> old = SplitSpace(old_text);
  *changed = old.size() != 3;
  std::string text;
  for (int k = 0; k < 3; ++k) {
    double before = 0;
    const bool parsed = old.size() == 3 && internal::ParseNumber(old[k], &before) ==
                                               internal::NumberParse::kOk;
    std::string token;
    if (parsed && std::abs(values(k) - before) <= tolerance) {
      token = old[k];
    } else {
      token = Number(values(k));
      *changed = true;
    }
    out_tokens[k] = token;
    text += (k == 0 ? "" : " ") + token;
  }
  return text;
}

Status Mismatch(const UrdfSource& src, const std::string& what) {
  return Status::Error(src.source + ": the calibrated model does not match this URDF: " + what);
}

// The calibrated model's joints those of the URDF's chain (count, names, types).
Status CheckOverlayJoints(const UrdfSource& src, const RobotModel& cal, const RobotModel& nominal) {
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
  return Status::Ok();
}

// The source text's elements and the edits made to it: the robot's <joint> children in document
// order are tree.joints.
class OverlayText {
 public:
  explicit OverlayText(const std::string& text) : text_(text) {}

  // Finds the elements; false when the robot or its joints cannot be located.
  Status Locate(const UrdfSource& src, size_t num_joints) {
    if (!ScanElements(text_, &elements_)) {
      return Status::Error(src.source + ": cannot locate the elements in the text for the overlay");
    }
    for (int e = 0; e < static_cast<int>(elements_.size()) && robot_ < 0; ++e) {
      if (elements_[e].parent == -1 && elements_[e].name == "robot") robot_ = e;
    }
    for (int e = 0; e < static_cast<int>(elements_.size()); ++e) {
      if (elements_[e].parent == robot_ && elements_[e].name == "joint") {
        joint_element_.push_back(e);
      }
    }
    if (robot_ < 0 || elements_[robot_].self_closing || joint_element_.size() != num_joints) {
      return Status::Error(src.source + ": cannot locate the joints in the text for the overlay");
    }
    return Status::Ok();
  }

  // A joint's origin written into its <origin> element: unchanged numbers keep their text, the
  // rotation is written as the roll, pitch, yaw nearest the file's. `written` (may be null)
  // receives the six numbers' text.
  void WriteOrigin(int ji, const SE3d& T, std::array<std::string, 6>* written) {
    const int je = joint_element_[ji];
    const int oe = ChildOf(je, "origin");
    const TextAttribute* xyz_attr = oe >= 0 ? elements_[oe].Attribute("xyz") : nullptr;
    const TextAttribute* rpy_attr = oe >= 0 ? elements_[oe].Attribute("rpy") : nullptr;
    const auto raw = [&](const TextAttribute* a) {
      return a == nullptr ? std::string("0 0 0")
                          : text_.substr(a->value_begin, a->value_end - a->value_begin);
    };
    Eigen::Vector3d old_rpy = Eigen::Vector3d::Zero();
    const std::vector<std::string> rpy_tokens = SplitSpace(raw(rpy_attr));
    for (int k = 0; k < 3 && rpy_tokens.size() == 3; ++k) {
      internal::ParseNumber(rpy_tokens[k], &old_rpy(k));
    }
    // Numbers that moved by less than these (m, rad) did not change: their text stays.
    constexpr double kSameMetres = 1e-12, kSameRadians = 1e-12;
    std::string tokens[6];
    bool xyz_changed = false, rpy_changed = false;
    const std::string xyz_text =
        NumbersText(raw(xyz_attr), T.t * kMmToMetres, kSameMetres, &xyz_changed, tokens);
    const std::string rpy_text = NumbersText(raw(rpy_attr), RpyNearest(T.R, old_rpy),
                                             kSameRadians, &rpy_changed, tokens + 3);
    if (written != nullptr) {
      for (int k = 0; k < 6; ++k) (*written)[k] = tokens[k];
    }
    if (oe < 0) {
      if (!xyz_changed && !rpy_changed) return;
      AppendChild(je, "<origin xyz=\"" + xyz_text + "\" rpy=\"" + rpy_text + "\"/>");
      return;
    }
    const TextElement& o = elements_[oe];
    const size_t insert_at = o.self_closing ? o.end - 2 : o.end - 1;
    for (const auto& [attr, changed, value, name] :
         {std::tuple{xyz_attr, xyz_changed, xyz_text, "xyz"},
          std::tuple{rpy_attr, rpy_changed, rpy_text, "rpy"}}) {
      if (!changed) continue;
      if (attr != nullptr) {
        edits_.Replace(attr->value_begin, attr->value_end, value);
      } else {
        edits_.Replace(insert_at, insert_at, std::string(" ") + name + "=\"" + value + "\"");
      }
    }
  }

  void WriteAxis(int ji, const Eigen::Vector3d& axis) {
    const int je = joint_element_[ji];
    const int ae = ChildOf(je, "axis");
    const TextAttribute* a = ae >= 0 ? elements_[ae].Attribute("xyz") : nullptr;
    if (a != nullptr) {
      edits_.Replace(a->value_begin, a->value_end, Triple(axis));
    } else {
      AppendChild(je, "<axis xyz=\"" + Triple(axis) + "\"/>");
    }
  }

  // The limits (in the file's units) into the joint's <limit>, or a new <limit>.
  void WriteLimits(int ji, double lower, double upper) {
    const int je = joint_element_[ji];
    const int le = ChildOf(je, "limit");
    const std::pair<const char*, double> bounds[2] = {{"lower", lower}, {"upper", upper}};
    if (le < 0) {
      AppendChild(je, "<limit lower=\"" + Number(lower) + "\" upper=\"" + Number(upper) +
                          "\" effort=\"0\" velocity=\"0\"/>");
      return;
    }
    const TextElement& l = elements_[le];
    for (const auto& [name, value] : bounds) {
      if (const TextAttribute* a = l.Attribute(name)) {
        edits_.Replace(a->value_begin, a->value_end, Number(value));
      } else {
        const size_t at = l.self_closing ? l.end - 2 : l.end - 1;
        edits_.Replace(at, at, std::string(" ") + name + "=\"" + Number(value) + "\"");
      }
    }
  }

  // `added` at the start of the line of </robot> (after its indentation when it has its own
  // line); the edited text.
  std::string Finish(std::string added) {
    size_t close = elements_[robot_].close_begin;
    const size_t line_start = text_.rfind('\n', close == 0 ? 0 : close - 1);
    bool own_line = line_start != std::string::npos;
    for (size_t b = own_line ? line_start + 1 : close; b < close; ++b) {
      own_line = own_line && (text_[b] == ' ' || text_[b] == '\t');
    }
    if (own_line) {
      close = line_start + 1;
    } else {
      added = "\n" + added;
    }
    edits_.Replace(close, close, added);
    return edits_.Apply(text_);
  }

 private:
  int ChildOf(int parent, const char* name) const {
    for (int e = parent + 1; e < static_cast<int>(elements_.size()); ++e) {
      if (elements_[e].begin >= elements_[parent].close_begin) break;
      if (elements_[e].parent == parent && elements_[e].name == name) return e;
    }
    return -1;
  }
  // A new child element's text after the start tag of element `e`, on its own line.
  void AppendChild(int e, const std::string& markup) {
    const TextElement& el = elements_[e];
    edits_.Replace(el.end, el.end, "\n" + IndentOf(text_, el.begin) + "  " + markup);
  }

  const std::string& text_;
  std::vector<TextElement> elements_;
  int robot_ = -1;
  std::vector<int> joint_element_;
  TextEdits edits_;
};

// The calibrated base frame is the measurement frame: the registration recorded with the model
// (T_measurement_base, lpoe_calibrate) places the measurement frame in the base frame, so that
// the URDF predicts in its base frame what the YAML model predicts there; without a recorded
// registration joint 1 keeps its URDF origin and the measurement frame takes
// T_measurement_base = C_1 N_1^-1 (the two are not separable).
SE3d OverlayMeasurementFrame(const RobotModel& cal, const RobotModel& nominal,
                             const UrdfOverlayOptions& options) {
  if (!options.in_measurement_frame) return SE3d();
  const bool recorded =
      !cal.T_measurement_base.R.isIdentity(0) || !cal.T_measurement_base.t.isZero(0);
  return recorded ? cal.T_measurement_base
                  : cal.joints[0].origin * nominal.joints[0].origin.Inverse();
}

// Moving joints: origin = (fixed joints folded before it)^-1 * calibrated local frame, the axis
// and the limits where they changed.
Status OverlayMovingJoints(const UrdfSource& src, const RobotModel& cal, const UrdfChain& chain,
                           const SE3d& T_measurement_base, UrdfTree* tree, OverlayText* out,
                           std::vector<OverlayJoint>* moved) {
  SE3d folded = chain.base_up;
  int k = 0;
  for (int ji : chain.path) {
    UrdfJoint& j = tree->joints[ji];
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
    OverlayJoint written{j.name, j.origin, axis, {}};
    out->WriteOrigin(ji, j.origin, &written.text);
    if ((axis - j.axis).norm() > 1e-12) {
      out->WriteAxis(ji, axis);
      j.axis = axis;
    }
    // The model's limits where they differ from the file's.
    if (!j.continuous && std::isfinite(c.lower) && std::isfinite(c.upper) &&
        (c.lower != j.lower || c.upper != j.upper)) {
      const double scale = j.kind == Kind::kPrismatic ? kMmToMetres : 1.0;
      out->WriteLimits(ji, c.lower * scale, c.upper * scale);
    }
    if (moved != nullptr) moved->push_back(written);
    folded = SE3d();
    if (++k == cal.num_joints()) break;
  }
  return Status::Ok();
}

// Tools that are links fixed after the flange take the calibrated pose in their own fixed joint
// (ancestors first); the others (returned) become new links on the tip.
std::vector<int> OverlayLinkTools(const RobotModel& cal, const UrdfChain& chain, UrdfTree* tree,
                                  OverlayText* out) {
  std::vector<std::pair<int, int>> link_tools;  // depth below the flange, tool index
  std::vector<int> new_tools;
  for (int t = 0; t < cal.num_tools(); ++t) {
    const auto it = tree->link_index.find(cal.tools[t].name);
    bool fixed = it != tree->link_index.end() && it->second != chain.flange &&
                 IsAncestorOrSelf(*tree, chain.flange, it->second);
    const std::vector<int> path =
        fixed ? PathBetween(*tree, chain.flange, it->second) : std::vector<int>();
    for (int ji : path) fixed = fixed && tree->joints[ji].kind == Kind::kFixed;
    if (fixed) {
      link_tools.push_back({static_cast<int>(path.size()), t});
    } else {
      new_tools.push_back(t);
    }
  }
  std::sort(link_tools.begin(), link_tools.end());
  for (const auto& [depth, t] : link_tools) {
    const int ji = tree->links[tree->link_index.at(cal.tools[t].name)].parent_joint;
    UrdfJoint& j = tree->joints[ji];
    j.origin = PoseInFlange(*tree, chain, j.parent).Inverse() * cal.tools[t].origin;
    out->WriteOrigin(ji, j.origin, nullptr);
  }
  return new_tools;
}

// What the calibration adds before </robot>, one block: a comment, the new tools as fixed links
// on the tip and the measurement frame as a fixed link on the base.
std::string OverlayAddedText(const RobotModel& cal, const UrdfTree& tree, const UrdfChain& chain,
                             const std::vector<int>& new_tools, const SE3d& T_measurement_base,
                             const UrdfOverlayOptions& options) {
  std::set<std::string> link_names, joint_names;
  for (const UrdfLink& l : tree.links) link_names.insert(l.name);
  for (const UrdfJoint& j : tree.joints) joint_names.insert(j.name);
  const std::string indent = "  ";
  auto fixed_joint_text = [&](const std::string& name, const std::string& parent,
                              const std::string& child, const SE3d& T) {
    return indent + "<link name=\"" + EscapeAttribute(child) + "\"/>\n" + indent +
           "<joint name=\"" + EscapeAttribute(name) + "\" type=\"fixed\">\n" + indent + indent +
           "<parent link=\"" + EscapeAttribute(parent) + "\"/>\n" + indent + indent +
           "<child link=\"" + EscapeAttribute(child) + "\"/>\n" + indent + indent +
           "<origin xyz=\"" + Triple(T.t * kMmToMetres) + "\" rpy=\"" +
           Triple(RpyFromRotation(T.R)) + "\"/>\n" + indent + "</joint>\n";
  };
  std::string changed;
  for (int ji : chain.moving) changed += (changed.empty() ? "" : ", ") + tree.joints[ji].name;
  std::string added =
      indent + "<!--" +
      CommentText(" Added by lpoe-calib " + std::string(kLpoeVersion) +
                  ": the measurement (tracker) frame and the measured tools (SMRs). Calibrated: "
                  "the origins (and axes) of the joints " +
                  changed +
                  " and the tool frames; everything else as in the source. ") +
      "-->\n";
  const SE3d tip_in_flange = PoseInFlange(tree, chain, chain.tip);
  const std::string tip = tree.links[chain.tip].name;
  for (int t : new_tools) {
    const std::string link =
        Unique(link_names.count(cal.tools[t].name) ? cal.tools[t].name + "_smr" : cal.tools[t].name,
               link_names);
    link_names.insert(link);
    const std::string joint = Unique(link + "_joint", joint_names);
    joint_names.insert(joint);
    added += fixed_joint_text(joint, tip, link, tip_in_flange.Inverse() * cal.tools[t].origin);
  }
  const std::string frame = Unique(options.measurement_link, link_names);
  added += fixed_joint_text(Unique(frame + "_joint", joint_names), tree.links[chain.base].name,
                            frame, T_measurement_base.Inverse());
  return added;
}

}  // namespace

Status urdf_internal::OverlayImpl(const UrdfSource& src, const RobotModel& cal,
                                  const UrdfOverlayOptions& options, std::string* xml,
                                  std::vector<OverlayJoint>* moved) {
  XMLDocument doc;
  UrdfTree tree;
  if (Status s = ReadTree(src.xml, src.source, &doc, &tree); !s.ok()) return s;
  UrdfChain chain;
  if (Status s = SelectChain(tree, src.options, &chain); !s.ok()) return s;
  RobotModel nominal;
  if (Status s = BuildModel(tree, chain, &nominal); !s.ok()) return s;
  if (Status s = CheckOverlayJoints(src, cal, nominal); !s.ok()) return s;
  OverlayText text(src.xml);
  if (Status s = text.Locate(src, tree.joints.size()); !s.ok()) return s;
  const SE3d T_measurement_base = OverlayMeasurementFrame(cal, nominal, options);
  if (Status s = OverlayMovingJoints(src, cal, chain, T_measurement_base, &tree, &text, moved);
      !s.ok()) {
    return s;
  }
  const std::vector<int> new_tools = OverlayLinkTools(cal, chain, &tree, &text);
  *xml = text.Finish(OverlayAddedText(cal, tree, chain, new_tools, T_measurement_base, options));
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
