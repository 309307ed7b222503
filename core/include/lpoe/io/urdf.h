// Robot models as URDF (http://wiki.ros.org/urdf/XML): import of a serial chain, and export.
//
// Import. URDF lengths are metres and angles radians; the library works in millimetres, so every
// length is multiplied by 1000 (a prismatic joint's value is then in mm, as everywhere else here).
// A URDF joint frame is its <origin> (xyz, rpy with R = Rz(yaw) Ry(pitch) Rx(roll)) in the parent
// link's frame, and the joint moves about/along <axis> in that frame; that is exactly an LPoE local
// frame T_{i-1,i}(0) and a twist in the joint's own frame:
//   revolute, continuous -> revolute,  twist (axis, 0)
//   prismatic            -> prismatic, twist (0, axis)
//   fixed                -> folded into the next moving joint's origin (or into the tools)
//   floating, planar     -> error (not a single-degree-of-freedom joint)
// The axis is normalized (a zero axis is an error); a missing <axis> is (1, 0, 0) and a missing
// <origin>, xyz or rpy is zero, as the URDF specification says. Limits, dynamics, inertials,
// visuals, collisions, transmissions and gazebo tags are ignored; a <mimic> on a chain joint is an
// error (the model has one independent value per joint).
//
// The chain runs from the base link (UrdfOptions::base_link, default the root link: the one link
// that is never a child) to the tip link (UrdfOptions::tip_link). Fixed joints on the chain fold
// into the next moving joint's origin; everything off the chain (side branches, fixed or moving:
// a camera mount, a gripper's fingers) is ignored. Without a tip link the candidate tips are the
// leaves below the base reached through a moving joint; their last moving joints must lie on one
// path (else an error lists the candidates: choose with tip_link). One candidate is the tip;
// several after the same last moving joint (a UR's ee_link and tool0) make that joint's child link,
// the flange, the tip. A <mimic> joint on the chain is an error naming it (off the chain it is
// ignored). Tools are links fixed to the flange (the child link of the last moving joint): the
// links named in UrdfOptions::tool_links, in that order, or by default the tip link. Tools are
// named after their links. Joint limits (<limit lower upper>, metres converted to mm for prismatic
// joints) become Joint::lower/upper; continuous joints and joints without <limit> are unlimited.
// The resulting model is validated.
//
// Errors are Status messages "<source>:<line>: what; expected ..." with the line of the offending
// XML element (or of the XML syntax error). Nothing throws or aborts on any input.
//
// Overlay (CalibratedUrdfOverlay). A model read from a URDF is written back into that same
// document's text, edited in place: every byte is kept but the numbers that change (unchanged
// numbers keep their text; changed ones are the shortest text that reads back as the same double;
// rpy the representation nearest the file's) and one block of additions before </robot>:
//   - each moving joint of the chain gets origin = F_i^-1 T_{i-1,i}(0), F_i the fixed joints folded
//     before it (which stay unchanged), and its axis when the calibrated one differs;
//   - its <limit> lower/upper where the model's limits differ from the file's;
//   - a tool that is a link fixed to the flange gets its calibrated pose in its own fixed joint
//     (other fixed joints on the way unchanged); any other tool is added as a fixed link on the
//     tip (named after the tool, or <tool>_smr when that name is taken);
//   - a link `measurement_frame` on a fixed joint from the base link. With in_measurement_frame
//     (the calibration ran in the tracker's frame, so joint 1's calibrated frame holds
//     T_measurement_base), the calibrated model's recorded T_measurement_base places the
//     measurement frame (T_base_measurement = T_measurement_base^-1) and joint 1 takes
//     T_measurement_base^-1 C_1, so that the URDF predicts in its base frame what the YAML does;
//     without a recorded one joint 1 keeps its URDF origin and the measurement frame takes
//     N_1 C_1^-1 (N nominal, C calibrated); otherwise its origin is the identity.
// Forward kinematics from `measurement_frame` to a tool's link then equals the calibrated model's.
// A calibrated revolute axis that does not pass through its frame origin (v != 0) cannot be written
// and is an error.
//
// UR kinematics (UrKinematicsYaml): for a model whose joints are shoulder_pan_joint ..
// wrist_3_joint (any common prefix), the calibrated origins of those six joints in the format of
// ROS-Industrial's ur_description (kinematics: {shoulder, upper_arm, forearm, wrist_1, wrist_2,
// wrist_3}: {x, y, z, roll, pitch, yaw}, hash): the overlay's text when every axis is the joint's
// z axis, else converted from the classic layout (axes along y, a link `base` and tool0 on
// wrist_3's axis; docs/urdf.md), else an error naming the layout needed.
//
// Export (RobotModelToUrdf, a model without a source URDF). Links are named base_link, link1..linkN
// and after the tools; joints keep their names and tools are attached with fixed joints. Numbers
// are the shortest text that reads back as the same double, so that an export then import
// reproduces forward kinematics to rounding (about 1e-12 mm). A revolute twist (omega, v) whose
// axis does not pass through the frame origin (v != 0) is written by moving the URDF joint frame to
// r = omega x v / |omega|^2, the point of the axis closest to the local frame origin: the origin
// becomes T_{i-1,i}(0) Trans(r_i) and the next frame Trans(-r_i) T_{i,i+1}(0), which leaves forward
// kinematics unchanged. Things URDF cannot express are dropped: the pitch omega . v of a revolute
// twist and the deviation of |omega| (revolute) or |v| (prismatic) from 1 (Validate() allows up to
// kTwistTolerance); axes are written normalized. Revolute joints with limits are written as
// `revolute` with them, without as `continuous`; prismatic joints without limits, which URDF
// requires to have <limit>, get a placeholder of +-1 m, marked by a comment.
#ifndef LPOE_URDF_H_
#define LPOE_URDF_H_

