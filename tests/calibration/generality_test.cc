// Issue 13 item 5: registration and calibration of every chain the model format allows, measured
// in a tracker frame metres away and turned: SCARA-like, planar and one-joint robots, and a model
// whose second tool is never measured (reported as not identified, the rest calibrated).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "lpoe/io/io.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/pipeline.h"
#include "lpoe/model/simulation.h"

namespace lpoe {
namespace {
namespace generality_test {

constexpr int kPoses = 120;
constexpr double kNoiseMm = 0.01;
// After calibration the held-out error is the noise, not the errors put in (about 1 mm).
constexpr double kFitRmsMm = 0.05;

const char kScara[] = R"(name: scara
joints:
  - {name: j1, type: revolute, origin: {xyz: [0, 0, 300], rpy: [0, 0, 0]}}
  - {name: j2, type: revolute, origin: {xyz: [350, 0, 0], rpy: [0, 0, 0]}}
  - {name: j3, type: prismatic, origin: {xyz: [300, 0, 0], rpy: [0, 0, 0]}}
  - {name: j4, type: revolute, origin: {xyz: [0, 0, -50], rpy: [0, 0, 0]}}
tools:
  - {name: smr, origin: {xyz: [40, 20, -30], rpy: [0, 0, 0]}}
)";
const char kPlanar[] = R"(name: planar
joints:
  - {name: j1, type: revolute, origin: {xyz: [0, 0, 100], rpy: [0, 0, 0]}}
  - {name: j2, type: revolute, origin: {xyz: [400, 0, 0], rpy: [0, 0, 0]}}
  - {name: j3, type: revolute, origin: {xyz: [300, 0, 0], rpy: [0, 0, 0]}}
tools:
  - {name: smr, origin: {xyz: [100, 0, 0], rpy: [0, 0, 0]}}
)";
const char kOneJoint[] = R"(name: one
joints:
  - {name: j1, type: revolute, origin: {xyz: [0, 0, 100], rpy: [0, 0, 0]}}
tools:
  - {name: smr, origin: {xyz: [300, 50, 20], rpy: [0, 0, 0]}}
)";

RobotModel Parse(const char* yaml) {
  RobotModel m;
  const Status s = ParseRobotModelYaml(yaml, "test", &m);
  EXPECT_TRUE(s.ok()) << s.message();
  return m;
}

// Measurements of `nominal` with small random errors, in a tracker frame 2 m away and turned.
MeasurementSet Measure(const RobotModel& nominal, RobotModel* actual_in_tracker) {
  const KinematicErrors errors = RandomErrors(nominal, 0.002, 1.0, 0.002, 0.0, 5);
  RobotModel actual = ApplyErrors(nominal, errors);
  SimulationOptions o;
  o.count = kPoses;
  o.noise_sigma = kNoiseMm;
  MeasurementSet data = SimulateMeasurements(actual, errors.joint_zero, o);
  Vector6d xi;
  xi << 0.3, -0.2, 1.1, 2000, -1500, 300;
  const SE3d T = ExpSE3(xi);
  for (int r = 0; r < data.size(); ++r) data.mutable_position(r) = T * data.position(r);
  actual.joints[0].origin = T * actual.joints[0].origin;
  *actual_in_tracker = actual;
  return data;
}

void ExpectCalibrated(const RobotModel& nominal) {
  RobotModel actual;
  const MeasurementSet data = Measure(nominal, &actual);
  MeasurementSet id, ver;
  data.SplitAt(kPoses * 2 / 3, &id, &ver);
  const PipelineResult r = RunCalibrationPipeline(nominal, id, ver, PipelineOptions());
  ASSERT_EQ(r.result.termination, Termination::kConverged) << r.result.message;
  EXPECT_TRUE(r.registration.moved) << r.registration.message;
  EXPECT_LT(r.verification_after.norm.rms, kFitRmsMm);
  EXPECT_EQ(r.verdict.level, VerdictLevel::kPass) << r.verdict.reason;
}

TEST(Generality, ScaraLikeRobotInATrackerFrame) { ExpectCalibrated(Parse(kScara)); }
TEST(Generality, PlanarRobotInATrackerFrame) { ExpectCalibrated(Parse(kPlanar)); }
TEST(Generality, OneJointRobotInATrackerFrame) { ExpectCalibrated(Parse(kOneJoint)); }

