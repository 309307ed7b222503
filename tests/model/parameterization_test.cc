// Tests of parameterization.h (docs/conventions.md): the centralizer and identifiable bases of a joint
// twist, the 27 + 15 split of cobot6 with position data, the rank of the stacked Jacobian restricted
// to the identifiable basis (full) and in the full 42 parameterization (exactly 27, the null space
// being the listed directions pushed into the next frame), and ApplyUpdate / ParameterDifference.
#include "lpoe/model/parameterization.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include <Eigen/SVD>
#include <gtest/gtest.h>

#include "lpoe/kinematics/eigen_decompositions.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/model/robot_model.h"
#include "test_util.h"

namespace lpoe {
namespace {
namespace parameterization_test {

using testing::FrameOf;
using testing::NamedRobot;
using testing::TestRandom;

constexpr int kTrials = 200;
constexpr uint64_t kSeed = 777;
constexpr int kConfigurations = 70;  // the identification set of section 4
constexpr double kTolerance = 1e-10;
// Rank decisions on the column-scaled stacked Jacobian: singular values below this fraction of the
// largest count as zero; identifiable ones must stay well above it.
constexpr double kRankTolerance = 1e-9;
constexpr double kMinimumRelativeSingularValue = 1e-6;

// A valid revolute twist about a random axis through a random point (v = -omega x r, so v != 0).
Vector6d RandomRevoluteTwist(TestRandom* rng, double offset) {
  const Eigen::Vector3d w = rng->UnitVector();
  Vector6d s;
  s << w, -w.cross(rng->Vector3(offset));
  return s;
}

Vector6d RandomPrismaticTwist(TestRandom* rng) {
  Vector6d s;
  s << Eigen::Vector3d::Zero(), rng->UnitVector();
  return s;
}

void ExpectBasisProperties(const Vector6d& s, int expected_identifiable) {
  const Eigen::MatrixXd N = TwistCentralizer(s);
  const Eigen::MatrixXd B = IdentifiableJointBasis(s);
  ASSERT_EQ(N.rows(), 6);
  ASSERT_EQ(B.rows(), 6);
  EXPECT_EQ(B.cols(), expected_identifiable) << s.transpose();
  EXPECT_EQ(N.cols(), 6 - expected_identifiable) << s.transpose();
  if (B.cols() + N.cols() != 6) return;
  const int k = static_cast<int>(B.cols());
  EXPECT_LT((B.transpose() * B - Eigen::MatrixXd::Identity(k, k)).norm(), kTolerance);
  EXPECT_LT((N.transpose() * N - Eigen::MatrixXd::Identity(6 - k, 6 - k)).norm(), kTolerance);
  EXPECT_LT((N.transpose() * B).norm(), kTolerance) << "basis not orthogonal to the centralizer";
  // The centralizer commutes with s, and contains s itself and (0, omega).
  const Matrix6d ad = LieBracketMatrix(s);
  EXPECT_LT((ad * N).norm(), kTolerance);
  EXPECT_LT((N * (N.transpose() * s) - s).norm(), kTolerance);
  Vector6d pure_translation;
  pure_translation << Eigen::Vector3d::Zero(), s.head<3>();
  EXPECT_LT((N * (N.transpose() * pure_translation) - pure_translation).norm(), kTolerance);
  // No direction of the identifiable basis commutes with s: ad_s B has full column rank.
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(ad * B);
  EXPECT_GT(svd.singularValues().minCoeff(), 1e-3) << s.transpose();
}

TEST(Parameterization, RevoluteJointHasFourIdentifiableDirections) {
  TestRandom rng(kSeed);
  ExpectBasisProperties(DefaultTwist(JointType::kRevolute), 4);
  for (int trial = 0; trial < kTrials; ++trial) {
    ExpectBasisProperties(RandomRevoluteTwist(&rng, 0.0), 4);    // axis through the origin
    ExpectBasisProperties(RandomRevoluteTwist(&rng, 500.0), 4);  // axis off the origin, v != 0
  }
}

TEST(Parameterization, PrismaticJointHasTwoIdentifiableDirections) {
  TestRandom rng(kSeed + 1);
  ExpectBasisProperties(DefaultTwist(JointType::kPrismatic), 2);
  for (int trial = 0; trial < kTrials; ++trial) ExpectBasisProperties(RandomPrismaticTwist(&rng), 2);
}

TEST(Parameterization, AxisAlignedBasisIsCanonical) {
  // About local z: lost rz and tz; kept rx, ry, tx, ty as the canonical vectors.
  const Eigen::MatrixXd B = IdentifiableJointBasis(DefaultTwist(JointType::kRevolute));
  ASSERT_EQ(B.cols(), 4);
  std::set<int> kept;
  for (int c = 0; c < 4; ++c) {
    int index = 0;
    EXPECT_NEAR(B.col(c).cwiseAbs().maxCoeff(&index), 1.0, kTolerance);
    kept.insert(index);
  }
  EXPECT_EQ(kept, (std::set<int>{0, 1, 3, 4}));
}

TEST(Parameterization, Cobot6PositionHas27ParametersAnd15Unidentifiable) {
  const RobotModel m = MakeCobot6();
  const Parameterization p =
      MakeParameterization(m, ParameterizationKind::kIdentifiable, DataKind::kPosition);
  EXPECT_EQ(p.num_parameters, 27);
  EXPECT_EQ(static_cast<int>(p.parameters.size()), 27);
  ASSERT_EQ(static_cast<int>(p.unidentifiable.size()), 15);
  ASSERT_EQ(static_cast<int>(p.basis.size()), 7);
  for (int f = 0; f < 6; ++f) EXPECT_EQ(p.basis[f].cols(), 4) << "joint frame " << f;
  EXPECT_EQ(p.basis[6].cols(), 3) << "tool frame";
  for (int f = 0; f < 7; ++f) EXPECT_EQ(p.offset[f], 4 * f);
  std::set<std::string> lost;
  for (const Direction& d : p.unidentifiable) {
    lost.insert(d.name);
    EXPECT_FALSE(d.reason.empty()) << d.name;
  }
  const std::set<std::string> expected = {
      "joint1.rz", "joint1.tz", "joint2.rz", "joint2.tz", "joint3.rz",
      "joint3.tz", "joint4.rz", "joint4.tz", "joint5.rz", "joint5.tz",
      "joint6.rz", "joint6.tz", "smr1.rx",   "smr1.ry",   "smr1.rz"};
  EXPECT_EQ(lost, expected);
  for (const Direction& d : p.parameters) EXPECT_TRUE(d.reason.empty()) << d.name;

  const Parameterization pose =
      MakeParameterization(m, ParameterizationKind::kIdentifiable, DataKind::kPose);
  EXPECT_EQ(pose.num_parameters, 30);
  EXPECT_EQ(static_cast<int>(pose.unidentifiable.size()), 12);
  EXPECT_EQ(pose.basis[6].cols(), 6);

  const Parameterization full =
      MakeParameterization(m, ParameterizationKind::kFull, DataKind::kPosition);
  EXPECT_EQ(full.num_parameters, 42);
  for (const Eigen::MatrixXd& B : full.basis) EXPECT_EQ(B, Eigen::MatrixXd::Identity(6, 6));
}

TEST(Parameterization, ParameterCountsOfTheOtherRobots) {
  // 4 per revolute, 2 per prismatic, 3 (position) or 6 (pose) per tool.
  const struct {
    RobotModel model;
    int position, pose;
  } cases[] = {{MakeUr5Like(), 27, 30}, {MakeSevenJointArm(), 31, 34}, {MakeArmWithPrismatic(), 25, 28}};
  for (const auto& c : cases) {
    EXPECT_EQ(MakeParameterization(c.model, ParameterizationKind::kIdentifiable, DataKind::kPosition)
                  .num_parameters,
              c.position)
        << c.model.name;
    EXPECT_EQ(
        MakeParameterization(c.model, ParameterizationKind::kIdentifiable, DataKind::kPose)
            .num_parameters,
        c.pose)
        << c.model.name;
  }
}

// The stacked Jacobian of `count` random configurations in the parameterization p (position rows,
// or pose rows of log(T_measured T_model^-1)).
Eigen::MatrixXd StackedJacobian(const RobotModel& m, const Parameterization& p, DataKind data,
                                int count, uint64_t seed) {
  TestRandom rng(seed);
  const int rows_per = data == DataKind::kPose ? 6 : 3;
  Eigen::MatrixXd J(rows_per * count, p.num_parameters);
  Eigen::MatrixXd J_frames;
  for (int r = 0; r < count; ++r) {
    const std::vector<double> q = rng.Configuration(m);
    if (data == DataKind::kPose) {
      ToolPoseJacobian(m, q.data(), 0, &J_frames);
      J_frames.topRows<3>() *= 1000.0;  // rad against mm, as the solver weights them
    } else {
      ToolPositionJacobian(m, q.data(), 0, &J_frames);
    }
    for (int f = 0; f < m.num_frames(); ++f) {
      J.block(rows_per * r, p.offset[f], rows_per, p.basis[f].cols()) =
          J_frames.middleCols(6 * f, 6) * p.basis[f];
    }
  }
  return J;
}

// Singular values of the column-scaled matrix, divided by the largest.
Eigen::VectorXd RelativeSingularValues(const Eigen::MatrixXd& J) {
  Eigen::VectorXd d(J.cols());
  for (int c = 0; c < J.cols(); ++c) d(c) = 1.0 / std::max(1e-300, J.col(c).norm());
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(J * d.asDiagonal());
  return svd.singularValues() / svd.singularValues()(0);
}

int Rank(const Eigen::VectorXd& relative_singular_values) {
  int rank = 0;
  for (int k = 0; k < relative_singular_values.size(); ++k) {
    rank += relative_singular_values(k) > kRankTolerance;
  }
  return rank;
}

TEST(Parameterization, IdentifiableJacobianHasFullColumnRank) {
  for (const NamedRobot& robot : testing::TestRobotsWithTiltedVariants(kSeed + 2)) {
    for (DataKind data : {DataKind::kPosition, DataKind::kPose}) {
      const Parameterization p =
          MakeParameterization(robot.model, ParameterizationKind::kIdentifiable, data);
      const Eigen::MatrixXd J = StackedJacobian(robot.model, p, data, kConfigurations, kSeed + 3);
      const Eigen::VectorXd s = RelativeSingularValues(J);
      EXPECT_EQ(Rank(s), p.num_parameters)
          << robot.name << (data == DataKind::kPose ? " pose" : " position");
      EXPECT_GT(s(s.size() - 1), kMinimumRelativeSingularValue)
          << robot.name << (data == DataKind::kPose ? " pose" : " position")
          << ": smallest relative singular value";
    }
  }
  // And the cobot6 count itself.
  const RobotModel m = MakeCobot6();
  const Parameterization p =
      MakeParameterization(m, ParameterizationKind::kIdentifiable, DataKind::kPosition);
  EXPECT_EQ(Rank(RelativeSingularValues(
                StackedJacobian(m, p, DataKind::kPosition, kConfigurations, kSeed + 4))),
            27);
}

// The null vector in the full parameterization (6 per frame) that a lost direction c of joint frame
// i generates: c at frame i and -Ad_{T_{i,i+1}(0)^-1} c at the next frame, since
// T_i exp(c) exp(s q) T_{i+1} = T_i exp(s q) T_{i+1} exp(Ad_{T_{i+1}^-1} c). A lost tool rotation is a
// null vector by itself.
Eigen::VectorXd NullVector(const RobotModel& m, const Direction& d) {
  Eigen::VectorXd x = Eigen::VectorXd::Zero(6 * m.num_frames());
  x.segment<6>(6 * d.frame) = d.vector;
  if (d.frame < m.num_joints()) {
    const SE3d& next = FrameOf(m, d.frame + 1);  // the next joint's origin, or the (only) tool
    x.segment<6>(6 * (d.frame + 1)) = -Adjoint(next.Inverse()) * d.vector;
  }
  return x;
}

TEST(Parameterization, FullJacobianHasRank27AndTheListedNullSpace) {
  for (const NamedRobot& robot : testing::TestRobotsWithTiltedVariants(kSeed + 5)) {
    const RobotModel& m = robot.model;
    const Parameterization full = MakeParameterization(m, ParameterizationKind::kFull, DataKind::kPosition);
    const Parameterization identifiable =
        MakeParameterization(m, ParameterizationKind::kIdentifiable, DataKind::kPosition);
    const Eigen::MatrixXd J = StackedJacobian(m, full, DataKind::kPosition, kConfigurations, kSeed + 6);
    const int lost = static_cast<int>(identifiable.unidentifiable.size());
    ASSERT_EQ(full.num_parameters, identifiable.num_parameters + lost) << robot.name;

    // Rank exactly the identifiable count (27 for the 6R arms).
    const Eigen::VectorXd s = RelativeSingularValues(J);
    EXPECT_EQ(Rank(s), identifiable.num_parameters) << robot.name;
    EXPECT_GT(s(identifiable.num_parameters - 1), kMinimumRelativeSingularValue) << robot.name;

    // The listed directions span the null space: each generates a null vector, and together they
    // are independent (so their span is the whole lost-dimension null space).
    Eigen::MatrixXd N(J.cols(), lost);
    for (int k = 0; k < lost; ++k) {
      const Direction& d = identifiable.unidentifiable[k];
      N.col(k) = NullVector(m, d);
      EXPECT_LT((J * N.col(k)).cwiseAbs().maxCoeff(), 1e-9 * J.cwiseAbs().maxCoeff())
          << robot.name << " " << d.name;
      if (d.frame == m.num_joints()) {
        // Tool rotations (position data): the direction alone is in the null space.
        EXPECT_LT((J.middleCols(6 * d.frame, 6) * d.vector).cwiseAbs().maxCoeff(),
                  1e-9 * J.cwiseAbs().maxCoeff())
            << robot.name << " " << d.name;
      }
    }
    Eigen::JacobiSVD<Eigen::MatrixXd> null_svd(N);
    EXPECT_GT(null_svd.singularValues()(lost - 1), 1e-3) << robot.name << ": dependent null vectors";
  }
}

TEST(Parameterization, CentralizerDirectionsReallyAreInvisible) {
  // Not just to first order: moving a lost direction into the next frame leaves the forward
  // kinematics unchanged for a finite perturbation.
  TestRandom rng(kSeed + 7);
  for (const NamedRobot& robot : testing::TestRobotsWithTiltedVariants(kSeed + 8)) {
    const RobotModel& m = robot.model;
    const Parameterization p =
        MakeParameterization(m, ParameterizationKind::kIdentifiable, DataKind::kPosition);
    for (const Direction& d : p.unidentifiable) {
      if (d.frame >= m.num_joints()) continue;
      const Vector6d c = 0.05 * d.vector;
      RobotModel moved = m;
      FrameOf(&moved, d.frame) = FrameOf(m, d.frame) * ExpSE3(c);
      const SE3d& next = FrameOf(m, d.frame + 1);
      FrameOf(&moved, d.frame + 1) = ExpSE3(Vector6d(-c)) * next;
      for (int trial = 0; trial < 5; ++trial) {
        const std::vector<double> q = rng.Configuration(m);
        EXPECT_LT((ToolPosition(moved, q.data()) - ToolPosition(m, q.data())).norm(), 1e-9)
            << robot.name << " " << d.name;
      }
    }
  }
}

TEST(Parameterization, ApplyUpdateAndParameterDifferenceRoundTrip) {
  TestRandom rng(kSeed + 9);
  for (const NamedRobot& robot : testing::TestRobotsWithTiltedVariants(kSeed + 10)) {
    for (ParameterizationKind kind : {ParameterizationKind::kIdentifiable, ParameterizationKind::kFull}) {
      for (DataKind data : {DataKind::kPosition, DataKind::kPose}) {
        const Parameterization p = MakeParameterization(robot.model, kind, data);
        Eigen::VectorXd x(p.num_parameters);
        for (int k = 0; k < x.size(); ++k) {
          // Rotations up to 0.5 rad, translations up to 10 mm.
          const bool rotation = p.parameters[k].vector.head<3>().norm() > 0.5;
          x(k) = rng.Uniform(-1, 1) * (rotation ? 0.5 : 10.0);
        }
        RobotModel updated = robot.model;
        ApplyUpdate(p, x, &updated);
        EXPECT_TRUE(updated.Validate().ok()) << updated.Validate().message();
        const Eigen::VectorXd back = ParameterDifference(p, robot.model, updated);
        EXPECT_LT((back - x).cwiseAbs().maxCoeff(), 1e-10)
            << robot.name << " " << ParameterizationName(kind);
        // The frames moved by exactly T_f exp((B_f x_f)^).
        for (int f = 0; f < robot.model.num_frames(); ++f) {
          const SE3d expected =
              FrameOf(robot.model, f) *
              ExpSE3(Vector6d(p.basis[f] * x.segment(p.offset[f], p.basis[f].cols())));
          EXPECT_LT(testing::RelativeMaxDifference(FrameOf(updated, f).Matrix(), expected.Matrix()),
                    1e-12);
        }
      }
    }
  }
}

TEST(Parameterization, ParseAndName) {
  ParameterizationKind kind = ParameterizationKind::kFull;
  EXPECT_TRUE(ParseParameterization("identifiable", &kind));
  EXPECT_EQ(kind, ParameterizationKind::kIdentifiable);
  EXPECT_TRUE(ParseParameterization("full", &kind));
  EXPECT_EQ(kind, ParameterizationKind::kFull);
  EXPECT_FALSE(ParseParameterization("Full", &kind));
  EXPECT_FALSE(ParseParameterization("", &kind));
  EXPECT_STREQ(ParameterizationName(ParameterizationKind::kFull), "full");
  EXPECT_STREQ(ParameterizationName(ParameterizationKind::kIdentifiable), "identifiable");
}

// Every joint block's parameters follow the block's term and current basis (name of the dominant
// parameter, "~" for a mixture, offsets after the frames), also when a block's basis was replaced
// directly before the next block is added: renumbering keeps an earlier block's entries only while
// they are current.
void ExpectJointBlockDirections(const Parameterization& p) {
  int offset = 0;
  for (const Eigen::MatrixXd& B : p.basis) offset += static_cast<int>(B.cols());
  for (size_t b = 0; b < p.joint_blocks.size(); ++b) {
    const JointBlock& block = p.joint_blocks[b];
    ASSERT_EQ(block.offset, offset) << b;
    for (int c = 0; c < block.basis.cols(); ++c) {
      const Direction& d = p.parameters[offset + c];
      EXPECT_EQ(d.joint_block, static_cast<int>(b));
      ASSERT_EQ(d.combination.size(), block.basis.rows());
      EXPECT_TRUE(d.combination == block.basis.col(c)) << d.name;
      int best = 0;
      const double top = block.basis.col(c).cwiseAbs().maxCoeff(&best);
      EXPECT_EQ(d.name, block.term->name() + "." + block.term->ParameterName(best) +
                            (top < 1.0 - 1e-9 ? "~" : ""));
    }
    offset += static_cast<int>(block.basis.cols());
  }
  EXPECT_EQ(p.num_parameters, offset);
  EXPECT_EQ(static_cast<int>(p.parameters.size()), offset);
}

TEST(Parameterization, JointBlockNamesFollowTheirTermAndBasis) {
  const RobotModel model = MakeCobot6();
  std::shared_ptr<const JointTerm> compliance, harmonics;
  ASSERT_TRUE(MakeJointTerm("compliance", model, &compliance).ok());
  ASSERT_TRUE(MakeJointTerm("harmonics", model, &harmonics).ok());
  Parameterization p =
      MakeParameterization(model, ParameterizationKind::kIdentifiable, DataKind::kPosition);
  AddJointBlock(compliance, &p);
  ExpectJointBlockDirections(p);
  // Block 0 reduced to a mixture of its first two parameters and its third.
  const int Pc = compliance->num_parameters();
  ASSERT_GE(Pc, 3);
  Eigen::MatrixXd mixed = Eigen::MatrixXd::Zero(Pc, 2);
  mixed(0, 0) = mixed(1, 0) = std::sqrt(0.5);
  mixed(2, 1) = 1.0;
  SetJointBlockBasis(0, mixed, "test", &p);
  ExpectJointBlockDirections(p);
  EXPECT_EQ(p.parameters[p.joint_blocks[0].offset].name.back(), '~');
  // Replaced directly (no renumbering) and then a block added: block 0 is named anew.
  Eigen::MatrixXd other = Eigen::MatrixXd::Zero(Pc, 2);
  other(Pc - 1, 0) = 1.0;
  other(0, 1) = 1.0;
  p.joint_blocks[0].basis = other;
  AddJointBlock(harmonics, &p);
  ExpectJointBlockDirections(p);
  EXPECT_EQ(p.parameters[p.joint_blocks[0].offset].name,
            compliance->name() + "." + compliance->ParameterName(Pc - 1));
  // The second block reduced: the first block's entries stay those of its basis.
  SetJointBlockBasis(1, Eigen::MatrixXd::Identity(harmonics->num_parameters(), 1), "test", &p);
  ExpectJointBlockDirections(p);
}

}  // namespace parameterization_test
}  // namespace
// Two combinations of one joint block dominated by the same parameter (here two kept ones, and the
// left-out ones beside them) get distinct names, so that the report's lists and correlation pairs
// name each combination once.
TEST(Parameterization, JointCombinationsSharingADominantParameterGetDistinctNames) {
  const RobotModel model = MakeCobot6();
  Parameterization p = MakeParameterization(model, ParameterizationKind::kIdentifiable,
                                            DataKind::kPosition);
  std::shared_ptr<const JointTerm> term;
  ASSERT_TRUE(MakeJointTerm("harmonics", model, &term).ok());
  AddJointBlock(term, &p);
  const int P = term->num_parameters();
  Eigen::MatrixXd basis = Eigen::MatrixXd::Zero(P, 2);  // orthonormal, both led by parameter 0
  basis.col(0) << std::sqrt(0.5), 0.5, 0.5, Eigen::VectorXd::Zero(P - 3);
  basis.col(1) << std::sqrt(0.5), -0.5, -0.5, Eigen::VectorXd::Zero(P - 3);
  SetJointBlockBasis(0, basis, "test", &p);
  const std::string lead = term->name() + "." + term->ParameterName(0) + "~";
  std::vector<std::string> kept;
  for (const Direction& d : p.parameters) {
    if (d.joint_block == 0) kept.push_back(d.name);
  }
  ASSERT_EQ(kept.size(), 2u);
  EXPECT_EQ(kept[0], lead);
  EXPECT_EQ(kept[1], lead + "#2");
  std::set<std::string> names(kept.begin(), kept.end());
  int left_out = 0;
  for (const Direction& d : p.unidentifiable) {
    if (d.joint_block != 0) continue;
    ++left_out;
    EXPECT_TRUE(names.insert(d.name).second) << "repeated name " << d.name;
  }
  EXPECT_EQ(left_out, P - 2);
  // Renumbering (here by copying the blocks into another parameterization) keeps the names.
  Parameterization copy = MakeParameterization(model, ParameterizationKind::kIdentifiable,
                                               DataKind::kPosition);
  CopyJointBlocks(p, &copy);
  std::set<std::string> copied;
  for (const Direction& d : copy.parameters) {
    if (d.joint_block == 0) copied.insert(d.name);
  }
  for (const Direction& d : copy.unidentifiable) {
    if (d.joint_block == 0) copied.insert(d.name);
  }
  EXPECT_EQ(copied, names);
}

}  // namespace lpoe
