// Robot programs: the compensation step, the same for every language (lpoe/program.h). The text
// side (tokens, rewriter, report) is program_text.cc; the parsers program_urscript.cc and
// program_rapid.cc.
#include "lpoe/program.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "lpoe/compensation.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/model/refusals.h"

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

std::string ProgramFrame(const RobotModel& nominal, ProgramLanguage language,
                         const std::string& frame) {
  if (!frame.empty()) return frame;
  // A UR controller's poses are in its Base frame, which ur_description calls `base` (base_link
  // turned by pi about z): the URScript default when the model has that frame.
  if (language == ProgramLanguage::kUrScript && nominal.FindFrame("base", false) != nullptr) {
    return "link:base";
  }
  return "base";
}

namespace {

// The compensation of the targets of one TCP: the request of lpoe_compensate's targets mode (and
// of its joints mode, for joint targets) with that TCP on the flange, and the controller's
// (nominal) inverse kinematics on the same TCP tool.
struct TcpSolvers {
  std::unique_ptr<Compensator> targets, joints;
  std::unique_ptr<InverseKinematics> controller;
  std::unique_ptr<KinematicChain> nominal_chain;
  int tool = 0;
};

// What every target of a program is compensated with: the flange and the frame of its poses.
struct ProgramSetting {
  std::string flange_name;
  TargetFrame frame_kind = TargetFrame::kBase;
  std::string frame_link;
};

// The models against each other and the program's flange and frame (program->flange, ->frame).
Status CheckProgramModels(const RobotModel& calibrated, const RobotModel& nominal,
                          const ProgramOptions& options, ParsedProgram* program,
                          ProgramSetting* setting) {
  if (calibrated.num_joints() != nominal.num_joints()) {
    return Status::Error("the calibrated model has " + std::to_string(calibrated.num_joints()) +
                         " joints, the nominal " + std::to_string(nominal.num_joints()));
  }
  for (const RobotModel* m : {&calibrated, &nominal}) {
    if (Status s = InverseKinematics::CheckModel(*m); !s.ok()) return s;
  }
  // The same check as lpoe_compensate --targets (lpoe/model/refusals.h): the nominal model describes the
  // calibrated arm.
  if (Status s = CheckNominalMatches(calibrated, nominal); !s.ok()) {
    return Status::Error("nominal: " + s.message());
  }
  SE3d flange_pose;
  std::string& flange_name = setting->flange_name;
  if (Status s = FindFlange(calibrated, options.flange, &flange_pose, &flange_name); !s.ok()) {
    return s;
  }
  if (SE3d unused; !FindFlange(nominal, flange_name, &unused).ok()) {
    return Status::Error("the nominal model " + nominal.name + " has no flange '" + flange_name +
                         "' (the calibrated model's)");
  }
  program->flange = flange_name.empty() ? "the last joint's frame" : flange_name;
  program->frame = ProgramFrame(nominal, program->language, options.frame);
  if (!ParseTargetFrame(program->frame, &setting->frame_kind, &setting->frame_link) ||
      setting->frame_kind == TargetFrame::kMeasurement) {
    return Status::Error("frame '" + program->frame +
                         "': a program's poses are in the base frame (base) or a controller base "
                         "of the models (link:NAME), which its controller knows");
  }
  return Status::Ok();
}

// The compensable targets in the order the program reaches them; every target's compensation
// reset, the unused ones marked.
std::vector<int> TargetsInMotionOrder(ParsedProgram* program) {
  std::vector<int> order;
  for (int k = 0; k < static_cast<int>(program->targets.size()); ++k) {
    ProgramTarget& t = program->targets[k];
    t.status = ProgramTargetStatus::kNotCompensated;
    t.new_values.clear();
    t.new_quadrants.clear();
    t.q_compensated.clear();
    t.q_controller.clear();
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
  return order;
}

// The last guard: a compensated number that is not finite is an error naming its line, never
// written.
Status CheckCompensationFinite(const ParsedProgram& program) {
  for (const ProgramTarget& t : program.targets) {
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

// The targets of one program compensated in motion order: each seeded at the previous one's
// joints (the controller's), with one set of solvers per distinct TCP.
class ProgramCompensator {
 public:
  ProgramCompensator(const RobotModel& calibrated, const RobotModel& nominal,
                     const ProgramOptions& options, const ProgramSetting& setting,
                     ParsedProgram* program)
      : calibrated_(calibrated),
        nominal_(nominal),
        options_(options),
        setting_(setting),
        program_(program),
        n_(calibrated.num_joints()),
        seed_(n_),
        q_nom_(n_),
        q_cal_(n_) {
    nominal_options_ = options.ik;
    nominal_options_.check_branch = false;
    const Joint& last = calibrated.joints.back();
    last_revolute_ = last.type == JointType::kRevolute;
    axis_w_ = last.twist.head<3>().normalized();
    axis_point_ = axis_w_.cross(last.twist.tail<3>());
  }

  // The joints before the first target: `home`, else the middle of the nominal limits.
  Status Start() {
    prev_.assign(n_, 0.0);
    if (!options_.home.empty()) {
      if (static_cast<int>(options_.home.size()) != n_) {
        return Status::Error("home has " + std::to_string(options_.home.size()) +
                             " joints, the model " + std::to_string(n_));
      }
      prev_ = options_.home;
      return Status::Ok();
    }
    for (int j = 0; j < n_; ++j) {
      const Joint& J = nominal_.joints[j];
      if (std::isfinite(J.lower) && std::isfinite(J.upper)) prev_[j] = 0.5 * (J.lower + J.upper);
    }
    return Status::Ok();
  }

  Status Compensate(ProgramTarget* t, bool wanted) {
    // The point on the flange that moves: the TCP, or for a stationary tool the work object the
    // robot holds.
    TcpSolvers* ts = SolversFor(t->stationary_tool ? t->frame : t->tcp);
    if (ts == nullptr) return failed_;
    if (t->kind == ProgramTargetKind::kJoint) {
      JointTarget(*ts, wanted, t);
    } else {
      CartesianTarget(*ts, wanted, t);
    }
    return Status::Ok();
  }

 private:
  // The solvers of a TCP, made when first needed (null when they cannot be: failed_ says why).
  TcpSolvers* SolversFor(const SE3d& tcp) {
    std::vector<double> key(tcp.R.data(), tcp.R.data() + 9);
    key.insert(key.end(), tcp.t.data(), tcp.t.data() + 3);
    auto it = solvers_.find(key);
    if (it != solvers_.end()) return &it->second;
    CompensationRequest r;
    r.model = calibrated_;
    r.has_nominal = true;
    r.nominal = nominal_;
    r.frame = setting_.frame_kind;
    r.frame_link = setting_.frame_link;
    const Eigen::Vector3d rpy = RpyFromRotation(tcp.R);
    r.tcp_offset = {tcp.t.x(), tcp.t.y(), tcp.t.z(), rpy.x(), rpy.y(), rpy.z()};
    r.flange = setting_.flange_name;
    r.ik = options_.ik;
    r.threads = 1;
    TcpSolvers ts;
    if (Status s = Compensator::Create(r, &ts.targets); !s.ok()) {
      failed_ = s;
      return nullptr;
    }
    r.joints_mode = true;
    r.joints_target_pose = true;
    r.frame = TargetFrame::kBase;
    if (Status s = Compensator::Create(r, &ts.joints); !s.ok()) {
      failed_ = s;
      return nullptr;
    }
    ts.tool = ts.targets->default_tool();
    ts.controller = std::make_unique<InverseKinematics>(ts.targets->nominal(), nominal_options_);
    ts.nominal_chain = std::make_unique<KinematicChain>(ts.targets->nominal());
    return &solvers_.emplace(key, std::move(ts)).first->second;
  }

  // The TCP's distance from the last joint's axis (the flange's rotation about it is identified
  // only with known SMR nests), the largest over the compensated targets.
  void NoteTcp(const TcpSolvers& ts) {
    if (!last_revolute_) return;
    const Eigen::Vector3d r = ts.targets->model().tools[ts.tool].origin.t - axis_point_;
    program_->tcp_off_flange_axis_mm =
        std::max(program_->tcp_off_flange_axis_mm, (r - axis_w_ * axis_w_.dot(r)).norm());
  }

  void Compensated(const TcpSolvers& ts, ProgramTarget* t) {
    t->q_compensated = q_cal_;
    t->q_controller = q_nom_;
    t->status = ProgramTargetStatus::kCompensated;
    t->reason.clear();
    NoteTcp(ts);
  }

  bool Degrees(const ProgramTarget& t, int j) const {
    return t.joint_encoding == JointEncoding::kDegrees &&
           nominal_.joints[j].type == JointType::kRevolute;
  }

  // lpoe_compensate --joints: the nominal TCP pose at the program's joints, reached by the
  // calibrated robot.
  void JointTarget(const TcpSolvers& ts, bool wanted, ProgramTarget* t) {
    if (static_cast<int>(t->numbers.size()) != n_) {
      t->compensable = false;
      t->reason = std::to_string(t->numbers.size()) + " joint values for a robot with " +
                  std::to_string(n_) + " joints";
      return;
    }
    for (int j = 0; j < n_; ++j) {
      q_nom_[j] = Degrees(*t, j) ? t->numbers[j].value / kDeg : t->numbers[j].value;
    }
    prev_ = q_nom_;
    if (!wanted) {
      t->status = ProgramTargetStatus::kNotSelected;
      t->reason = "name does not match targets_only (taught point)";
      return;
    }
    IkTarget target;
    target.tool = ts.tool;
    const IkResult r = ts.joints->SolveRow(&target, q_nom_.data(), q_cal_.data());
    if (r.status != IkStatus::kOk) {
      t->reason = std::string("the calibrated robot reaches this pose ") + IkReason(r.status);
      return;
    }
    double max_dq = 0;
    for (int j = 0; j < n_; ++j) {
      t->new_values.push_back(Degrees(*t, j) ? q_cal_[j] * kDeg : q_cal_[j]);
      if (nominal_.joints[j].type == JointType::kRevolute) {
        max_dq = std::max(max_dq, std::abs(q_cal_[j] - q_nom_[j]) * kDeg);
      }
    }
    const SE3d a = ts.nominal_chain->Pose(q_nom_.data(), ts.tool);
    const SE3d b = ts.nominal_chain->Pose(q_cal_.data(), ts.tool);
    t->correction_mm = (b.t - a.t).norm();
    t->correction_deg = max_dq;
    Compensated(ts, t);
  }

  void CartesianTarget(const TcpSolvers& ts, bool wanted, ProgramTarget* t) {
    SE3d pose;
    std::string why;
    if (!DecodePose(*t, &pose, &why)) {
      t->compensable = false;
      t->reason = why;
      return;
    }
    // The controller's seed: qnear, else the previous target's joints moved into the quadrants.
    seed_ = static_cast<int>(t->qnear.size()) == n_ ? t->qnear : prev_;
    for (const ProgramTarget::Quadrant& qd : t->quadrants) {
      if (qd.joint < n_ && Quadrant(seed_[qd.joint]) != static_cast<int>(qd.number.value)) {
        seed_[qd.joint] = (qd.number.value + 0.5) * kPi / 2;
      }
    }
    // The target in the program's frame, and in the models' base frame for the controller.
    // Robot-held tool: the TCP (flange * tcp) at the target in the work object (frame * pose).
    // Stationary tool (tcp fixed in the program's frame): the work object the robot holds
    // (flange * frame) where flange * frame * pose = tcp.
    const SE3d in_frame = t->stationary_tool ? t->tcp * pose.Inverse() : t->frame * pose;
    const SE3d in_base = ts.targets->frame_pose() * in_frame;
    IkTarget target;
    target.tool = ts.tool;
    target.position = in_base.t;
    target.rotation = in_base.R;
    target.has_orientation = true;
    const IkResult rn = ts.controller->Solve(target, seed_.data(), q_nom_.data());
    if (rn.status != IkStatus::kOk && rn.status != IkStatus::kBranch) {
      t->reason = std::string("the nominal model reaches this target ") + IkReason(rn.status) +
                  " (the controller would not run it)";
      return;
    }
    prev_ = q_nom_;
    if (!wanted) {
      t->status = ProgramTargetStatus::kNotSelected;
      t->reason = "name does not match targets_only (taught point)";
      return;
    }
    // Exactly a --targets row: this pose in the program's frame, this TCP, seeded at q_nom.
    target.position = in_frame.t;
    target.rotation = in_frame.R;
    const IkResult rc = ts.targets->SolveRow(&target, q_nom_.data(), q_cal_.data());
    if (rc.status != IkStatus::kOk) {
      t->reason = std::string("the calibrated robot reaches this target ") + IkReason(rc.status);
      return;
    }
    const SE3d moved = ts.nominal_chain->Pose(q_cal_.data(), ts.tool);
    const SE3d corrected = t->stationary_tool
                               ? moved.Inverse() * ts.targets->frame_pose() * t->tcp
                               : (ts.targets->frame_pose() * t->frame).Inverse() * moved;
    t->new_values = EncodePose(*t, corrected);
    for (const ProgramTarget::Quadrant& qd : t->quadrants) {
      t->new_quadrants.push_back(qd.joint < n_ ? Quadrant(q_cal_[qd.joint]) : qd.number.value);
    }
    t->correction_mm = (corrected.t - pose.t).norm();
    t->correction_deg = Angle(pose.R.transpose() * corrected.R) * kDeg;
    Compensated(ts, t);
  }

  const RobotModel& calibrated_;
  const RobotModel& nominal_;
  const ProgramOptions& options_;
  const ProgramSetting& setting_;
  ParsedProgram* program_;
  const int n_;
  IkOptions nominal_options_;
  bool last_revolute_ = false;
  Eigen::Vector3d axis_w_, axis_point_;
  std::map<std::vector<double>, TcpSolvers> solvers_;
  Status failed_ = Status::Ok();
  std::vector<double> prev_, seed_, q_nom_, q_cal_;
};

}  // namespace

Status CompensateProgram(const RobotModel& calibrated, const RobotModel& nominal,
                         const ProgramOptions& options, ParsedProgram* program) {
  ProgramSetting setting;
  if (Status s = CheckProgramModels(calibrated, nominal, options, program, &setting); !s.ok()) {
    return s;
  }
  TargetNameFilter selected;
  if (Status s = selected.Compile(options.targets_only); !s.ok()) return s;
  ProgramCompensator compensator(calibrated, nominal, options, setting, program);
  if (Status s = compensator.Start(); !s.ok()) return s;
  const std::vector<int> order = TargetsInMotionOrder(program);
  // The flange's rotation about the last joint's axis: identified only with known SMR nests.
  program->flange_rotation_identified = calibrated.HasFixedTool();
  program->fixed_tools.clear();
  for (const Tool& tool : calibrated.tools) {
    if (tool.fixed) program->fixed_tools += (program->fixed_tools.empty() ? "" : ", ") + tool.name;
  }
  program->tcp_off_flange_axis_mm = 0;
  for (const int k : order) {
    ProgramTarget& t = program->targets[k];
    const bool wanted = options.targets_only.empty() || selected.Matches(t.name);
    if (Status s = compensator.Compensate(&t, wanted); !s.ok()) return s;
  }
  return CheckCompensationFinite(*program);
}

Status CompensateProgramText(std::string_view text, ProgramLanguage language,
                             const RobotModel& calibrated, const RobotModel& nominal,
                             const ProgramOptions& options, std::string* output,
                             ParsedProgram* program) {
  if (Status s = ParseProgram(text, language, program); !s.ok()) return s;
  // A text with no target in the language given that reads as the other language's program is
  // the wrong --language, not a program with nothing to compensate.
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
