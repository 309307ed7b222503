#include "lpoe/prior.h"

#include <glog/logging.h>

namespace lpoe {

Matrix6d DefaultFrameInformation(const RobotModel& model, int f, const PriorScales& scales,
                                 double scale) {
  const bool tool = f >= model.num_joints();
  const double rotation = 1e-3 * (tool ? scales.tool_rotation_mrad : scales.frame_rotation_mrad);
  const double translation = tool ? scales.tool_translation_mm : scales.frame_translation_mm;
  Vector6d d;
  d << Eigen::Vector3d::Constant(1.0 / (rotation * rotation * scale * scale)),
      Eigen::Vector3d::Constant(1.0 / (translation * translation * scale * scale));
  return d.asDiagonal();
}

Matrix6d FrameInformation(const ParameterPrior& prior, const RobotModel& model, int f) {
  if (f < static_cast<int>(prior.frame_information.size())) {
    return prior.frame_information[f] / (prior.scale * prior.scale);
  }
  return DefaultFrameInformation(model, f, prior.scales, prior.scale);
}

Vector6d FrameDeviation(const RobotModel& reference, const RobotModel& model, int f) {
  CHECK_EQ(reference.num_frames(), model.num_frames());
  const int n = model.num_joints();
  const SE3d& a = f < n ? reference.joints[f].origin : reference.tools[f - n].origin;
  const SE3d& b = f < n ? model.joints[f].origin : model.tools[f - n].origin;
  return LogSE3(a.Inverse() * b);
}

}  // namespace lpoe
