// An LPoE model as a KDL chain, for the benchmarks that compare against KDL (compiled only when
// KDL is found, LPOE_HAVE_KDL). The chain is a fixed segment carrying joint 1's local frame, then
// per joint a RotZ joint whose segment ends at the next local frame (the tool frame after the last
// joint). KDL's Segment(joint, f_tip) poses as joint(q) * f_tip, so the product is exactly
// T_0,1(0) Rz(q_1) T_1,2(0) ... Rz(q_n) T_n,tool. This is KDL's best case (n + 1 segments; a
// separate fixed segment per frame would add n - 1 more frame products). Joints must be revolute
// about local z (cobot6).
#ifndef LPOE_BENCHMARKS_KDL_CHAIN_H_
#define LPOE_BENCHMARKS_KDL_CHAIN_H_

#include <kdl/chain.hpp>
#include <kdl/frames.hpp>

#include "lpoe/model/robot_model.h"

namespace lpoe {
namespace bench {

inline KDL::Frame ToKdl(const SE3d& X) {
  const Eigen::Matrix3d& R = X.R;
  return KDL::Frame(KDL::Rotation(R(0, 0), R(0, 1), R(0, 2), R(1, 0), R(1, 1), R(1, 2), R(2, 0),
                                  R(2, 1), R(2, 2)),
                    KDL::Vector(X.t(0), X.t(1), X.t(2)));
}

inline KDL::Chain KdlChain(const RobotModel& m) {
  KDL::Chain chain;
  chain.addSegment(KDL::Segment("base", KDL::Joint(KDL::Joint::None), ToKdl(m.joints[0].origin)));
  for (int i = 0; i < m.num_joints(); ++i) {
    const SE3d& next = i + 1 < m.num_joints() ? m.joints[i + 1].origin : m.tools[0].origin;
    chain.addSegment(
        KDL::Segment(m.joints[i].name, KDL::Joint(m.joints[i].name, KDL::Joint::RotZ), ToKdl(next)));
  }
  return chain;
}

}  // namespace bench
}  // namespace lpoe

#endif  // LPOE_BENCHMARKS_KDL_CHAIN_H_
