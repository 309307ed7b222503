// Internal to the URDF files of core/src: the link/joint tree of a parsed URDF document, the
// serial chain chosen from it, and the steps the reader, the overlay, the UR kinematics file and
// the export share. urdf_read.cc parses (ReadTree, SelectChain, BuildModel), urdf_overlay.cc writes
// calibrated origins into the source document, urdf_ur.cc writes ROS-Industrial's UR kinematics
// file from the overlay, urdf_write.cc exports a model without a source URDF.
#ifndef LPOE_CORE_SRC_URDF_TREE_H_
#define LPOE_CORE_SRC_URDF_TREE_H_

#include <tinyxml2.h>

#include <array>
#include <limits>
#include <map>
#include <set>
#include <string>
#include <string_view>
#include <vector>

#include "lpoe/io/io.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/kinematics/se3.h"
#include "lpoe/status.h"
#include "lpoe/io/urdf.h"

namespace lpoe {
namespace urdf_internal {

using tinyxml2::XMLDocument;
using tinyxml2::XMLElement;

constexpr double kMetresToMm = 1000.0;
constexpr double kMmToMetres = 1e-3;
// An axis shorter than this cannot be normalized meaningfully.
constexpr double kMinAxisNorm = 1e-9;
// Placeholder prismatic limit written on export (metres); the model carries no limits.
constexpr double kPlaceholderPrismaticLimit = 1.0;

// A name in single quotes for a message (at most 60 characters shown).
std::string Quote(std::string_view s);
// The shortest text that reads back as the same double (-0 written as 0).
std::string Number(double v);
// "x y z" of three such numbers.
std::string Triple(const Eigen::Vector3d& v);
// "joint 'name'".
std::string JointContext(const std::string& name);

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
  // A base link fixed to the arm's root rather than above the arm (ur_description's `base`):
  // the fixed joints climbed from it to the first link above the tip, and the pose of that link
  // in the base link's frame (their inverses composed). Empty and the identity otherwise.
  std::vector<int> up;
  SE3d base_up;
  int tip = -1;                 // link: the end of the chain
  std::vector<int> path;        // joints from base to tip, in order
  std::vector<int> moving;      // the moving joints of `path`, in order
  int flange = -1;              // the child link of the last moving joint
  std::vector<int> tool_links;  // link indices, fixed to the flange
};

// True when link `a` is `b` or one of its ancestors.
bool IsAncestorOrSelf(const UrdfTree& tree, int a, int b);
// The joints from link `from` down to link `to` (which must descend from it), in order.
std::vector<int> PathBetween(const UrdfTree& tree, int from, int to);
// The pose of link `l` in the flange frame, through fixed joints.
SE3d PoseInFlange(const UrdfTree& tree, const UrdfChain& chain, int l);

// Parses `xml` into `doc` and the tree of its links and joints (steps 1-4); errors name the line.
Status ReadTree(const std::string& xml, const std::string& source, XMLDocument* doc,
                UrdfTree* tree);
// The chain from the base link to the tip link, and its tools (step 5).
Status SelectChain(const UrdfTree& tree, const UrdfOptions& options, UrdfChain* chain);
// The LPoE model of the chain, fixed joints folded into the next moving joint's origin (step 6).
Status BuildModel(const UrdfTree& tree, const UrdfChain& chain, RobotModel* model);

// `name`, with '_' appended until it is not in `taken`.
std::string Unique(std::string name, const std::set<std::string>& taken);

// The calibrated URDF origin of each moving joint of the chain (mm), for the UR kinematics file.
struct OverlayJoint {
  std::string name;
  SE3d origin;
  Eigen::Vector3d axis;
  std::array<std::string, 6> text;  // x y z (m) roll pitch yaw (rad) as written in the URDF
};
// The roll, pitch, yaw of R nearest `old` (the file's): the branch and whole turns closest to it,
// the gimbal-lock case shared between roll and yaw; reproduces R.
Eigen::Vector3d RpyNearest(const Eigen::Matrix3d& R, const Eigen::Vector3d& old);
// The source document with the calibrated origins written into it (`xml`), and the moved joints
// (`moved`, may be null).
Status OverlayImpl(const UrdfSource& src, const RobotModel& cal, const UrdfOverlayOptions& options,
                   std::string* xml, std::vector<OverlayJoint>* moved);

// Writes the text `make` produces to `path` atomically; nothing is written when it fails.
template <typename Make>
Status WriteMade(const std::string& path, Make make) {
  std::string text;
  if (Status s = make(&text); !s.ok()) return Status::Error(path + ": not written: " + s.message());
  return WriteFileAtomically(path, text);
}

}  // namespace urdf_internal
}  // namespace lpoe

#endif  // LPOE_CORE_SRC_URDF_TREE_H_
