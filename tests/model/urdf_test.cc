// Tests of URDF import and export (lpoe/io/urdf.h): round trips through URDF text reproduce forward
// kinematics, a hand-written UR-like URDF matches a forward kinematics computed here directly from
// URDF semantics (independent of the library's SE3 code), and malformed files are rejected with the
// file name and line in the message (tests/data/urdf/bad_*.urdf).
#include "lpoe/io/urdf.h"

#include <gtest/gtest.h>
#include <unistd.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "lpoe/io/io.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/kinematics/se3.h"
#include "lpoe/model/simulation.h"

namespace lpoe {
namespace {
namespace urdf_test {

namespace fs = std::filesystem;

// Forward kinematics after a round trip (docs/file_formats.md asks this of written models).
constexpr double kRoundTripToleranceMm = 1e-9;
constexpr double kRotationTolerance = 1e-12;
// Against the independent URDF forward kinematics (different rounding paths only).
constexpr double kIndependentToleranceMm = 1e-9;
constexpr int kRandomConfigurations = 100;
constexpr double kPrismaticRangeMm = 200.0;

std::string UrdfDir() { return std::string(LPOE_TEST_DATA_DIR) + "/urdf"; }

std::vector<double> RandomConfiguration(const RobotModel& model, std::mt19937_64* rng) {
  std::vector<double> q;
  for (const Joint& j : model.joints) {
    const double range = j.type == JointType::kRevolute ? kPi : kPrismaticRangeMm;
    q.push_back(std::uniform_real_distribution<double>(-range, range)(*rng));
  }
  return q;
}

// Largest position (mm) and rotation difference of every tool over random configurations.
void ExpectSameKinematics(const RobotModel& a, const RobotModel& b, double tol_mm,
                          uint64_t seed = 7) {
  ASSERT_EQ(a.num_joints(), b.num_joints());
  ASSERT_EQ(a.num_tools(), b.num_tools());
  std::mt19937_64 rng(seed);
  double max_dp = 0, max_dr = 0;
  for (int c = 0; c < kRandomConfigurations; ++c) {
    const std::vector<double> q = RandomConfiguration(a, &rng);
    for (int k = 0; k < a.num_tools(); ++k) {
      const SE3d Ta = ToolPose(a, q.data(), k);
      const SE3d Tb = ToolPose(b, q.data(), k);
      max_dp = std::max(max_dp, (Ta.t - Tb.t).norm());
      max_dr = std::max(max_dr, (Ta.R - Tb.R).norm());
    }
  }
  EXPECT_LT(max_dp, tol_mm) << a.name;
  EXPECT_LT(max_dr, kRotationTolerance) << a.name;
}

RobotModel RoundTrip(const RobotModel& model) {
  const std::string xml = RobotModelToUrdf(model);
  RobotModel back;
  UrdfOptions options;  // several tools on the flange: name them (else the flange is the tool)
  for (const Tool& t : model.tools) options.tool_links.push_back(t.name);
  const Status s = ParseRobotModelUrdf(xml, "roundtrip.urdf", &back, options);
  EXPECT_TRUE(s.ok()) << s.message() << "\n" << xml;
  return back;
}

// cobot6 with every twist replaced by a random unit axis through a random point (v != 0), so that
// the export has to move the URDF joint frames onto the axes.
RobotModel OffAxisModel(uint64_t seed) {
  RobotModel m = MakeCobot6();
  m.name = "off_axis";
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal;
  std::uniform_real_distribution<double> point(-150.0, 150.0);
  for (Joint& j : m.joints) {
    const Eigen::Vector3d w = Eigen::Vector3d{normal(rng), normal(rng), normal(rng)}.normalized();
    const Eigen::Vector3d p{point(rng), point(rng), point(rng)};
    j.twist << w, p.cross(w);  // v = -w x p: rotation about the line through p
  }
  m.tools.push_back(
      Tool{"smr2", SE3d(RotationFromRpy(0.3, -0.2, 0.1), Eigen::Vector3d(-30, 50, 80))});
  EXPECT_TRUE(m.Validate().ok()) << m.Validate().message();
  return m;
}

TEST(Urdf, ExportImportRoundTrip) {
  std::vector<RobotModel> models = {MakeCobot6(), MakeUr5Like(), MakeArmWithPrismatic(),
                                    MakeSevenJointArm(), OffAxisModel(3)};
  for (uint64_t seed : {11u, 12u, 13u}) {
    const RobotModel nominal = seed == 12u ? MakeArmWithPrismatic() : MakeCobot6();
    RobotModel tilted = ApplyErrors(nominal, RandomErrors(nominal, 0.02, 3.0, 0.05, 0.0, seed));
    tilted.name = "tilted" + std::to_string(seed);
    models.push_back(tilted);
  }
  for (const RobotModel& m : models) {
    SCOPED_TRACE(m.name);
    ASSERT_TRUE(m.Validate().ok()) << m.Validate().message();
    const RobotModel back = RoundTrip(m);
    EXPECT_EQ(back.name, m.name);
    ASSERT_EQ(back.num_joints(), m.num_joints());
    for (int i = 0; i < m.num_joints(); ++i) {
      EXPECT_EQ(back.joints[i].name, m.joints[i].name);
      EXPECT_EQ(back.joints[i].type, m.joints[i].type);
    }
    ASSERT_EQ(back.num_tools(), m.num_tools());
    for (int k = 0; k < m.num_tools(); ++k) EXPECT_EQ(back.tools[k].name, m.tools[k].name);
    ExpectSameKinematics(m, back, kRoundTripToleranceMm);
    // A second round trip is stable too (the imported model has axes through its frame origins).
    ExpectSameKinematics(m, RoundTrip(back), kRoundTripToleranceMm);
  }
}

TEST(Urdf, RandomTiltedTwistsHaveOffsetAxes) {
  // The tilted models above must actually exercise v != 0, or the frame shift goes untested.
  const RobotModel nominal = MakeCobot6();
  const RobotModel tilted = ApplyErrors(nominal, RandomErrors(nominal, 0.02, 3.0, 0.05, 0.0, 11));
  const RobotModel off = OffAxisModel(3);
  double max_v = 0;
  for (const Joint& j : off.joints) max_v = std::max(max_v, j.twist.tail<3>().norm());
  EXPECT_GT(max_v, 10.0);
  double max_tilt = 0;
  for (const Joint& j : tilted.joints) {
    max_tilt = std::max(max_tilt, (j.twist.head<3>() - Eigen::Vector3d::UnitZ()).norm());
  }
  EXPECT_GT(max_tilt, 1e-3);
}

TEST(Urdf, GimbalLockOriginsRoundTrip) {
  // Origins at and near pitch = +-pi/2, composed by matrix products (so that the small entries
  // cos(pitch) sin(roll) carry absolute, not relative, rounding errors): reading roll and yaw off
  // those entries loses up to 1e-3 rad there. The tool is 1 m out so that a rotation error of
  // 1e-12 would show as 1e-9 mm.
  RobotModel m;
  m.name = "gimbal";
  const double offsets[] = {0.0, 1e-12, -1e-12, 1e-9, -1e-7, 1e-5, 0.3};
  int i = 0;
  for (double eps : offsets) {
    ++i;
    const double pitch = (i % 2 == 0 ? -1 : 1) * (kPi / 2 - eps);
    Joint j;
    j.name = "joint" + std::to_string(i);
    j.origin.R = (Eigen::AngleAxisd(-0.4 * i, Eigen::Vector3d::UnitZ()) *
                  Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
                  Eigen::AngleAxisd(0.7 * i, Eigen::Vector3d::UnitX()))
                     .toRotationMatrix();
    j.origin.t = Eigen::Vector3d(10 * i, -20, 300);
    m.joints.push_back(j);
  }
  m.tools.push_back(
      Tool{"far", SE3d(RotationFromRpy(0.1, kPi / 2, 0.2), Eigen::Vector3d(1000, 0, 0))});
  ASSERT_TRUE(m.Validate().ok());
  ExpectSameKinematics(m, RoundTrip(m), kRoundTripToleranceMm);
  // Local frames themselves (all twists pass through the origins, so no shift) survive to rounding.
  const RobotModel back = RoundTrip(m);
  for (int k = 0; k < m.num_joints(); ++k) {
    EXPECT_LT((back.joints[k].origin.R - m.joints[k].origin.R).norm(), 1e-14) << k;
    EXPECT_LT((back.joints[k].origin.t - m.joints[k].origin.t).norm(), 1e-12) << k;
  }
}

TEST(Urdf, ExportNamesLinksAndTools) {
  RobotModel m = MakeCobot6();
  m.tools.push_back(Tool{"link2", SE3d()});  // collides with a generated link name
  ASSERT_TRUE(m.Validate().ok());
  const std::string xml = RobotModelToUrdf(m);
  EXPECT_NE(xml.find("<robot name=\"cobot6\">"), std::string::npos) << xml;
  EXPECT_NE(xml.find("<link name=\"base_link\"/>"), std::string::npos) << xml;
  EXPECT_NE(xml.find("<link name=\"link1\"/>"), std::string::npos) << xml;
  EXPECT_NE(xml.find("<link name=\"link6\"/>"), std::string::npos) << xml;
  EXPECT_NE(xml.find("<link name=\"smr1\"/>"), std::string::npos) << xml;
  EXPECT_NE(xml.find("<link name=\"link2_\"/>"), std::string::npos) << xml;
  EXPECT_NE(xml.find("type=\"fixed\""), std::string::npos) << xml;
  EXPECT_EQ(xml.find("nan"), std::string::npos) << xml;
  const RobotModel back = RoundTrip(m);
  ASSERT_EQ(back.num_tools(), 2);
  EXPECT_EQ(back.tools[0].name, "smr1");
  EXPECT_EQ(back.tools[1].name, "link2");
  ExpectSameKinematics(m, back, kRoundTripToleranceMm);
}

TEST(Urdf, FileRoundTrip) {
  const fs::path dir = fs::temp_directory_path() / ("lpoe_urdf_test_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const std::string path = (dir / "arm.urdf").string();
  const RobotModel m = MakeArmWithPrismatic();
  ASSERT_TRUE(WriteRobotModelUrdf(path, m).ok());
  RobotModel back;
  const Status s = ReadRobotModelUrdf(path, &back);
  ASSERT_TRUE(s.ok()) << s.message();
  ExpectSameKinematics(m, back, kRoundTripToleranceMm);
  RobotModel invalid = m;
  invalid.tools.clear();
  EXPECT_FALSE(WriteRobotModelUrdf((dir / "invalid.urdf").string(), invalid).ok());
  EXPECT_FALSE(fs::exists(dir / "invalid.urdf"));
  RobotModel untouched = m;
  const Status missing = ReadRobotModelUrdf((dir / "missing.urdf").string(), &untouched);
  EXPECT_FALSE(missing.ok());
  EXPECT_NE(missing.message().find("missing.urdf"), std::string::npos);
  fs::remove_all(dir);
}

// ---------------------------------------------------------------------------------------------------
// Independent forward kinematics of URDF semantics: T = prod origin(xyz, rpy) * motion(axis, q),
// plain 4x4 matrices, Eigen::AngleAxisd, metres; converted to mm at the end.

struct UrdfJointSpec {
  Eigen::Vector3d xyz, rpy;
  Eigen::Vector3d axis;  // unused for fixed joints
  enum Type { kFixed, kRevolute, kPrismatic } type;
};

Eigen::Matrix4d OriginMatrix(const UrdfJointSpec& j) {
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  T.topLeftCorner<3, 3>() = (Eigen::AngleAxisd(j.rpy.z(), Eigen::Vector3d::UnitZ()) *
                             Eigen::AngleAxisd(j.rpy.y(), Eigen::Vector3d::UnitY()) *
                             Eigen::AngleAxisd(j.rpy.x(), Eigen::Vector3d::UnitX()))
                                .toRotationMatrix();
  T.topRightCorner<3, 1>() = j.xyz;
  return T;
}

// q: one value per moving joint, radians or metres.
Eigen::Matrix4d UrdfForwardKinematics(const std::vector<UrdfJointSpec>& chain,
                                      const std::vector<double>& q_urdf) {
  Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
  size_t k = 0;
  for (const UrdfJointSpec& j : chain) {
    T = T * OriginMatrix(j);
    if (j.type == UrdfJointSpec::kFixed) continue;
    Eigen::Matrix4d M = Eigen::Matrix4d::Identity();
    const Eigen::Vector3d axis = j.axis.normalized();
    if (j.type == UrdfJointSpec::kRevolute) {
      M.topLeftCorner<3, 3>() = Eigen::AngleAxisd(q_urdf[k], axis).toRotationMatrix();
    } else {
      M.topRightCorner<3, 1>() = axis * q_urdf[k];
    }
    ++k;
    T = T * M;
  }
  T.topRightCorner<3, 1>() *= 1000.0;  // metres -> mm
  return T;
}

void ExpectMatchesUrdfKinematics(const RobotModel& model, const std::vector<UrdfJointSpec>& chain) {
  std::mt19937_64 rng(5);
  double max_dp = 0, max_dr = 0;
  for (int c = 0; c < kRandomConfigurations; ++c) {
    const std::vector<double> q = RandomConfiguration(model, &rng);
    std::vector<double> q_urdf = q;
    for (int i = 0; i < model.num_joints(); ++i) {
      if (model.joints[i].type == JointType::kPrismatic) q_urdf[i] = q[i] / 1000.0;
    }
    const Eigen::Matrix4d expected = UrdfForwardKinematics(chain, q_urdf);
    const SE3d actual = ToolPose(model, q.data(), 0);
    max_dp = std::max(max_dp, (actual.t - expected.topRightCorner<3, 1>()).norm());
    max_dr = std::max(max_dr, (actual.R - expected.topLeftCorner<3, 3>()).norm());
  }
  EXPECT_LT(max_dp, kIndependentToleranceMm);
  EXPECT_LT(max_dr, kRotationTolerance);
}

// tests/data/urdf/ur_like.urdf, transcribed by hand from the file.
std::vector<UrdfJointSpec> UrLikeChain() {
  const double h = 1.5707963267948966;
  using V = Eigen::Vector3d;
  return {
      {V(0.1, -0.05, 0.02), V(0, 0, 0.5), V::Zero(), UrdfJointSpec::kFixed},       // world_joint
      {V(0, 0, 0.089159), V(0, 0, 0), V(0, 0, 1), UrdfJointSpec::kRevolute},       // shoulder_pan
      {V(0, 0.13585, 0), V(0, h, 0), V(0, 1, 0), UrdfJointSpec::kRevolute},        // shoulder_lift
      {V(0, -0.1197, 0.425), V(0, 0, 0), V(0, 1, 0), UrdfJointSpec::kRevolute},    // elbow
      {V(0, 0, 0.39225), V(0, h, 0), V(0, 1, 0), UrdfJointSpec::kRevolute},        // wrist_1
      {V(0, 0.093, 0), V(0, 0, 0), V(0, 0, 1), UrdfJointSpec::kRevolute},          // wrist_2
      {V(0, 0, 0.09465), V(0, 0, 0), V(0, 1, 0), UrdfJointSpec::kRevolute},        // wrist_3
      {V(0, 0.0823, 0), V(0, 0, h), V::Zero(), UrdfJointSpec::kFixed},             // flange
      {V(0.05, 0.02, 0.03), V(0.1, -0.2, 0.3), V::Zero(), UrdfJointSpec::kFixed},  // tool
  };
}

TEST(Urdf, UrLikeFixtureMatchesIndependentKinematics) {
  RobotModel m;
  const Status s = ReadRobotModelUrdf(UrdfDir() + "/ur_like.urdf", &m);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_EQ(m.name, "ur_like");
  ASSERT_EQ(m.num_joints(), 6);
  const char* names[] = {"shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint",
                         "wrist_1_joint",      "wrist_2_joint",       "wrist_3_joint"};
  for (int i = 0; i < 6; ++i) {
    EXPECT_EQ(m.joints[i].name, names[i]);
    EXPECT_EQ(m.joints[i].type, JointType::kRevolute);
  }
  // Axes along y stay along y in the joint frame (the twist is the URDF axis, v = 0).
  EXPECT_LT((m.joints[1].twist - (Vector6d() << 0, 1, 0, 0, 0, 0).finished()).norm(), 1e-15);
  // The fixed world joint is folded into the first origin (mm).
  EXPECT_LT((m.joints[0].origin.t - Eigen::Vector3d(100, -50, 20 + 89.159)).norm(), 1e-12);
  // The side branches (base, camera_link) are ignored; the tip link is the one tool.
  ASSERT_EQ(m.num_tools(), 1);
  EXPECT_EQ(m.tools[0].name, "tool_smr");
  ExpectMatchesUrdfKinematics(m, UrLikeChain());

  // The same arm exported and read back.
  ExpectSameKinematics(m, RoundTrip(m), kRoundTripToleranceMm);
}

TEST(Urdf, FixedJointsFoldedIntoTools) {
  RobotModel m;
  UrdfOptions options;
  options.tool_links = {"tool_smr", "flange", "wrist_3_link"};
  const Status s = ReadRobotModelUrdf(UrdfDir() + "/ur_like.urdf", &m, options);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(m.num_tools(), 3);
  EXPECT_EQ(m.tools[0].name, "tool_smr");
  EXPECT_EQ(m.tools[1].name, "flange");
  EXPECT_EQ(m.tools[2].name, "wrist_3_link");
  const std::vector<UrdfJointSpec> chain = UrLikeChain();
  const SE3d flange(RotationFromRpy(0.0, 0.0, 1.5707963267948966), Eigen::Vector3d(0, 82.3, 0));
  const SE3d tool(RotationFromRpy(0.1, -0.2, 0.3), Eigen::Vector3d(50, 20, 30));
  EXPECT_LT((m.tools[1].origin.Matrix() - flange.Matrix()).norm(), 1e-12);
  EXPECT_LT((m.tools[0].origin.Matrix() - (flange * tool).Matrix()).norm(), 1e-12);
  EXPECT_LT((m.tools[2].origin.Matrix() - Eigen::Matrix4d::Identity()).norm(), 0.0 + 1e-300);

  // Tool links that do not exist, or lie before the last moving joint, are errors.
  RobotModel untouched = MakeCobot6();
  options.tool_links = {"no_such_link"};
  Status bad = ReadRobotModelUrdf(UrdfDir() + "/ur_like.urdf", &untouched, options);
  EXPECT_FALSE(bad.ok());
  EXPECT_NE(bad.message().find("no_such_link"), std::string::npos) << bad.message();
  options.tool_links = {"camera_link"};
  bad = ReadRobotModelUrdf(UrdfDir() + "/ur_like.urdf", &untouched, options);
  EXPECT_FALSE(bad.ok());
  EXPECT_NE(bad.message().find("ur_like.urdf:"), std::string::npos) << bad.message();
  EXPECT_NE(bad.message().find("camera_link"), std::string::npos) << bad.message();
  EXPECT_EQ(untouched.name, "cobot6");  // left unchanged on error
}

TEST(Urdf, PrismaticAndTiltedAxesMatchIndependentKinematics) {
  // Non-normalized and tilted axes, a prismatic joint (URDF metres, model mm), fixed joints
  // between moving joints, before the first and after the last, links listed after the joints.
  const std::string xml = R"(<?xml version="1.0"?>
<robot name="mixed">
  <joint name="mount" type="fixed">
    <parent link="world"/><child link="base"/>
    <origin xyz="0.5 0.25 -0.125" rpy="0.2 0.1 -0.3"/>
  </joint>
  <joint name="j1" type="revolute">
    <parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0.3"/>
    <axis xyz="0 0 2"/>
  </joint>
  <joint name="j2" type="prismatic">
    <parent link="l1"/><child link="l2"/>
    <origin rpy="1.5707963267948966 0 0"/>
    <axis xyz="0.6 0 0.8"/>
  </joint>
  <joint name="spacer" type="fixed">
    <parent link="l2"/><child link="l2b"/>
    <origin xyz="0.1 0.2 0.3" rpy="-0.4 0.5 0.6"/>
  </joint>
  <joint name="j3" type="continuous">
    <parent link="l2b"/><child link="l3"/>
    <origin xyz="0.05 -0.02 0.4" rpy="0 -1.5707963267948966 0"/>
    <axis xyz="  1   -1  +0.5e0 "/>
  </joint>
  <joint name="j4" type="revolute">
    <parent link="l3"/><child link="l4"/>
    <origin xyz="0.01 0.02 0.03" rpy="0.3 0.2 0.1"/>
  </joint>
  <joint name="tcp" type="fixed">
    <parent link="l4"/><child link="tcp_link"/>
    <origin xyz="0 0 0.1"/>
  </joint>
  <link name="world"/><link name="base"/><link name="l1"/><link name="l2"/><link name="l2b"/>
  <link name="l3"/><link name="l4"/><link name="tcp_link"/>
</robot>
)";
  RobotModel m;
  const Status s = ParseRobotModelUrdf(xml, "mixed.urdf", &m);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(m.num_joints(), 4);
  EXPECT_EQ(m.joints[1].type, JointType::kPrismatic);
  EXPECT_LT((m.joints[1].twist - (Vector6d() << 0, 0, 0, 0.6, 0, 0.8).finished()).norm(), 1e-15);
  EXPECT_LT((m.joints[2].twist.head<3>() - Eigen::Vector3d(1, -1, 0.5) / 1.5).norm(), 1e-15);
  EXPECT_LT((m.joints[3].twist.head<3>() - Eigen::Vector3d::UnitX()).norm(), 0.0 + 1e-300)
      << "a missing <axis> is (1, 0, 0)";
  ASSERT_EQ(m.num_tools(), 1);
  EXPECT_EQ(m.tools[0].name, "tcp_link");
  using V = Eigen::Vector3d;
  const double h = 1.5707963267948966;
  const std::vector<UrdfJointSpec> chain = {
      {V(0.5, 0.25, -0.125), V(0.2, 0.1, -0.3), V::Zero(), UrdfJointSpec::kFixed},
      {V(0, 0, 0.3), V::Zero(), V(0, 0, 2), UrdfJointSpec::kRevolute},
      {V::Zero(), V(h, 0, 0), V(0.6, 0, 0.8), UrdfJointSpec::kPrismatic},
      {V(0.1, 0.2, 0.3), V(-0.4, 0.5, 0.6), V::Zero(), UrdfJointSpec::kFixed},
      {V(0.05, -0.02, 0.4), V(0, -h, 0), V(1, -1, 0.5), UrdfJointSpec::kRevolute},
      {V(0.01, 0.02, 0.03), V(0.3, 0.2, 0.1), V(1, 0, 0), UrdfJointSpec::kRevolute},
      {V(0, 0, 0.1), V::Zero(), V::Zero(), UrdfJointSpec::kFixed},
  };
  ExpectMatchesUrdfKinematics(m, chain);
  ExpectSameKinematics(m, RoundTrip(m), kRoundTripToleranceMm);
}

TEST(Urdf, SeveralLeavesOnTheFlangeMakeTheFlangeTheTool) {
  const std::string xml = R"(<robot name="two_tools">
  <link name="base"/><link name="l1"/><link name="smr_a"/><link name="smr_b"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/></joint>
  <joint name="fa" type="fixed"><parent link="l1"/><child link="smr_a"/><origin xyz="0.1 0 0"/></joint>
  <joint name="fb" type="fixed"><parent link="l1"/><child link="smr_b"/><origin xyz="0 0.2 0"/></joint>
</robot>)";
  RobotModel m;
  // Several leaves after the same last moving joint (a UR's ee_link and tool0): the flange is the
  // tip and the one tool.
  ASSERT_TRUE(ParseRobotModelUrdf(xml, "two_tools.urdf", &m).ok());
  ASSERT_EQ(m.num_tools(), 1);
  EXPECT_EQ(m.tools[0].name, "l1");
  // Named, they are the tools.
  UrdfOptions options;
  options.tool_links = {"smr_a", "smr_b"};
  const Status s = ParseRobotModelUrdf(xml, "two_tools.urdf", &m, options);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(m.num_tools(), 2);
  EXPECT_EQ(m.tools[0].name, "smr_a");
  EXPECT_EQ(m.tools[1].name, "smr_b");
  EXPECT_LT((m.tools[1].origin.t - Eigen::Vector3d(0, 200, 0)).norm(), 1e-13);

