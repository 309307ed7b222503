// The calibrated URDF write-back: a cell URDF with meshes, limits,
// inertials, a fixed base link, tool0 on an adapter, a side branch (camera) and a gripper with a
// mimic joint is calibrated by the tools from tracker data (in a frame metres away from the base)
// with --tip_link=tool0, and the written file is checked by urdfdom, not by our reader:
//   - every link and joint of the source is there with its name, type, parents, limits, mimic,
//     meshes and inertials; joints off the calibrated chain keep their origins;
//   - `measurement_frame` is a separate fixed link on the base link at the YAML's registration,
//     and the cell placement (world -> base_link) is unchanged;
//   - forward kinematics composed from urdfdom's joint origins and axes, from measurement_frame to
//     tool0, equals the calibrated model's (our YAML output) to 1e-6 mm;
//   - check_urdf accepts the file; the UR kinematics YAML holds the written joint origins.
#include <gtest/gtest.h>
#include <urdf_parser/urdf_parser.h>
#include <yaml-cpp/yaml.h>

#include <Eigen/Geometry>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <map>
#include <random>
#include <set>
#include <sstream>
#include <string>

#include "lpoe/io/io.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/model/simulation.h"
#include "lpoe/io/urdf.h"

namespace lpoe {
namespace {
namespace urdf_overlay_test {

namespace fs = std::filesystem;

constexpr double kFkToleranceMm = 1e-6;
constexpr double kRotationTolerance = 1e-9;
constexpr int kFkTrials = 25;
const char* const kChain[6] = {"shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint",
                               "wrist_1_joint",      "wrist_2_joint",       "wrist_3_joint"};

std::string Fixture() { return std::string(LPOE_TEST_DATA_DIR) + "/urdf/cell_ur5e.urdf"; }

std::string Slurp(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

int RunCommand(const std::string& cmd) {
  const int rc = std::system((cmd + " > /dev/null 2>&1").c_str());
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

Eigen::Isometry3d ToIsometry(const urdf::Pose& p) {
  double x, y, z, w;
  p.rotation.getQuaternion(x, y, z, w);
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::Quaterniond(w, x, y, z).toRotationMatrix();
  T.translation() = Eigen::Vector3d(p.position.x, p.position.y, p.position.z);
  return T;
}

// The pose of `link` in the root link (metres), composed from urdfdom's joints: origin, then the
// joint's motion about/along its axis by q (0 for joints not in `q`).
Eigen::Isometry3d RootPose(const urdf::ModelInterface& model, const std::string& link,
                           const std::map<std::string, double>& q) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  for (urdf::LinkConstSharedPtr l = model.getLink(link); l && l->parent_joint;
       l = model.getLink(l->parent_joint->parent_link_name)) {
    const urdf::Joint& j = *l->parent_joint;
    const auto it = q.find(j.name);
    const double value = it == q.end() ? 0.0 : it->second;
    const Eigen::Vector3d axis(j.axis.x, j.axis.y, j.axis.z);
    Eigen::Isometry3d motion = Eigen::Isometry3d::Identity();
    if (j.type == urdf::Joint::REVOLUTE || j.type == urdf::Joint::CONTINUOUS) {
      motion.linear() = Eigen::AngleAxisd(value, axis.normalized()).toRotationMatrix();
    } else if (j.type == urdf::Joint::PRISMATIC) {
      motion.translation() = axis.normalized() * value;
    }
    T = ToIsometry(j.parent_to_joint_origin_transform) * motion * T;
  }
  return T;
}

std::string MeshOf(const urdf::GeometrySharedPtr& g) {
  if (!g || g->type != urdf::Geometry::MESH) return "";
  return static_cast<const urdf::Mesh&>(*g).filename;
}

class UrdfOverlay : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(fs::temp_directory_path() /
                        ("lpoe_urdf_overlay_" + std::to_string(::getpid())));
    fs::create_directories(*dir_);
    const std::string d = dir_->string() + "/";
    // Tracker data of an arm with random kinematic errors, measured at tool0 in the base frame...
    ASSERT_EQ(RunCommand(std::string(LPOE_SIMULATE_PATH) + " --model=" + Fixture() +
                         " --tip_link=tool0 --errors=random --count=60 --noise_sigma=0.01 --seed=5"
                         " --output=" +
                         d + "base.csv"),
              0);
    // ... then moved into a tracker frame 2.8 m away and turned.
    RobotModel nominal;
    UrdfOptions options;
    options.tip_link = "tool0";
    ASSERT_TRUE(ReadRobotModelUrdf(Fixture(), &nominal, options).ok());
    MeasurementSet data;
    ASSERT_TRUE(ReadMeasurements(d + "base.csv", nominal, AngleUnit::kRadians, &data).ok());
    const SE3d T_tracker_base(RotationFromRpy(0.1, -0.05, 2.2), Eigen::Vector3d(2500, -1200, 300));
    for (int r = 0; r < data.size(); ++r) {
      data.mutable_position(r) = T_tracker_base * data.position(r);
    }
    ASSERT_TRUE(WriteMeasurements(d + "tracker.csv", nominal, data).ok());
    calibrate_rc_ = RunCommand(std::string(LPOE_CALIBRATE_PATH) + " --model=" + Fixture() +
                               " --tip_link=tool0 --measurements=" + d +
                               "tracker.csv --output=" + d + "cal.yaml --urdf_output=" + d +
                               "cal.urdf --ur_kinematics_output=" + d + "kin.yaml --plots_dir=");
  }
  static void TearDownTestSuite() {
    std::error_code ec;
    fs::remove_all(*dir_, ec);
    delete dir_;
  }
  void SetUp() override {
    ASSERT_EQ(calibrate_rc_, 0);
    source_ = urdf::parseURDFFile(Fixture());
    written_ = urdf::parseURDFFile(Path("cal.urdf"));
    ASSERT_TRUE(source_ != nullptr);
    ASSERT_TRUE(written_ != nullptr) << Slurp(Path("cal.urdf"));
  }
  static std::string Path(const std::string& name) { return (*dir_ / name).string(); }

