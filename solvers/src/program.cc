// Robot programs: the compensation step, the same for every language (lpoe/program.h). The text
// side (tokens, rewriter, report) is program_text.cc; the parsers program_urscript.cc and
// program_rapid.cc.
#include "lpoe/program.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include "lpoe/kinematics.h"
#include "lpoe/refusals.h"

namespace lpoe {

namespace {

constexpr double kDeg = 180.0 / kPi;

int Quadrant(double q) { return static_cast<int>(std::floor(q / (kPi / 2))); }

double Angle(const Eigen::Matrix3d& R) {
  return std::acos(std::clamp((R.trace() - 1) / 2, -1.0, 1.0));
}

// The pose (mm) of a Cartesian record from its numbers; false when they do not make one.
bool DecodePose(const ProgramTarget& t, SE3d* pose, std::string* why) {
  const auto& v = t.numbers;
  if (t.pose_encoding == PoseEncoding::kMetresRotationVector) {
    if (v.size() != 6) {
      *why = "a pose needs 6 numbers";
      return false;
    }
    pose->t = Eigen::Vector3d(v[0].value, v[1].value, v[2].value) * 1000.0;
    pose->R = ExpSO3(Eigen::Vector3d(v[3].value, v[4].value, v[5].value));
    return true;
  }
  if (v.size() != 7) {
    *why = "a pose needs 7 numbers";
    return false;
  }
  pose->t = Eigen::Vector3d(v[0].value, v[1].value, v[2].value);
  Eigen::Vector4d q(v[4].value, v[5].value, v[6].value, v[3].value);  // x y z w
  if (std::abs(q.norm() - 1) > 1e-3) {
    *why = "the orientation quaternion is not normalized (norm " + std::to_string(q.norm()) + ")";
    return false;
  }
  pose->R = QuaternionToRotation<double>(q / q.norm());
  return true;
}

// New numbers for `pose`, the representation nearest the original's (rotation vector branch,
// quaternion sign).
std::vector<double> EncodePose(const ProgramTarget& t, const SE3d& pose) {
  const auto& v = t.numbers;
  if (t.pose_encoding == PoseEncoding::kMetresRotationVector) {
    Eigen::Vector3d rv = LogSO3(pose.R);
    const Eigen::Vector3d old(v[3].value, v[4].value, v[5].value);
    const double a = rv.norm();
    if (a > 1e-9) {
      const Eigen::Vector3d alt = rv * (1 - 2 * kPi / a);
      if ((alt - old).norm() < (rv - old).norm()) rv = alt;
    }
    return {pose.t.x() / 1000, pose.t.y() / 1000, pose.t.z() / 1000, rv.x(), rv.y(), rv.z()};
  }
  Eigen::Vector4d q = RotationToQuaternion<double>(pose.R);  // x y z w
  const Eigen::Vector4d old(v[4].value, v[5].value, v[6].value, v[3].value);
  if (q.dot(old) < 0) q = -q;
  return {pose.t.x(), pose.t.y(), pose.t.z(), q(3), q(0), q(1), q(2)};
}

const char* IkReason(IkStatus s) {
  switch (s) {
    case IkStatus::kOk:
      return "reached";
    case IkStatus::kUnreachable:
      return "out of reach";
    case IkStatus::kLimit:
      return "outside the joint limits";
    case IkStatus::kSingular:
      return "at a singularity";
    case IkStatus::kBranch:
      return "only on another configuration branch (across a singular surface)";
  }
  return "?";
}

}  // namespace

int ResolveFlangeTool(const RobotModel& model, const std::string& flange, std::string* message) {
  if (!flange.empty()) {
    const int t = model.FindTool(flange);
    if (t < 0) *message = "the model " + model.name + " has no tool '" + flange + "'";
    return t;
  }
  const int t = model.FindTool("flange");
  if (t >= 0) return t;
  if (model.num_tools() == 1) return 0;
  *message = "the model " + model.name +
             " has no tool named 'flange' and several tools; say which one is the controller's "
             "flange (tool0) with --flange";
  return -1;
}

Status CompensateProgram(const RobotModel& calibrated, const RobotModel& nominal,
                         const ProgramOptions& options, ParsedProgram* program) {
  if (calibrated.num_joints() != nominal.num_joints()) {
    return Status::Error("the calibrated model has " + std::to_string(calibrated.num_joints()) +
                         " joints, the nominal " + std::to_string(nominal.num_joints()));
  }
  for (const RobotModel* m : {&calibrated, &nominal}) {
    if (Status s = InverseKinematics::CheckModel(*m); !s.ok()) return s;
  }
  // The same check as lpoe_compensate --targets (lpoe/refusals.h): the nominal model describes the
  // calibrated arm.
  if (Status s = CheckNominalMatches(calibrated, nominal); !s.ok()) {
    return Status::Error("nominal: " + s.message());
  }
  std::string message;
  const int flange_cal = ResolveFlangeTool(calibrated, options.flange, &message);
  if (flange_cal < 0) return Status::Error(message);
  const int flange_nom = ResolveFlangeTool(nominal, calibrated.tools[flange_cal].name, &message);
  if (flange_nom < 0) return Status::Error(message);
  TargetNameFilter selected;
  if (Status s = selected.Compile(options.targets_only); !s.ok()) return s;
  const int n = calibrated.num_joints();
  std::vector<double> prev(n, 0.0);
  if (!options.home.empty()) {
    if (static_cast<int>(options.home.size()) != n) {
      return Status::Error("home has " + std::to_string(options.home.size()) +
                           " joints, the model " + std::to_string(n));
    }
    prev = options.home;
  } else {
    for (int j = 0; j < n; ++j) {
      const Joint& J = nominal.joints[j];
      if (std::isfinite(J.lower) && std::isfinite(J.upper)) prev[j] = 0.5 * (J.lower + J.upper);
    }
  }
  IkOptions nominal_options = options.ik;
  nominal_options.check_branch = false;
  const InverseKinematics ik_cal(calibrated, options.ik);
  const InverseKinematics ik_nom(nominal, nominal_options);
  const KinematicChain nom_chain(nominal);

  std::vector<int> order;
  for (int k = 0; k < static_cast<int>(program->targets.size()); ++k) {
    ProgramTarget& t = program->targets[k];
    t.status = ProgramTargetStatus::kNotCompensated;
    t.new_values.clear();
    t.new_quadrants.clear();
    if (!t.compensable) continue;
    if (!t.used) {
      t.compensable = false;
      t.reason = "not used by a motion instruction (its tool and frame are unknown)";
      continue;
    }
    order.push_back(k);
  }
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return program->targets[a].order < program->targets[b].order;
  });
  // The flange's rotation about the last joint's axis: identified only with known SMR nests.
  program->flange_rotation_identified = calibrated.HasFixedTool();
  program->fixed_tools.clear();
  for (const Tool& tool : calibrated.tools) {
    if (tool.fixed) program->fixed_tools += (program->fixed_tools.empty() ? "" : ", ") + tool.name;
  }
  program->tcp_off_flange_axis_mm = 0;
  const Joint& last = calibrated.joints.back();
  const bool last_revolute = last.type == JointType::kRevolute;
  const Eigen::Vector3d axis_w = last.twist.head<3>().normalized();
  const Eigen::Vector3d axis_point = axis_w.cross(last.twist.tail<3>());
  // `tcp`: the working point on the flange (the TCP, or for a stationary tool the target on the
  // work object the robot holds).
  auto note_tcp = [&](const SE3d& tcp) {
    if (!last_revolute) return;
    const Eigen::Vector3d r = (calibrated.tools[flange_cal].origin * tcp).t - axis_point;
    program->tcp_off_flange_axis_mm =
        std::max(program->tcp_off_flange_axis_mm, (r - axis_w * axis_w.dot(r)).norm());
  };
  std::vector<double> seed(n), q_nom(n), q_cal(n);
  for (const int k : order) {
    ProgramTarget& t = program->targets[k];
    const bool wanted = options.targets_only.empty() || selected.Matches(t.name);
    if (t.kind == ProgramTargetKind::kJoint) {
      if (static_cast<int>(t.numbers.size()) != n) {
        t.compensable = false;
        t.reason = std::to_string(t.numbers.size()) + " joint values for a robot with " +
                   std::to_string(n) + " joints";
        continue;
      }
      for (int j = 0; j < n; ++j) {
        const bool deg = t.joint_encoding == JointEncoding::kDegrees &&
                         nominal.joints[j].type == JointType::kRevolute;
        q_nom[j] = deg ? t.numbers[j].value / kDeg : t.numbers[j].value;
      }
      prev = q_nom;
      if (!wanted) {
        t.status = ProgramTargetStatus::kNotSelected;
        t.reason = "name does not match targets_only (taught point)";
        continue;
      }
      const SE3d X = calibrated.T_measurement_base * nom_chain.Pose(q_nom.data(), flange_nom);
      IkTarget target;
      target.tool = flange_cal;
      target.position = X.t;
      target.rotation = X.R;
      target.has_orientation = true;
      const IkResult r = ik_cal.Solve(target, q_nom.data(), q_cal.data());
      if (r.status != IkStatus::kOk) {
        t.reason = std::string("the calibrated robot reaches this pose ") + IkReason(r.status);
        continue;
      }
      double max_dq = 0;
      for (int j = 0; j < n; ++j) {
        const bool deg = t.joint_encoding == JointEncoding::kDegrees &&
                         nominal.joints[j].type == JointType::kRevolute;
        t.new_values.push_back(deg ? q_cal[j] * kDeg : q_cal[j]);
        if (nominal.joints[j].type == JointType::kRevolute) {
          max_dq = std::max(max_dq, std::abs(q_cal[j] - q_nom[j]) * kDeg);
        }
      }
      // The point that moves: the TCP, or the work object the robot holds past a stationary tool.
      const SE3d& moving = t.stationary_tool ? t.frame : t.tcp;
      const SE3d a = nom_chain.Pose(q_nom.data(), flange_nom) * moving;
      const SE3d b = nom_chain.Pose(q_cal.data(), flange_nom) * moving;
      t.correction_mm = (b.t - a.t).norm();
      t.correction_deg = max_dq;
      t.status = ProgramTargetStatus::kCompensated;
      t.reason.clear();
      note_tcp(moving);
      continue;
    }
    SE3d pose;
    std::string why;
    if (!DecodePose(t, &pose, &why)) {
      t.compensable = false;
      t.reason = why;
      continue;
    }
    // The controller's seed: qnear, else the previous target's joints moved into the quadrants.
    if (static_cast<int>(t.qnear.size()) == n) {
      seed = t.qnear;
    } else {
      seed = prev;
    }
    for (const ProgramTarget::Quadrant& qd : t.quadrants) {
      if (qd.joint < n && Quadrant(seed[qd.joint]) != static_cast<int>(qd.number.value)) {
        seed[qd.joint] = (qd.number.value + 0.5) * kPi / 2;
      }
    }
    // Robot-held tool: the TCP (flange * tcp) at the target in the work object (frame * pose).
    // Stationary tool: the work object the robot holds (flange * frame) has the fixed tool (tcp,
    // in the base frame) at the target: flange * frame * pose = tcp.
    const SE3d flange_base = t.stationary_tool ? t.tcp * pose.Inverse() * t.frame.Inverse()
                                               : t.frame * pose * t.tcp.Inverse();
    IkTarget target;
    target.tool = flange_nom;
    target.position = flange_base.t;
    target.rotation = flange_base.R;
    target.has_orientation = true;
    const IkResult rn = ik_nom.Solve(target, seed.data(), q_nom.data());
    if (rn.status != IkStatus::kOk && rn.status != IkStatus::kBranch) {
      t.reason = std::string("the nominal model reaches this target ") + IkReason(rn.status) +
                 " (the controller would not run it)";
      continue;
    }
    prev = q_nom;
    if (!wanted) {
      t.status = ProgramTargetStatus::kNotSelected;
      t.reason = "name does not match targets_only (taught point)";
      continue;
    }
    const SE3d measured = calibrated.T_measurement_base * flange_base;
    target.tool = flange_cal;
    target.position = measured.t;
    target.rotation = measured.R;
    const IkResult rc = ik_cal.Solve(target, q_nom.data(), q_cal.data());
    if (rc.status != IkStatus::kOk) {
      t.reason = std::string("the calibrated robot reaches this target ") + IkReason(rc.status);
      continue;
    }
    const SE3d flange_cal_q = nom_chain.Pose(q_cal.data(), flange_nom);
    const SE3d corrected = t.stationary_tool ? (flange_cal_q * t.frame).Inverse() * t.tcp
                                             : t.frame.Inverse() * flange_cal_q * t.tcp;
    t.new_values = EncodePose(t, corrected);
    for (const ProgramTarget::Quadrant& qd : t.quadrants) {
      t.new_quadrants.push_back(qd.joint < n ? Quadrant(q_cal[qd.joint]) : qd.number.value);
    }
    t.correction_mm = (corrected.t - pose.t).norm();
    t.correction_deg = Angle(pose.R.transpose() * corrected.R) * kDeg;
    t.status = ProgramTargetStatus::kCompensated;
    t.reason.clear();
    note_tcp(t.stationary_tool ? t.frame * pose : t.tcp);
  }
  // The last guard (issue 40): a compensated number that is not finite is an error naming its
  // line, never written.
  for (const ProgramTarget& t : program->targets) {
    if (t.status != ProgramTargetStatus::kCompensated) continue;
    bool finite = std::isfinite(t.correction_mm) && std::isfinite(t.correction_deg);
    for (double v : t.new_values) finite = finite && std::isfinite(v);
    for (double v : t.new_quadrants) finite = finite && std::isfinite(v);
    if (!finite) {
      return Status::Error("line " + std::to_string(t.line) + ": target " + t.name +
                           ": the compensation is not finite (the models predict NaN or "
                           "infinity there); nothing written");
    }
  }
  return Status::Ok();
}

Status CompensateProgramText(std::string_view text, ProgramLanguage language,
                             const RobotModel& calibrated, const RobotModel& nominal,
                             const ProgramOptions& options, std::string* output,
                             ParsedProgram* program) {
  if (Status s = ParseProgram(text, language, program); !s.ok()) return s;
  // A text with no target in the language given that reads as the other language's program is
  // the wrong --language (issue 40), not a program with nothing to compensate.
  if (program->targets.empty()) {
    const ProgramLanguage other =
        language == ProgramLanguage::kRapid ? ProgramLanguage::kUrScript : ProgramLanguage::kRapid;
    ParsedProgram probe;
    if (ParseProgram(text, other, &probe).ok() && !probe.targets.empty()) {
      return Status::Error(std::string("the text has no ") + ProgramLanguageName(language) +
                           " motion target but reads as a " + ProgramLanguageName(other) +
                           " program (" + std::to_string(probe.targets.size()) +
                           " targets, the first on line " + std::to_string(probe.targets[0].line) +
                           "): the language given does not fit the text");
    }
  }
  if (Status s = CompensateProgram(calibrated, nominal, options, program); !s.ok()) return s;
  *output = RewriteProgram(text, *program);
  return Status::Ok();
}

}  // namespace lpoe