  // No fixed link after the last moving joint: its child link is the tool.
  const std::string bare = R"(<robot name="bare">
  <link name="base"/><link name="l1"/>
  <joint name="j1" type="prismatic"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/></joint>
</robot>)";
  ASSERT_TRUE(ParseRobotModelUrdf(bare, "bare.urdf", &m).ok());
  ASSERT_EQ(m.num_tools(), 1);
  EXPECT_EQ(m.tools[0].name, "l1");
  EXPECT_LT((m.tools[0].origin.Matrix() - Eigen::Matrix4d::Identity()).norm(), 1e-300);
}

// ---------------------------------------------------------------------------------------------------
// The overlay write-back, read again by our own reader (urdf_overlay_test reads it with urdfdom).

std::string UrLikeText() {
  std::string xml;
  EXPECT_TRUE(ReadFile(UrdfDir() + "/ur_like.urdf", &xml).ok());
  return xml;
}

TEST(UrdfOverlayWrite, CalibratedFramesAndAxesReadBack) {
  RobotModel nominal;
  UrdfSource source;
  UrdfOptions options;
  options.tool_links = {"tool_smr", "flange"};
  ASSERT_TRUE(ParseRobotModelUrdf(UrLikeText(), "ur_like.urdf", &nominal, options, &source).ok());
  EXPECT_EQ(source.options.tool_links, options.tool_links);
  // Frame errors of a few mm and mrad on every joint and tool; joint 3's axis tilted (v stays 0).
  RobotModel calibrated = ApplyErrors(nominal, RandomErrors(nominal, 0.005, 3.0, 0.0, 0.0, 21));
  calibrated.joints[2].twist.head<3>() =
      (calibrated.joints[2].twist.head<3>() + Eigen::Vector3d(0.01, 0, -0.02)).normalized();
  ASSERT_TRUE(calibrated.Validate().ok());
  std::string xml;
  const Status s = CalibratedUrdfOverlay(source, calibrated, UrdfOverlayOptions(), &xml);
  ASSERT_TRUE(s.ok()) << s.message();
  RobotModel back;
  const Status r = ParseRobotModelUrdf(xml, "overlay.urdf", &back, options);
  ASSERT_TRUE(r.ok()) << r.message() << "\n" << xml;
  ExpectSameKinematics(calibrated, back, kRoundTripToleranceMm);
  for (int i = 0; i < back.num_joints(); ++i) {
    EXPECT_EQ(back.joints[i].lower, nominal.joints[i].lower);
    EXPECT_EQ(back.joints[i].upper, nominal.joints[i].upper);
  }
  // Fixed joints folded into the frames are unchanged, the source's lines kept.
  EXPECT_NE(xml.find("<origin xyz=\"0.1 -0.05 0.02\" rpy=\"0 0 0.5\"/>"), std::string::npos) << xml;
  EXPECT_NE(xml.find("lower=\"-6.28318530718\""), std::string::npos);
  EXPECT_NE(xml.find("<link name=\"measurement_frame\"/>"), std::string::npos);
  EXPECT_NE(xml.find("<link name=\"camera_link\"/>"), std::string::npos);

  // Changed limits are written (and only then).
  calibrated.joints[1].lower = -1.0;
  ASSERT_TRUE(CalibratedUrdfOverlay(source, calibrated, UrdfOverlayOptions(), &xml).ok());
  ASSERT_TRUE(ParseRobotModelUrdf(xml, "overlay.urdf", &back, options).ok());
  EXPECT_EQ(back.joints[1].lower, -1.0);
  EXPECT_EQ(back.joints[2].lower, nominal.joints[2].lower);
}

TEST(UrdfOverlayWrite, MeasurementFrameTakesTheBaseTransform) {
  RobotModel nominal;
  UrdfSource source;
  ASSERT_TRUE(ParseRobotModelUrdf(UrLikeText(), "ur_like.urdf", &nominal, {}, &source).ok());
  RobotModel calibrated = ApplyErrors(nominal, RandomErrors(nominal, 0.005, 3.0, 0.0, 0.0, 22));
  const SE3d T_measurement_base(RotationFromRpy(0.2, 0.1, -1.0), Eigen::Vector3d(2000, 500, -300));
  calibrated.joints[0].origin = T_measurement_base * calibrated.joints[0].origin;
  UrdfOverlayOptions overlay;
  overlay.in_measurement_frame = true;
  overlay.measurement_link = "tracker";
  std::string xml;
  ASSERT_TRUE(CalibratedUrdfOverlay(source, calibrated, overlay, &xml).ok());
  RobotModel back;
  ASSERT_TRUE(ParseRobotModelUrdf(xml, "overlay.urdf", &back).ok());
  // Joint 1 keeps its URDF origin; everything after it is calibrated.
  EXPECT_LT((back.joints[0].origin.Matrix() - nominal.joints[0].origin.Matrix()).norm(), 1e-12);
  // The written tracker joint holds O = T_root_tracker; the calibrated model is O^-1 * the chain.
  const size_t at = xml.find("<joint name=\"tracker_joint\" type=\"fixed\">");
  ASSERT_NE(at, std::string::npos) << xml;
  double v[6];
  ASSERT_EQ(std::sscanf(xml.c_str() + xml.find("<origin", at),
                        "<origin xyz=\"%lf %lf %lf\" rpy=\"%lf %lf %lf\"", &v[0], &v[1], &v[2],
                        &v[3], &v[4], &v[5]),
            6);
  const SE3d O(RotationFromRpy(v[3], v[4], v[5]), Eigen::Vector3d(v[0], v[1], v[2]) * 1e3);
  RobotModel from_tracker = back;
  from_tracker.joints[0].origin = O.Inverse() * back.joints[0].origin;
  ExpectSameKinematics(calibrated, from_tracker, kRoundTripToleranceMm);
  // O^-1 is the tracker's transform up to the base-frame errors (a few mm, mrad).
  EXPECT_LT((O.Inverse().t - T_measurement_base.t).norm(), 20.0);
  EXPECT_LT((O.Inverse().R - T_measurement_base.R).norm(), 0.05);
}

TEST(UrdfOverlayWrite, FlangeToolBecomesAnSmrLinkOnTheTip) {
  const std::string xml = R"(<robot name="two_tools">
  <link name="base"/><link name="l1"/><link name="a"/><link name="b"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="fa" type="fixed"><parent link="l1"/><child link="a"/><origin xyz="0.1 0 0"/></joint>
  <joint name="fb" type="fixed"><parent link="l1"/><child link="b"/><origin xyz="0 0.2 0"/></joint>
</robot>)";
  RobotModel m;
  UrdfSource source;
  ASSERT_TRUE(ParseRobotModelUrdf(xml, "two.urdf", &m, {}, &source).ok());
  ASSERT_EQ(m.tools[0].name, "l1");
  m.tools[0].origin = SE3d(Eigen::Matrix3d::Identity(), Eigen::Vector3d(30, 40, 50));
  std::string out;
  ASSERT_TRUE(CalibratedUrdfOverlay(source, m, UrdfOverlayOptions(), &out).ok());
  UrdfOptions options;
  options.tool_links = {"l1_smr"};
  RobotModel back;
  const Status s = ParseRobotModelUrdf(out, "out.urdf", &back, options);
  ASSERT_TRUE(s.ok()) << s.message() << "\n" << out;
  EXPECT_LT((back.tools[0].origin.t - Eigen::Vector3d(30, 40, 50)).norm(), 1e-12);
}

