// Robot programs compensated in place: a UR5 URScript program and an ABB-style RAPID
// module, generated on the nominal model; a true robot with errors; a calibration from simulated
// tracker data; the compensated programs run by a simulated controller (the nominal model's
// inverse kinematics) on the true robot.
#include "lpoe/program.h"
#include "lpoe/model/refusals.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>
#include <string>
#include <vector>

#include "lpoe/compensation.h"
#include "lpoe/inverse_kinematics.h"
#include "lpoe/io/io.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/pipeline.h"
#include "lpoe/model/simulation.h"

namespace lpoe {
namespace {
namespace program_test {

constexpr double kDeg = 180.0 / kPi;

// Deterministic uniform numbers.
class Random {
 public:
  explicit Random(uint64_t seed) : s_(seed * 6364136223846793005ULL + 1442695040888963407ULL) {}
  double Uniform(double a, double b) {
    s_ = s_ * 6364136223846793005ULL + 1442695040888963407ULL;
    return a + (b - a) * static_cast<double>(s_ >> 11) / static_cast<double>(1ULL << 53);
  }

 private:
  uint64_t s_;
};

std::string Num(double x, int decimals) {
  char b[64];
  std::snprintf(b, sizeof(b), "%.*f", decimals, x);
  return b;
}

// The true robot, its calibration and the nominal model, made once for all tests.
struct Cell {
  RobotModel nominal, actual, calibrated;
  std::vector<double> joint_zero;
  int flange = -1;
};

const Cell& TheCell() {
  static const Cell* cell = [] {
    Cell* c = new Cell;
    c->nominal = MakeUr5Like();
    Tool flange;
    flange.name = "flange";
    c->nominal.tools.push_back(flange);
    c->flange = c->nominal.FindTool("flange");
    KinematicErrors errors = RandomErrors(c->nominal, 0.02, 8.0, 0.01, 0.02, 32);
    // The nest's and the flange's frames are known (the fixture): no error there. The last link's
    // frame and its joint zero have errors like every other joint's: calibrating with the nest
    // held fixed (--fixed_tools, docs/identifiability.md "Known SMR nests") identifies them.
    const int n = c->nominal.num_joints();
    for (int t = 0; t < c->nominal.num_tools(); ++t) errors.frame[n + t].setZero();
    c->actual = ApplyErrors(c->nominal, errors);
    EXPECT_TRUE(SetFixedTools({c->nominal.tools[0].name}, &c->nominal).ok());
    c->joint_zero = errors.joint_zero;
    SimulationOptions o;
    o.count = 200;
    o.noise_sigma = 0.005;
    o.seed = 5;
    o.lower = {-2.5, -2.5, -2.5, -2.5, -2.5, -2.5};
    o.upper = {2.5, 2.5, 2.5, 2.5, 2.5, 2.5};
    MeasurementSet data = SimulateMeasurements(c->actual, c->joint_zero, o);
    // The tracker's frame registered to the robot's base (the programs' frame): a calibration
    // in another frame places the robot there by a rigid fit, which absorbs part of the base's
    // error, and the programs' targets must then be measured in that frame too.
    PipelineOptions options;
    options.kfold = 0;
    const PipelineResult r = RunCalibrationPipeline(c->nominal, data, MeasurementSet(), options);
    EXPECT_EQ(r.result.termination, Termination::kConverged) << r.result.message;
    c->calibrated = r.result.model;
    // As lpoe_calibrate writes it: the registration, for compensation, when it moved the base.
    if (r.registered && r.registration.moved) {
      c->calibrated.T_measurement_base = r.registration.T_measurement_base;
    }
    return c;
  }();
  return *cell;
}

// Where the true robot's TCP is at commanded joints q.
SE3d TrueTcp(const Cell& c, const std::vector<double>& q, const SE3d& tcp) {
  std::vector<double> qa(q);
  for (size_t j = 0; j < qa.size(); ++j) qa[j] += c.joint_zero[j];
  return ToolPose(c.actual, qa.data(), c.flange) * tcp;
}

// The simulated controller: the nominal model's inverse kinematics from `seed`.
bool ControllerIk(const Cell& c, const SE3d& tcp_base, const SE3d& tcp,
                  const std::vector<double>& seed, std::vector<double>* q) {
  IkOptions o;
  o.check_branch = false;
  const InverseKinematics ik(c.nominal, o);
  IkTarget t;
  t.tool = c.flange;
  const SE3d f = tcp_base * tcp.Inverse();
  t.position = f.t;
  t.rotation = f.R;
  t.has_orientation = true;
  q->resize(seed.size());
  const IkResult r = ik.Solve(t, seed.data(), q->data());
  return r.status == IkStatus::kOk || r.status == IkStatus::kBranch;
}

// A direct calibrated inverse kinematics from `seed`.
std::vector<double> CalibratedIk(const Cell& c, const SE3d& tcp_base, const SE3d& tcp,
                                 const std::vector<double>& seed) {
  const InverseKinematics ik(c.calibrated);
  IkTarget t;
  t.tool = c.calibrated.FindTool("flange");
  const SE3d f = c.calibrated.T_measurement_base * tcp_base * tcp.Inverse();
  t.position = f.t;
  t.rotation = f.R;
  t.has_orientation = true;
  std::vector<double> q(seed.size());
  ik.Solve(t, seed.data(), q.data());
  return q;
}

// Every byte outside the numbers of compensated targets is the input's; the numbers parse.
void ExpectOnlyNumbersChanged(const std::string& in, const std::string& out,
                              const ParsedProgram& program) {
  std::vector<std::pair<size_t, size_t>> spans;
  for (const ProgramTarget& t : program.targets) {
    if (t.status != ProgramTargetStatus::kCompensated) continue;
    for (const ProgramNumber& n : t.numbers) spans.emplace_back(n.begin, n.end);
    for (const auto& q : t.quadrants) spans.emplace_back(q.number.begin, q.number.end);
  }
  std::sort(spans.begin(), spans.end());
  size_t at = 0, o = 0;
  for (const auto& s : spans) {
    const std::string_view seg(in.data() + at, s.first - at);
    ASSERT_EQ(std::string_view(out).substr(o, seg.size()), seg) << "at input byte " << at;
    o += seg.size();
    size_t k = o;
    if (k < out.size() && (out[k] == '-' || out[k] == '+')) ++k;
    double v;
    const auto r = std::from_chars(out.data() + k, out.data() + out.size(), v);
    ASSERT_EQ(r.ec, std::errc()) << "no number at output byte " << o;
    o = r.ptr - out.data();
    at = s.second;
  }
  EXPECT_EQ(std::string_view(out).substr(o), std::string_view(in).substr(at));
}

struct Errors {
  std::vector<double> compensated, direct, uncompensated;
};

// Runs every target of the compensated program (re-parsed from `out`) on the true robot through
// the simulated controller, seeded with the joints the program was planned at (`planned`, by
// target name); the same for the direct calibrated IK and the original program.
Errors RunOnTrueRobot(const Cell& c, const ParsedProgram& before, const std::string& out,
                      ProgramLanguage language,
                      const std::vector<std::pair<std::string, std::vector<double>>>& planned) {
  ParsedProgram after;
  EXPECT_TRUE(ParseProgram(out, language, &after).ok());
  EXPECT_EQ(after.targets.size(), before.targets.size());
  Errors e;
  for (size_t k = 0; k < before.targets.size() && k < after.targets.size(); ++k) {
    const ProgramTarget& b = before.targets[k];
    const ProgramTarget& a = after.targets[k];
    if (b.status != ProgramTargetStatus::kCompensated) continue;
    EXPECT_EQ(a.name, b.name);
    std::vector<double> seed;
    for (const auto& p : planned) {
      if (p.first == b.name) seed = p.second;
    }
    EXPECT_EQ(seed.size(), 6u) << b.name;
    if (seed.size() != 6) continue;
    if (b.kind == ProgramTargetKind::kJoint) {
      std::vector<double> q0(6), q1(6);
      const double s = b.joint_encoding == JointEncoding::kDegrees ? 1 / kDeg : 1;
      for (int j = 0; j < 6; ++j) {
        q0[j] = b.numbers[j].value * s;
        q1[j] = a.numbers[j].value * s;
      }
      const SE3d wanted = ToolPose(c.nominal, q0.data(), c.flange) * b.tcp;
      e.compensated.push_back((TrueTcp(c, q1, b.tcp).t - wanted.t).norm());
      e.direct.push_back(
          (TrueTcp(c, CalibratedIk(c, wanted, b.tcp, q0), b.tcp).t - wanted.t).norm());
      e.uncompensated.push_back((TrueTcp(c, q0, b.tcp).t - wanted.t).norm());
      continue;
    }
    auto pose = [&](const ProgramTarget& t) {
      SE3d T;
      const auto& v = t.numbers;
      if (t.pose_encoding == PoseEncoding::kMetresRotationVector) {
        T.t = Eigen::Vector3d(v[0].value, v[1].value, v[2].value) * 1000;
        T.R = ExpSO3(Eigen::Vector3d(v[3].value, v[4].value, v[5].value));
      } else {
        T.t = Eigen::Vector3d(v[0].value, v[1].value, v[2].value);
        Eigen::Vector4d q(v[4].value, v[5].value, v[6].value, v[3].value);
        T.R = QuaternionToRotation<double>(q / q.norm());
      }
      return b.frame * T;
    };
    const SE3d wanted = pose(b), corrected = pose(a);
    std::vector<double> q_ctrl, q_orig;
    const bool reached = ControllerIk(c, corrected, b.tcp, seed, &q_ctrl) &&
                         ControllerIk(c, wanted, b.tcp, seed, &q_orig);
    EXPECT_TRUE(reached) << b.name;
    if (!reached) continue;
    const std::vector<double> q_direct = CalibratedIk(c, wanted, b.tcp, seed);
    e.compensated.push_back((TrueTcp(c, q_ctrl, b.tcp).t - wanted.t).norm());
    e.direct.push_back((TrueTcp(c, q_direct, b.tcp).t - wanted.t).norm());
    e.uncompensated.push_back((TrueTcp(c, q_orig, b.tcp).t - wanted.t).norm());
    // The controller goes to the calibrated solution, and confdata (RAPID) is that solution's.
    for (int j = 0; j < 6; ++j) EXPECT_NEAR(q_ctrl[j], q_direct[j], 1e-5) << b.name;
    for (const auto& qd : a.quadrants) {
      EXPECT_EQ(qd.number.value, std::floor(q_direct[qd.joint] / (kPi / 2))) << b.name;
    }
  }
  return e;
}

void ExpectCompensated(const Errors& e, size_t at_least) {
  ASSERT_GE(e.compensated.size(), at_least);
  double sum_unc = 0, max_comp = 0, max_direct = 0;
  for (size_t k = 0; k < e.compensated.size(); ++k) {
    EXPECT_LE(e.compensated[k], 1.5 * e.direct[k] + 1e-3) << "target " << k;
    sum_unc += e.uncompensated[k];
    max_comp = std::max(max_comp, e.compensated[k]);
    max_direct = std::max(max_direct, e.direct[k]);
  }
  const double mean_unc = sum_unc / e.compensated.size();
  EXPECT_GT(mean_unc, 10.0);  // tens of mm before
  EXPECT_LT(max_comp, 0.1 * mean_unc);
  std::printf(
      "  %zu targets: uncompensated mean %.2f mm; compensated max %.4f mm, direct "
      "calibrated IK max %.4f mm\n",
      e.compensated.size(), mean_unc, max_comp, max_direct);
}

// A Polyscope-style URScript program on the nominal model: globals for waypoints (pose and
// joints), a TCP, a feature plane, movej / movel / movec, qnear, a run-time target.
struct Generated {
  std::string text;
  std::vector<std::pair<std::string, std::vector<double>>> planned;  // target name -> joints
};

Generated UrProgram(const Cell& c, int waypoints) {
  Generated g;
  const SE3d tcp(ExpSO3(Eigen::Vector3d(0, 0, 0.3)), Eigen::Vector3d(15, -25, 160));
  const SE3d plane(ExpSO3(Eigen::Vector3d(0.05, -0.02, 0.6)), Eigen::Vector3d(-300, -250, 120));
  const Eigen::Vector3d tcp_rv = LogSO3(tcp.R), plane_rv = LogSO3(plane.R);
  std::string head =
      "def Program():\n  set_standard_analog_input_domain(0, 1)\n"
      "  set_tcp(p[" +
      Num(tcp.t.x() / 1000, 6) + ", " + Num(tcp.t.y() / 1000, 6) + ", " + Num(tcp.t.z() / 1000, 6) +
      ", " + Num(tcp_rv.x(), 6) + ", " + Num(tcp_rv.y(), 6) + ", " + Num(tcp_rv.z(), 6) + "])\n";
  head += "  global Plane_1=p[" + Num(plane.t.x() / 1000, 6) + "," + Num(plane.t.y() / 1000, 6) +
          "," + Num(plane.t.z() / 1000, 6) + "," + Num(plane_rv.x(), 6) + "," +
          Num(plane_rv.y(), 6) + "," + Num(plane_rv.z(), 6) + "]\n";
  // The same TCP and plane as the program reads them (6 decimals).
  std::string body = "  $ 1 \"Robot Program\"\n";
  Random rng(7);
  const double centre[6] = {0.4, -1.3, 1.6, -1.9, -1.5, 0.4};
  auto joints = [&]() {
    std::vector<double> q(6);
    for (int j = 0; j < 6; ++j) q[j] = centre[j] + rng.Uniform(-0.35, 0.35);
    return q;
  };
  auto pose_text = [&](const SE3d& X) {
    const Eigen::Vector3d rv = LogSO3(X.R);
    return "p[" + Num(X.t.x() / 1000, 12) + ", " + Num(X.t.y() / 1000, 12) + ", " +
           Num(X.t.z() / 1000, 12) + ", " + Num(rv.x(), 12) + ", " + Num(rv.y(), 12) + ", " +
           Num(rv.z(), 12) + "]";
  };
  auto joint_text = [&](const std::vector<double>& q) {
    std::string s = "[";
    for (int j = 0; j < 6; ++j) s += (j ? ", " : "") + Num(q[j], 12);
    return s + "]";
  };
  // The TCP and plane the controller uses are the ones written (6 decimals): re-read them.
  ParsedProgram probe;
  EXPECT_TRUE(ParseProgram(head + "movel(pose_trans(Plane_1, p[0,0,0,0,0,0]))\n",
                           ProgramLanguage::kUrScript, &probe)
                  .ok());
  const SE3d tcp_used = probe.targets.at(0).tcp, plane_used = probe.targets.at(0).frame;
  for (int k = 1; k <= waypoints; ++k) {
    const std::vector<double> q = joints();
    const SE3d base_tcp = ToolPose(c.nominal, q.data(), c.flange) * tcp_used;
    const std::string w = "Waypoint_" + std::to_string(k);
    switch (k % 5) {
      case 0:  // joint waypoint
        head += "  global " + w + "_q=" + joint_text(q) + "\n";
        body += "  movej(" + w + "_q, a=1.3962634015954636, v=1.0471975511965976)\n";
        g.planned.push_back({w + "_q", q});
        break;
      case 1:  // pose + qnear, in the feature
        head += "  global " + w + "_p=" + pose_text(plane_used.Inverse() * base_tcp) + "\n";
        head += "  global " + w + "_q=" + joint_text(q) + "\n";
        body += "  movej(get_inverse_kin(pose_trans(Plane_1, " + w + "_p), qnear=" + w +
                "_q), a=1.39, v=1.04)\n";
        g.planned.push_back({w + "_p", q});
        break;
      case 2:  // movel in the feature; Polyscope's companion joints, unused
        head += "  global " + w + "_p=" + pose_text(plane_used.Inverse() * base_tcp) + "\n";
        head += "  global " + w + "_q=" + joint_text(q) + "\n";
        body += "  movel(pose_trans(Plane_1, " + w + "_p), a=1.2, v=0.25)\r\n";
        g.planned.push_back({w + "_p", q});
        break;
      case 3: {  // inline literal, base frame
        body += "  movel(" + pose_text(base_tcp) + ", a=1.2, v=0.25, r=0.005)\n";
        g.planned.push_back({"#inline", q});
        break;
      }
      case 4: {  // movec: via and to
        const std::vector<double> q2 = joints();
        const SE3d to = ToolPose(c.nominal, q2.data(), c.flange) * tcp_used;
        body += "  movec(" + pose_text(base_tcp) + ",  " + pose_text(to) +
                ", a=1.2, v=0.25, r=0, mode=0)\n";
        g.planned.push_back({"#inline", q});
        g.planned.push_back({"#inline", q2});
        break;
      }
    }
  }
  body += "  movel(pose_add(get_actual_tcp_pose(), p[0, 0, 0.01, 0, 0, 0]), a=1.2, v=0.25)\n";
  body += "  # a comment with p[1, 2, 3, 4, 5, 6] and movel(p[0,0,0,0,0,0])\n";
  g.text = head + body + "end\n";
  return g;
}

// Fills the inline targets' names ("#inline" placeholders, in text order) from the parse.
void NameInline(const ParsedProgram& p,
                std::vector<std::pair<std::string, std::vector<double>>>* planned) {
  size_t k = 0;
  for (const ProgramTarget& t : p.targets) {
    if (t.name.find(':') == std::string::npos || t.numbers.empty()) continue;
    while (k < planned->size() && (*planned)[k].first != "#inline") ++k;
    if (k == planned->size()) break;
    (*planned)[k++].first = t.name;
  }
}

TEST(Program, UrScriptCompensatedOnTheTrueRobot) {
  const Cell& c = TheCell();
  Generated g = UrProgram(c, 110);
  ParsedProgram program;
  std::string out;
  ProgramOptions options;
  ASSERT_TRUE(CompensateProgramText(g.text, ProgramLanguage::kUrScript, c.calibrated, c.nominal,
                                    options, &out, &program)
                  .ok());
  NameInline(program, &g.planned);
  int compensated = 0, runtime = 0;
  for (const ProgramTarget& t : program.targets) {
    if (t.status == ProgramTargetStatus::kCompensated) ++compensated;
    if (t.name.rfind("movel:", 0) == 0 && t.numbers.empty()) {
      ++runtime;
      EXPECT_NE(t.reason.find("pose_add(get_actual_tcp_pose()"), std::string::npos) << t.reason;
    }
    if (t.status != ProgramTargetStatus::kCompensated) {
      EXPECT_TRUE(t.name.rfind("movel:", 0) == 0 && t.numbers.empty())
          << t.name << " line " << t.line << ": " << t.reason;
    }
  }
  EXPECT_EQ(runtime, 1);
  EXPECT_GE(compensated, 100);
  // No feature, TCP, qnear or unused companion among the targets.
  for (const ProgramTarget& t : program.targets) {
    EXPECT_NE(t.name, "Plane_1");
    EXPECT_FALSE(t.name.size() > 2 && t.name.compare(t.name.size() - 2, 2, "_q") == 0 &&
                 t.name.rfind("Waypoint_", 0) == 0 && std::stoi(t.name.substr(9)) % 5 != 0);
  }
  ExpectOnlyNumbersChanged(g.text, out, program);
  ExpectCompensated(RunOnTrueRobot(c, program, out, ProgramLanguage::kUrScript, g.planned), 100);
}

// An ABB-style module: tooldata, a wobjdata with user and object frames, robtargets with
// confdata, a jointtarget with MoveAbsJ, inline targets, Offs; CRLF line ends.
Generated RapidProgram(const Cell& c, int points) {
  Generated g;
  auto quat = [](const Eigen::Matrix3d& R) {
    const Eigen::Vector4d q = RotationToQuaternion<double>(R);
    return "[" + Num(q(3), 9) + "," + Num(q(0), 9) + "," + Num(q(1), 9) + "," + Num(q(2), 9) + "]";
  };
  auto xyz = [](const Eigen::Vector3d& t, int d) {
    return "[" + Num(t.x(), d) + "," + Num(t.y(), d) + "," + Num(t.z(), d) + "]";
  };
  const SE3d tool(ExpSO3(Eigen::Vector3d(0, 0.2, 0.1)), Eigen::Vector3d(12, -30, 180));
  const SE3d user(ExpSO3(Eigen::Vector3d(0, 0, 0.5)), Eigen::Vector3d(-350, -300, 50));
  const SE3d object(ExpSO3(Eigen::Vector3d(0.02, 0, -0.3)), Eigen::Vector3d(40, 25, 10));
  std::string decl = "%%%\r\n  VERSION:1\r\n  LANGUAGE:ENGLISH\r\n%%%\r\n\r\nMODULE MainModule\r\n";
  decl += "  ! Generated for the compensation test\r\n";
  decl += "  PERS tooldata tGripper:=[TRUE,[" + xyz(tool.t, 3) + "," + quat(tool.R) +
          "],[2.5,[0,0,80],[1,0,0,0],0,0,0]];\r\n";
  decl += "  TASK PERS wobjdata wTable:=[FALSE,TRUE,\"\",[" + xyz(user.t, 3) + "," + quat(user.R) +
          "],[" + xyz(object.t, 3) + "," + quat(object.R) + "]];\r\n";
  std::string body = "  PROC main()\r\n";
  ParsedProgram probe;
  EXPECT_TRUE(
      ParseProgram(
          decl + "PROC x()\r\nMoveL [[0,0,0],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]], v10, "
                 "fine, tGripper\\WObj:=wTable;\r\nENDPROC\r\nENDMODULE\r\n",
          ProgramLanguage::kRapid, &probe)
          .ok());
  const SE3d tcp_used = probe.targets.at(0).tcp, wobj_used = probe.targets.at(0).frame;
  Random rng(11);
  const double centre[6] = {0.3, -1.4, 1.5, -1.7, -1.5, 0.8};
  auto joints = [&]() {
    std::vector<double> q(6);
    for (int j = 0; j < 6; ++j) q[j] = centre[j] + rng.Uniform(-0.35, 0.35);
    return q;
  };
  auto robtarget = [&](const std::vector<double>& q) {
    const SE3d X = wobj_used.Inverse() * ToolPose(c.nominal, q.data(), c.flange) * tcp_used;
    auto cf = [&](int j) { return std::to_string(static_cast<int>(std::floor(q[j] / (kPi / 2)))); };
    return "[" + xyz(X.t, 3) + "," + quat(X.R) + ",[" + cf(0) + "," + cf(3) + "," + cf(5) +
           ",0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]]";
  };
  const std::vector<double> home = joints();
  decl += "  CONST jointtarget jHome:=[[";
  for (int j = 0; j < 6; ++j) decl += (j ? "," : "") + Num(home[j] * kDeg, 4);
  decl += "],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];\r\n";
  g.planned.push_back({"jHome", home});
  body += "    MoveAbsJ jHome\\NoEOffs, v1000, z50, tGripper;\r\n";
  for (int k = 1; k <= points; ++k) {
    const std::vector<double> q = joints();
    const std::string name = "p" + std::to_string(k * 10);
    switch (k % 4) {
      case 0:
      case 1:
        decl += "  CONST robtarget " + name + ":=" + robtarget(q) + ";\r\n";
        body += "    Move" + std::string(k % 4 ? "L " : "J ") + name +
                ", v500, z10, tGripper\\WObj:=wTable;\r\n";
        g.planned.push_back({name, q});
        break;
      case 2:
        body += "    MoveL " + robtarget(q) + ", v200, fine, tGripper\\WObj:=wTable;\r\n";
        g.planned.push_back({"#inline", q});
        break;
      case 3: {
        const std::vector<double> q2 = joints();
        decl += "  PERS robtarget " + name + ":=" + robtarget(q2) + ";\r\n";
        body +=
            "    MoveC " + robtarget(q) + ", " + name + ", v100, z5, tGripper\\WObj:=wTable;\r\n";
        body += "    MoveL Offs(" + name + ", 0, 0, 50), v200, z10, tGripper\\WObj:=wTable;\r\n";
        g.planned.push_back({"#inline", q});
        g.planned.push_back({name, q2});
        break;
      }
    }
  }
  body += "  ENDPROC\r\nENDMODULE\r\n";
  g.text = decl + body;
  return g;
}

TEST(Program, RapidCompensatedOnTheTrueRobot) {
  const Cell& c = TheCell();
  Generated g = RapidProgram(c, 60);
  ParsedProgram program;
  std::string out;
  ASSERT_TRUE(CompensateProgramText(g.text, ProgramLanguage::kRapid, c.calibrated, c.nominal,
                                    ProgramOptions(), &out, &program)
                  .ok());
  NameInline(program, &g.planned);
  int offs = 0, compensated = 0;
  for (const ProgramTarget& t : program.targets) {
    if (t.status == ProgramTargetStatus::kCompensated) {
      ++compensated;
      continue;
    }
    EXPECT_TRUE(t.numbers.empty()) << t.name << " line " << t.line << ": " << t.reason;
    EXPECT_NE(t.reason.find("Offs("), std::string::npos) << t.reason;
    ++offs;
  }
  EXPECT_EQ(offs, 15);
  EXPECT_GE(compensated, 70);
  ExpectOnlyNumbersChanged(g.text, out, program);
  int quadrants_changed = 0;
  for (const ProgramTarget& t : program.targets) {
    for (size_t k = 0; k < t.new_quadrants.size(); ++k) {
      quadrants_changed += t.new_quadrants[k] != t.quadrants[k].number.value;
    }
  }
  EXPECT_GT(quadrants_changed, 0);  // joint 1 near 0: some targets change quadrant (RunOnTrueRobot)
  // The CRLF line ends are all still there.
  EXPECT_EQ(std::count(out.begin(), out.end(), '\r'),
            std::count(g.text.begin(), g.text.end(), '\r'));
  ExpectCompensated(RunOnTrueRobot(c, program, out, ProgramLanguage::kRapid, g.planned), 70);
}

// RAPID's robhold as the RAPID reference manual defines it: in tooldata TRUE means the robot holds
// the tool, FALSE a stationary tool; in wobjdata TRUE means the robot holds the work object (used
// with a stationary tool). The usual module (tooldata TRUE, wobj0) is compensated; the inverted
// reading would leave it alone.
TEST(Program, RapidRobholdAsRapidDefinesIt) {
  const Cell& c = TheCell();
  const std::string target = "[[150,-450,350],[0,0,1,0],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]]";
  auto module = [&](const std::string& tool_robhold, const std::string& wobj_robhold) {
    return "MODULE M\n"
           "  PERS tooldata tool1:=[" + tool_robhold +
           ",[[0,15,140],[1,0,0,0]],[1,[0,0,1],[1,0,0,0],0,0,0]];\n"
           "  PERS wobjdata wobj1:=[" + wobj_robhold +
           ",TRUE,\"\",[[0,0,0],[1,0,0,0]],[[0,0,0],[1,0,0,0]]];\n"
           "  CONST robtarget p1:=" + target + ";\n"
           "  PROC main()\n"
           "    MoveL p1, v100, fine, tool1\\WObj:=wobj1;\n"
           "  ENDPROC\n"
           "ENDMODULE\n";
  };
  struct Case {
    const char* tool;
    const char* wobj;
    bool compensated, stationary;
    const char* reason;
  };
  const Case cases[] = {
      {"TRUE", "FALSE", true, false, ""},  // the robot holds the tool: the common case
      {"FALSE", "TRUE", true, true, ""},   // a stationary tool, the robot holds the work object
      {"FALSE", "FALSE", false, false, "tool tool1 is a stationary tool (robhold FALSE)"},
      {"TRUE", "TRUE", false, false, "work object wobj1 is held by the robot (robhold TRUE"},
      {"held", "FALSE", false, false, "tool tool1: its robhold is not TRUE or FALSE"},
  };
  for (const Case& k : cases) {
    const std::string text = module(k.tool, k.wobj);
    ParsedProgram program;
    std::string out;
    ASSERT_TRUE(CompensateProgramText(text, ProgramLanguage::kRapid, c.calibrated, c.nominal,
                                      ProgramOptions(), &out, &program)
                    .ok())
        << text;
    ASSERT_EQ(program.targets.size(), 1u);
    const ProgramTarget& t = program.targets[0];
    EXPECT_EQ(t.status == ProgramTargetStatus::kCompensated, k.compensated)
        << k.tool << " " << k.wobj << ": " << t.reason;
    EXPECT_EQ(t.stationary_tool, k.stationary) << k.tool << " " << k.wobj;
    EXPECT_NE(t.reason.find(k.reason), std::string::npos) << t.reason;
    EXPECT_EQ(out != text, k.compensated);
    if (k.compensated) {
      EXPECT_GT(t.correction_mm, 1.0);
      EXPECT_EQ(ProgramReportJson(program).find("\"stationary_tool\": true") != std::string::npos,
                k.stationary);
    }
  }
}

// A stationary tool (tooldata robhold FALSE, its tframe in the world frame) and a work object the
// robot holds (wobjdata robhold TRUE, its uframe on the flange): the robtarget is the tool's pose in
// the work object. The controller puts the flange at tframe * target^-1 * (uframe oframe)^-1; on the
// true robot the compensated targets are as accurate as a direct calibrated IK.
TEST(Program, RapidStationaryToolCompensatedOnTheTrueRobot) {
  const Cell& c = TheCell();
  auto quat = [](const Eigen::Matrix3d& R) {
    const Eigen::Vector4d q = RotationToQuaternion<double>(R);
    return "[" + Num(q(3), 9) + "," + Num(q(0), 9) + "," + Num(q(1), 9) + "," + Num(q(2), 9) + "]";
  };
  auto xyz = [](const Eigen::Vector3d& t) {
    return "[" + Num(t.x(), 4) + "," + Num(t.y(), 4) + "," + Num(t.z(), 4) + "]";
  };
  const SE3d fixed_tool(ExpSO3(Eigen::Vector3d(0.1, 2.9, 0.2)), Eigen::Vector3d(420, 180, 250));
  const SE3d user(ExpSO3(Eigen::Vector3d(0.05, 0, 0.3)), Eigen::Vector3d(10, -20, 110));
  const SE3d object(ExpSO3(Eigen::Vector3d(0, 0.1, 0)), Eigen::Vector3d(30, 0, 15));
  std::string decl = "MODULE M\n  PERS tooldata tFixed:=[FALSE,[" + xyz(fixed_tool.t) + "," +
                     quat(fixed_tool.R) + "],[1,[0,0,1],[1,0,0,0],0,0,0]];\n";
  decl += "  PERS wobjdata wHeld:=[TRUE,TRUE,\"\",[" + xyz(user.t) + "," + quat(user.R) + "],[" +
          xyz(object.t) + "," + quat(object.R) + "]];\n";
  // The frames as the program states them (rounded), from the parser.
  ParsedProgram probe;
  ASSERT_TRUE(ParseProgram(decl + "PROC x()\nMoveL [[0,0,0],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,"
                                  "9E9,9E9]], v10, fine, tFixed\\WObj:=wHeld;\nENDPROC\nENDMODULE\n",
                           ProgramLanguage::kRapid, &probe)
                  .ok());
  ASSERT_TRUE(probe.targets.at(0).stationary_tool);
  const SE3d tool_used = probe.targets[0].tcp, wobj_used = probe.targets[0].frame;
  Random rng(3);
  const double centre[6] = {0.6, -1.5, 1.4, -1.4, -1.6, 0.2};
  std::string body = "  PROC main()\n";
  std::vector<std::pair<std::string, std::vector<double>>> planned;
  for (int k = 1; k <= 20; ++k) {
    std::vector<double> q(6);
    for (int j = 0; j < 6; ++j) q[j] = centre[j] + rng.Uniform(-0.3, 0.3);
    // The tool's pose in the work object the robot holds at q (nominal model).
    const SE3d X = (ToolPose(c.nominal, q.data(), c.flange) * wobj_used).Inverse() * tool_used;
    auto cf = [&](int j) { return std::to_string(static_cast<int>(std::floor(q[j] / (kPi / 2)))); };
    const std::string name = "s" + std::to_string(k);
    decl += "  CONST robtarget " + name + ":=[" + xyz(X.t) + "," + quat(X.R) + ",[" + cf(0) + "," +
            cf(3) + "," + cf(5) + ",0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];\n";
    body += "    MoveL " + name + ", v100, fine, tFixed\\WObj:=wHeld;\n";
    planned.push_back({name, q});
  }
  const std::string text = decl + body + "  ENDPROC\nENDMODULE\n";
  ParsedProgram program;
  std::string out;
  ASSERT_TRUE(CompensateProgramText(text, ProgramLanguage::kRapid, c.calibrated, c.nominal,
                                    ProgramOptions(), &out, &program)
                  .ok());
  ExpectOnlyNumbersChanged(text, out, program);
  ParsedProgram after;
  ASSERT_TRUE(ParseProgram(out, ProgramLanguage::kRapid, &after).ok());
  ASSERT_EQ(after.targets.size(), program.targets.size());
  auto pose = [](const ProgramTarget& t) {
    const auto& v = t.numbers;
    Eigen::Vector4d q(v[4].value, v[5].value, v[6].value, v[3].value);
    return SE3d(QuaternionToRotation<double>(q / q.norm()),
                Eigen::Vector3d(v[0].value, v[1].value, v[2].value));
  };
  // Where the true robot puts the fixed tool in the work object at commanded joints q.
  auto achieved = [&](const std::vector<double>& q) {
    return TrueTcp(c, q, wobj_used).Inverse() * tool_used;
  };
  Errors e;
  for (size_t k = 0; k < program.targets.size(); ++k) {
    const ProgramTarget& b = program.targets[k];
    ASSERT_EQ(b.status, ProgramTargetStatus::kCompensated) << b.name << ": " << b.reason;
    const SE3d wanted = pose(b), corrected = pose(after.targets[k]);
    const std::vector<double>& seed = planned[k].second;
    const SE3d identity;
    std::vector<double> q_ctrl, q_orig;
    ASSERT_TRUE(ControllerIk(c, tool_used * corrected.Inverse() * wobj_used.Inverse(), identity,
                             seed, &q_ctrl));
    ASSERT_TRUE(
        ControllerIk(c, tool_used * wanted.Inverse() * wobj_used.Inverse(), identity, seed, &q_orig));
    const std::vector<double> q_direct =
        CalibratedIk(c, tool_used * wanted.Inverse() * wobj_used.Inverse(), identity, seed);
    e.compensated.push_back((achieved(q_ctrl).t - wanted.t).norm());
    e.direct.push_back((achieved(q_direct).t - wanted.t).norm());
    e.uncompensated.push_back((achieved(q_orig).t - wanted.t).norm());
  }
  ExpectCompensated(e, 20);
}

TEST(Program, TargetsOnlyLeavesTaughtPointsAlone) {
  const Cell& c = TheCell();
  const Generated g = UrProgram(c, 20);
  ParsedProgram program;
  std::string out;
  ProgramOptions options;
  options.targets_only = "Waypoint_1[0-9]?_.*";
  ASSERT_TRUE(CompensateProgramText(g.text, ProgramLanguage::kUrScript, c.calibrated, c.nominal,
                                    options, &out, &program)
                  .ok());
  int selected = 0;
  for (const ProgramTarget& t : program.targets) {
    if (t.numbers.empty()) continue;
    const bool match =
        t.name.rfind("Waypoint_1", 0) == 0 && (t.name.size() == 12 || t.name.size() == 13);
    EXPECT_EQ(t.status,
              match ? ProgramTargetStatus::kCompensated : ProgramTargetStatus::kNotSelected)
        << t.name;
    selected += match;
  }
  // Waypoint_1 and Waypoint_10 .. 19 but the inline ones (13, 14, 18, 19: k % 5 == 3, 4).
  EXPECT_EQ(selected, 7);
  ExpectOnlyNumbersChanged(g.text, out, program);
  const std::string report = ProgramReportJson(program);
  EXPECT_NE(report.find("\"not_selected\": "), std::string::npos);
  EXPECT_NE(report.find("\"name\": \"Waypoint_2_p\""), std::string::npos);
  // The TCP is (15, -25, 160) mm from the flange: 29.2 mm off its axis.
  EXPECT_NE(report.find("\"tcp_off_flange_axis_mm\": 29.15"), std::string::npos) << report;
  // Calibrated with the nest fixed: the flange's rotation about its axis was identified.
  EXPECT_TRUE(program.flange_rotation_identified);
  EXPECT_NE(report.find("\"flange_rotation_identified\": true"), std::string::npos) << report;
  EXPECT_NE(FlangeRotationNote(program).find("was identified"), std::string::npos);
  // Without fixed tools the report says it was not, with the lever arm: 29.15 mm * 0.1 deg.
  RobotModel unfixed = c.calibrated;
  for (Tool& t : unfixed.tools) t.fixed = false;
  ASSERT_TRUE(CompensateProgramText(g.text, ProgramLanguage::kUrScript, unfixed, c.nominal,
                                    options, &out, &program)
                  .ok());
  EXPECT_FALSE(program.flange_rotation_identified);
  const std::string free_report = ProgramReportJson(program);
  EXPECT_NE(free_report.find("\"flange_rotation_identified\": false"), std::string::npos);
  EXPECT_NE(free_report.find("\"tcp_error_mm_per_0.1_deg\": 0.0508"), std::string::npos)
      << free_report;
  EXPECT_NE(FlangeRotationNote(program).find("was not identified"), std::string::npos);
}

void ExpectError(const std::string& text, ProgramLanguage language, const std::string& line,
                 const std::string& what) {
  ParsedProgram p;
  const Status s = ParseProgram(text, language, &p);
  ASSERT_FALSE(s.ok()) << text;
  EXPECT_NE(s.message().find(line), std::string::npos) << s.message();
  EXPECT_NE(s.message().find(what), std::string::npos) << s.message();
  EXPECT_TRUE(p.targets.empty());
}

TEST(Program, MalformedProgramsNameTheLine) {
  ExpectError("def p():\n  movej([0,0,0,0,0,0])\n  movel(p[0.1, 0.2, 0.3, 0, 0, 0, a=1)\nend\n",
              ProgramLanguage::kUrScript, "line 3", "'['");
  ExpectError("def p():\n  x = (1 + 2\n  movel(p[0.1, 0.2, 0.3, 0, 0, 0])\nend\n",
              ProgramLanguage::kUrScript, "line 2", "never closed");
  ExpectError("def p():\n  movel(p[0.1, 0.2, 0.3, 0, 0])\nend\n", ProgramLanguage::kUrScript,
              "line 2", "6 numbers");
  ExpectError("def p():\n  # caf\xC3\xA9 ok\n  movel(p[0.1, 0.2, 0.3, 0, 0, 0]) # \xFF\xFE\nend\n",
              ProgramLanguage::kUrScript, "line 3", "UTF-8");
  const std::string head =
      "MODULE M\r\n  PERS tooldata t1:=[TRUE,[[0,0,100],[1,0,0,0]],"
      "[1,[0,0,1],[1,0,0,0],0,0,0]];\r\n";
  ExpectError(head +
                  "  CONST robtarget p1:=[[1,2,3],[1,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];"
                  "\r\nENDMODULE\r\n",
              ProgramLanguage::kRapid, "line 3", "4 quaternion numbers");
  ExpectError(head +
                  "  PROC main()\r\n    MoveL [[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,"
                  "9E9]], v100, z10, tFoo;\r\n  ENDPROC\r\nENDMODULE\r\n",
              ProgramLanguage::kRapid, "line 4", "unknown tool 'tFoo'");
  ExpectError(head +
                  "  PROC main()\r\n    MoveL p1, v100, z10, t1\\WObj:=wNope;\r\n  ENDPROC\r\n"
                  "ENDMODULE\r\n",
              ProgramLanguage::kRapid, "line 4", "unknown work object");
  ExpectError(head +
                  "  PROC main()\r\n    MoveL [[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,"
                  "9E9], v100, z10, t1;\r\n  ENDPROC\r\nENDMODULE\r\n",
              ProgramLanguage::kRapid, "line 4", "never closed");
  std::string big(kMaxProgramBytes + 10, ' ');
  for (size_t i = 0; i < big.size(); i += 1000) big[i] = '\n';
  ExpectError(big, ProgramLanguage::kUrScript, "line ", "larger than");
}

TEST(Program, RunTimeValuesAreReportedNotChanged) {
  const Cell& c = TheCell();
  const std::string text =
      "def p():\n"
      "  global home_q=[0.4, -1.3, 1.6, -1.9, -1.5, 0.4]\n"
      "  movej(home_q)\n"
      "  global a_p=p[0.1, -0.4, 0.3, 0, 3.1, 0]\n"
      "  a_p = pose_add(a_p, p[0, 0, 0.01, 0, 0, 0])\n"
      "  movel(a_p)\n"
      "  set_tcp(get_tcp_offset())\n"
      "  movel(p[0.1, -0.4, 0.35, 0, 3.1, 0])\n"
      "  movel(unknown_p)\n"
      "end\n";
  ParsedProgram program;
  std::string out;
  ASSERT_TRUE(CompensateProgramText(text, ProgramLanguage::kUrScript, c.calibrated, c.nominal,
                                    ProgramOptions(), &out, &program)
                  .ok());
  // The literal assigned to a_p on line 4 is never moved to (reassigned first): not a target.
  ASSERT_EQ(program.targets.size(), 4u);
  EXPECT_EQ(program.targets[0].name, "home_q");
  EXPECT_EQ(program.targets[0].status, ProgramTargetStatus::kCompensated);
  EXPECT_EQ(program.targets[1].name, "a_p");
  EXPECT_EQ(program.targets[1].line, 6);
  EXPECT_NE(program.targets[1].reason.find("assigned at run time on line 5"), std::string::npos);
  EXPECT_NE(program.targets[2].reason.find("set_tcp on line 7"), std::string::npos);
  EXPECT_EQ(program.targets[3].name, "unknown_p");
  for (size_t k = 1; k < 4; ++k) {
    EXPECT_EQ(program.targets[k].status, ProgramTargetStatus::kNotCompensated);
  }
  ExpectOnlyNumbersChanged(text, out, program);
  EXPECT_NE(out.substr(0, 60), text.substr(0, 60));  // home_q changed
  EXPECT_EQ(out.substr(out.find("  global a_p")), text.substr(text.find("  global a_p")));
}

#ifdef LPOE_COMPENSATE_PATH
std::string ReadAll(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// Runs the tool; its exit code, stderr in *err.
int RunTool(const std::string& args, const std::string& dir, std::string* err) {
  const std::string log = dir + "/stderr.txt";
  const int rc =
      std::system((std::string(LPOE_COMPENSATE_PATH) + " " + args + " 2>" + log).c_str());
  *err = ReadAll(log);
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

TEST(Program, ToolWritesTheProgramAndRefusesBadInput) {
  const Cell& c = TheCell();
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("lpoe_program_test_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  const std::string d = dir.string();
  ASSERT_TRUE(WriteRobotModel(d + "/cal.yaml", c.calibrated).ok());
  ASSERT_TRUE(WriteRobotModel(d + "/nom.yaml", c.nominal).ok());
  const Generated g = UrProgram(c, 12);
  std::ofstream(d + "/in.script", std::ios::binary) << g.text;
  const std::string models = "--model=" + d + "/cal.yaml --nominal=" + d + "/nom.yaml ";
  std::string err;
  // The library's result, from the models as written.
  RobotModel cal, nom;
  ASSERT_TRUE(ReadRobotModel(d + "/cal.yaml", &cal).ok());
  ASSERT_TRUE(ReadRobotModel(d + "/nom.yaml", &nom).ok());
  ParsedProgram program;
  std::string expected;
  ASSERT_TRUE(CompensateProgramText(g.text, ProgramLanguage::kUrScript, cal, nom, ProgramOptions(),
                                    &expected, &program)
                  .ok());
  EXPECT_EQ(RunTool(models + "--program=" + d + "/in.script --output=" + d +
                        "/out.script --report=" + d + "/report.json",
                    d, &err),
            0)
      << err;
  EXPECT_EQ(ReadAll(d + "/out.script"), expected);
  EXPECT_NE(ReadAll(d + "/report.json").find("\"compensated\": "), std::string::npos);
  EXPECT_NE(err.find("not compensated: computed at run time"), std::string::npos) << err;
  // --strict: the run-time target makes it exit 8, the output written all the same.
  EXPECT_EQ(
      RunTool(models + "--strict --program=" + d + "/in.script --output=" + d + "/strict.script", d,
              &err),
      8)
      << err;
  EXPECT_EQ(ReadAll(d + "/strict.script"), expected);
  // OUT == IN refused, the program untouched.
  EXPECT_EQ(
      RunTool(models + "--program=" + d + "/in.script --output=" + d + "/./in.script", d, &err), 1);
  EXPECT_EQ(ReadAll(d + "/in.script"), g.text);
  // A malformed program: the line named, nothing written.
  std::ofstream(d + "/bad.mod", std::ios::binary)
      << "MODULE M\n  PROC main()\n    MoveL "
         "[[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]], "
         "v100, z10, tool9;\n  ENDPROC\nENDMODULE\n";
  EXPECT_EQ(RunTool(models + "--program=" + d + "/bad.mod --output=" + d + "/bad_out.mod", d, &err),
            2);
  EXPECT_NE(err.find("line 3: unknown tool 'tool9'"), std::string::npos) << err;
  EXPECT_FALSE(std::filesystem::exists(d + "/bad_out.mod"));
  // No language.
  EXPECT_EQ(RunTool(models + "--program=" + d + "/in.txt --output=" + d + "/x.txt", d, &err), 1);
  std::filesystem::remove_all(dir);
}
#endif

TEST(Program, UrScriptForms) {
  const Cell& c = TheCell();
  const std::vector<double> q = {0.4, -1.3, 1.6, -1.9, -1.5, 0.4};
  const SE3d tcp(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0, 0, 100));
  const SE3d feature(ExpSO3(Eigen::Vector3d(0, 0, 0.2)), Eigen::Vector3d(100, -50, 20));
  const SE3d X = ToolPose(c.nominal, q.data(), c.flange) * tcp;
  auto lit = [](const SE3d& T) {
    const Eigen::Vector3d rv = LogSO3(T.R);
    return "p[" + Num(T.t.x() / 1000, 12) + "," + Num(T.t.y() / 1000, 12) + "," +
           Num(T.t.z() / 1000, 12) + "," + Num(rv.x(), 12) + "," + Num(rv.y(), 12) + "," +
           Num(rv.z(), 12) + "]";
  };
  std::string qs = "[";
  for (int j = 0; j < 6; ++j) qs += (j ? "," : "") + Num(q[j], 12);
  qs += "]";
  const std::string text = "def p():\n  local tool_1 = " + lit(tcp) + "\n  set_tcp(tool_1)\n" +
                           "  servoj(" + qs + ", t=0.002)\n" +  // joints
                           "  movep(" + lit(X) + ", a=1.2, v=0.25, r=0.01)\n" +
                           "  movej(get_inverse_kin(pose_trans(" + lit(feature) + ", " +
                           lit(feature.Inverse() * X) + "), qnear=" + qs + "))\n" +
                           "  movel(pose_trans(feature_var, " + lit(X) + "))\nend\n";
  ParsedProgram program;
  std::string out;
  ASSERT_TRUE(CompensateProgramText(text, ProgramLanguage::kUrScript, c.calibrated, c.nominal,
                                    ProgramOptions(), &out, &program)
                  .ok());
  ASSERT_EQ(program.targets.size(), 4u);
  EXPECT_EQ(program.targets[0].kind, ProgramTargetKind::kJoint);
  EXPECT_EQ(program.targets[0].name, "servoj:4");
  for (int k = 0; k < 3; ++k) {
    EXPECT_EQ(program.targets[k].status, ProgramTargetStatus::kCompensated)
        << program.targets[k].name << ": " << program.targets[k].reason;
    EXPECT_EQ(program.targets[k].tcp_name, "tool_1");
  }
  EXPECT_EQ(program.targets[1].name, "movep:5");
  EXPECT_EQ(program.targets[2].qnear.size(), 6u);
  EXPECT_LT((program.targets[2].frame.t - feature.t).norm(), 1e-6);
  // The same pose, in the base frame and in the feature: the same correction.
  EXPECT_NEAR(program.targets[1].correction_mm, program.targets[2].correction_mm, 1e-4);
  EXPECT_GT(program.targets[1].correction_mm, 1.0);
  // A feature variable never assigned: run time.
  EXPECT_EQ(program.targets[3].status, ProgramTargetStatus::kNotCompensated);
  EXPECT_NE(program.targets[3].reason.find("feature_var"), std::string::npos)
      << program.targets[3].reason;
  ExpectOnlyNumbersChanged(text, out, program);
}

// A number the new values leave the same to the decimals it is rewritten with (URScript: 10) keeps
// its bytes, even when written with more; a changed one is rewritten. Both read back as their new
// values to those decimals (the property the program fuzz targets check; a fuzzer finding).
TEST(Program, RewriteKeepsTheBytesOfAnUnchangedNumber) {
  const std::string text =
      "def p():\n  servoj([0.4, -1.9999999999999993, 1.6, -1.9, -1.5, 0.41], t=0.002)\nend\n";
  ParsedProgram program;
  ASSERT_TRUE(ParseProgram(text, ProgramLanguage::kUrScript, &program).ok());
  ASSERT_EQ(program.targets.size(), 1u);
  ProgramTarget& t = program.targets[0];
  ASSERT_EQ(t.numbers.size(), 6u);
  EXPECT_EQ(t.numbers[1].value, -1.9999999999999993);
  t.status = ProgramTargetStatus::kCompensated;
  for (const ProgramNumber& n : t.numbers) t.new_values.push_back(n.value);
  t.new_values[0] = 0.5;   // changed
  t.new_values[1] = -2.0;  // the same to 10 decimals
  const std::string out = RewriteProgram(text, program);
  EXPECT_EQ(
      out, "def p():\n  servoj([0.5, -1.9999999999999993, 1.6, -1.9, -1.5, 0.41], t=0.002)\nend\n");
  ParsedProgram again;
  ASSERT_TRUE(ParseProgram(out, ProgramLanguage::kUrScript, &again).ok());
  ASSERT_EQ(again.targets.size(), 1u);
  for (size_t k = 0; k < t.numbers.size(); ++k) {
    EXPECT_LE(std::abs(again.targets[0].numbers[k].value - t.new_values[k]),
              0.5 * std::pow(10.0, -t.numbers[k].decimals))
        << k;
  }
}

TEST(Program, RapidTargetUsedWithTwoToolsIsLeftAlone) {
  const Cell& c = TheCell();
  const std::string text =
      "MODULE M\n"
      "  PERS tooldata t1:=[TRUE,[[0,0,100],[1,0,0,0]],[1,[0,0,1],[1,0,0,0],0,0,0]];\n"
      "  PERS tooldata t2:=[TRUE,[[0,0,150],[1,0,0,0]],[1,[0,0,1],[1,0,0,0],0,0,0]];\n"
      "  VAR robtarget p1:=[[300,-200,400],[0,0,1,0],[0,-1,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n"
      "  VAR robtarget p2:=[[300,-200,450],[0,0,1,0],[0,-1,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n"
      "  PROC main()\n"
      "    MoveL p1, v100, fine, t1;\n"
      "    MoveL p1, v100, fine, t2;\n"
      "    p2.trans.z := p2.trans.z + 10;\n"
      "    MoveL p2, v100, fine, tool0;\n"
      "  ENDPROC\n"
      "ENDMODULE\n";
  ParsedProgram program;
  std::string out;
  ASSERT_TRUE(CompensateProgramText(text, ProgramLanguage::kRapid, c.calibrated, c.nominal,
                                    ProgramOptions(), &out, &program)
                  .ok());
  ASSERT_EQ(program.targets.size(), 2u);
  EXPECT_EQ(program.targets[0].name, "p1");
  EXPECT_NE(program.targets[0].reason.find("different tools (lines 7 and 8)"), std::string::npos)
      << program.targets[0].reason;
  EXPECT_EQ(program.targets[1].name, "p2");
  EXPECT_NE(program.targets[1].reason.find("assigned at run time on line 9"), std::string::npos)
      << program.targets[1].reason;
  EXPECT_EQ(out, text);
}

// A padded set_tcp argument (1 MB) before many targets: no record copies it (each target used to
// hold the TCP's whole text, and 1.1 MB of URScript ran out of memory); the TCP is read all the same.
TEST(Program, LargeSpansAreNotCopiedPerTarget) {
  const std::string pad(1 << 20, ' ');
  std::string text = "def p():\n  set_tcp(p[0.0, 0.0," + pad + "0.1, 0.0, 0.0, 0.0])\n";
  for (int k = 0; k < 200; ++k) {
    text += "  movel(p[0.3, -0.2, " + std::to_string(0.3 + 0.001 * k) + ", 0.0, 3.1, 0.0])\n";
  }
  text += "  movel(pose_add(get_actual_tcp_pose(), p[0.0," + pad + "0.0, 0.01, 0, 0, 0]))\nend\n";
  ParsedProgram program;
  ASSERT_TRUE(ParseProgram(text, ProgramLanguage::kUrScript, &program).ok());
  ASSERT_EQ(program.targets.size(), 201u);
  for (const ProgramTarget& t : program.targets) {
    EXPECT_LE(t.tcp_name.size(), 83u);
    EXPECT_LE(t.reason.size(), 140u);
  }
  EXPECT_NEAR(program.targets[0].tcp.t.z(), 100.0, 1e-9);
  EXPECT_EQ(program.targets[0].tcp_name.substr(0, 11), "p[0.0, 0.0,");
  EXPECT_EQ(program.targets[0].tcp_name.substr(program.targets[0].tcp_name.size() - 3), "...");
  EXPECT_NE(program.targets[200].reason.find("computed at run time: pose_add("), std::string::npos);
}

// The last guard before a compensation is written or returned: a non-finite joint value or pose is
// an error naming its line (or row), the others pass.
TEST(Program, NonFiniteCompensationIsAnErrorNamingTheRow) {
  CompensatedRows rows;
  rows.q = {0.1, 0.2, 0.3, 0.4, std::nan(""), 0.6};
  rows.results.resize(3);
  const int lines[3] = {5, 7, 9};
  Status s = CheckCompensatedFinite(rows, lines, 0, "t.csv");
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("t.csv: line 9: the compensation is not finite"), std::string::npos)
      << s.message();
  rows.q[4] = 0.5;
  EXPECT_TRUE(CheckCompensatedFinite(rows, lines, 0, "t.csv").ok());
  rows.corrected.resize(3);
  rows.corrected[1].t.x() = std::numeric_limits<double>::infinity();
  s = CheckCompensatedFinite(rows, nullptr, 100, "targets");
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("targets: row 101:"), std::string::npos) << s.message();
}

// A RAPID robtarget declared twice is an error naming both lines; a module whose text is URScript
// (or the reverse) does not fit the language given.
TEST(Program, RapidNameDeclaredTwiceAndTheWrongLanguage) {
  ExpectError("MODULE M\n"
              "  CONST robtarget p1:=[[1,2,3],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n"
              "  VAR robtarget P1:=[[1,2,4],[1,0,0,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n"
              "ENDMODULE\n",
              ProgramLanguage::kRapid, "line 3", "P1 is declared twice (first on line 2)");
  const Cell& c = TheCell();
  const std::string ur = "def p():\n  movej([0.4, -1.3, 1.6, -1.9, -1.5, 0.4])\nend\n";
  ParsedProgram program;
  std::string out;
  const Status s = CompensateProgramText(ur, ProgramLanguage::kRapid, c.calibrated, c.nominal,
                                         ProgramOptions(), &out, &program);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("reads as a urscript program (1 targets, the first on line 2)"),
            std::string::npos)
      << s.message();
  EXPECT_TRUE(CompensateProgramText(ur, ProgramLanguage::kUrScript, c.calibrated, c.nominal,
                                    ProgramOptions(), &out, &program)
                  .ok());
  // A program with no target in either language is not an error.
  EXPECT_TRUE(CompensateProgramText("MODULE M\nENDMODULE\n", ProgramLanguage::kRapid, c.calibrated,
                                    c.nominal, ProgramOptions(), &out, &program)
                  .ok());
}

TEST(Program, LanguageFromPath) {
  ProgramLanguage l;
  EXPECT_TRUE(ProgramLanguageFromPath("dir/x.script", &l));
  EXPECT_EQ(l, ProgramLanguage::kUrScript);
  EXPECT_TRUE(ProgramLanguageFromPath("X.MODX", &l));
  EXPECT_EQ(l, ProgramLanguage::kRapid);
  EXPECT_TRUE(ProgramLanguageFromPath("a.prg", &l));
  EXPECT_FALSE(ProgramLanguageFromPath("a.mod/x", &l));
  EXPECT_FALSE(ProgramLanguageFromPath("x.src", &l));
}

}  // namespace program_test
}  // namespace
}  // namespace lpoe