  static fs::path* dir_;
  static int calibrate_rc_;
  urdf::ModelInterfaceSharedPtr source_, written_;
};

fs::path* UrdfOverlay::dir_ = nullptr;
int UrdfOverlay::calibrate_rc_ = -1;

TEST_F(UrdfOverlay, EveryNameLimitMeshAndInertialIsKept) {
  std::vector<urdf::LinkSharedPtr> links;
  source_->getLinks(links);
  ASSERT_GT(links.size(), 15u);
  for (const urdf::LinkSharedPtr& a : links) {
    SCOPED_TRACE(a->name);
    const urdf::LinkConstSharedPtr b = written_->getLink(a->name);
    ASSERT_TRUE(b != nullptr);
    ASSERT_EQ(a->visual_array.size(), b->visual_array.size());
    for (size_t k = 0; k < a->visual_array.size(); ++k) {
      EXPECT_EQ(MeshOf(a->visual_array[k]->geometry), MeshOf(b->visual_array[k]->geometry));
    }
    ASSERT_EQ(a->collision_array.size(), b->collision_array.size());
    for (size_t k = 0; k < a->collision_array.size(); ++k) {
      EXPECT_EQ(MeshOf(a->collision_array[k]->geometry), MeshOf(b->collision_array[k]->geometry));
    }
    ASSERT_EQ(a->inertial == nullptr, b->inertial == nullptr);
    if (a->inertial) {
      EXPECT_EQ(a->inertial->mass, b->inertial->mass);
      EXPECT_EQ(a->inertial->ixx, b->inertial->ixx);
      EXPECT_EQ(a->inertial->origin.position.z, b->inertial->origin.position.z);
    }
  }
  const std::set<std::string> chain(std::begin(kChain), std::end(kChain));
  int joints = 0;
  for (const auto& [name, a] : source_->joints_) {
    SCOPED_TRACE(name);
    ++joints;
    const urdf::JointConstSharedPtr b = written_->getJoint(name);
    ASSERT_TRUE(b != nullptr);
    EXPECT_EQ(a->type, b->type);
    EXPECT_EQ(a->parent_link_name, b->parent_link_name);
    EXPECT_EQ(a->child_link_name, b->child_link_name);
    ASSERT_EQ(a->limits == nullptr, b->limits == nullptr);
    if (a->limits) {
      EXPECT_EQ(a->limits->lower, b->limits->lower);
      EXPECT_EQ(a->limits->upper, b->limits->upper);
      EXPECT_EQ(a->limits->effort, b->limits->effort);
      EXPECT_EQ(a->limits->velocity, b->limits->velocity);
    }
    ASSERT_EQ(a->mimic == nullptr, b->mimic == nullptr);
    if (chain.count(name) == 0 && name != "flange-tool0") {  // off the calibrated chain
      EXPECT_EQ(ToIsometry(a->parent_to_joint_origin_transform).matrix(),
                ToIsometry(b->parent_to_joint_origin_transform).matrix());
    }
  }
  EXPECT_EQ(joints, 15);
  EXPECT_EQ(written_->joints_.size(), source_->joints_.size() + 1);  // + measurement_frame_joint
  const std::string text = Slurp(Path("cal.urdf"));
  for (const char* kept :
       {"<transmission name=\"wrist_3_joint_trans\">",
        "<mechanicalReduction>1</mechanicalReduction>", "<gazebo reference=\"shoulder_link\">",
        "libgazebo_ros_control.so", "xmlns:xacro="}) {
    EXPECT_NE(text.find(kept), std::string::npos) << kept;
  }
}

TEST_F(UrdfOverlay, MeasurementFrameIsSeparateAndTheBaseStays) {
  const urdf::LinkConstSharedPtr m = written_->getLink("measurement_frame");
  ASSERT_TRUE(m != nullptr);
  ASSERT_TRUE(m->parent_joint != nullptr);
  EXPECT_EQ(m->parent_joint->type, urdf::Joint::FIXED);
  EXPECT_EQ(m->parent_joint->parent_link_name, "world");
  // The tracker stands metres away from the robot: its frame is not folded into joint 1.
  EXPECT_GT(ToIsometry(m->parent_joint->parent_to_joint_origin_transform).translation().norm(),
            2.0);
  EXPECT_EQ(written_->getRoot()->name, "world");
  // One model: the measurement frame is the YAML's recorded registration
  // (T_base_measurement = T_measurement_base^-1) and joint 1 takes T_measurement_base^-1 C_1, so
  // that the URDF predicts in its base frame what the YAML predicts there.
  RobotModel calibrated;
  ASSERT_TRUE(ReadRobotModel(Path("cal.yaml"), &calibrated).ok());
  const SE3d base_from_measurement = calibrated.T_measurement_base.Inverse();
  EXPECT_LT((ToIsometry(m->parent_joint->parent_to_joint_origin_transform).translation() * 1000.0 -
             base_from_measurement.t)
                .norm(),
            1e-6);
  std::map<std::string, double> zero;
  for (const char* j : kChain) zero[j] = 0.0;
  const Eigen::Isometry3d shoulder = RootPose(*written_, "shoulder_link", zero);
  const SE3d expected = base_from_measurement * calibrated.joints[0].origin;
  EXPECT_LT((shoulder.translation() * 1000.0 - expected.t).norm(), 1e-6);
  EXPECT_LT((shoulder.linear() - expected.R).norm(), 1e-9);
  // The other chain joints did change: the calibration moved them.
  const Eigen::Isometry3d e0 =
      ToIsometry(source_->getJoint("elbow_joint")->parent_to_joint_origin_transform);
  const Eigen::Isometry3d e1 =
      ToIsometry(written_->getJoint("elbow_joint")->parent_to_joint_origin_transform);
  EXPECT_GT((e0.translation() - e1.translation()).norm(), 1e-5);
}

TEST_F(UrdfOverlay, IndependentKinematicsEqualTheCalibratedModel) {
  RobotModel calibrated;
  ASSERT_TRUE(ReadRobotModel(Path("cal.yaml"), &calibrated).ok());
  ASSERT_EQ(calibrated.num_joints(), 6);
  ASSERT_EQ(calibrated.num_tools(), 1);
  EXPECT_EQ(calibrated.tools[0].name, "tool0");
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> angle(-3.0, 3.0);
  double worst_mm = 0, worst_rot = 0;
  for (int trial = 0; trial < kFkTrials; ++trial) {
    double q[6];
    std::map<std::string, double> named;
    for (int i = 0; i < 6; ++i) named[kChain[i]] = q[i] = angle(rng);
    const Eigen::Isometry3d T_root_meas = RootPose(*written_, "measurement_frame", named);
    const Eigen::Isometry3d T_root_tool = RootPose(*written_, "tool0", named);
    const Eigen::Isometry3d T = T_root_meas.inverse() * T_root_tool;
    const SE3d expected = ToolPose(calibrated, q, 0);
    worst_mm = std::max(worst_mm, (T.translation() * 1000.0 - expected.t).norm());
    worst_rot = std::max(worst_rot, (T.linear() - expected.R).norm());
  }
  RecordProperty("worst_mm", std::to_string(worst_mm));
  std::cout << "worst FK difference " << worst_mm << " mm, " << worst_rot << " (rotation)\n";
  EXPECT_LT(worst_mm, kFkToleranceMm);
  EXPECT_LT(worst_rot, kRotationTolerance);
}

TEST_F(UrdfOverlay, CheckUrdfAcceptsTheWrittenFile) {
  EXPECT_EQ(RunCommand(std::string(CHECK_URDF_PATH) + " " + Path("cal.urdf")), 0);
  EXPECT_NE(RunCommand(std::string(CHECK_URDF_PATH) + " " + Path("missing.urdf")), 0);
}

TEST_F(UrdfOverlay, UrKinematicsHoldTheWrittenJointOrigins) {
  const YAML::Node kin = YAML::LoadFile(Path("kin.yaml"))["kinematics"];
  const char* keys[6] = {"shoulder", "upper_arm", "forearm", "wrist_1", "wrist_2", "wrist_3"};
  for (int i = 0; i < 6; ++i) {
    SCOPED_TRACE(keys[i]);
    const YAML::Node k = kin[keys[i]];
    ASSERT_TRUE(k.IsMap());
    const Eigen::Isometry3d T =
        ToIsometry(written_->getJoint(kChain[i])->parent_to_joint_origin_transform);
    EXPECT_LT((T.translation() -
               Eigen::Vector3d(k["x"].as<double>(), k["y"].as<double>(), k["z"].as<double>()))
                  .norm(),
              1e-12);
    const Eigen::Matrix3d R =
        RotationFromRpy(k["roll"].as<double>(), k["pitch"].as<double>(), k["yaw"].as<double>());
    EXPECT_LT((T.linear() - R).norm(), 1e-12);
  }
  EXPECT_EQ(kin["hash"].as<std::string>().rfind("lpoe_calib_", 0), 0u);
}

TEST_F(UrdfOverlay, UrdfFlagsWithoutAUrdfOrAUrAreUsageErrors) {
  const std::string cal = std::string(LPOE_CALIBRATE_PATH) + " --plots_dir= ";
  const std::string out = Path("refused.yaml");
  // A YAML model has no links to choose from.
  EXPECT_EQ(RunCommand(cal + "--model=" + std::string(LPOE_DATA_DIR) +
                       "/cobot6.yaml --tip_link=tool0 --output=" + out),
            1);
  // ur_like's joints are not named like a UR's.
  const std::string ur_like = std::string(LPOE_TEST_DATA_DIR) + "/urdf/ur_like.urdf";
  ASSERT_EQ(RunCommand(std::string(LPOE_SIMULATE_PATH) + " --model=" + ur_like +
                       " --errors=none --count=30 --output=" + Path("ur_like.csv")),
            0);
  EXPECT_EQ(RunCommand(cal + "--model=" + ur_like + " --measurements=" + Path("ur_like.csv") +
                       " --ur_kinematics_output=" + out),
            1);
  // An ambiguous tree is an input error naming the candidates.
  EXPECT_EQ(RunCommand(cal + "--model=" + Fixture() + " --measurements=" + Path("tracker.csv") +
                       " --output=" + out),
            2);
  EXPECT_FALSE(fs::exists(out));
}

// ---------------------------------------------------------------------------------------------------
// Chain selection on the same cell (library level).

TEST(UrdfChain, AmbiguousTreeListsTheCandidateTips) {
  RobotModel m = MakeCobot6();
  const Status s = ReadRobotModelUrdf(Fixture(), &m);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("'left_finger'"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("'right_finger'"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("tip_link"), std::string::npos) << s.message();
  EXPECT_EQ(m.name, "cobot6");
}

TEST(UrdfChain, MimicJointOnTheChainIsRefusedByName) {
  RobotModel m;
  UrdfOptions options;
  options.tip_link = "right_finger";
  const Status s = ReadRobotModelUrdf(Fixture(), &m, options);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("'right_finger_joint'"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("mimic"), std::string::npos) << s.message();
  // The finger that is not a mimic extends the chain to 7 joints.
  options.tip_link = "left_finger";
  ASSERT_TRUE(ReadRobotModelUrdf(Fixture(), &m, options).ok());
  ASSERT_EQ(m.num_joints(), 7);
  EXPECT_EQ(m.joints[6].type, JointType::kPrismatic);
  EXPECT_DOUBLE_EQ(m.joints[6].lower, 0.0);
  EXPECT_DOUBLE_EQ(m.joints[6].upper, 40.0);  // 0.04 m in mm
}

TEST(UrdfChain, BaseAndTipLinksAndLimits) {
  RobotModel world, base;
  UrdfOptions options;
  options.tip_link = "tool0";
  ASSERT_TRUE(ReadRobotModelUrdf(Fixture(), &world, options).ok());
  options.base_link = "base_link";
  ASSERT_TRUE(ReadRobotModelUrdf(Fixture(), &base, options).ok());
  // The pedestal (world -> base_link) is folded into joint 1 only when the base is the root.
  const SE3d pedestal(RotationFromRpy(0.0, 0.0, 0.7853981633974483),
                      Eigen::Vector3d(800, -350, 740));
  EXPECT_LT(((pedestal * base.joints[0].origin).Matrix() - world.joints[0].origin.Matrix()).norm(),
            1e-9);
  EXPECT_DOUBLE_EQ(world.joints[2].lower, -3.141592653589793);
  EXPECT_DOUBLE_EQ(world.joints[2].upper, 3.141592653589793);
  EXPECT_DOUBLE_EQ(world.joints[0].upper, 2 * 3.141592653589793);
  // Bad choices name the link.
  options.base_link = "camera_link";
  Status s = ReadRobotModelUrdf(Fixture(), &base, options);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("'tool0' is not below the base link 'camera_link'"), std::string::npos)
      << s.message();
  options.base_link = "";
  options.tip_link = "no_such_link";
  s = ReadRobotModelUrdf(Fixture(), &base, options);
  EXPECT_NE(s.message().find("tip link 'no_such_link' does not exist"), std::string::npos)
      << s.message();
}

TEST(UrdfChain, SimulationStaysWithinTheJointLimits) {
  std::string xml = Slurp(Fixture());
  // Narrow the elbow to [-0.5, 0.3] rad.
  const std::string from = "lower=\"-3.141592653589793\" upper=\"3.141592653589793\"";
  ASSERT_NE(xml.find(from), std::string::npos);
  xml.replace(xml.find(from), from.size(), "lower=\"-0.5\" upper=\"0.3\"");
  RobotModel m;
  UrdfOptions options;
  options.tip_link = "tool0";
  ASSERT_TRUE(ParseRobotModelUrdf(xml, "narrow.urdf", &m, options).ok());
  SimulationOptions sim;
  sim.count = 500;
  const MeasurementSet data = SimulateMeasurements(m, {}, sim);
  double lo = 1e9, hi = -1e9;
  for (int r = 0; r < data.size(); ++r) {
    lo = std::min(lo, data.q(r)[2]);
    hi = std::max(hi, data.q(r)[2]);
  }
  EXPECT_GE(lo, -0.5);
  EXPECT_LE(hi, 0.3);
  EXPECT_LT(lo, -0.4);  // the whole range is used
  EXPECT_GT(hi, 0.2);
}

// A joint name with "--" (found by fuzz_urdf) is listed in the overlay's comment: the comment must
// stay well formed so that the overlay reads back.
TEST(UrdfOverlayComment, JointNameWithDashesReadsBack) {
  const std::string xml = R"(<?xml version="1.0"?>
<robot name="two">
  <link name="base"/><link name="l1"/><link name="tip"/>
  <joint name="j--><![CDATA[1-" type="revolute">
    <parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0.096" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="2" velocity="1"/>
  </joint>
  <joint name="j2" type="revolute">
    <parent link="l1"/><child link="tip"/>
    <origin xyz="0.1 0 0" rpy="0 0 0"/><axis xyz="0 1 0"/>
    <limit lower="-3" upper="3" effort="2" velocity="1"/>
  </joint>
</robot>
)";
  RobotModel model;
  UrdfSource source;
  ASSERT_TRUE(ParseRobotModelUrdf(xml, "dashes.urdf", &model, {}, &source).ok());
  std::string overlay;
  ASSERT_TRUE(CalibratedUrdfOverlay(source, model, {}, &overlay).ok());
  RobotModel back;
  const Status s = ParseRobotModelUrdf(overlay, "overlay.urdf", &back);
  ASSERT_TRUE(s.ok()) << s.message() << "\n" << overlay;
  EXPECT_EQ(back.num_joints(), 2);
  EXPECT_EQ(back.joints[0].name, model.joints[0].name);
}

}  // namespace urdf_overlay_test
}  // namespace
}  // namespace lpoe