TEST(UrdfOverlayWrite, ModelsThatDoNotFitAreRefused) {
  RobotModel nominal;
  UrdfSource source;
  ASSERT_TRUE(ParseRobotModelUrdf(UrLikeText(), "ur_like.urdf", &nominal, {}, &source).ok());
  std::string xml;
  RobotModel renamed = nominal;
  renamed.joints[3].name = "wrist_one";
  Status s = CalibratedUrdfOverlay(source, renamed, UrdfOverlayOptions(), &xml);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("'wrist_one'"), std::string::npos) << s.message();
  RobotModel off_axis = nominal;
  const Eigen::Vector3d w = off_axis.joints[1].twist.head<3>();
  off_axis.joints[1].twist.tail<3>() = w.cross(Eigen::Vector3d(5, 0, 0) - w * w.x() * 5);
  ASSERT_TRUE(off_axis.Validate().ok());
  s = CalibratedUrdfOverlay(source, off_axis, UrdfOverlayOptions(), &xml);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("does not pass through"), std::string::npos) << s.message();
  // Not a UR: no UR kinematics.
  EXPECT_FALSE(IsUrModel(MakeCobot6()));
  EXPECT_TRUE(IsUrModel(nominal));
  RobotModel cobot = MakeCobot6();
  s = UrKinematicsYaml(source, cobot, UrdfOverlayOptions(), &xml);
  EXPECT_NE(s.message().find("not a UR robot"), std::string::npos) << s.message();
  // ur_like's joints turn about y: the UR file needs z axes.
  s = UrKinematicsYaml(source, nominal, UrdfOverlayOptions(), &xml);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("z axis"), std::string::npos) << s.message();
}

