// The fleet prior where it matters to a user (docs/recalibration.md, "A new robot of a known
// type"): 8 robots of one type calibrated over their workspace at commissioning, and a ninth
// measured with 20 poses where its cell lets the tracker see them (a narrow region, one joint that
// barely moves), held out over the whole workspace. Realistic magnitudes: a UR5-like 6R arm with 3
// SMRs off the flange axis, a tracker 3 m away, commanded joint values, noise 0.02 mm per axis,
// joint harmonics of a few hundredths of a mrad that no calibration here models (always present),
// and a fleet whose deviation from the drawing is partly the type's (shared) and partly each
// robot's own.
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "lpoe/joint_errors.h"
#include "lpoe/kinematics.h"
#include "lpoe/model_covariance.h"
#include "lpoe/pipeline.h"
#include "lpoe/recalibration.h"
#include "lpoe/registration.h"
#include "lpoe/simulation.h"
#include "three_smr_cell.h"

namespace lpoe {
namespace {
namespace fleet_prior_test {

constexpr double kNoise = 0.02;

RobotModel Drawing() { return testing::ThreeSmrUr5(); }

SE3d Tracker(uint64_t seed) { return testing::TrackerThreeMetresAway(seed, 0.05); }

struct Robot {
  RobotModel actual;  // its geometry and its (unmodelled) joint harmonics
  std::vector<double> zero;
};

// A robot of the type: its own deviation (0.2 mm, 0.3 mrad, zeros 0.5 mrad) and harmonics of
// about 0.03 mrad per joint.
Robot Member(const RobotModel& type, uint64_t seed) {
  const KinematicErrors e = RandomErrors(type, 0.0003, 0.2, 0.0002, 0.0005, seed);
  Robot r{ApplyErrors(type, e), e.joint_zero};
  JointErrorPhysics physics;
  physics.stiffness.assign(r.actual.num_joints(), 0.0);  // rigid: the harmonics only
  std::mt19937_64 rng(seed + 7);
  std::normal_distribution<double> h(0.0, 3e-5);
  for (int j = 0; j < r.actual.num_joints(); ++j) {
    physics.harmonics.push_back(Eigen::Vector4d(h(rng), h(rng), h(rng), h(rng)));
  }
  ApplyJointErrorPhysics(physics, {"harmonics"}, &r.actual);
  return r;
}

// `poses` configurations uniform in [lower, upper] per joint, every SMR at each, in tracker frame T.
MeasurementSet Measure(const Robot& r, int poses, uint64_t seed, const SE3d& T, double noise,
                       const std::vector<double>& lower, const std::vector<double>& upper) {
  std::mt19937_64 rng(seed);
  SimulationOptions o;
  o.all_tools = true;
  for (int c = 0; c < poses; ++c) {
    for (int j = 0; j < 6; ++j) {
      o.configurations.push_back(std::uniform_real_distribution<double>(lower[j], upper[j])(rng));
    }
  }
  o.noise_sigma = noise;
  o.seed = seed + 1;
  const MeasurementSet d = SimulateMeasurements(r.actual, r.zero, o);
  MeasurementSet out(d.num_joints());
  for (int k = 0; k < d.size(); ++k) out.Add(d.q(k), T * d.position(k), d.target(k));
  return out;
}

const std::vector<double> kWorkspaceLower(6, -kPi), kWorkspaceUpper(6, kPi);
// The ninth robot's cell: what the tracker sees of it there (joint 6 barely moves).
const std::vector<double> kCellLower = {-0.5, -2.0, 0.6, -2.2, 1.0, -0.1};
const std::vector<double> kCellUpper = {0.5, -1.0, 1.8, -0.8, 2.0, 0.1};

// RMS distance of a model's SMRs from the robot's over the whole workspace (noise-free, with its
// harmonics), after a rigid fit of the model into that frame.
double HeldOut(const Robot& r, const RobotModel& model) {
  const MeasurementSet fresh = Measure(r, 300, 4242, SE3d(), 0.0, kWorkspaceLower, kWorkspaceUpper);
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

PipelineOptions LeastSquares() {
  PipelineOptions o;
  o.prior = nullptr;
  return o;
}

TEST(FleetPrior, NewRobotOfAKnownTypeFromTwentyPosesInItsCell) {
  const RobotModel drawing = Drawing();
  // The type's own deviation from the drawing (every robot of it shares it).
  const RobotModel type = ApplyErrors(drawing, RandomErrors(drawing, 0.003, 2.0, 0.002, 0.0, 99));
  std::vector<RobotModel> calibrated;
  for (int k = 0; k < 8; ++k) {
    const PipelineResult r = RunCalibrationPipeline(
        drawing,
        Measure(Member(type, 100 + k), 60, 200 + k, Tracker(300 + k), kNoise, kWorkspaceLower,
                kWorkspaceUpper),
        MeasurementSet(6), PipelineOptions());
    ASSERT_TRUE(r.result.converged()) << r.result.message;
    calibrated.push_back(r.result.model);
  }
  RobotModel mean;
  ModelCovariance covariance;
  ASSERT_TRUE(FleetPrior(calibrated, &mean, &covariance).ok());
  const ParameterPrior prior = PriorFromCovariance(mean, covariance, PriorScales());
  // Six ninth robots, each measured in its cell (20 poses, every SMR) from another tracker stand.
  double fleet2 = 0, ls2 = 0;
  int better = 0;
  constexpr int kRobots = 6;
  for (int k = 0; k < kRobots; ++k) {
    const Robot ninth = Member(type, 108 + k);
    const MeasurementSet twenty =
        Measure(ninth, 20, 408 + k, Tracker(400 + k), kNoise, kCellLower, kCellUpper);
    PipelineOptions o;
    o.prior = std::make_shared<const ParameterPrior>(prior);
    const RecalibrationResult fleet = Recalibrate(mean, twenty, MeasurementSet(6), o);
    ASSERT_TRUE(fleet.run.result.converged()) << fleet.run.result.message;
    const PipelineResult ls =
        RunCalibrationPipeline(drawing, twenty, MeasurementSet(6), LeastSquares());
    ASSERT_TRUE(ls.result.converged()) << ls.result.message;
    const double e_fleet = HeldOut(ninth, fleet.run.result.model);
    const double e_ls = HeldOut(ninth, ls.result.model);
    const double e_mean = HeldOut(ninth, mean);
    // What the fleet contributed: the parameters whose information is mostly the prior's.
    const Eigen::VectorXd& share = fleet.run.result.data_share;
    int from_prior = 0;
    std::string names;
    for (int c = 0; c < share.size(); ++c) {
      if (!(share(c) < 0.5)) continue;
      ++from_prior;
      names += " " + fleet.run.identifiability.parameter_names[c];
    }
    std::cout << "robot " << k + 9 << ": held out over the workspace: fleet prior + 20 poses "
              << e_fleet << " mm, least squares of the 20 poses " << e_ls
              << " mm, the fleet mean alone " << e_mean << " mm; " << from_prior << " of "
              << share.size() << " parameters mostly from the fleet:" << names << "\n";
    EXPECT_LT(e_fleet, e_mean);
    EXPECT_GT(from_prior, 0);
    fleet2 += e_fleet * e_fleet / kRobots;
    ls2 += e_ls * e_ls / kRobots;
    better += e_fleet < e_ls ? 1 : 0;
  }
  const double floor_rms = HeldOut(
      Member(type, 108),
      RunCalibrationPipeline(drawing,
                             Measure(Member(type, 108), 300, 77, Tracker(78), kNoise,
                                     kWorkspaceLower, kWorkspaceUpper),
                             MeasurementSet(6), LeastSquares())
          .result.model);
  std::cout << "RMS over the " << kRobots << " robots: fleet prior + 20 poses " << std::sqrt(fleet2)
            << " mm, least squares " << std::sqrt(ls2) << " mm (ratio "
            << std::sqrt(fleet2 / ls2) << "); the fleet better for " << better
            << "; 300 poses over the workspace (robot 9) " << floor_rms << " mm\n";
  // Better on average, not by a large factor (docs/recalibration.md, "A new robot of a known type").
  EXPECT_LT(std::sqrt(fleet2), 0.9 * std::sqrt(ls2));
  EXPECT_GE(better, kRobots / 2 + 1);
}

}  // namespace fleet_prior_test
}  // namespace
}  // namespace lpoe
