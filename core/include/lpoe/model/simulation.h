// Synthetic measurements as in the paper's section 4 (eqs. (33), (34)): the "actual" robot has errors
// in its local frames (dp'), its twists (ds') and its joint zeros (dq'); positions are computed on it
// and Gaussian noise is added.
#ifndef LPOE_SIMULATION_H_
#define LPOE_SIMULATION_H_

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "lpoe/terms/joint_errors.h"
#include "lpoe/measurements/measurements.h"
#include "lpoe/model/robot_model.h"

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

// Non-geometric errors of a small arm (docs/joint_errors.md). Stiffness per joint: `stiffness` when
// given (N m/rad, N/mm for prismatic joints), else 2e4 for the first two joints (base, shoulder),
// 3e3 for the third (elbow) and 1.5e3 for the wrist joints. Link k weighs 0.1 kg + 1.25 kg/m times
// its length (the distance from its frame to the next joint's, or to the first tool for the last
// link), times `mass_scale`, its centre of mass half-way along it plus up to 10 mm per axis at
// random. For cobot6 that gives 0.19-0.65 kg per link, deflections of 210 (shoulder) and 570
// (elbow) arcsec peak to peak and 0.34 mm RMS at the tool that no geometric model absorbs
// (docs/joint_errors.md): heavier links at these stiffnesses would deflect the elbow by thousands of
// arcsec.
// Harmonics: each of the two harmonics of every revolute joint has an amplitude uniform in
// [harmonics_min, harmonics_max] (rad) and a uniform random phase.
struct SmallArmOptions {
  std::vector<double> stiffness;
  double mass_scale = 1.0;
  double harmonics_min = 5.0 / 206264.80624709636;   // 5 arcsec
  double harmonics_max = 30.0 / 206264.80624709636;  // 30 arcsec
  uint64_t seed = 11;
};
JointErrorPhysics SmallArmJointErrors(const RobotModel& model, const SmallArmOptions& options);

// Gives `actual` the joint-space terms named `terms` (registry names, lpoe/terms/joint_term.h), each with
// its truth values from `physics` (JointTermKind::Simulate: compliance from the stiffnesses and
// masses, harmonics from their coefficients, a term without a physical description here from
// physics.seed). Its gravity and payload are used as they are.
void ApplyJointErrorPhysics(const JointErrorPhysics& physics, const std::vector<std::string>& terms,
                            RobotModel* actual);

// `actual` with its joint-zero errors folded in: T_i(0) <- T_i(0) exp(s_i^ zero_i), and every term
// re-expressed in the commanded angle by its registry entry (harmonics: a sin(q + z) + b cos(q + z)
// = a' sin q + b' cos q; a term that leaves a constant over adds it to the joint's zero).
// Its prediction at the commanded q reproduces what SimulateMeasurements measures without noise.
RobotModel FoldJointZeros(const RobotModel& actual, const std::vector<double>& joint_zero);

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

// Random configurations q (commanded values), measured on `actual` at q + joint_zero (eq. (34)) plus
// the joint offsets of the non-geometric terms `actual` carries (evaluated at q + joint_zero).
MeasurementSet SimulateMeasurements(const RobotModel& actual, const std::vector<double>& joint_zero,
                                    const SimulationOptions& options);

}  // namespace lpoe

#endif  // LPOE_SIMULATION_H_