TEST(Generality, UnmeasuredToolIsReportedAndTheRestCalibrated) {
  RobotModel nominal = MakeCobot6();
  Tool second = nominal.tools[0];
  second.name = "smr2";
  second.origin.t = Eigen::Vector3d(-40, 30, 60);
  nominal.tools.push_back(second);
  RobotModel actual;
  const MeasurementSet data = Measure(nominal, &actual);  // every row measures tool 0
  for (SolverKind solver : {SolverKind::kLinear, SolverKind::kCeres}) {
    PipelineOptions o;
    o.solver = solver;
    o.ceres.num_threads = 1;
    const PipelineResult r = RunCalibrationPipeline(nominal, data, MeasurementSet(), o);
    ASSERT_EQ(r.result.termination, Termination::kConverged) << r.result.message;
    EXPECT_LT(r.identification_after.norm.rms, kFitRmsMm);
    bool reported = false;
    for (const Direction& d : r.identifiability.unidentifiable) {
      reported = reported || (d.name.rfind("smr2.t", 0) == 0 &&
                              d.reason.find("never measured") != std::string::npos);
    }
    EXPECT_TRUE(reported) << "solver " << static_cast<int>(solver);  // both solvers list it
    // The unmeasured tool keeps the frame it was given (in the registered model).
    EXPECT_LT((r.result.model.tools[1].origin.t - r.start.tools[1].origin.t).norm(), 1e-12);
  }
}

// ---- A tool on the last joint's axis (a UR robot's tool0 measured directly): turning the last
// joint never moves it, so the tilt of that axis about the point is not identifiable from position
// data at any poses. It is kept as given and reported; everything else is calibrated.

RobotModel UrWithToolOnLastAxis() {
  RobotModel m = MakeUr5Like();
  m.tools.resize(1);
  m.tools[0].name = "tool0";
  m.tools[0].origin = SE3d(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0, 0, 82.3));
  return m;
}

// Data of `nominal` with realistic errors (about 1 mm, 0.1 degree, joint zeros 0.1 degree), in the
// base frame or in a tracker frame; `actual` with its joint zeros folded in, in the data's frame.
// `tool_on_axis`: the actual tool stays on the actual last axis (no error across it).
MeasurementSet MeasureWithZeros(const RobotModel& nominal, bool tracker_frame, bool pose,
                                RobotModel* actual, bool tool_on_axis = false) {
  KinematicErrors errors = RandomErrors(nominal, 0.002, 1.0, 0.002, 0.002, 9);
  if (tool_on_axis) {
    errors.frame[nominal.num_joints()].tail<3>().head<2>().setZero();
    errors.twist[nominal.num_joints() - 1].setZero();
  }
  const RobotModel with_errors = ApplyErrors(nominal, errors);
  SimulationOptions o;
  o.count = kPoses;
  o.noise_sigma = kNoiseMm;
  o.pose = pose;
  o.orientation_noise_sigma = pose ? 1e-5 : 0.0;
  MeasurementSet data = SimulateMeasurements(with_errors, errors.joint_zero, o);
  *actual = FoldJointZeros(with_errors, errors.joint_zero);
  if (tracker_frame) {
    Vector6d xi;
    xi << 0.3, -0.2, 1.1, 2000, -1500, 300;
    const SE3d T = ExpSE3(xi);
    MeasurementSet moved(data.num_joints());
    for (int r = 0; r < data.size(); ++r) {
      if (pose) {
        moved.AddPose(data.q(r), T * data.pose(r), data.target(r));
      } else {
        moved.Add(data.q(r), T * data.position(r), data.target(r));
      }
    }
    data = moved;
    actual->joints[0].origin = T * actual->joints[0].origin;
  }
  return data;
}

// Largest position difference between two models over fresh configurations.
double MaxPredictionDifference(const RobotModel& a, const RobotModel& b) {
  SimulationOptions o;
  o.count = 200;
  o.seed = 77;
  const MeasurementSet fresh = SimulateMeasurements(a, std::vector<double>(a.num_joints(), 0.0), o);
  double worst = 0;
  for (int r = 0; r < fresh.size(); ++r) {
    worst = std::max(worst, (ToolPosition(b, fresh.q(r), 0) - fresh.position(r)).norm());
  }
  return worst;
}

bool ReportedOnTheAxis(const PipelineResult& r, const std::string& name) {
  for (const Direction& d : r.identifiability.unidentifiable) {
    if (d.name == name && d.reason.find("lies on joint6's axis") != std::string::npos) return true;
  }
  return false;
}

