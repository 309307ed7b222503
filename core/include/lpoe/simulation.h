// Synthetic measurements as in the paper's section 4 (eqs. (33), (34)): the "actual" robot has errors
// in its local frames (dp'), its twists (ds') and its joint zeros (dq'); positions are computed on it
// and Gaussian noise is added.
#ifndef LPOE_SIMULATION_H_
#define LPOE_SIMULATION_H_

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "lpoe/measurements.h"
#include "lpoe/robot_model.h"

namespace lpoe {

struct KinematicErrors {
  std::vector<Vector6d> frame;   // dp'_f, (omega, v), one per local frame (joints then tools)
  std::vector<Vector6d> twist;   // ds'_i, (omega, v), one per joint
  std::vector<double> joint_zero;  // dq'_i (rad or mm), one per joint
};

// The paper's Table 2 for cobot6 (6 joints, 1 tool), with ds' read as docs/conventions.md says.
KinematicErrors PaperTable2Errors();

// Random errors: frame rotations uniform in [-rot, rot] rad per component, translations in
// [-trans, trans] mm, twist axes tilted by up to `tilt` rad, joint zeros in [-zero, zero].
KinematicErrors RandomErrors(const RobotModel& model, double rot, double trans, double tilt,
                             double zero, uint64_t seed);

// The actual robot of eq. (33): T^a_f = T_f exp(dp'_f^), twist s_i + ds'_i (renormalized to a valid
// twist of the joint's type). Joint-zero errors are not part of a model; SimulateMeasurements adds
// them to q.
RobotModel ApplyErrors(const RobotModel& nominal, const KinematicErrors& errors);

struct SimulationOptions {
  int count = 100;
  double noise_sigma = 0.0;  // mm, isotropic per axis
  bool pose = false;         // also record the orientation (pose data)
  double orientation_noise_sigma = 0.0;  // rad, per axis, right perturbation
  uint64_t seed = 1;
  // Joint ranges: uniform in [lower, upper] per joint; default [-pi, pi] for revolute, [-100, 100] mm
  // for prismatic joints, narrowed to the joint's limits (Joint::lower/upper).
  std::vector<double> lower, upper;
  // Targets cycle through the model's tools when true; else every row measures tool 0.
  bool all_tools = false;
  // When not empty: measure at these configurations (row-major, n per row; `count`, `lower` and
  // `upper` are ignored), every tool at each one when `all_tools` (rows pose by pose), else tool 0.
  std::vector<double> configurations;
};

// Random configurations q (commanded values), measured on `actual` at q + joint_zero (eq. (34)).
MeasurementSet SimulateMeasurements(const RobotModel& actual, const std::vector<double>& joint_zero,
                                    const SimulationOptions& options);

}  // namespace lpoe

#endif  // LPOE_SIMULATION_H_
