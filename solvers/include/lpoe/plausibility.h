// Is a calibration result plausible? A least-squares fit "converges" on data that do not fit the
// model at all (positions in metres, degrees read as radians, swapped columns, random points): the
// verdict compares what the fit did with what a calibration can do.
//   residual:    per-axis RMS after calibration against the expected noise, sqrt(sigma^2 + g^2) with
//                sigma the tracker noise (--noise_sigma) and g = kNonGeometricMm what a geometric
//                model leaves on a real robot (docs/conventions.md): check above 2x, fail above 10x;
//   scale:       spread of the measured points about their centroid against the spread of the
//                model's points at the same joint values (rigid-invariant): metres, micrometres or a
//                scale factor show here; check beyond 5 %, fail beyond 20 %;
//   joint units: revolute values beyond 2 pi read as radians look like degrees (fail beyond 4 pi);
//                values all within +-2 pi read as degrees look like radians (check);
//   link lengths: | |t_cal| - |t_start| | / max(|t_start|, 100 mm, L / 10) of joint frames 2..n, L
//                the chain's length (sum of |t| of frames 2..n and the tools; upstream axis errors
//                move the next axes by their lever arm, whatever a short link's length): check
//                above 3 %, fail above 10 %; tool offsets: check above 10 mm, fail above 50 mm;
//   rotations:   angle of R_start^T R_cal of joint frames 2..n and tools (a joint offset shows
//                here, added to tilts of the axes that the next frame absorbs; the paper's own
//                errors reach 4.4 degrees): check above 6 degrees, fail above 15 degrees.
// The first frame (the base) is left out: registration moves it by design. Parameter changes are
// compared after AlignGauge (moves along the joints' own axes, which change no prediction, removed).
#ifndef LPOE_PLAUSIBILITY_H_
#define LPOE_PLAUSIBILITY_H_

#include <string>
#include <vector>

#include "lpoe/measurements/measurements.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/model/statistics.h"

namespace lpoe {

enum class VerdictLevel { kPass, kCheck, kFail };
const char* VerdictLevelName(VerdictLevel level);  // "pass" | "check" | "fail"

struct VerdictCheck {
  std::string name;     // residual | scale | joint_units | link_lengths | rotations
  VerdictLevel level = VerdictLevel::kPass;
  double value = 0;     // the figure tested (units in the message)
  double limit = 0;     // the check (not fail) limit of that figure
  std::string message;  // one line
};

struct Verdict {
  VerdictLevel level = VerdictLevel::kPass;
  std::string reason;  // the message of the first worst check
  std::vector<VerdictCheck> checks;
};

// What a geometric calibration leaves per axis on a real robot (mm): compliance, gear errors.
constexpr double kNonGeometricMm = 0.3;
// A typical laser tracker's noise per axis (mm), the default of --noise_sigma.
constexpr double kTypicalTrackerNoiseMm = 0.03;

struct PlausibilityOptions {
  double noise_sigma = kTypicalTrackerNoiseMm;  // mm per axis
  bool joint_values_in_degrees = false;         // the file's revolute values were degrees
  // Pose data: the tools' rotations are judged too (with position data they change no prediction;
  // the full parameterization moves them freely). RunCalibrationPipeline sets it.
  bool use_orientation = false;
  // How far the data determine each local frame's change (joints, then tools; empty: unknown), in
  // standard deviations: the Mahalanobis norm of the change of the frame's identified parameters
  // under the estimate's (posterior) covariance, and under the prior's (infinity without a prior).
  // A parameter-change check above its limit whose change is within kDeterminedSigmas of either is
  // at most `check` (a change the data do not determine, or one the prior allows, is not
  // implausible); every such check's message says which. RunCalibrationPipeline fills them.
  std::vector<double> frame_change_sigmas;
  std::vector<double> frame_prior_sigmas;
};

// A change within this many of its standard deviations (or of the prior's) is not judged absurd.
constexpr double kDeterminedSigmas = 3.0;

// `calibrated` moved, along each joint's centralizer (rotation about and translation along its own
// axis; parameterization.h), as close to `start` as it goes, each move compensated in the next frame
// (the tools after the last joint): the same robot, every prediction unchanged, in the gauge of
// `start`. Parameter changes are compared in it.
RobotModel AlignGauge(const RobotModel& start, const RobotModel& calibrated);

// `start`: the model the solver started from (nominal, registered when registration moved it);
// `calibrated`: its result; `after`: errors of `calibrated` on `data`.
Verdict AssessPlausibility(const RobotModel& start, const RobotModel& calibrated,
                           const MeasurementSet& data, const ErrorStatistics& after,
                           const PlausibilityOptions& options);

}  // namespace lpoe

#endif  // LPOE_PLAUSIBILITY_H_
