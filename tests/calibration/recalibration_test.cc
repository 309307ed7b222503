// Recalibration and fleet priors (docs/recalibration.md), simulated with realistic
// magnitudes: a UR5-like 6R arm with 3 SMRs off the flange axis, a tracker 3 m away (standing
// elsewhere in each session), frame errors of a few mm and mrad, noise 0.02 mm per axis.
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "lpoe/io/io.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/model/model_covariance.h"
#include "lpoe/pipeline.h"
#include "lpoe/recalibration.h"
#include "lpoe/registration.h"
#include "lpoe/model/simulation.h"
#include "three_smr_cell.h"

namespace lpoe {
namespace {
namespace recalibration_test {

constexpr double kNoise = 0.02;

RobotModel Nominal() { return testing::ThreeSmrUr5(); }

SE3d Tracker(uint64_t seed) { return testing::TrackerThreeMetresAway(seed, 0.3); }

// An actual robot: `model` (its errors in its frames) with joint zeros `zero`.
struct Robot {
  RobotModel with_errors;
  std::vector<double> zero;
};

Robot RandomRobot(const RobotModel& type, uint64_t seed) {
  const KinematicErrors e = RandomErrors(type, 0.002, 1.0, 0.001, 0.002, seed);
  return {ApplyErrors(type, e), e.joint_zero};
}

// `poses` configurations, every SMR at each (or only the first when `one_smr`), in tracker frame T.
MeasurementSet Measure(const Robot& r, int poses, uint64_t seed, const SE3d& T, double noise,
                       bool one_smr = false) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> angle(-kPi, kPi);
  SimulationOptions o;
  o.all_tools = !one_smr;
  for (int c = 0; c < poses * 6; ++c) o.configurations.push_back(angle(rng));
  o.noise_sigma = noise;
  o.seed = seed + 1;
  const MeasurementSet d = SimulateMeasurements(r.with_errors, r.zero, o);
  MeasurementSet out(d.num_joints());
  for (int k = 0; k < d.size(); ++k) out.Add(d.q(k), T * d.position(k), d.target(k));
  return out;
}

// RMS distance of a model's points from the actual robot's (noise-free, fresh configurations, every
// SMR), after a rigid fit of the model into the fresh data's frame (a model of another session).
double HeldOut(const Robot& r, const RobotModel& model, const SE3d& T, bool one_smr = false) {
  const MeasurementSet fresh = Measure(r, 200, 4242, T, 0.0, one_smr);
  std::vector<Eigen::Vector3d> predicted, measured;
  for (int k = 0; k < fresh.size(); ++k) {
    predicted.push_back(PredictToolPosition(model, fresh.q(k), fresh.target(k)));
    measured.push_back(fresh.position(k));
  }
  SE3d fit;
  EXPECT_TRUE(FitRigidTransform(predicted, measured, &fit).ok());
  double sum = 0;
  for (size_t k = 0; k < predicted.size(); ++k) sum += (fit * predicted[k] - measured[k]).squaredNorm();
  return std::sqrt(sum / predicted.size());
}

struct Calibration {
  RobotModel model;
  ModelCovariance covariance;
};

Calibration Calibrate(const RobotModel& start, const MeasurementSet& data) {
  const PipelineResult r = RunCalibrationPipeline(start, data, MeasurementSet(data.num_joints()),
                                                  PipelineOptions());
  EXPECT_TRUE(r.result.converged()) << r.result.message;
  return {r.result.model, CovarianceOf(r.result)};
}

PipelineOptions WithPrior(const ParameterPrior& prior) {
  PipelineOptions o;
  o.prior = std::make_shared<const ParameterPrior>(prior);
  return o;
}

PipelineOptions LeastSquares() {
  PipelineOptions o;
  o.prior = nullptr;
  return o;
}

// The covariance block survives its YAML (written with the model, read back strictly).
TEST(Recalibration, CovarianceBlockRoundTrip) {
  const RobotModel type = Nominal();
  const Robot a = RandomRobot(type, 5);
  const Calibration cal = Calibrate(type, Measure(a, 60, 1, Tracker(1), kNoise));
  const std::string path = ::testing::TempDir() + "/recalibration_test_cal.yaml";
  ASSERT_TRUE(WriteRobotModel(path, cal.model).ok());
  {
    std::string text = RobotModelToYaml(cal.model) + ModelCovarianceYaml(cal.model, cal.covariance);
    FILE* f = std::fopen(path.c_str(), "w");
    ASSERT_NE(f, nullptr);
    std::fputs(text.c_str(), f);
    std::fclose(f);
  }
  RobotModel read;
  ParameterPrior prior;
  ASSERT_TRUE(ReadPrior(path, PriorScales(), &read, &prior).ok());
  ModelCovariance back;
  ASSERT_TRUE(ReadModelCovariance(path, read, &back).ok());
  ASSERT_EQ(back.frames.size(), cal.covariance.frames.size());
  for (size_t f = 0; f < back.frames.size(); ++f) {
    ASSERT_EQ(back.frames[f].size(), cal.covariance.frames[f].size());
    if (back.frames[f].size() > 0) {
      EXPECT_LE((back.frames[f] - cal.covariance.frames[f]).cwiseAbs().maxCoeff(),
                1e-12 * cal.covariance.frames[f].cwiseAbs().maxCoeff());
    }
  }
  EXPECT_NEAR(back.data_sigma, cal.covariance.data_sigma, 1e-12);
  EXPECT_TRUE(prior.informative);
  // A model reader takes the file as a model (the block is the prior's).
  RobotModel plain;
  EXPECT_TRUE(ReadRobotModel(path, &plain).ok());
  // Strict: a frame listed twice, a non-symmetric matrix, an unknown key are refused with the line.
  const std::string bad = ::testing::TempDir() + "/recalibration_test_bad.yaml";
  for (const std::string& block :
       {std::string("covariance:\n  frames:\n    - {name: joint1, matrix: [1,0,0,0,0,0, 0,1,0,0,0,0, "
                    "0,0,1,0,0,0, 0,0,0,1,0,0, 0,0,0,0,1,0, 0,0,0,0,0,1]}\n    - {name: joint1, "
                    "matrix: [1,0,0,0,0,0, 0,1,0,0,0,0, 0,0,1,0,0,0, 0,0,0,1,0,0, 0,0,0,0,1,0, "
                    "0,0,0,0,0,1]}\n"),
        std::string("covariance:\n  frames:\n    - {name: joint1, matrix: [1,2,0,0,0,0, 0,1,0,0,0,0, "
                    "0,0,1,0,0,0, 0,0,0,1,0,0, 0,0,0,0,1,0, 0,0,0,0,0,1]}\n"),
        std::string("covariance:\n  frame: []\n")}) {
    FILE* f = std::fopen(bad.c_str(), "w");
    ASSERT_NE(f, nullptr);
    std::fputs((RobotModelToYaml(cal.model) + block).c_str(), f);
    std::fclose(f);
    const Status s = ReadPrior(bad, PriorScales(), &read, &prior);
    EXPECT_FALSE(s.ok());
    EXPECT_NE(s.message().find(bad + ":"), std::string::npos) << s.message();
  }
}

// Maintenance: joint 3's zero moves 0.2 deg, joint 5's frame 0.3 mm and 1 mrad. 15 new poses with
// the previous calibration as prior against a least-squares fit of the same 15 poses and against
// the previous model used as is.
TEST(Recalibration, MaintenanceFromFifteenPoses) {
  const RobotModel type = Nominal();
  const Robot before = RandomRobot(type, 7);
  const Calibration previous = Calibrate(type, Measure(before, 150, 11, Tracker(11), kNoise));
  Robot after = before;
  after.zero[2] += 0.2 * kPi / 180;
  // Joint 5's frame: 1 mrad about an axis across its own and joint 4's (not a zero shift of
  // either), 0.3 mm across its axis.
  const SE3d& F = after.with_errors.joints[4].origin;
  const Eigen::Vector3d axis4 = F.R.transpose() * after.with_errors.joints[3].twist.head<3>();
  const Eigen::Vector3d across = Eigen::Vector3d::UnitZ().cross(axis4).normalized();
  Vector6d d;
  d << 0.001 * across, 0.3 * Eigen::Vector3d::UnitZ().cross(across);
  after.with_errors.joints[4].origin = F * ExpSE3(d);
  const SE3d T = Tracker(12);
  const MeasurementSet fifteen = Measure(after, 15, 13, T, kNoise);
  ParameterPrior prior = PriorFromCovariance(previous.model, previous.covariance, PriorScales());
  const RecalibrationResult map =
      Recalibrate(previous.model, fifteen, MeasurementSet(6), WithPrior(prior));
  ASSERT_TRUE(map.run.result.converged()) << map.run.result.message;
  const PipelineResult ls =
      RunCalibrationPipeline(previous.model, fifteen, MeasurementSet(6), LeastSquares());
  ASSERT_TRUE(ls.result.converged()) << ls.result.message;
  const double e_map = HeldOut(after, map.run.result.model, T);
  const double e_ls = HeldOut(after, ls.result.model, T);
  const double e_previous = HeldOut(after, previous.model, T);
  std::string names;
  for (const ChangedGroup& g : map.changed) names += g.name + " (" + std::to_string(g.chi2) + "); ";
  std::cout << "held out: MAP " << e_map << " mm, least squares " << e_ls << " mm, previous "
            << e_previous << " mm; changed: " << names << "\n";
  EXPECT_LE(1.5 * e_map, e_ls);
  EXPECT_LE(10 * e_map, e_previous);
  EXPECT_NE(names.find("joint3"), std::string::npos) << names;
  EXPECT_NE(names.find("joint5"), std::string::npos) << names;
}

// No change: the prior and 15 poses, or 8 single-SMR points (fewer rows than parameters), are no
// worse held out than the prior model (within 10 %).
TEST(Recalibration, NoChangeKeepsThePrior) {
  const RobotModel type = Nominal();
  const Robot robot = RandomRobot(type, 17);
  const Calibration previous = Calibrate(type, Measure(robot, 150, 21, Tracker(21), kNoise));
  const ParameterPrior prior = PriorFromCovariance(previous.model, previous.covariance, PriorScales());
  const SE3d T = Tracker(22);
  const double e_prior = HeldOut(robot, previous.model, T);
  for (const bool few : {false, true}) {
    const MeasurementSet data = few ? Measure(robot, 8, 23, T, kNoise, true)
                                    : Measure(robot, 15, 23, T, kNoise);
    const RecalibrationResult r = Recalibrate(previous.model, data, MeasurementSet(6), WithPrior(prior));
    ASSERT_TRUE(r.run.result.converged()) << r.run.result.message;
    const double e = HeldOut(robot, r.run.result.model, T);
    std::cout << (few ? "8 single-SMR points" : "15 poses") << ": held out " << e
              << " mm against the prior model's " << e_prior << " mm; " << r.changed.size()
              << " groups changed\n";
    EXPECT_LE(e, 1.1 * e_prior);
    EXPECT_TRUE(r.changed.empty());
  }
}

// Joint-space terms (--joint_errors=harmonics) in the changed-group test: a previous calibration
// with the harmonics as prior; 15 new poses of the unchanged robot find no group changed and stay
// at the prior model's accuracy; after a gearbox swap on joint 3 (its harmonics new) the term is
// found changed and the recalibration beats the previous model used as is.
TEST(Recalibration, JointSpaceTermsInTheGroupTest) {
  const RobotModel type = Nominal();
  Robot robot = RandomRobot(type, 27);
  JointErrorPhysics physics;
  physics.stiffness.assign(6, 0.0);
  std::mt19937_64 rng(28);
  std::normal_distribution<double> h(0.0, 1e-4);  // 0.1 mrad per coefficient
  for (int j = 0; j < 6; ++j) physics.harmonics.push_back(Eigen::Vector4d(h(rng), h(rng), h(rng), h(rng)));
  ApplyJointErrorPhysics(physics, {"harmonics"}, &robot.with_errors);
  PipelineOptions with_terms;
  with_terms.joint_errors = {"harmonics"};
  const PipelineResult previous = RunCalibrationPipeline(
      type, Measure(robot, 150, 29, Tracker(29), kNoise), MeasurementSet(6), with_terms);
  ASSERT_TRUE(previous.result.converged()) << previous.result.message;
  const ModelCovariance covariance = CovarianceOf(previous.result);
  ASSERT_EQ(covariance.term_names.size(), 1u);
  PipelineOptions o = with_terms;
  o.prior = std::make_shared<const ParameterPrior>(
      PriorFromCovariance(previous.result.model, covariance, PriorScales()));
  const SE3d T = Tracker(30);
  const double e_prior = HeldOut(robot, previous.result.model, T);
  const RecalibrationResult same =
      Recalibrate(previous.result.model, Measure(robot, 15, 31, T, kNoise), MeasurementSet(6), o);
  ASSERT_TRUE(same.run.result.converged()) << same.run.result.message;
  const double e_same = HeldOut(robot, same.run.result.model, T);
  // The gearbox swap: joint 3's harmonics drawn anew.
  Robot swapped = robot;
  std::vector<double>& values = *swapped.with_errors.joint_errors.MutableValues("harmonics");
  const std::vector<double> before = values;
  JointErrorPhysics other = physics;
  other.harmonics[2] = Eigen::Vector4d(h(rng), h(rng), h(rng), h(rng));
  RobotModel redrawn = robot.with_errors;
  ApplyJointErrorPhysics(other, {"harmonics"}, &redrawn);
  values = redrawn.joint_errors.Values("harmonics");
  ASSERT_NE(values, before);
  const RecalibrationResult map =
      Recalibrate(previous.result.model, Measure(swapped, 15, 32, T, kNoise), MeasurementSet(6), o);
  ASSERT_TRUE(map.run.result.converged()) << map.run.result.message;
  std::string names;
  for (const ChangedGroup& g : map.changed) names += g.name + "; ";
  const double e_map = HeldOut(swapped, map.run.result.model, T);
  const double e_previous = HeldOut(swapped, previous.result.model, T);
  std::cout << "harmonics: unchanged robot, 15 poses " << e_same << " mm against the prior model's "
            << e_prior << " mm, " << same.changed.size() << " groups changed; joint 3's gearbox "
            << "swapped: " << e_map << " mm against the previous model's " << e_previous
            << " mm; changed: " << names << "\n";
  EXPECT_TRUE(same.changed.empty());
  EXPECT_LE(e_same, 1.1 * e_prior);
  EXPECT_NE(names.find("harmonics"), std::string::npos) << names;
  EXPECT_LT(2 * e_map, e_previous);
}

// Fleet: a prior from 8 calibrated robots of one type (their mean and per-frame sample covariance),
// and 20 poses of a ninth (one SMR each): the data move the fleet's mean to the ninth robot.
// (Against the 20 poses alone, in this simulation without unmodelled errors, the fleet prior is
// about as good: see docs/recalibration.md, "Limitations".)
// Models of another chain are refused.
TEST(Recalibration, FleetPriorFromEightRobots) {
  // The type: the drawing's model with a systematic deviation that every robot of the type shares
  // (its manufacturing), each robot with smaller errors of its own.
  const RobotModel drawing = Nominal();
  const RobotModel type = ApplyErrors(drawing, RandomErrors(drawing, 0.003, 2.0, 0.002, 0.0, 99));
  auto member = [&](uint64_t seed) {
    const KinematicErrors e = RandomErrors(type, 0.0003, 0.2, 0.0002, 0.0005, seed);
    return Robot{ApplyErrors(type, e), e.joint_zero};
  };
  std::vector<RobotModel> calibrated;
  for (int k = 0; k < 8; ++k) {
    calibrated.push_back(
        Calibrate(drawing, Measure(member(100 + k), 80, 200 + k, Tracker(300 + k), kNoise)).model);
  }
  RobotModel mean;
  ModelCovariance covariance;
  ASSERT_TRUE(FleetPrior(calibrated, &mean, &covariance).ok());
  EXPECT_EQ(covariance.models, 8);
  const Robot ninth = member(108);
  const SE3d T = Tracker(400);
  // 20 poses of the ninth with one SMR each (60 equations for 33 parameters).
  const MeasurementSet twenty = Measure(ninth, 20, 401, T, kNoise, true);
  const RecalibrationResult fleet = Recalibrate(
      mean, twenty, MeasurementSet(6), WithPrior(PriorFromCovariance(mean, covariance, PriorScales())));
  ASSERT_TRUE(fleet.run.result.converged()) << fleet.run.result.message;
  const PipelineResult alone =
      RunCalibrationPipeline(drawing, twenty, MeasurementSet(6), PipelineOptions());
  ASSERT_TRUE(alone.result.converged()) << alone.result.message;
  // Held out at the measured SMR only (the other two are not in the 20 poses).
  const double e_fleet = HeldOut(ninth, fleet.run.result.model, T, true);
  const double e_alone = HeldOut(ninth, alone.result.model, T, true);
  std::cout << "held out: fleet prior + 20 poses " << e_fleet << " mm, 20 poses alone " << e_alone
            << " mm\n";
  EXPECT_LE(10 * e_fleet, HeldOut(ninth, mean, T, true));
  EXPECT_EQ(fleet.run.result.data_share.size(), fleet.run.result.parameterization.num_parameters);
  RobotModel other = calibrated[1];
  other.joints.pop_back();
  RobotModel m;
  ModelCovariance c;
  const Status refused = FleetPrior({calibrated[0], other}, &m, &c);
  EXPECT_FALSE(refused.ok());
  EXPECT_NE(refused.message().find("one chain"), std::string::npos) << refused.message();
}

}  // namespace recalibration_test
}  // namespace
}  // namespace lpoe