TEST(Generality, ToolOnTheLastAxisIsCalibratedWithTheAxisTiltReported) {
  const RobotModel nominal = UrWithToolOnLastAxis();
  for (const bool tracker_frame : {false, true}) {
    for (const bool register_frames : {false, true}) {
      if (tracker_frame && !register_frames) continue;  // needs registration
      // The actual tool on the actual axis too: registration then moves the tool by the noise only,
      // which must not make the axis' tilt look identifiable.
      for (const bool on_axis : {false, true}) {
        for (const SolverKind solver : {SolverKind::kLinear, SolverKind::kCeres}) {
          for (const ParameterizationKind kind :
               {ParameterizationKind::kIdentifiable, ParameterizationKind::kFull}) {
            // Regression: Levenberg-Marquardt on the full parameterization drifted along the lost
            // tilt, which comes back weakly through joint 5's gauge directions once the model
            // moves, until the iteration limit (lpoe_calibrate exit code 4). Its steps are now
            // measured in the identifiable directions, as the linear solver's truncated
            // pseudo-inverse solves them (ceres_solver.cc, ConvergenceWatch).
            SCOPED_TRACE(::testing::Message()
                         << "tracker frame " << tracker_frame << ", register " << register_frames
                         << ", actual tool on the axis " << on_axis << ", solver "
                         << static_cast<int>(solver) << ", parameterization "
                         << ParameterizationName(kind));
            RobotModel actual;
            const MeasurementSet data =
                MeasureWithZeros(nominal, tracker_frame, false, &actual, on_axis);
            PipelineOptions o;
            o.solver = solver;
            o.parameterization = kind;
            o.register_frames = register_frames;
            o.ceres.num_threads = 1;
            const PipelineResult r = RunCalibrationPipeline(nominal, data, MeasurementSet(), o);
            ASSERT_EQ(r.result.termination, Termination::kConverged) << r.result.message;
            EXPECT_EQ(r.verdict.level, VerdictLevel::kPass) << r.verdict.reason;
            EXPECT_LT(r.identification_after.norm.rms, kFitRmsMm);
            // Decided at the data's estimate, not at the nominal tool0: the tilt is left out only
            // when the actual point is on the axis; about a millimetre off it (the random tool
            // error), the data determine the tilt, weakly (docs/identifiability.md).
            EXPECT_EQ(ReportedOnTheAxis(r, "joint6.rx"), on_axis);
            EXPECT_EQ(ReportedOnTheAxis(r, "joint6.ry"), on_axis);
            // The errors are recovered: the calibrated robot predicts the actual one everywhere.
            EXPECT_LT(MaxPredictionDifference(actual, r.geometric), 4 * kFitRmsMm);
            EXPECT_GT(MaxPredictionDifference(actual, nominal), 1.0);  // not vacuous
          }
        }
      }
    }
  }
}

TEST(Generality, ToolOnTheLastAxisWithPoseDataIsFullyIdentified) {
  const RobotModel nominal = UrWithToolOnLastAxis();
  RobotModel actual;
  const MeasurementSet data = MeasureWithZeros(nominal, false, true, &actual);
  PipelineOptions o;
  o.use_orientation = true;
  const PipelineResult r = RunCalibrationPipeline(nominal, data, MeasurementSet(), o);
  ASSERT_EQ(r.result.termination, Termination::kConverged) << r.result.message;
  EXPECT_FALSE(ReportedOnTheAxis(r, "joint6.rx"));
  EXPECT_LT(MaxPredictionDifference(actual, r.geometric), 4 * kFitRmsMm);
}

// Too few or too similar poses are still refused (not "reduced"), with what to do.
TEST(Generality, PosesThatDoNotMoveAJointAreStillRefused) {
  const RobotModel nominal = MakeCobot6();
  RobotModel actual;
  MeasurementSet data = MeasureWithZeros(nominal, false, false, &actual);
  for (int r = 0; r < data.size(); ++r) data.mutable_q(r)[2] = 0.3;  // joint 3 never moves
  const PipelineResult r =
      RunCalibrationPipeline(nominal, data, MeasurementSet(), PipelineOptions());
  EXPECT_EQ(r.result.termination, Termination::kNotIdentifiable);
  EXPECT_NE(r.result.message.find("move every joint"), std::string::npos) << r.result.message;
}

}  // namespace generality_test
}  // namespace
}  // namespace lpoe
