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
// The chain runs from the root link (the one link that is never a child) through every moving
// joint; a link from which two moving joints descend (directly or through fixed joints) is a
// branching chain and an error naming the link. Side branches of fixed joints only (a camera mount,
// a "base" frame) are ignored. Tools are links after the last moving joint, reached through fixed
// joints: the links named in UrdfOptions::tool_links (in that order), or by default every leaf of
// that fixed subtree, in document order (for a plain chain: the tip link alone). If the last moving
// joint's child link has no fixed children, it is itself the tool (identity origin). Tools are
// named after their links. The resulting model is validated.
//
// Errors are Status messages "<source>:<line>: what; expected ..." with the line of the offending
// XML element (or of the XML syntax error). Nothing throws or aborts on any input.
//
// Export. Links are named base_link, link1..linkN and after the tools; joints keep their names and
// tools are attached with fixed joints. Numbers have 17 significant digits, so that an export then
// import reproduces forward kinematics to rounding (about 1e-12 mm). A revolute twist (omega, v)
// whose axis does not pass through the frame origin (v != 0) is written by moving the URDF joint
// frame to r = omega x v / |omega|^2, the point of the axis closest to the local frame origin: the
// origin becomes T_{i-1,i}(0) Trans(r_i) and the next frame Trans(-r_i) T_{i,i+1}(0), which leaves
// forward kinematics unchanged. Things URDF cannot express are dropped: the pitch omega . v of a
// revolute twist and the deviation of |omega| (revolute) or |v| (prismatic) from 1 (Validate()
// allows up to kTwistTolerance); axes are written normalized. Revolute joints are written as
// `continuous` (the model has no limits); prismatic joints, which URDF requires to have <limit>,
// get a placeholder of +-1 m, marked by a comment.
#ifndef LPOE_URDF_H_
#define LPOE_URDF_H_

#include <string>
#include <vector>

#include "lpoe/robot_model.h"
#include "lpoe/status.h"

namespace lpoe {

struct UrdfOptions {
  // Links that become the model's tools, in this order. Each must lie after the last moving joint
  // (its child link or a link reached from it through fixed joints). Empty: every leaf link after
  // the last moving joint, in document order (the tip link for a plain chain).
  std::vector<std::string> tool_links;
};

// Reads a robot model from URDF text; `source` names the file in messages. On error `model` is left
// unchanged.
Status ParseRobotModelUrdf(const std::string& xml, const std::string& source, RobotModel* model,
                           const UrdfOptions& options = {});
Status ReadRobotModelUrdf(const std::string& path, RobotModel* model,
                          const UrdfOptions& options = {});

// URDF text of `model` (which should pass Validate()); see the export notes above.
std::string RobotModelToUrdf(const RobotModel& model);
Status WriteRobotModelUrdf(const std::string& path, const RobotModel& model);

}  // namespace lpoe

#endif  // LPOE_URDF_H_
