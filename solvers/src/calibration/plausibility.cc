#include "lpoe/plausibility.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "lpoe/kinematics/kinematics.h"
#include "lpoe/measurements/measurement_kind_dispatch.h"
#include "lpoe/model/parameterization.h"

namespace lpoe {
namespace {

constexpr double kTwoPi = 6.283185307179586;
constexpr double kDegree = kTwoPi / 360.0;

VerdictCheck Make(const char* name, double value, double check, double fail, std::string message) {
  VerdictCheck c;
  c.name = name;
  c.value = value;
  c.limit = check;
  c.level = !(value <= fail) ? VerdictLevel::kFail
            : value > check  ? VerdictLevel::kCheck
                             : VerdictLevel::kPass;
  c.message = std::move(message);
  return c;
}

std::string Format(const char* format, double a, double b = 0, double c = 0) {
  char buf[320];
  std::snprintf(buf, sizeof(buf), format, a, b, c);
  return buf;
}

// RMS distance of the points from their centroid.
double Spread(const std::vector<Eigen::Vector3d>& p) {
  if (p.empty()) return 0;
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (const auto& x : p) c += x;
  c /= static_cast<double>(p.size());
  double s = 0;
  for (const auto& x : p) s += (x - c).squaredNorm();
  return std::sqrt(s / static_cast<double>(p.size()));
}

// Passes for the gauge alignment (the centralizer is a subgroup: the projection converges at once
// for a frame already close; a few passes make it exact for large differences).
constexpr int kGaugePasses = 3;
// Link length changes are relative to max(|t|, kMinLinkScaleMm, kChainFraction * chain length).
constexpr double kMinLinkScaleMm = 100.0;
constexpr double kChainFraction = 0.1;

}  // namespace

RobotModel AlignGauge(const RobotModel& start, const RobotModel& calibrated) {
  RobotModel out = calibrated;
  const int n = out.num_joints();
  for (int i = 0; i < n && i < start.num_joints(); ++i) {
    const Eigen::MatrixXd N = TwistCentralizer(out.joints[i].twist);
    if (N.cols() == 0) continue;
    for (int pass = 0; pass < kGaugePasses; ++pass) {
      const SE3d& a = start.joints[i].origin;
      SE3d& b = out.joints[i].origin;
      const Vector6d difference = LogSE3(b.Inverse() * a);
      const Vector6d c = N * (N.transpose() * difference);
      if (!c.allFinite()) break;
      // T_{i-1,i} exp(c) exp(s q) exp(-c) T_{i,i+1} = T_{i-1,i} exp(s q) T_{i,i+1}.
      b = b * ExpSE3(c);
      const SE3d back = ExpSE3(Vector6d(-c));
      if (i + 1 < n) {
        out.joints[i + 1].origin = back * out.joints[i + 1].origin;
      } else {
        for (Tool& t : out.tools) t.origin = back * t.origin;
      }
    }
  }
  return out;
}

const char* VerdictLevelName(VerdictLevel level) {
  switch (level) {
    case VerdictLevel::kPass:
      return "pass";
    case VerdictLevel::kCheck:
      return "check";
    case VerdictLevel::kFail:
      return "fail";
  }
  return "fail";
}

namespace {

// ---- Units of the joint values (before anything else: they explain the rest).
void CheckJointUnits(const RobotModel& start, const MeasurementSet& data,
                     const PlausibilityOptions& options, std::vector<VerdictCheck>* checks) {
  double max_q = 0;
  std::vector<int> revolute;
  for (int j = 0; j < start.num_joints() && j < data.num_joints(); ++j) {
    if (start.joints[j].type == JointType::kRevolute) revolute.push_back(j);
  }
  const bool any_revolute = !revolute.empty();
  for (int r = 0; r < data.size() && any_revolute; ++r) {  // one pass, in memory order
    const double* q = data.q(r);
    for (int j : revolute) max_q = std::max(max_q, std::abs(q[j]));
  }
  if (!any_revolute || data.empty()) return;
  if (!options.joint_values_in_degrees) {
    // Within 2 pi (or the joints' own limits, when wider) radians are what they say; beyond,
    // they look like degrees.
    double widest = kTwoPi;
    for (int j : revolute) {
      const Joint& J = start.joints[j];
      if (std::isfinite(J.lower) && std::isfinite(J.upper)) {
        widest = std::max({widest, std::abs(J.lower), std::abs(J.upper)});
      }
    }
    const bool within = max_q <= widest;
    checks->push_back(Make(
        "joint_units", max_q, widest, 2 * widest,
        within ? Format("revolute joint values reach %.4g rad, within %.4g rad (2 pi or the "
                        "joint limits)",
                        max_q, widest)
               : Format("revolute joint values reach %.4g rad (beyond %.4g rad, 2 pi or the "
                        "joint limits: they look like degrees: use --angle_unit=deg)",
                        max_q, widest)));
    return;
  }
  // Read as degrees, every value within 2 pi degrees: the file was radians.
  const double max_deg = max_q / kDegree;
  VerdictCheck c = Make("joint_units", max_deg, 0, 0,
                        Format("revolute joint values read as degrees reach only %.4g deg "
                               "(within 2 pi: they look like radians: use --angle_unit=rad)",
                               max_deg));
  c.level = max_deg <= kTwoPi ? VerdictLevel::kCheck : VerdictLevel::kPass;
  c.limit = kTwoPi;
  checks->push_back(c);
}

// ---- Scale: measured spread against the model's spread at the same joint values.
void CheckScale(const RobotModel& start, const MeasurementSet& data,
                std::vector<VerdictCheck>* checks) {
  if (data.size() < 3) return;
  std::vector<Eigen::Vector3d> measured, model;
  const int stride = std::max(1, data.size() / 10000);
  for (int r = 0; r < data.size(); r += stride) {
    measured.push_back(data.position(r));
    model.push_back(ToolPosition(start, data.q(r), data.target(r)));
  }
  const double sm = Spread(measured), sp = Spread(model);
  const double ratio = sp > 0 ? sm / sp : INFINITY;
  const double deviation = ratio > 0 ? std::abs(std::log(ratio)) : INFINITY;
  std::string hint;
  if (ratio > 1e-4 && ratio < 3e-3) {
    hint = ": positions look like metres: use --length_unit=m";
  } else if (ratio > 300 && ratio < 1e4) {
    hint = ": positions look like micrometres: convert them to mm";
  } else {
    hint = ": check the length unit, the columns and the model";
  }
  checks->push_back(Make("scale", deviation, std::log(1.05), std::log(1.2),
                         Format("the measured points spread %.4g times as far as the model's "
                                "points at the same joint values",
                                ratio) +
                             (deviation > std::log(1.05) ? hint : "")));
}

// ---- Residual against the expected noise.
VerdictCheck ResidualCheck(const RobotModel& calibrated, const ErrorStatistics& after,
                           const PlausibilityOptions& options) {
  const double rms_axis = after.norm.rms / std::sqrt(3.0);
  const double expected = std::hypot(options.noise_sigma, kNonGeometricMm);
  const double ratio = rms_axis / expected;
  VerdictCheck c = Make(
      "residual", ratio, 2.0, 10.0,
      Format("RMS error after calibration %.4g mm per axis, %.3g times the expected %.3g mm "
             "(tracker noise and non-geometric errors)",
             rms_axis, ratio, expected));
  // Far above the noise with a geometric model only: non-geometric errors the joint-space
  // terms may explain (docs/joint_errors.md).
  if (ratio > 2.0 && calibrated.joint_errors.empty()) {
    c.message += "; a geometric model leaves this much: try --joint_errors=auto (compliance, "
                 "harmonics, gear ratios, chosen by cross-validation)";
  }
  return c;
}

// Whether the data determine a check's change (frame f): a change within kDeterminedSigmas of its
// own standard deviations, or of the prior's, is at most `check`.
VerdictCheck Determined(VerdictCheck c, int f, const PlausibilityOptions& options) {
  if (c.level == VerdictLevel::kPass || f < 0 ||
      f >= static_cast<int>(options.frame_change_sigmas.size())) {
    return c;
  }
  const double z = options.frame_change_sigmas[f];
  const double zp = f < static_cast<int>(options.frame_prior_sigmas.size())
                        ? options.frame_prior_sigmas[f]
                        : INFINITY;
  if (z <= kDeterminedSigmas || zp <= kDeterminedSigmas) {
    if (c.level == VerdictLevel::kFail) c.level = VerdictLevel::kCheck;
    c.message += Format("; not determined by the data: %.3g of its standard deviations", z);
    if (std::isfinite(zp)) c.message += Format(", %.3g of the prior's", zp);
  } else {
    c.message += Format("; determined by the data: %.3g of its standard deviations", z);
    if (std::isfinite(zp)) c.message += Format(", %.3g of the prior's", zp);
  }
  return c;
}

// ---- Parameter changes (joint frames 2..n, tools), in the gauge closest to the start: the
// motions along each joint's own axis that the identifiable parameterization pushes into the next
// frame change no prediction, so they are no change of the robot (on parallel axes, as on a UR
// arm, they otherwise add up to centimetres).
void CheckParameterChanges(const RobotModel& start, const RobotModel& calibrated,
                           const PlausibilityOptions& options, std::vector<VerdictCheck>* checks) {
  const RobotModel aligned = AlignGauge(start, calibrated);
  double worst_len = 0, worst_tool = 0, worst_rot = 0;
  int len_f = -1, tool_f = -1, rot_f = -1;
  std::string len_name, tool_name, rot_name;
  const int n = start.num_joints();
  // Errors of the links before a joint add up along the chain (a tilt of 0.03 rad over 400 mm
  // moves the next axes by 12 mm): short links are judged against a tenth of the chain's length.
  double chain_length = 0;
  for (int f = 1; f < start.num_frames(); ++f) {
    chain_length += (f < n ? start.joints[f].origin : start.tools[f - n].origin).t.norm();
  }
  const double floor_mm = std::max(kMinLinkScaleMm, kChainFraction * chain_length);
  for (int f = 1; f < start.num_frames(); ++f) {
    const SE3d& a = f < n ? start.joints[f].origin : start.tools[f - n].origin;
    const SE3d& b = f < n ? aligned.joints[f].origin : aligned.tools[f - n].origin;
    const std::string name = f < n ? start.joints[f].name : start.tools[f - n].name;
    const double rot = LogSO3(Eigen::Matrix3d(a.R.transpose() * b.R)).norm();
    // A tool's rotation counts only where the tracker kind sees it (the pose kind's data).
    const bool sees_rotation =
        f < n || TrackerDataKind(TrackerKindId(options.use_orientation)) == DataKind::kPose;
    if (rot > worst_rot && sees_rotation) {
      worst_rot = rot, rot_name = name, rot_f = f;
    }
    if (f < n) {
      const double rel = std::abs(b.t.norm() - a.t.norm()) / std::max(a.t.norm(), floor_mm);
      if (rel > worst_len) worst_len = rel, len_name = name, len_f = f;
    } else {
      const double d = (b.t - a.t).norm();
      if (d > worst_tool) worst_tool = d, tool_name = name, tool_f = f;
    }
  }
  if (n > 1) {
    checks->push_back(Determined(
        Make("link_lengths", worst_len, 0.03, 0.10,
             Format("largest link length change %.3g %%", 100 * worst_len) +
                 (len_name.empty() ? "" : " (" + len_name + ")") +
                 (worst_len > 0.03 ? ": more than a calibration corrects" : "")),
        len_f, options));
  }
  checks->push_back(Determined(Make("tool_offsets", worst_tool, 10.0, 50.0,
                                    Format("largest tool offset change %.4g mm", worst_tool) +
                                        (tool_name.empty() ? "" : " (" + tool_name + ")")),
                               tool_f, options));
  checks->push_back(Determined(
      Make("rotations", worst_rot / kDegree, 6.0, 15.0,
           Format("largest frame rotation change %.3g deg", worst_rot / kDegree) +
               (rot_name.empty() ? "" : " (" + rot_name + ")") +
               (worst_rot > 6 * kDegree ? ": more than a joint offset or axis "
                                          "error a calibration corrects"
                                        : "")),
      rot_f, options));
}

}  // namespace

Verdict AssessPlausibility(const RobotModel& start, const RobotModel& calibrated,
                           const MeasurementSet& data, const ErrorStatistics& after,
                           const PlausibilityOptions& options) {
  Verdict v;
  CheckJointUnits(start, data, options, &v.checks);
  CheckScale(start, data, &v.checks);
  v.checks.push_back(ResidualCheck(calibrated, after, options));
  CheckParameterChanges(start, calibrated, options, &v.checks);
  for (const VerdictCheck& c : v.checks) {
    if (c.level > v.level) {
      v.level = c.level;
      v.reason = c.message;
    }
  }
  if (v.level == VerdictLevel::kPass) v.reason = "residual, scale and parameter changes plausible";
  return v;
}

}  // namespace lpoe
