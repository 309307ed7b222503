// Tests of simulation.h: the reading of the paper's Table 2 (docs/conventions.md), error injection
// (eq. (33)) that keeps twists valid, measurement generation (eq. (34)) that is deterministic per seed,
// and noise with the requested statistics.
#include "lpoe/model/simulation.h"

#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "lpoe/kinematics/kinematics.h"
#include "lpoe/model/robot_model.h"
#include "test_util.h"

namespace lpoe {
namespace {
namespace simulation_test {

using testing::FrameOf;
using testing::NamedRobot;

constexpr double kTolerance = 1e-12;
constexpr uint64_t kSeed = 31;
// Rows for the noise statistics: the sample standard deviation is then within
// sigma / sqrt(2 n) ~ 0.35% of sigma; the tests allow 2.5% (about 7 standard errors).
constexpr int kNoiseRows = 40000;
constexpr double kSigmaRelativeTolerance = 0.025;

TEST(Simulation, PaperTable2ReadsDsAsTiltOfTheRotationAxis) {
  const KinematicErrors e = PaperTable2Errors();
  ASSERT_EQ(e.frame.size(), 7u);
  ASSERT_EQ(e.twist.size(), 6u);
  ASSERT_EQ(e.joint_zero.size(), 6u);
  const RobotModel nominal = MakeCobot6();
  const RobotModel actual = ApplyErrors(nominal, e);

  // Joint i's actual axis, in its own frame: ds' is written (v, omega) in Table 2.
  const Eigen::Vector3d axes[6] = {
      {0, std::sin(0.01), std::cos(0.01)},    {0, -std::sin(0.015), std::cos(0.015)},
      {std::sin(0.023), 0, std::cos(0.023)},  {-std::sin(0.004), 0, std::cos(0.004)},
      {0, std::sin(0.031), std::cos(0.031)},  {std::sin(0.013), 0, std::cos(0.013)}};
  for (int i = 0; i < 6; ++i) {
    Vector6d expected;
    expected << axes[i], Eigen::Vector3d::Zero();
    EXPECT_LT((actual.joints[i].twist - expected).norm(), kTolerance) << "joint " << i + 1;
  }

  // dp' is in (omega, v) order: rotations of milliradians, translations of millimetres.
  Vector6d dp1, dp7;
  dp1 << 0, 0.001, 0.002, 2, 1.5, 0.5;
  dp7 << 0.005, 0.002, -0.003, 1.6, 2, 3.2;
  EXPECT_LT((e.frame[0] - dp1).norm(), kTolerance);
  EXPECT_LT((e.frame[6] - dp7).norm(), kTolerance);
  for (const Vector6d& dp : e.frame) {
    EXPECT_LE(dp.head<3>().cwiseAbs().maxCoeff(), 0.005);
    EXPECT_GE(dp.tail<3>().cwiseAbs().maxCoeff(), 1.0);
  }
  // eq. (33): T^a = T exp(dp'^).
  for (int f = 0; f < 7; ++f) {
    const SE3d expected = FrameOf(nominal, f) * ExpSE3(e.frame[f]);
    EXPECT_LT(testing::RelativeMaxDifference(FrameOf(actual, f).Matrix(), expected.Matrix()),
              kTolerance)
        << "frame " << f;
  }
  const std::vector<double> zeros = {0, 0.03, 0.01, 0.02, 0.015, 0.02};
  EXPECT_EQ(e.joint_zero, zeros);
}

TEST(Simulation, ApplyErrorsKeepsTwistsValid) {
  const RobotModel table2 = ApplyErrors(MakeCobot6(), PaperTable2Errors());
  EXPECT_TRUE(table2.Validate().ok()) << table2.Validate().message();
  for (const NamedRobot& robot : testing::TestRobots()) {
    for (uint64_t seed = 1; seed <= 20; ++seed) {
      constexpr double kTilt = 0.3;  // large, so that an unnormalized twist would be caught
      const KinematicErrors e = RandomErrors(robot.model, 0.01, 5.0, kTilt, 0.05, seed);
      const RobotModel actual = ApplyErrors(robot.model, e);
      ASSERT_TRUE(actual.Validate().ok()) << robot.name << ": " << actual.Validate().message();
      for (int i = 0; i < actual.num_joints(); ++i) {
        const Joint& j = actual.joints[i];
        const Joint& n = robot.model.joints[i];
        if (j.type == JointType::kRevolute) {
          EXPECT_NEAR(j.twist.head<3>().norm(), 1.0, kTolerance);
          EXPECT_NEAR(j.twist.head<3>().dot(j.twist.tail<3>()), 0.0, kTolerance);
        } else {
          EXPECT_EQ(j.twist.head<3>().norm(), 0.0);
          EXPECT_NEAR(j.twist.tail<3>().norm(), 1.0, kTolerance);
        }
        // The axis is tilted by at most the bound.
        const Eigen::Vector3d a = j.type == JointType::kRevolute ? j.twist.head<3>() : j.twist.tail<3>();
        const Eigen::Vector3d b = j.type == JointType::kRevolute ? n.twist.head<3>() : n.twist.tail<3>();
        EXPECT_LE(std::atan2(a.cross(b).norm(), a.dot(b)), kTilt + 1e-12);
        EXPECT_LE(std::abs(e.joint_zero[i]), 0.05);
      }
      for (const Vector6d& dp : e.frame) {
        EXPECT_LE(dp.head<3>().cwiseAbs().maxCoeff(), 0.01);
        EXPECT_LE(dp.tail<3>().cwiseAbs().maxCoeff(), 5.0);
      }
    }
  }
}

TEST(Simulation, NoErrorsGiveTheNominalModel) {
  for (const NamedRobot& robot : testing::TestRobots()) {
    const RobotModel same = ApplyErrors(robot.model, RandomErrors(robot.model, 0, 0, 0, 0, 3));
    for (int f = 0; f < robot.model.num_frames(); ++f) {
      EXPECT_EQ(FrameOf(same, f).Matrix(), FrameOf(robot.model, f).Matrix()) << robot.name;
    }
    for (int i = 0; i < robot.model.num_joints(); ++i) {
      EXPECT_LT((same.joints[i].twist - robot.model.joints[i].twist).norm(), kTolerance);
    }
  }
}

TEST(Simulation, MeasurementsAreTheActualForwardKinematics) {
  const KinematicErrors e = PaperTable2Errors();
  const RobotModel actual = ApplyErrors(MakeCobot6(), e);
  SimulationOptions options;
  options.count = 200;
  options.pose = true;
  const MeasurementSet data = SimulateMeasurements(actual, e.joint_zero, options);
  ASSERT_EQ(data.size(), 200);
  ASSERT_TRUE(data.has_orientation());
  for (int r = 0; r < data.size(); ++r) {
    std::vector<double> q(data.q(r), data.q(r) + 6);
    for (int i = 0; i < 6; ++i) {
      EXPECT_GE(q[i], -kPi);
      EXPECT_LE(q[i], kPi);
      q[i] += e.joint_zero[i];  // eq. (34): measured at the commanded value plus the zero error
    }
    const SE3d T = ToolPose(actual, q.data());
    EXPECT_LT((data.position(r) - T.t).norm(), 1e-9) << "row " << r;
    EXPECT_LT((data.orientation(r) - T.R).cwiseAbs().maxCoeff(), kTolerance) << "row " << r;
    EXPECT_EQ(data.target(r), 0);
  }
}

TEST(Simulation, SameSeedGivesIdenticalData) {
  const RobotModel actual = ApplyErrors(MakeCobot6(), PaperTable2Errors());
  SimulationOptions options;
  options.count = 100;
  options.noise_sigma = 0.03;
  options.seed = 2022;
  const MeasurementSet a = SimulateMeasurements(actual, PaperTable2Errors().joint_zero, options);
  const MeasurementSet b = SimulateMeasurements(actual, PaperTable2Errors().joint_zero, options);
  options.seed = 2023;
  const MeasurementSet c = SimulateMeasurements(actual, PaperTable2Errors().joint_zero, options);
  ASSERT_EQ(a.size(), b.size());
  bool any_different = false;
  for (int r = 0; r < a.size(); ++r) {
    for (int i = 0; i < 6; ++i) {
      EXPECT_EQ(a.q(r)[i], b.q(r)[i]);  // bitwise
      any_different |= a.q(r)[i] != c.q(r)[i];
    }
    EXPECT_EQ(a.position(r), b.position(r));
  }
  EXPECT_TRUE(any_different) << "a different seed must give different configurations";
  // Random errors are deterministic per seed too.
  const RobotModel m = MakeSevenJointArm();
  const KinematicErrors e1 = RandomErrors(m, 0.005, 3, 0.03, 0.03, 9);
  const KinematicErrors e2 = RandomErrors(m, 0.005, 3, 0.03, 0.03, 9);
  const KinematicErrors e3 = RandomErrors(m, 0.005, 3, 0.03, 0.03, 10);
  for (size_t f = 0; f < e1.frame.size(); ++f) {
    EXPECT_EQ(e1.frame[f], e2.frame[f]);
    EXPECT_NE(e1.frame[f], e3.frame[f]);
  }
  EXPECT_EQ(e1.joint_zero, e2.joint_zero);
}

TEST(Simulation, NoiseHasTheRequestedSigma) {
  const KinematicErrors e = PaperTable2Errors();
  const RobotModel actual = ApplyErrors(MakeCobot6(), e);
  for (double sigma : {0.03, std::sqrt(0.2)}) {
    SimulationOptions options;
    options.count = kNoiseRows;
    options.noise_sigma = sigma;
    options.pose = true;
    options.orientation_noise_sigma = 1e-4;
    options.seed = 5;
    const MeasurementSet data = SimulateMeasurements(actual, e.joint_zero, options);
    Eigen::Vector3d sum = Eigen::Vector3d::Zero(), sum_sq = Eigen::Vector3d::Zero();
    Eigen::Vector3d rot_sum_sq = Eigen::Vector3d::Zero();
    double cross = 0;
    for (int r = 0; r < data.size(); ++r) {
      std::vector<double> q(data.q(r), data.q(r) + 6);
      for (int i = 0; i < 6; ++i) q[i] += e.joint_zero[i];
      const SE3d T = ToolPose(actual, q.data());
      const Eigen::Vector3d n = data.position(r) - T.t;
      sum += n;
      sum_sq += n.cwiseProduct(n);
      cross += n.x() * n.y();
      // Orientation noise is a right perturbation: R_measured = R exp(w^).
      const Eigen::Vector3d w = LogSO3(Eigen::Matrix3d(T.R.transpose() * data.orientation(r)));
      rot_sum_sq += w.cwiseProduct(w);
    }
    const double n = data.size();
    for (int k = 0; k < 3; ++k) {
      const double mean = sum(k) / n;
      const double sd = std::sqrt(sum_sq(k) / n - mean * mean);
      EXPECT_NEAR(sd, sigma, kSigmaRelativeTolerance * sigma) << "axis " << k << " sigma " << sigma;
      EXPECT_NEAR(mean, 0.0, 6 * sigma / std::sqrt(n)) << "axis " << k << " sigma " << sigma;
      EXPECT_NEAR(std::sqrt(rot_sum_sq(k) / n), 1e-4, kSigmaRelativeTolerance * 1e-4) << "axis " << k;
    }
    EXPECT_NEAR(cross / n / (sigma * sigma), 0.0, 6 / std::sqrt(n)) << "x and y noise correlated";
  }
}

TEST(Simulation, AllToolsCyclesTheTargets) {
  RobotModel nominal = MakeCobot6();
  nominal.tools.push_back(Tool{"smr2", SE3d(Eigen::Matrix3d::Identity(), Eigen::Vector3d(-40, 0, 60))});
  const KinematicErrors e = RandomErrors(nominal, 0.005, 3, 0.03, 0.03, 4);
  const RobotModel actual = ApplyErrors(nominal, e);
  SimulationOptions options;
  options.count = 10;
  options.all_tools = true;
  const MeasurementSet data = SimulateMeasurements(actual, e.joint_zero, options);
  for (int r = 0; r < data.size(); ++r) {
    EXPECT_EQ(data.target(r), r % 2);
    std::vector<double> q(data.q(r), data.q(r) + 6);
    for (int i = 0; i < 6; ++i) q[i] += e.joint_zero[i];
    EXPECT_LT((data.position(r) - ToolPosition(actual, q.data(), data.target(r))).norm(), 1e-9);
  }
}

TEST(Simulation, PrismaticJointRangeIsInMillimetres) {
  const RobotModel m = MakeArmWithPrismatic();
  SimulationOptions options;
  options.count = 500;
  const MeasurementSet data = SimulateMeasurements(m, {}, options);
  double largest = 0;
  for (int r = 0; r < data.size(); ++r) {
    const double q = data.q(r)[1];  // joint 2 is prismatic
    EXPECT_LE(std::abs(q), 100.0);
    largest = std::max(largest, std::abs(q));
  }
  EXPECT_GT(largest, 90.0) << "prismatic joint values should span [-100, 100] mm";
}

}  // namespace simulation_test
}  // namespace
}  // namespace lpoe