#include <string>
#include <vector>

#include "lpoe/model/robot_model.h"
#include "lpoe/status.h"

namespace lpoe {

struct UrdfOptions {
  // The link whose frame is the model's base frame; empty: the root link. A link fixed beside the
  // arm (ur_description's `base`) is reached by climbing its fixed joints.
  std::string base_link;
  // The end of the chain; empty: chosen as described above (an error when ambiguous).
  std::string tip_link;
  // Links that become the model's tools, in this order. Each must be fixed to the last moving link
  // of the chain. Empty: the tip link. When there is no tip_link and the tree is ambiguous, the
  // first of them is the tip.
  std::vector<std::string> tool_links;
};

// The URDF a model was read from, kept for the overlay write-back.
struct UrdfSource {
  std::string xml;
  std::string source;  // the file name, for messages
  UrdfOptions options;
};

// Reads a robot model from URDF text; `source` names the file in messages. On error `model` is left
// unchanged. `kept` (may be null) receives what CalibratedUrdfOverlay needs.
Status ParseRobotModelUrdf(const std::string& xml, const std::string& source, RobotModel* model,
                           const UrdfOptions& options = {}, UrdfSource* kept = nullptr);
Status ReadRobotModelUrdf(const std::string& path, RobotModel* model,
                          const UrdfOptions& options = {}, UrdfSource* kept = nullptr);

struct UrdfOverlayOptions {
  // The calibrated model's base frame is the measurement frame (the data were registered).
  bool in_measurement_frame = false;
  // Name of the added measurement-frame link (its joint is "<name>_joint").
  std::string measurement_link = "measurement_frame";
};

// `source` with the calibrated joint origins, axes, limits and tools of `calibrated` written into
// it, plus the measurement frame (see above). `calibrated` must have the joints of the model read
// from `source` (names, types, order) and pass Validate().
Status CalibratedUrdfOverlay(const UrdfSource& source, const RobotModel& calibrated,
                             const UrdfOverlayOptions& options, std::string* xml);
Status WriteCalibratedUrdf(const std::string& path, const UrdfSource& source,
                           const RobotModel& calibrated, const UrdfOverlayOptions& options);

// True for a six-joint model named like a Universal Robots arm (shoulder_pan_joint ..
// wrist_3_joint, one common prefix allowed).
bool IsUrModel(const RobotModel& model);

// The UR kinematics YAML of the overlay (see above).
Status UrKinematicsYaml(const UrdfSource& source, const RobotModel& calibrated,
                        const UrdfOverlayOptions& options, std::string* yaml);
Status WriteUrKinematicsYaml(const std::string& path, const UrdfSource& source,
                             const RobotModel& calibrated, const UrdfOverlayOptions& options);

// URDF text of `model` (which should pass Validate()); see the export notes above.
std::string RobotModelToUrdf(const RobotModel& model);
Status WriteRobotModelUrdf(const std::string& path, const RobotModel& model);

}  // namespace lpoe

#endif  // LPOE_URDF_H_
