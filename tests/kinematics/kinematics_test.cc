// Tests of kinematics.h: the analytic Jacobians of the error model (eqs. (18), (29)) against central
// finite differences of right perturbations of every local frame, and the templated chain
// (ChainPose / ChainPosition) against the double forward kinematics, by value and, instantiated
// with ceres::Jet, by derivative.
#include "lpoe/kinematics/kinematics.h"

#include <algorithm>
#include <cmath>
#include <iostream>
#include <string>
#include <type_traits>
#include <vector>

#include <ceres/jet.h>
#include <gtest/gtest.h>

#include "lpoe/model/robot_model.h"
#include "lpoe/kinematics/se3.h"
#include "test_util.h"

namespace lpoe {

// Explicit instantiation of the chain with a Jet (one template for double and Jet, docs/architecture.md).
using Jet6 = ceres::Jet<double, 6>;
template SE3<Jet6> ChainPose<Jet6>(const RobotModel& model, const SE3<Jet6>* joint_origins,
                                   const SE3<Jet6>& tool_origin, const double* q);
template Vector3<Jet6> ChainPosition<Jet6>(const RobotModel& model, const SE3<Jet6>* joint_origins,
                                           const Vector3<Jet6>& tool_point, const double* q);

namespace {
namespace kinematics_test {

using testing::FrameOf;
using testing::NamedRobot;
using testing::PerturbFrame;
using testing::TestRandom;

constexpr int kConfigurations = 20;
constexpr uint64_t kSeed = 4242;
// Central differences: with a step of 1e-4 the truncation error of the rotation columns (lever arms
// ~1e3 mm) is ~1e-9 relative and the round-off ~1e-8 relative.
constexpr double kFdStep = 1e-4;
constexpr double kFdRelativeTolerance = 1e-6;
// Agreement between two evaluations of the same chain (different order of products).
constexpr double kValueRelativeTolerance = 1e-12;
// Jet derivatives against the analytic Jacobian: both exact, so only round-off separates them.
constexpr double kJetRelativeTolerance = 1e-10;

// Enough Jet components for 8 local frames (the 7-joint arm with one tool).
constexpr int kMaxFrames = 8;
using JetAll = ceres::Jet<double, 6 * kMaxFrames>;

std::vector<NamedRobot> Robots() { return testing::TestRobotsWithTiltedVariants(kSeed); }

// Per column: |a - b|max <= tolerance * max(1, |b|max).
void ExpectColumnsNear(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b, double tolerance,
                       const std::string& what) {
  ASSERT_EQ(a.rows(), b.rows());
  ASSERT_EQ(a.cols(), b.cols());
  for (int c = 0; c < a.cols(); ++c) {
    const double scale = std::max(1.0, b.col(c).cwiseAbs().maxCoeff());
    EXPECT_LE((a.col(c) - b.col(c)).cwiseAbs().maxCoeff(), tolerance * scale)
        << what << ", column " << c << " (frame " << c / 6 << ", direction " << c % 6 << ")\n"
        << "analytic " << a.col(c).transpose() << "\nreference " << b.col(c).transpose();
  }
}

Eigen::MatrixXd PositionJacobianByFiniteDifferences(const RobotModel& model, const double* q,
                                                    int tool) {
  Eigen::MatrixXd J(3, 6 * model.num_frames());
  for (int f = 0; f < model.num_frames(); ++f) {
    for (int k = 0; k < 6; ++k) {
      const Vector6d h = kFdStep * Vector6d::Unit(k);
      J.col(6 * f + k) = (ToolPosition(PerturbFrame(model, f, h), q, tool) -
                          ToolPosition(PerturbFrame(model, f, -h), q, tool)) /
                         (2 * kFdStep);
    }
  }
  return J;
}

// d/d dp of log(T(perturbed) T^-1)^vee.
Eigen::MatrixXd PoseJacobianByFiniteDifferences(const RobotModel& model, const double* q,
                                                int tool) {
  const SE3d T_inverse = ToolPose(model, q, tool).Inverse();
  Eigen::MatrixXd J(6, 6 * model.num_frames());
  for (int f = 0; f < model.num_frames(); ++f) {
    for (int k = 0; k < 6; ++k) {
      const Vector6d h = kFdStep * Vector6d::Unit(k);
      J.col(6 * f + k) = (LogSE3(ToolPose(PerturbFrame(model, f, h), q, tool) * T_inverse) -
                          LogSE3(ToolPose(PerturbFrame(model, f, -h), q, tool) * T_inverse)) /
                         (2 * kFdStep);
    }
  }
  return J;
}

TEST(Kinematics, JointMotionIsTheExponentialOfTheTwist) {
  TestRandom rng(kSeed);
  for (const NamedRobot& robot : Robots()) {
    for (const Joint& joint : robot.model.joints) {
      for (int trial = 0; trial < kConfigurations; ++trial) {
        const double q = joint.type == JointType::kRevolute ? rng.Uniform(-kPi, kPi)
                                                            : rng.Uniform(-100, 100);
        const SE3d expected = ExpSE3(Vector6d(joint.twist * q));
        const SE3d actual = JointMotion(joint, q);
        EXPECT_LT(testing::RelativeMaxDifference(actual.Matrix(), expected.Matrix()), 1e-12)
            << robot.name << " " << joint.name << " q = " << q;
      }
    }
  }
}

// ---- Each joint model type on its own (kinematics.h, "Joint models"): its motion is the exponential
// of its twist, its data applied left and right is that motion, its derivative and Jacobian columns
// are the finite differences of the motion, on doubles and on Jets (whose derivative parts give
// d/dq exactly).

using JetQ = ceres::Jet<double, 1>;

// Central differences of a function of q with values ~1e3 (translations in mm): step 1e-5 rad or
// mm leaves truncation ~1e-10 and round-off ~1e-8 relative.
constexpr double kJointFdStep = 1e-5;
constexpr double kJointFdTolerance = 1e-7;

// A twist of each model: RevoluteZJoint's is e_z; RevoluteJoint's an axis through a point off the
// origin, with a pitch when `pitch`; PrismaticJoint's a unit direction.
template <typename Model>
Vector6d TwistOf(TestRandom* rng, bool pitch);
template <>
Vector6d TwistOf<RevoluteZJoint>(TestRandom*, bool) {
  return (Vector6d() << 0, 0, 1, 0, 0, 0).finished();
}
template <>
Vector6d TwistOf<RevoluteJoint>(TestRandom* rng, bool pitch) {
  const Eigen::Vector3d w = rng->UnitVector();
  const Eigen::Vector3d point = rng->Vector3(300);
  Vector6d s;
  s << w, -w.cross(point) + (pitch ? rng->Uniform(-5, 5) : 0.0) * w;
  return s;
}
template <>
Vector6d TwistOf<PrismaticJoint>(TestRandom* rng, bool) {
  Vector6d s;
  s << Eigen::Vector3d::Zero(), rng->UnitVector();
  return s;
}

JointType TypeOf(JointModelId id) {
  return id == JointModelId::kPrismatic ? JointType::kPrismatic : JointType::kRevolute;
}

template <typename Model>
void ExpectJointModelIsItsTwistsExponential(uint64_t seed) {
  TestRandom rng(seed);
  const bool prismatic = Model::kId == JointModelId::kPrismatic;
  for (int trial = 0; trial < kConfigurations; ++trial) {
    const Vector6d s = TwistOf<Model>(&rng, trial % 2 == 1);
    const double q = prismatic ? rng.Uniform(-500, 500) : rng.Uniform(-kPi, kPi);
    const SE3d G = rng.Pose(800);             // the joint's frame before it moves
    const Eigen::Vector3d x = rng.Vector3(400);  // a point beyond the joint, in its moved frame
    const std::string at = "trial " + std::to_string(trial) + " q = " + std::to_string(q);

    // The classification and the one switch reach this type.
    Joint joint;
    joint.type = TypeOf(Model::kId);
    joint.twist = s;
    EXPECT_EQ(JointModelOf(joint), Model::kId) << at;
    const bool reached = VisitJointModel(JointModelOf(joint), [](auto m) {
      return std::is_same_v<decltype(m), Model>;
    });
    EXPECT_TRUE(reached) << at;

    // Motion = exp(s^ q), and JointMotion gives it.
    const SE3d M = Model::Motion(s, q);
    const SE3d expected = ExpSE3(Vector6d(s * q));
    EXPECT_LT(testing::RelativeMaxDifference(M.Matrix(), expected.Matrix()), 1e-12) << at;
    EXPECT_EQ(JointMotion(joint, q).Matrix(), M.Matrix()) << at;

    // Its data applied to a point (BackwardChain) and to a running transform (ForwardChain).
    const auto data = Model::DataAt(s, q);
    Eigen::Vector3d p = x;
    Model::ApplyLeft(data, &p);
    EXPECT_LT((p - M * x).norm(), 1e-12 * std::max(1.0, x.norm())) << at;
    SE3Accumulator<double> X;
    X.Set(G);
    Model::ApplyRight(data, &X);
    EXPECT_LT(testing::RelativeMaxDifference(X.X.Matrix(), (G * M).Matrix()), 1e-12) << at;

    // Derivative = d exp(s^ q)/dq = exp(s^ q) s^, against central differences.
    const Eigen::Matrix4d D = Model::Derivative(s, data);
    const Eigen::Matrix4d fd = (Model::Motion(s, q + kJointFdStep).Matrix() -
                         Model::Motion(s, q - kJointFdStep).Matrix()) /
                        (2 * kJointFdStep);
    EXPECT_LT(testing::RelativeMaxDifference(D, fd), kJointFdTolerance) << at << "\n" << D << "\n" << fd;
    EXPECT_LT(testing::RelativeMaxDifference(D, M.Matrix() * Hat6(s)), 1e-12) << at;

    // The Jacobian columns at G: dP/dq of P = G M(q) x, and d log(T(q + h) T(q)^-1)/dh of
    // T = G M(q) (Ad_G s), against central differences; BaseAxis is the pose column's rotation.
    const Eigen::Vector3d P = G * (M * x);
    const Eigen::Vector3d d = P - G.t;
    Eigen::Vector3d column;
    Model::PositionColumn(G.R.data(), d.data(), s, column.data());
    const Eigen::Vector3d fd_column = (G * (Model::Motion(s, q + kJointFdStep) * x) -
                                       G * (Model::Motion(s, q - kJointFdStep) * x)) /
                                      (2 * kJointFdStep);
    EXPECT_LT(testing::RelativeMaxDifference(column, fd_column), kJointFdTolerance) << at;
    Vector6d pose_column;
    Model::PoseColumn(G.R.data(), G.t.data(), s, pose_column.data());
    const SE3d T_inverse = (G * M).Inverse();
    const Vector6d fd_pose = (LogSE3(G * Model::Motion(s, q + kJointFdStep) * T_inverse) -
                              LogSE3(G * Model::Motion(s, q - kJointFdStep) * T_inverse)) /
                             (2 * kJointFdStep);
    EXPECT_LT(testing::RelativeMaxDifference(pose_column, fd_pose), kJointFdTolerance) << at;
    EXPECT_LT((Model::BaseAxis(G.R, s) - pose_column.head<3>()).norm(), 1e-12) << at;

    // On Jets: the same values, and the derivative part of the motion (one infinitesimal on q) is
    // the Derivative; applied left and right, the derivative parts are Derivative's action.
    const JetQ qj(q, 0);
    const SE3<JetQ> Mj = Model::Motion(s, qj);
    const auto data_j = Model::DataAt(s, qj);
    Vector3<JetQ> pj = x.cast<JetQ>();
    Model::ApplyLeft(data_j, &pj);
    SE3Accumulator<JetQ> Xj;
    Xj.Set(G);
    Model::ApplyRight(data_j, &Xj);
    const Eigen::Matrix4d DG = G.Matrix() * D;  // d(G M)/dq
    const Eigen::Vector3d Dx = D.topLeftCorner<3, 3>() * x + D.topRightCorner<3, 1>();  // d(M x)/dq
    for (int r = 0; r < 3; ++r) {
      EXPECT_LT(std::abs(pj(r).a - p(r)), 1e-12 * std::max(1.0, x.norm())) << at;
      EXPECT_NEAR(pj(r).v(0), Dx(r), 1e-12 * std::max(1.0, Dx.norm())) << at;
      EXPECT_NEAR(Mj.t(r).v(0), D(r, 3), 1e-12 * std::max(1.0, D.col(3).norm())) << at;
      EXPECT_NEAR(Xj.X.t(r).v(0), DG(r, 3), 1e-12 * std::max(1.0, DG.col(3).norm())) << at;
      for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(Mj.R(r, c).a, M.R(r, c), 1e-15) << at;
        EXPECT_NEAR(Mj.R(r, c).v(0), D(r, c), 1e-12) << at;
        EXPECT_NEAR(Xj.X.R(r, c).v(0), DG(r, c), 1e-12) << at;
      }
    }
    // The Jet motion's derivative is the Derivative of the Jet data (same values).
    const Matrix4<JetQ> Dj = Model::Derivative(s, data_j);
    for (int r = 0; r < 4; ++r) {
      for (int c = 0; c < 4; ++c) EXPECT_NEAR(Dj(r, c).a, D(r, c), 1e-12 * std::max(1.0, D.norm()));
    }
  }
}

TEST(JointModels, RevoluteZIsItsTwistsExponentialOnDoublesAndJets) {
  ExpectJointModelIsItsTwistsExponential<RevoluteZJoint>(kSeed + 40);
}

TEST(JointModels, RevoluteIsItsTwistsExponentialOnDoublesAndJets) {
  ExpectJointModelIsItsTwistsExponential<RevoluteJoint>(kSeed + 41);
}

TEST(JointModels, PrismaticIsItsTwistsExponentialOnDoublesAndJets) {
  ExpectJointModelIsItsTwistsExponential<PrismaticJoint>(kSeed + 42);
}

// The chain's dispatch: a model mixing the three types gives, through KinematicChain (ids decided
// once), ToolPose/ToolPosition (classified per call) and JointMotions (stored data), the product of
// the joints' exponentials.
TEST(JointModels, EveryDispatchGivesTheProductOfExponentials) {
  TestRandom rng(kSeed + 43);
  RobotModel model;
  const JointModelId ids[] = {JointModelId::kRevoluteZ, JointModelId::kPrismatic,
                              JointModelId::kRevolute, JointModelId::kRevoluteZ,
                              JointModelId::kRevolute};
  for (JointModelId id : ids) {
    Joint j;
    j.name = "j" + std::to_string(model.joints.size());
    j.type = TypeOf(id);
    j.origin = rng.Pose(300);
    j.twist = id == JointModelId::kRevoluteZ ? TwistOf<RevoluteZJoint>(&rng, false)
              : id == JointModelId::kPrismatic ? TwistOf<PrismaticJoint>(&rng, false)
                                               : TwistOf<RevoluteJoint>(&rng, false);
    model.joints.push_back(j);
  }
  Tool tool;
  tool.name = "tool";
  tool.origin = rng.Pose(100);
  model.tools.push_back(tool);
  ASSERT_TRUE(model.Validate().ok()) << model.Validate().message();
  const KinematicChain chain(model);
  for (int i = 0; i < model.num_joints(); ++i) EXPECT_EQ(chain.joint_model(i), ids[i]);
  for (int trial = 0; trial < kConfigurations; ++trial) {
    std::vector<double> q;
    for (JointModelId id : ids) {
      q.push_back(id == JointModelId::kPrismatic ? rng.Uniform(-300, 300) : rng.Uniform(-kPi, kPi));
    }
    SE3d expected;
    for (int i = 0; i < model.num_joints(); ++i) {
      expected = expected * model.joints[i].origin * ExpSE3(Vector6d(model.joints[i].twist * q[i]));
    }
    expected = expected * tool.origin;
    EXPECT_LT(testing::RelativeMaxDifference(chain.Pose(q.data()).Matrix(), expected.Matrix()), 1e-12);
    EXPECT_LT(testing::RelativeMaxDifference(ToolPose(model, q.data()).Matrix(), expected.Matrix()),
              1e-12);
    EXPECT_LT((chain.Position(q.data()) - expected.t).norm(), 1e-12 * expected.t.norm());
    EXPECT_LT((ToolPosition(model, q.data()) - expected.t).norm(), 1e-12 * expected.t.norm());
    std::vector<SE3d> origins;
    for (const Joint& j : model.joints) origins.push_back(j.origin);
    const JointMotions<double> motions(model, q.data());
    EXPECT_LT(testing::RelativeMaxDifference(
                  ChainPose(motions, model.num_joints(), origins.data(), tool.origin).Matrix(),
                  expected.Matrix()),
              1e-12);
    EXPECT_LT((ChainPosition(motions, model.num_joints(), origins.data(), tool.origin.t) -
               expected.t).norm(),
              1e-12 * expected.t.norm());
  }
}

TEST(Kinematics, ToolPositionJacobianMatchesFiniteDifferences) {
  TestRandom rng(kSeed + 1);
  for (const NamedRobot& robot : Robots()) {
    ASSERT_TRUE(robot.model.Validate().ok()) << robot.name << ": " << robot.model.Validate().message();
    for (int trial = 0; trial < kConfigurations; ++trial) {
      const std::vector<double> q = rng.Configuration(robot.model);
      Eigen::MatrixXd J;
      const Eigen::Vector3d P = ToolPositionJacobian(robot.model, q.data(), 0, &J);
      EXPECT_LT((P - ToolPosition(robot.model, q.data())).norm(), 1e-9) << robot.name;
      ExpectColumnsNear(J, PositionJacobianByFiniteDifferences(robot.model, q.data(), 0),
                        kFdRelativeTolerance, robot.name);
    }
  }
}

TEST(Kinematics, ToolPoseJacobianMatchesFiniteDifferences) {
  TestRandom rng(kSeed + 2);
  for (const NamedRobot& robot : Robots()) {
    for (int trial = 0; trial < kConfigurations; ++trial) {
      const std::vector<double> q = rng.Configuration(robot.model);
      Eigen::MatrixXd J;
      const SE3d T = ToolPoseJacobian(robot.model, q.data(), 0, &J);
      EXPECT_LT(testing::RelativeMaxDifference(T.Matrix(), ToolPose(robot.model, q.data()).Matrix()),
                kValueRelativeTolerance)
          << robot.name;
      ExpectColumnsNear(J, PoseJacobianByFiniteDifferences(robot.model, q.data(), 0),
                        kFdRelativeTolerance, robot.name);
    }
  }
}

TEST(Kinematics, JacobiansOfASecondToolIgnoreTheFirst) {
  RobotModel model = MakeCobot6();
  model.tools.push_back(Tool{"smr2", SE3d(RotationFromRpy(0.3, -0.2, 1.0),
                                          Eigen::Vector3d(-50, 30, 80))});
  ASSERT_TRUE(model.Validate().ok());
  TestRandom rng(kSeed + 3);
  for (int trial = 0; trial < kConfigurations; ++trial) {
    const std::vector<double> q = rng.Configuration(model);
    for (int tool = 0; tool < 2; ++tool) {
      Eigen::MatrixXd Jp, Jpose;
      ToolPositionJacobian(model, q.data(), tool, &Jp);
      ToolPoseJacobian(model, q.data(), tool, &Jpose);
      ASSERT_EQ(Jp.cols(), 6 * 8);
      // The columns of the other tool are exactly zero; finite differences agree everywhere.
      const int other = 6 * (6 + 1 - tool);
      EXPECT_EQ(Jp.middleCols(other, 6).cwiseAbs().maxCoeff(), 0.0);
      EXPECT_EQ(Jpose.middleCols(other, 6).cwiseAbs().maxCoeff(), 0.0);
      ExpectColumnsNear(Jp, PositionJacobianByFiniteDifferences(model, q.data(), tool),
                        kFdRelativeTolerance, "position, tool " + std::to_string(tool));
      ExpectColumnsNear(Jpose, PoseJacobianByFiniteDifferences(model, q.data(), tool),
                        kFdRelativeTolerance, "pose, tool " + std::to_string(tool));
    }
  }
}

TEST(Kinematics, ChainPositionEqualsToolPosition) {
  TestRandom rng(kSeed + 4);
  for (const NamedRobot& robot : Robots()) {
    const RobotModel& m = robot.model;
    std::vector<SE3d> origins;
    for (const Joint& j : m.joints) origins.push_back(j.origin);
    for (int trial = 0; trial < kConfigurations; ++trial) {
      const std::vector<double> q = rng.Configuration(m);
      const Eigen::Vector3d expected = ToolPosition(m, q.data());
      const double scale = std::max(1.0, expected.norm());
      EXPECT_LT((ChainPosition(m, origins.data(), m.tools[0].origin.t, q.data()) - expected).norm(),
                kValueRelativeTolerance * scale)
          << robot.name;
      EXPECT_LT(testing::RelativeMaxDifference(
                    ChainPose(m, origins.data(), m.tools[0].origin, q.data()).Matrix(),
                    ToolPose(m, q.data()).Matrix()),
                kValueRelativeTolerance)
          << robot.name;
    }
  }
}

// Frames perturbed by Jet infinitesimals: frame f carries derivative components 6 f .. 6 f + 5.
template <typename J>
void SeededFrames(const RobotModel& m, std::vector<SE3<J>>* origins, SE3<J>* tool) {
  origins->clear();
  for (int f = 0; f < m.num_frames(); ++f) {
    Vector6<J> delta;
    for (int k = 0; k < 6; ++k) delta(k) = J(0.0, 6 * f + k);
    const SE3<J> X = FrameOf(m, f).template cast<J>() * ExpSE3(delta);
    if (f < m.num_joints()) {
      origins->push_back(X);
    } else if (f == m.num_joints()) {
      *tool = X;
    }
  }
}

TEST(Kinematics, JetChainPoseMatchesValuesAndAnalyticJacobians) {
  TestRandom rng(kSeed + 5);
  for (const NamedRobot& robot : Robots()) {
    const RobotModel& m = robot.model;
    ASSERT_LE(m.num_frames(), kMaxFrames);
    const int columns = 6 * m.num_frames();
    std::vector<SE3<JetAll>> origins;
    SE3<JetAll> tool;
    SeededFrames(m, &origins, &tool);
    for (int trial = 0; trial < kConfigurations / 4; ++trial) {
      const std::vector<double> q = rng.Configuration(m);
      const SE3<JetAll> X = ChainPose(m, origins.data(), tool, q.data());
      const SE3d T = ToolPose(m, q.data());

      // Values.
      Eigen::Matrix4d value;
      const Matrix4<JetAll> XM = X.Matrix();
      for (int r = 0; r < 4; ++r) {
        for (int c = 0; c < 4; ++c) value(r, c) = XM(r, c).a;
      }
      EXPECT_LT(testing::RelativeMaxDifference(value, T.Matrix()), kValueRelativeTolerance)
          << robot.name;

      // Position derivative == ToolPositionJacobian.
      Eigen::MatrixXd Jp, Jpose;
      ToolPositionJacobian(m, q.data(), 0, &Jp);
      ToolPoseJacobian(m, q.data(), 0, &Jpose);
      Eigen::MatrixXd autodiff_p(3, columns);
      for (int r = 0; r < 3; ++r) autodiff_p.row(r) = X.t(r).v.head(columns).transpose();
      ExpectColumnsNear(autodiff_p, Jp, kJetRelativeTolerance, robot.name + " position");

      // ChainPosition gives the same derivative.
      const Vector3<JetAll> P = ChainPosition(m, origins.data(), tool.t, q.data());
      for (int r = 0; r < 3; ++r) autodiff_p.row(r) = P(r).v.head(columns).transpose();
      ExpectColumnsNear(autodiff_p, Jp, kJetRelativeTolerance, robot.name + " ChainPosition");

      // Pose derivative: d log(T(dp) T^-1)^vee / d dp == ToolPoseJacobian.
      const Vector6<JetAll> y = LogSE3(X * T.Inverse().cast<JetAll>());
      Eigen::MatrixXd autodiff_pose(6, columns);
      for (int r = 0; r < 6; ++r) {
        EXPECT_LT(std::abs(y(r).a), 1e-9) << robot.name;
        autodiff_pose.row(r) = y(r).v.head(columns).transpose();
      }
      ExpectColumnsNear(autodiff_pose, Jpose, kJetRelativeTolerance, robot.name + " pose");
    }
  }
}

TEST(Kinematics, JetChainWithSixComponentsDifferentiatesOneFrame) {
  // The explicitly instantiated Jet<double, 6> chain, differentiating one frame at a time.
  TestRandom rng(kSeed + 6);
  const RobotModel m = MakeCobot6();
  const std::vector<double> q = rng.Configuration(m);
  Eigen::MatrixXd Jp;
  ToolPositionJacobian(m, q.data(), 0, &Jp);
  for (int f = 0; f < m.num_frames(); ++f) {
    std::vector<SE3<Jet6>> origins;
    SE3<Jet6> tool = m.tools[0].origin.cast<Jet6>();
    for (const Joint& j : m.joints) origins.push_back(j.origin.cast<Jet6>());
    Vector6<Jet6> delta;
    for (int k = 0; k < 6; ++k) delta(k) = Jet6(0.0, k);
    SE3<Jet6>& X = f < m.num_joints() ? origins[f] : tool;
    X = X * ExpSE3(delta);
    const Vector3<Jet6> P = ChainPosition(m, origins.data(), tool.t, q.data());
    Eigen::MatrixXd autodiff(3, 6);
    for (int r = 0; r < 3; ++r) autodiff.row(r) = P(r).v.transpose();
    ExpectColumnsNear(autodiff, Jp.middleCols(6 * f, 6), kJetRelativeTolerance,
                      "frame " + std::to_string(f));
  }
}

// SinCosMany (the solvers' passes over many rows) against libm, value by value: within 2 ulp over
// joint ranges, near multiples of pi/2 (where the reduction cancels), for large and non-finite
// values, and independent of the block it is computed in.
TEST(Kinematics, SinCosManyIsWithinTwoUlpOfLibm) {
  constexpr int kRandomValues = 20000;
  constexpr double kMaxUlps = 2.0;
  TestRandom rng(kSeed + 7);
  std::vector<double> x = {0.0, -0.0, 1e-300, -1e-20, 1e-8, 0.5, kPi / 4,
                           kPi / 2, kPi, -kPi, 3 * kPi / 2,
                           2 * kPi, 524288.0, -524288.0, 524289.5, 1e6, -3e9, 1e300};
  for (int k = -1000; k <= 1000; k += 7) x.push_back(k * (kPi / 2));
  for (int k = 0; k < kRandomValues; ++k) x.push_back(rng.Uniform(-20.0, 20.0));
  for (int k = 0; k < 100; ++k) x.push_back(rng.Uniform(-2e5, 2e5));
  const int n = static_cast<int>(x.size());
  std::vector<double> s(n), c(n);
  SinCosMany(x.data(), n, s.data(), c.data());
  auto ulps = [](double got, double want) {
    const double ulp = std::nextafter(std::abs(want), INFINITY) - std::abs(want);
    return std::abs(got - want) / ulp;
  };
  double worst = 0;
  for (int k = 0; k < n; ++k) {
    worst = std::max({worst, ulps(s[k], std::sin(x[k])), ulps(c[k], std::cos(x[k]))});
    ASSERT_LE(ulps(s[k], std::sin(x[k])), kMaxUlps) << "sin(" << x[k] << ")";
    ASSERT_LE(ulps(c[k], std::cos(x[k])), kMaxUlps) << "cos(" << x[k] << ")";
  }
  std::cout << "[sincos] worst " << worst << " ulp over " << n << " values\n";
  // Not finite: NaN in, NaN out.
  const double bad[3] = {NAN, INFINITY, -INFINITY};
  double bs[3], bc[3];
  SinCosMany(bad, 3, bs, bc);
  for (int k = 0; k < 3; ++k) EXPECT_TRUE(std::isnan(bs[k]) && std::isnan(bc[k])) << bad[k];
  // A value's result does not depend on where it sits in the block.
  for (int k = 0; k + 7 <= 70; ++k) {
    double one_s, one_c;
    SinCosMany(&x[k], 1, &one_s, &one_c);
    EXPECT_EQ(one_s, s[k]);
    EXPECT_EQ(one_c, c[k]);
  }
}

// The forward passes with sin and cos given by the caller are the passes that compute them.
TEST(Kinematics, GivenSinCosGiveTheSamePositionsAndJacobians) {
  TestRandom rng(kSeed + 8);
  for (const NamedRobot& robot : Robots()) {
    const RobotModel& m = robot.model;
    const KinematicChain chain(m);
    const Parameterization p =
        MakeParameterization(m, ParameterizationKind::kIdentifiable, DataKind::kPosition);
    const BasisJacobian bj(m, p);
    const int n = m.num_joints();
    std::vector<FrameRt> frames(n + 1);
    for (int trial = 0; trial < 20; ++trial) {
      const std::vector<double> q = rng.Configuration(m);
      std::vector<double> s(n), c(n);
      for (int i = 0; i < n; ++i) SinCos(q[i], &s[i], &c[i]);
      EXPECT_LE((chain.Position(q.data(), s.data(), c.data(), 0) - ToolPosition(m, q.data(), 0))
                    .norm(),
                1e-9)
          << robot.name;
      Eigen::MatrixXd J1(3, p.num_parameters), J2(3, p.num_parameters);
      const Eigen::Vector3d P1 = bj.Position(q.data(), 0, J1.data(), 3, frames.data());
      const Eigen::Vector3d P2 =
          bj.Position(q.data(), s.data(), c.data(), 0, J2.data(), 3, frames.data());
      EXPECT_EQ(P1, P2) << robot.name;
      EXPECT_EQ(J1, J2) << robot.name;
    }
  }
}

}  // namespace kinematics_test
}  // namespace
}  // namespace lpoe
