// The frames a controller uses, on a stand-in for a UR5 described by ur_description:
// tests/data/urdf/ur5_classic_cell.urdf (world -> base_link -> ... -> wrist_3_link, tool0 fixed to
// it 82.3 mm out and turned by -pi/2, the controller's `base` frame base_link turned by pi about z),
// three SMR nests at known positions on tool0, a true robot with frame errors and joint-zero errors,
// a laser tracker 3 m away. The calibration (SMR nests held fixed) is written as YAML and as a URDF
// overlay; a URScript path with set_tcp (poses in `base`), a RAPID module (robtargets in wobj0 with
// a tooldata) and base-frame target rows are compensated with each, executed by a simulated
// controller running the nominal model's inverse kinematics on the true robot, and every TCP must
// land within 0.05 mm of its intended pose in the base frame the calibration defines.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "lpoe/compensation.h"
#include "lpoe/inverse_kinematics.h"
#include "lpoe/io/io.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/pipeline.h"
#include "lpoe/plausibility.h"
#include "lpoe/program.h"
#include "lpoe/model/refusals.h"
#include "lpoe/model/simulation.h"
#include "lpoe/io/urdf.h"
#include "urdf/urdf_tree.h"

namespace lpoe {
namespace {
namespace controller_frames_test {

constexpr double kDeg = 180.0 / kPi;

std::string ReadText(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

std::string CellPath() { return std::string(LPOE_TEST_DATA_DIR) + "/urdf/ur5_classic_cell.urdf"; }

UrdfOptions CellOptions() {
  UrdfOptions o;
  o.tool_links = {"smr1", "smr2", "smr3"};
  return o;
}

std::string Num(double x, int decimals) {
  char b[64];
  std::snprintf(b, sizeof(b), "%.*f", decimals, x);
  return b;
}

// The cell, made once: nominal (from the URDF), truth, tracker, calibration, URDF overlay.
struct Cell {
  UrdfSource source;
  RobotModel nominal, actual, calibrated, urdf_calibrated;
  std::vector<double> joint_zero;
  SE3d T_tracker_base;  // the true tracker pose
  SE3d F_base;          // ur_description's `base` in the chain's base frame
  std::string urdf_text;
  std::vector<std::vector<double>> path;  // planned joints of the program path
};

const Cell& TheCell() {
  static const Cell* cell = [] {
    Cell* c = new Cell;
    EXPECT_TRUE(ReadRobotModelUrdf(CellPath(), &c->nominal, CellOptions(), &c->source).ok());
    EXPECT_TRUE(FindBaseFrame(c->nominal, "base", &c->F_base).ok());
    const int n = c->nominal.num_joints();
    // Frame errors of a few mrad and mm, joint zeros of a few mrad; the nests are known (no
    // error relative to tool0, which is fixed to the last link as the URDF says).
    KinematicErrors errors = RandomErrors(c->nominal, 0.004, 2.0, 0.0, 0.006, 41);
    for (int t = 0; t < c->nominal.num_tools(); ++t) errors.frame[n + t].setZero();
    c->actual = ApplyErrors(c->nominal, errors);
    c->joint_zero = errors.joint_zero;
    EXPECT_TRUE(SetFixedTools({"smr1", "smr2", "smr3"}, &c->nominal).ok());
    SimulationOptions o;
    o.count = 120;
    o.noise_sigma = 0.005;
    o.seed = 9;
    o.all_tools = true;
    o.lower = std::vector<double>(n, -2.6);
    o.upper = std::vector<double>(n, 2.6);
    std::vector<double> configurations;
    {
      // Random configurations, every nest measured at each.
      const MeasurementSet q_only = SimulateMeasurements(c->actual, c->joint_zero, o);
      for (int r = 0; r < q_only.size(); ++r) {
        configurations.insert(configurations.end(), q_only.q(r), q_only.q(r) + n);
      }
    }
    o.configurations = configurations;
    const MeasurementSet in_base = SimulateMeasurements(c->actual, c->joint_zero, o);
    // The tracker 3 m away, turned.
    c->T_tracker_base = SE3d(RotationFromRpy(0.02, -0.015, 2.3), Eigen::Vector3d(2400, -1700, -350));
    MeasurementSet tracker(n);
    for (int r = 0; r < in_base.size(); ++r) {
      tracker.Add(in_base.q(r), c->T_tracker_base * in_base.position(r), in_base.target(r));
    }
    PipelineOptions options;
    options.kfold = 0;
    const PipelineResult r = RunCalibrationPipeline(c->nominal, tracker, MeasurementSet(), options);
    EXPECT_EQ(r.result.termination, Termination::kConverged) << r.result.message;
    EXPECT_TRUE(r.registered && r.registration.moved);
    c->calibrated = r.result.model;
    c->calibrated.T_measurement_base = r.registration.T_measurement_base;
    // The URDF write-back, read back as every ROS tool would.
    UrdfOverlayOptions overlay;
    overlay.in_measurement_frame = true;
    EXPECT_TRUE(CalibratedUrdfOverlay(c->source, c->calibrated, overlay, &c->urdf_text).ok());
    EXPECT_TRUE(
        ParseRobotModelUrdf(c->urdf_text, "calibrated.urdf", &c->urdf_calibrated, CellOptions())
            .ok());
    // A path: 16 poses a few degrees apart.
    const std::vector<double> q0 = {0.4, -1.3, 1.5, -1.9, -1.4, 0.3};
    for (int k = 0; k < 16; ++k) {
      std::vector<double> q(q0);
      for (int j = 0; j < n; ++j) q[j] += 0.035 * k * (j % 2 == 0 ? 1 : -1) * (1 + 0.2 * j);
      c->path.push_back(q);
    }
    return c;
  }();
  return *cell;
}

const SE3d kTcp(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0, 0, 150));  // set_tcp(p[0,0,0.15,..])

SE3d FlangeFrame(const RobotModel& m, const std::string& name) {
  SE3d pose;
  EXPECT_TRUE(FindFlange(m, name, &pose).ok());
  return pose;
}

// The TCP of the true robot at commanded joints q, in the tracker's frame.
SE3d TrueTcpInTracker(const Cell& c, const std::vector<double>& q, const SE3d& tcp) {
  std::vector<double> qa(q);
  for (size_t j = 0; j < qa.size(); ++j) qa[j] += c.joint_zero[j];
  const SE3d flange = ToolPose(c.actual, qa.data(), 0) * c.actual.tools[0].origin.Inverse() *
                      FlangeFrame(c.nominal, "tool0");
  return c.T_tracker_base * flange * tcp;
}

// The simulated controller: the nominal model's inverse kinematics for the TCP pose `tcp_base`
// (in the chain's base frame), seeded at `seed`.
std::vector<double> ControllerIk(const Cell& c, const SE3d& tcp_base,
                                 const std::vector<double>& seed, const SE3d& tcp) {
  RobotModel m = c.nominal;
  m.tools.push_back(Tool{"tcp", FlangeFrame(c.nominal, "tool0") * tcp});
  IkOptions o;
  o.check_branch = false;
  const InverseKinematics ik(m, o);
  IkTarget t;
  t.tool = m.num_tools() - 1;
  t.position = tcp_base.t;
  t.rotation = tcp_base.R;
  t.has_orientation = true;
  std::vector<double> q(seed.size());
  const IkResult r = ik.Solve(t, seed.data(), q.data());
  EXPECT_TRUE(r.status == IkStatus::kOk || r.status == IkStatus::kBranch);
  return q;
}

// The intended TCP poses of the path, in the chain's base frame: where the nominal model puts
// the TCP at the planned joints (a CAD program).
std::vector<SE3d> IntendedInBase(const Cell& c, const SE3d& tcp = kTcp) {
  std::vector<SE3d> out;
  for (const auto& q : c.path) {
    out.push_back(ToolPose(c.nominal, q.data(), 0) * c.nominal.tools[0].origin.Inverse() *
                  FlangeFrame(c.nominal, "tool0") * tcp);
  }
  return out;
}

// |executed - intended| (mm) on the true robot for poses given to the controller in the chain's
// base frame, the intended poses placed in the tracker by the calibration's registration.
std::vector<double> Execute(const Cell& c, const std::vector<SE3d>& commanded_base,
                            const SE3d& tcp = kTcp) {
  const std::vector<SE3d> intended = IntendedInBase(c, tcp);
  std::vector<double> errors;
  for (size_t k = 0; k < commanded_base.size(); ++k) {
    const std::vector<double> q = ControllerIk(c, commanded_base[k], c.path[k], tcp);
    const SE3d want = c.calibrated.T_measurement_base * intended[k];
    errors.push_back((TrueTcpInTracker(c, q, tcp).t - want.t).norm());
  }
  return errors;
}

double Max(const std::vector<double>& v) { return *std::max_element(v.begin(), v.end()); }

// p[x, y, z, rx, ry, rz] (m, rotation vector) of a pose in mm.
std::string UrPose(const SE3d& T) {
  const Eigen::Vector3d r = LogSO3(T.R);
  return "p[" + Num(T.t.x() / 1000, 9) + ", " + Num(T.t.y() / 1000, 9) + ", " +
         Num(T.t.z() / 1000, 9) + ", " + Num(r.x(), 9) + ", " + Num(r.y(), 9) + ", " +
         Num(r.z(), 9) + "]";
}

// A Polyscope-style URScript path: the home as joints, then movel poses in UR's Base frame.
std::string UrScript(const Cell& c) {
  std::string s = "def cell():\n  set_tcp(p[0, 0, 0.15, 0, 0, 0])\n  movej([";
  for (int j = 0; j < 6; ++j) s += (j ? ", " : "") + Num(c.path[0][j], 9);
  s += "])\n";
  for (const SE3d& X : IntendedInBase(c)) s += "  movel(" + UrPose(c.F_base.Inverse() * X) + ")\n";
  return s + "end\n";
}

// An ABB-style module: the same path, for the flange (the built-in tool0: a tooldata's robhold is
// read as RAPID defines it), as robtargets in wobj0 (the chain's base).
std::string Rapid(const Cell& c) {
  std::string s = "MODULE Cell\n  CONST jointtarget home := [[";
  for (int j = 0; j < 6; ++j) s += (j ? "," : "") + Num(c.path[0][j] * kDeg, 6);
  s += "],[9E9,9E9,9E9,9E9,9E9,9E9]];\n";
  const std::vector<SE3d> intended = IntendedInBase(c, SE3d());
  for (size_t k = 0; k < intended.size(); ++k) {
    const Eigen::Vector4d q = RotationToQuaternion<double>(intended[k].R);  // x y z w
    const auto cf = [&](int j) {
      return std::to_string(static_cast<int>(std::floor(c.path[k][j] / (kPi / 2))));
    };
    s += "  CONST robtarget p" + std::to_string(k) + " := [[" + Num(intended[k].t.x(), 5) + "," +
         Num(intended[k].t.y(), 5) + "," + Num(intended[k].t.z(), 5) + "],[" + Num(q(3), 10) +
         "," + Num(q(0), 10) + "," + Num(q(1), 10) + "," + Num(q(2), 10) + "],[" + cf(0) + "," +
         cf(3) + "," + cf(5) + ",0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n";
  }
  s += "  PROC main()\n    MoveAbsJ home, v100, fine, tool0;\n";
  for (size_t k = 0; k < intended.size(); ++k) {
    s += "    MoveL p" + std::to_string(k) + ", v100, fine, tool0\\WObj:=wobj0;\n";
  }
  return s + "  ENDPROC\nENDMODULE\n";
}

// The compensated program's Cartesian targets, in the chain's base frame, in program order.
std::vector<SE3d> CompensatedPoses(const std::string& out, ProgramLanguage language,
                                   const SE3d& frame) {
  ParsedProgram p;
  EXPECT_TRUE(ParseProgram(out, language, &p).ok());
  std::vector<SE3d> poses;
  for (const ProgramTarget& t : p.targets) {
    if (t.kind != ProgramTargetKind::kCartesian || t.numbers.empty()) continue;
    const auto& v = t.numbers;
    SE3d X;
    if (language == ProgramLanguage::kUrScript) {
      X.t = Eigen::Vector3d(v[0].value, v[1].value, v[2].value) * 1000.0;
      X.R = ExpSO3(Eigen::Vector3d(v[3].value, v[4].value, v[5].value));
    } else {
      X.t = Eigen::Vector3d(v[0].value, v[1].value, v[2].value);
      X.R = QuaternionToRotation<double>(
          Eigen::Vector4d(v[4].value, v[5].value, v[6].value, v[3].value).normalized());
    }
    poses.push_back(frame * X);
  }
  return poses;
}

TEST(ControllerFramesTest, UrScriptPosesAreReadInUrBaseAndLandOnTheTargets) {
  const Cell& c = TheCell();
  const std::string text = UrScript(c);
  for (const RobotModel* cal : {&c.calibrated, &c.urdf_calibrated}) {
    SCOPED_TRACE(cal == &c.calibrated ? "YAML model" : "URDF model");
    ProgramOptions options;  // the defaults: frame link:base (ur_description), flange tool0
    std::string out;
    ParsedProgram program;
    ASSERT_TRUE(CompensateProgramText(text, ProgramLanguage::kUrScript, *cal, c.nominal, options,
                                      &out, &program)
                    .ok());
    EXPECT_EQ(program.frame, "link:base");
    EXPECT_EQ(program.flange, "tool0");
    int compensated = 0;
    for (const ProgramTarget& t : program.targets) {
      compensated += t.status == ProgramTargetStatus::kCompensated;
      EXPECT_NE(t.status, ProgramTargetStatus::kNotCompensated) << t.name << ": " << t.reason;
    }
    EXPECT_EQ(compensated, 17);  // the home and 16 poses
    const std::vector<double> e =
        Execute(c, CompensatedPoses(out, ProgramLanguage::kUrScript, c.F_base));
    std::cout << (cal == &c.calibrated ? "YAML" : "URDF") << " model: URScript TCPs within "
              << Max(e) << " mm of their targets\n";
    EXPECT_LT(Max(e), 0.05);
  }
  // Uncompensated, the same program misses by millimetres: the test can fail.
  const std::vector<double> e0 =
      Execute(c, CompensatedPoses(text, ProgramLanguage::kUrScript, c.F_base));
  std::cout << "uncompensated: " << Max(e0) << " mm\n";
  EXPECT_GT(Max(e0), 1.0);
  // Read in the chain's base instead (--frame=base), the poses are mirrored: nothing near.
  ProgramOptions in_chain_base;
  in_chain_base.frame = "base";
  std::string out;
  ParsedProgram program;
  ASSERT_TRUE(CompensateProgramText(text, ProgramLanguage::kUrScript, c.calibrated, c.nominal,
                                    in_chain_base, &out, &program)
                  .ok());
  EXPECT_EQ(program.frame, "base");
}

TEST(ControllerFramesTest, RapidModuleLandsOnTheTargets) {
  const Cell& c = TheCell();
  const std::string text = Rapid(c);
  for (const RobotModel* cal : {&c.calibrated, &c.urdf_calibrated}) {
    SCOPED_TRACE(cal == &c.calibrated ? "YAML model" : "URDF model");
    std::string out;
    ParsedProgram program;
    ASSERT_TRUE(CompensateProgramText(text, ProgramLanguage::kRapid, *cal, c.nominal, {}, &out,
                                      &program)
                    .ok());
    EXPECT_EQ(program.frame, "base");  // RAPID: wobj0 is the robot's base
    for (const ProgramTarget& t : program.targets) {
      EXPECT_EQ(t.status, ProgramTargetStatus::kCompensated) << t.name << ": " << t.reason;
    }
    const std::vector<double> e =
        Execute(c, CompensatedPoses(out, ProgramLanguage::kRapid, SE3d()), SE3d());
    std::cout << "RAPID flange poses within " << Max(e) << " mm\n";
    EXPECT_LT(Max(e), 0.05);
  }
}

// --targets rows in `base` with --tcp on tool0, and the same poses as a program: the same joints.
TEST(ControllerFramesTest, TargetRowsAndProgramTargetsTakeTheSamePath) {
  const Cell& c = TheCell();
  const std::vector<SE3d> intended = IntendedInBase(c);
  const std::string script = UrScript(c);
  // The poses as the program gives them (in `base`, decoded from its numbers).
  const std::vector<SE3d> in_base = CompensatedPoses(script, ProgramLanguage::kUrScript, SE3d());
  for (const RobotModel* cal : {&c.calibrated, &c.urdf_calibrated}) {
    SCOPED_TRACE(cal == &c.calibrated ? "YAML model" : "URDF model");
    CompensationRequest r;
    r.model = *cal;
    r.has_nominal = true;
    r.nominal = c.nominal;
    ASSERT_TRUE(ParseTargetFrame("link:base", &r.frame, &r.frame_link));
    r.tcp = "0,0,150";  // on the flange, tool0 by default
    std::unique_ptr<Compensator> comp;
    ASSERT_TRUE(Compensator::Create(r, &comp).ok());
    EXPECT_EQ(comp->flange_name(), "tool0");
    // Rows for the exact poses of the path, seeded at the planned joints: on target.
    const auto solve = [&](const std::vector<SE3d>& poses,
                           const std::vector<std::vector<double>>& seed_rows, CompensatedRows* rows) {
      std::vector<IkTarget> targets;
      std::vector<double> seeds;
      for (size_t k = 0; k < poses.size(); ++k) {
        IkTarget t;
        t.tool = comp->default_tool();
        t.position = poses[k].t;
        t.rotation = poses[k].R;
        t.has_orientation = true;
        targets.push_back(t);
        seeds.insert(seeds.end(), seed_rows[k].begin(), seed_rows[k].end());
      }
      comp->Solve(seeds.data(), &targets, rows);
    };
    std::vector<SE3d> exact;
    for (const SE3d& X : intended) exact.push_back(c.F_base.Inverse() * X);
    CompensatedRows rows;
    solve(exact, c.path, &rows);
    std::vector<SE3d> corrected;
    for (int k = 0; k < rows.size(); ++k) {
      EXPECT_EQ(rows.results[k].status, IkStatus::kOk);
      corrected.push_back(rows.corrected[k]);
    }
    std::cout << "target rows: TCPs within " << Max(Execute(c, corrected)) << " mm\n";
    EXPECT_LT(Max(Execute(c, corrected)), 0.05);

    // The program, and rows of the same poses (as its numbers give them) seeded where the
    // controller's inverse kinematics put the original targets: the same joints, to the bit.
    std::string out;
    ParsedProgram program;
    ASSERT_TRUE(CompensateProgramText(script, ProgramLanguage::kUrScript, *cal, c.nominal, {},
                                      &out, &program)
                    .ok());
    std::vector<std::vector<double>> controller;
    std::vector<const ProgramTarget*> cartesian;
    for (const ProgramTarget& t : program.targets) {
      if (t.kind != ProgramTargetKind::kCartesian) continue;
      ASSERT_EQ(t.q_controller.size(), 6u) << t.name;
      controller.push_back(t.q_controller);
      cartesian.push_back(&t);
    }
    ASSERT_EQ(cartesian.size(), in_base.size());
    CompensatedRows same;
    solve(in_base, controller, &same);
    for (size_t k = 0; k < cartesian.size(); ++k) {
      ASSERT_EQ(cartesian[k]->q_compensated.size(), 6u);
      for (int j = 0; j < 6; ++j) {
        EXPECT_EQ(cartesian[k]->q_compensated[j], same.q[k * 6 + j])
            << cartesian[k]->name << " joint " << j + 1;
      }
      // And the same solution as the exact rows' (their poses differ by the program's rounding).
      for (int j = 0; j < 6; ++j) {
        EXPECT_NEAR(cartesian[k]->q_compensated[j], rows.q[k * 6 + j], 1e-8);
      }
    }
  }
  // The TCP is on the flange (tool0), not in the last joint's frame: on this URDF the two differ
  // by 82.3 mm and a quarter turn.
  EXPECT_NEAR((FlangeFrame(c.nominal, "tool0") * kTcp).t.norm(), 82.3 + 150, 1e-9);
}

TEST(ControllerFramesTest, YamlAndUrdfAreOneModel) {
  const Cell& c = TheCell();
  // The URDF, read back with the same chain, predicts in its base frame what the YAML predicts in
  // the base frame (the YAML's registration recorded).
  const SE3d base_from_measurement = c.calibrated.T_measurement_base.Inverse();
  double worst = 0;
  for (const auto& q : c.path) {
    for (int t = 0; t < 3; ++t) {
      const Eigen::Vector3d yaml = base_from_measurement * ToolPose(c.calibrated, q.data(), t).t;
      const Eigen::Vector3d urdf = ToolPose(c.urdf_calibrated, q.data(), t).t;
      worst = std::max(worst, (yaml - urdf).norm());
    }
  }
  std::cout << "YAML and URDF predictions differ by " << worst << " mm at most\n";
  EXPECT_LT(worst, 1e-6);
  // The measurement frame hangs below the base: FK from it is the YAML model's.
  const NamedFrame* m = c.urdf_calibrated.FindFrame("measurement_frame", false);
  ASSERT_NE(m, nullptr);
  EXPECT_LT((m->pose.t - base_from_measurement.t).norm(), 1e-6);
}

TEST(ControllerFramesTest, UrdfWriteBackChangesOnlyTheCalibratedOrigins) {
  const Cell& c = TheCell();
  const std::string source = ReadText(CellPath());
  const std::string& out = c.urdf_text;
  const size_t added = out.find("  <!-- Added by lpoe-calib");
  ASSERT_NE(added, std::string::npos);
  // Everything after the added block is the source's end.
  const size_t close = out.find("</robot>", added);
  ASSERT_NE(close, std::string::npos);
  EXPECT_EQ(out.substr(close), source.substr(source.rfind("</robot>")));
  std::vector<std::string> a, b;
  {
    std::istringstream sa(source.substr(0, source.rfind("</robot>"))), sb(out.substr(0, added));
    for (std::string l; std::getline(sa, l);) a.push_back(l);
    for (std::string l; std::getline(sb, l);) b.push_back(l);
  }
  ASSERT_EQ(a.size(), b.size());
  int changed = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    if (a[i] == b[i]) continue;
    ++changed;
    EXPECT_NE(b[i].find("<origin "), std::string::npos) << "line " << i + 1 << ": " << b[i];
  }
  EXPECT_GE(changed, 1);
  EXPECT_LE(changed, 6);  // the six moving joints at most
  // The fixed joints' origins, the meshes, materials, transmission and gazebo tags are untouched.
  for (const char* kept : {"<origin xyz=\"0 0.0823 0\" rpy=\"-1.570796325 0 0\"/>",
                           "<mesh filename=\"package://ur_description/meshes/ur5/visual/base.dae\"/>",
                           "<mechanicalReduction>1</mechanicalReduction>",
                           "<origin xyz=\"0 0 0\" rpy=\"0 0 -3.14159265\"/>"}) {
    EXPECT_NE(out.find(kept), std::string::npos) << kept;
  }
}

TEST(ControllerFramesTest, RpyNearestKeepsTheFileRepresentation) {
  using urdf_internal::RpyNearest;
  for (const Eigen::Vector3d& old :
       {Eigen::Vector3d(0, 1.5708, 0), Eigen::Vector3d(0.3, kPi / 2, -0.2),
        Eigen::Vector3d(3.0, 0.2, -3.1), Eigen::Vector3d(-3.1, 2.9, 3.0),
        Eigen::Vector3d(0, -kPi / 2, 0)}) {
    const Eigen::Matrix3d R = RotationFromRpy(old(0), old(1), old(2));
    const Eigen::Vector3d got = RpyNearest(R, old);
    EXPECT_LT((got - old).norm(), 1e-7) << old.transpose() << " -> " << got.transpose();
    EXPECT_LT((RotationFromRpy(got(0), got(1), got(2)) - R).norm(), 1e-12);
    // A small calibration change keeps the rotation exact, on the branch nearest the file's.
    const Eigen::Matrix3d Rc = R * ExpSO3(Eigen::Vector3d(2e-3, -1e-3, 3e-3));
    const Eigen::Vector3d near = RpyNearest(Rc, old);
    EXPECT_LT((RotationFromRpy(near(0), near(1), near(2)) - Rc).norm(), 1e-12);
    EXPECT_LE((near - old).norm(), (RpyFromRotation(Rc) - old).norm() + 1e-12);
  }
}

TEST(ControllerFramesTest, ControllerBaseAsTheBaseLink) {
  const Cell& c = TheCell();
  // --base_link=base: the chain starts at the controller's base (beside base_link, fixed to it).
  UrdfOptions o = CellOptions();
  o.base_link = "base";
  RobotModel in_base;
  ASSERT_TRUE(ReadRobotModelUrdf(CellPath(), &in_base, o).ok());
  for (const auto& q : c.path) {
    const SE3d a = ToolPose(in_base, q.data(), 0);
    const SE3d b = c.F_base.Inverse() * ToolPose(c.nominal, q.data(), 0);
    EXPECT_LT((a.t - b.t).norm(), 1e-9);
  }
  // Written back: the overlay keeps the file's fixed joints and predicts the model.
  std::string xml;
  UrdfSource src;
  ASSERT_TRUE(ReadRobotModelUrdf(CellPath(), &in_base, o, &src).ok());
  ASSERT_TRUE(CalibratedUrdfOverlay(src, in_base, {}, &xml).ok());
  RobotModel back;
  ASSERT_TRUE(ParseRobotModelUrdf(xml, "back.urdf", &back, o).ok());
  EXPECT_LT((ToolPose(back, c.path[3].data(), 1).t - ToolPose(in_base, c.path[3].data(), 1).t).norm(),
            1e-9);
  // Named base and flange frames.
  EXPECT_NE(c.nominal.FindFrame("base", false), nullptr);
  EXPECT_NE(c.nominal.FindFrame("tool0", true), nullptr);
  SE3d unused;
  const Status bad = FindBaseFrame(c.nominal, "nowhere", &unused);
  EXPECT_NE(bad.message().find("base_link"), std::string::npos) << bad.message();
}

// --ur_kinematics_output from the classic layout: converted so that the current ur_description
// (shoulder_pan_joint on `base`, every joint about z, tool0 = wrist_3_link) puts tool0 where the
// calibrated URDF does.
TEST(ControllerFramesTest, UrKinematicsFromTheClassicLayout) {
  const Cell& c = TheCell();
  UrdfOverlayOptions overlay;
  overlay.in_measurement_frame = true;
  std::string yaml;
  ASSERT_TRUE(UrKinematicsYaml(c.source, c.calibrated, overlay, &yaml).ok());
  // Read the six origins back.
  std::vector<double> v;
  std::istringstream in(yaml);
  for (std::string line; std::getline(in, line);) {
    const size_t colon = line.find(": ");
    const std::string key = line.substr(0, colon);
    if (colon == std::string::npos || key.find_first_not_of(' ') != 4) continue;
    v.push_back(std::stod(line.substr(colon + 2)));
  }
  ASSERT_EQ(v.size(), 36u) << yaml;
  for (const auto& q : c.path) {
    SE3d T = c.F_base;  // UR's Base: base_link_inertia in the current layout
    for (int i = 0; i < 6; ++i) {
      const double* o = &v[6 * i];
      T = T * SE3d(RotationFromRpy(o[3], o[4], o[5]), Eigen::Vector3d(o[0], o[1], o[2]) * 1000.0) *
          SE3d(RotationFromRpy(0.0, 0.0, q[i]), Eigen::Vector3d::Zero());
    }
    const SE3d want = ToolPose(c.urdf_calibrated, q.data(), 0) *
                      c.urdf_calibrated.tools[0].origin.Inverse() *
                      FlangeFrame(c.urdf_calibrated, "tool0");
    EXPECT_LT((T.t - want.t).norm(), 1e-6);
    // The file's -1.570796325 for -pi/2 turns tool0's z off wrist_3's axis by 1.8e-9 rad: the
    // conversion keeps tool0's pose, so the rotation about z differs from the axis by that much.
    EXPECT_LT((T.R - want.R).norm(), 1e-8);
  }
}

// The named frames go through the YAML model (the calibration's output) unchanged, and a bad
// `on:` names its line.
TEST(ControllerFramesTest, NamedFramesRoundTripThroughYaml) {
  const Cell& c = TheCell();
  const std::string yaml = RobotModelToYaml(c.calibrated);
  EXPECT_NE(yaml.find("frames:"), std::string::npos);
  RobotModel back;
  ASSERT_TRUE(ParseRobotModelYaml(yaml, "cal.yaml", &back).ok());
  ASSERT_EQ(back.frames.size(), c.calibrated.frames.size());
  for (size_t k = 0; k < back.frames.size(); ++k) {
    EXPECT_EQ(back.frames[k].name, c.calibrated.frames[k].name);
    EXPECT_EQ(back.frames[k].on_flange, c.calibrated.frames[k].on_flange);
    EXPECT_LT((back.frames[k].pose.t - c.calibrated.frames[k].pose.t).norm(), 1e-9);
    EXPECT_LT((back.frames[k].pose.R - c.calibrated.frames[k].pose.R).norm(), 1e-12);
  }
  std::string bad = yaml;
  const size_t on = bad.find("    on: flange");
  ASSERT_NE(on, std::string::npos);
  bad.replace(on, std::string("    on: flange").size(), "    on: wrist");
  const int line = 1 + static_cast<int>(std::count(bad.begin(), bad.begin() + on, '\n'));
  const Status s = ParseRobotModelYaml(bad, "bad.yaml", &back);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("bad.yaml:" + std::to_string(line) + ":"), std::string::npos)
      << s.message();
}

// Without UR's `base` frame the classic layout cannot be converted: the refusal names the layout.
TEST(ControllerFramesTest, UrKinematicsRefusalSaysWhichLayout) {
  std::string xml = ReadText(CellPath());
  const size_t a = xml.find("  <joint name=\"base_link-base_fixed_joint\"");
  const size_t b = xml.find("<link name=\"base\"/>");
  ASSERT_NE(a, std::string::npos);
  ASSERT_NE(b, std::string::npos);
  xml.erase(a, b + std::string("<link name=\"base\"/>").size() - a);
  RobotModel model;
  UrdfSource source;
  ASSERT_TRUE(ParseRobotModelUrdf(xml, "no_base.urdf", &model, CellOptions(), &source).ok());
  std::string yaml;
  const Status s = UrKinematicsYaml(source, model, {}, &yaml);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("current ur_description layout"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("a link `base`"), std::string::npos) << s.message();
}

// The verdict's unit check judges 6.27 rad as what it is (a UR joint within +-2 pi), and a
// geometric fit far above the noise suggests --joint_errors=auto.
TEST(VerdictChecks, JointUnitsAndJointErrorsHint) {
  const RobotModel m = MakeUr5Like();
  SimulationOptions o;
  o.count = 40;
  o.lower = std::vector<double>(6, -6.27);
  o.upper = std::vector<double>(6, 6.27);
  MeasurementSet data = SimulateMeasurements(m, std::vector<double>(6, 0.0), o);
  data.mutable_q(0)[0] = 6.27;
  ErrorStatistics after;
  after.norm.rms = 0.05;
  const auto check = [](const Verdict& v, const std::string& name) {
    for (const VerdictCheck& c : v.checks) {
      if (c.name == name) return c;
    }
    return VerdictCheck();
  };
  PlausibilityOptions options;
  VerdictCheck units = check(AssessPlausibility(m, m, data, after, options), "joint_units");
  EXPECT_EQ(units.level, VerdictLevel::kPass) << units.message;
  EXPECT_EQ(units.message.find("degrees"), std::string::npos) << units.message;
  data.mutable_q(0)[0] = 40.0;  // degrees read as radians
  units = check(AssessPlausibility(m, m, data, after, options), "joint_units");
  EXPECT_NE(units.level, VerdictLevel::kPass);
  EXPECT_NE(units.message.find("look like degrees"), std::string::npos) << units.message;
  data.mutable_q(0)[0] = 1.0;
  // Residuals 5 times what noise and non-geometric errors explain: the hint, for a geometric model.
  after.norm.rms = 5 * std::sqrt(3.0) * std::hypot(options.noise_sigma, kNonGeometricMm);
  VerdictCheck residual = check(AssessPlausibility(m, m, data, after, options), "residual");
  EXPECT_EQ(residual.level, VerdictLevel::kCheck);
  EXPECT_NE(residual.message.find("--joint_errors=auto"), std::string::npos) << residual.message;
  after.norm.rms = 0.5 * std::sqrt(3.0) * std::hypot(options.noise_sigma, kNonGeometricMm);
  residual = check(AssessPlausibility(m, m, data, after, options), "residual");
  EXPECT_EQ(residual.message.find("--joint_errors"), std::string::npos) << residual.message;
}

}  // namespace controller_frames_test
}  // namespace
}  // namespace lpoe
