// Registration of a nominal model to measurements taken in an arbitrary rigid frame (a laser
// tracker metres away and turned arbitrarily, docs/conventions.md). Linearizing the error model
// around a nominal model expressed in the wrong frame fails, so the calibration starts in stages:
//   1. a rigid fit (Horn / Kabsch) of the nominal predicted points to the measured points; the
//      transform is folded into joint 1's local frame, whose parent is then the measurement frame;
//   2. the base frame (all 6 directions) and the tool points, with the nominal joints;
//   3. everything (the caller's solver).
#ifndef LPOE_REGISTRATION_H_
#define LPOE_REGISTRATION_H_

#include <string>
#include <vector>

#include <Eigen/Core>

#include "lpoe/measurements/measurements.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/status.h"

namespace lpoe {

// T minimizing sum_k |T * from_k - to_k|^2 (rotation proper, det +1). Needs three or more points not
// on one line.
Status FitRigidTransform(const std::vector<Eigen::Vector3d>& from,
                         const std::vector<Eigen::Vector3d>& to, SE3d* T_to_from);

struct RegistrationReport {
  SE3d T_measurement_base;     // stage 1: the measurement frame from the nominal base frame
  double rms_nominal = 0;      // mm, nominal model as given
  double rms_rigid = 0;        // mm, after stage 1
  double rms_base_tools = 0;   // mm, after stage 2
  // Stage 1 moved the base by more than kFrameMismatchMm or kFrameMismatchRad: the measurements are
  // not in the model's base frame. Smaller moves only absorb kinematic errors of the robot itself.
  bool moved = false;
  std::string message;
};

// A rigid fit beyond these means the measurement frame is not the model's base frame.
constexpr double kFrameMismatchMm = 50.0;
constexpr double kFrameMismatchRad = 0.05;

// Larger data sets are registered on this many evenly spaced rows (the rms figures of the report
// are then those of the subset).
constexpr int kMaxRegistrationRows = 10000;

// Runs stages 1 and 2 and returns the registered model in `registered` (the input to stage 3).
Status RegisterToMeasurements(const RobotModel& nominal, const MeasurementSet& data,
                              RobotModel* registered, RegistrationReport* report);

}  // namespace lpoe

#endif  // LPOE_REGISTRATION_H_
