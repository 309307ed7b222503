// Issue 13 item 5: registration and calibration of every chain the model format allows, measured
// in a tracker frame metres away and turned: SCARA-like, planar and one-joint robots, and a model
// whose second tool is never measured (reported as not identified, the rest calibrated).
#include <cmath>
#include <string>

#include <gtest/gtest.h>

#include "lpoe/io.h"
#include "lpoe/kinematics.h"
#include "lpoe/pipeline.h"
#include "lpoe/simulation.h"

namespace lpoe {
namespace {

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
    if (solver == SolverKind::kLinear) {
      EXPECT_TRUE(reported);
    }
    // The unmeasured tool keeps the frame it was given (in the registered model).
    EXPECT_LT((r.result.model.tools[1].origin.t - r.start.tools[1].origin.t).norm(), 1e-12);
  }
}

}  // namespace
}  // namespace lpoe