TEST(Urdf, ExportWritesLimits) {
  RobotModel m = MakeArmWithPrismatic();
  for (Joint& j : m.joints) {
    j.lower = j.type == JointType::kRevolute ? -2.5 : -80.0;
    j.upper = j.type == JointType::kRevolute ? 1.5 : 120.0;
  }
  m.joints[0].lower = -std::numeric_limits<double>::infinity();  // one unlimited joint
  m.joints[0].upper = std::numeric_limits<double>::infinity();
  const RobotModel back = RoundTrip(m);
  ASSERT_EQ(back.num_joints(), m.num_joints());
  for (int i = 0; i < m.num_joints(); ++i) {
    EXPECT_EQ(back.joints[i].lower, m.joints[i].lower) << i;
    EXPECT_EQ(back.joints[i].upper, m.joints[i].upper) << i;
  }
  EXPECT_NE(RobotModelToUrdf(m).find("type=\"continuous\""), std::string::npos);
}

// ---------------------------------------------------------------------------------------------------
// Malformed input.

struct BadCase {
  const char* file;
  int line;
  const char* contains;  // a piece of the explanation
};

TEST(Urdf, BadFilesAreRejectedWithFileAndLine) {
  const BadCase cases[] = {
      {"bad_malformed.urdf", 7, "malformed XML"},  // <child> not closed
      {"bad_axis_numbers.urdf", 9, "has 2 numbers"},
      {"bad_axis_missing_xyz.urdf", 8, "no attribute xyz"},
      {"bad_joint_type.urdf", 5, "unknown type 'revolut'"},
      {"bad_zero_axis.urdf", 14, "zero vector"},
      {"bad_branching.urdf", 4, "'hub' branches"},
      {"bad_nan.urdf", 8, "non-finite number 'nan'"},
      {"bad_inf.urdf", 8, "non-finite number '-inf'"},
      {"bad_out_of_range.urdf", 8, "the number '1e9', out of range"},  // 10^6 km
      {"bad_non_numeric.urdf", 8, "non-numeric value '1.57rad'"},
      {"bad_floating.urdf", 5, "more than one degree of freedom"},
      {"bad_missing_child.urdf", 5, "no <child> element"},
      {"bad_unknown_link.urdf", 7, "unknown link 'bb'"},
      {"bad_two_parents.urdf", 10, "already the child"},
      {"bad_no_moving_joint.urdf", 2, "no revolute"},
      {"bad_not_robot.urdf", 3, "root element is <sdf>"},
      {"bad_two_roots.urdf", 11, "a second root element <robot>"},
  };
  for (const BadCase& c : cases) {
    SCOPED_TRACE(c.file);
    const std::string path = UrdfDir() + "/" + c.file;
    ASSERT_TRUE(fs::exists(path)) << path;
    RobotModel m = MakeCobot6();
    const Status s = ReadRobotModelUrdf(path, &m);
    ASSERT_FALSE(s.ok());
    const std::string expected_prefix = path + ":" + std::to_string(c.line) + ": ";
    EXPECT_EQ(s.message().rfind(expected_prefix, 0), 0u) << s.message();
    EXPECT_NE(s.message().find(c.contains), std::string::npos) << s.message();
    EXPECT_NE(s.message().find("; expected "), std::string::npos) << s.message();
    EXPECT_EQ(m.name, "cobot6") << "the model must be left unchanged on error";
  }
}

TEST(Urdf, GarbageInputNeverCrashes) {
  // Truncations and byte flips of a valid file: every one either parses or reports a line.
  std::string text;
  ASSERT_TRUE(ReadFile(UrdfDir() + "/ur_like.urdf", &text).ok());
  std::mt19937_64 rng(17);
  int rejected = 0;
  for (int trial = 0; trial < 400; ++trial) {
    std::string mutated = text;
    if (trial % 2 == 0) {
      mutated.resize(std::uniform_int_distribution<size_t>(0, text.size())(rng));
    } else {
      for (int k = 0; k < 3; ++k) {
        const size_t at = std::uniform_int_distribution<size_t>(0, text.size() - 1)(rng);
        mutated[at] = static_cast<char>(std::uniform_int_distribution<int>(0, 255)(rng));
      }
    }
    RobotModel m;
    const Status s = ParseRobotModelUrdf(mutated, "mutated.urdf", &m);
    if (!s.ok()) {
      ++rejected;
      EXPECT_EQ(s.message().rfind("mutated.urdf:", 0), 0u) << s.message();
    }
  }
  EXPECT_GT(rejected, 100);
  // Out-of-range numbers and an empty document.
  RobotModel m;
  EXPECT_FALSE(ParseRobotModelUrdf("", "empty.urdf", &m).ok());
  const std::string huge = R"(<robot name="r"><link name="a"/><link name="b"/>
<joint name="j" type="revolute"><parent link="a"/><child link="b"/><origin xyz="1e999 0 0"/></joint></robot>)";
  const Status s = ParseRobotModelUrdf(huge, "huge.urdf", &m);
  EXPECT_FALSE(s.ok());
  EXPECT_EQ(s.message().rfind("huge.urdf:2: ", 0), 0u) << s.message();
}

}  // namespace urdf_test
}  // namespace
}  // namespace lpoe
