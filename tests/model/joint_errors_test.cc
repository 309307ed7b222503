// Non-geometric joint-space terms (lpoe/terms/joint_errors.h): the compliance regressor against the
// potential energy of the links, Jacobians against finite differences and autodiff, the identifiable
// reduction, the simulator's magnitudes, the YAML round trip and PredictPositions.
#include "lpoe/terms/joint_errors.h"

#include <ceres/jet.h>
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include <Eigen/Dense>

#include "lpoe/kinematics/eigen_decompositions.h"
#include "lpoe/io/io.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/model/simulation.h"
#include "test_util.h"

namespace lpoe {
namespace {
namespace joint_errors_test {

using testing::TestRandom;

constexpr int kTrials = 20;
constexpr double kArcsecPerRadian = 206264.80624709636;
// Central differences of smooth functions with these steps: errors O(h^2).
constexpr double kStepRad = 1e-6;
constexpr double kRelativeTolerance = 1e-6;
constexpr double kRoundTripToleranceMm = 1e-9;

// A model with a payload and random physics (stiffness 1 so that dq = tau).
struct Loaded {
  RobotModel model;
  JointErrorPhysics physics;
};

Loaded MakeLoaded(const RobotModel& base, uint64_t seed) {
  Loaded out{base, {}};
  TestRandom rng(seed);
  const int n = base.num_joints();
  for (int k = 0; k < n; ++k) {
    out.physics.stiffness.push_back(1.0);
    out.physics.link_mass.push_back(rng.Uniform(0.5, 4.0));
    out.physics.link_com.push_back(rng.Vector3(200.0));
  }
  out.model.payload.mass = 1.7;
  out.model.payload.com = Eigen::Vector3d(10, -20, 55);
  out.model.gravity = ExpSO3(Eigen::Vector3d(0.004, -0.003, 0)) * out.model.gravity;
  return out;
}

// Position of a point fixed to link k (k's frame) at q.
Eigen::Vector3d PointOnLink(const RobotModel& model, int k, const Eigen::Vector3d& point,
                            const double* q) {
  RobotModel truncated = model;
  truncated.joints.resize(k + 1);
  truncated.joint_errors = JointErrorTerms();
  truncated.tools = {Tool{"point", SE3d(Eigen::Matrix3d::Identity(), point)}};
  return ToolPosition(truncated, q, 0);
}

// Gravity torque about joint j as minus the derivative of the potential energy V = -sum m g . p,
// by central differences: independent of the regressor's twist algebra.
double TorqueFromPotential(const Loaded& l, std::vector<double> q, int j) {
  const RobotModel& model = l.model;
  const int n = model.num_joints();
  auto work = [&](const std::vector<double>& qq) {
    double w = 0;
    for (int k = j; k < n; ++k) {
      w += l.physics.link_mass[k] * model.gravity.dot(PointOnLink(model, k, l.physics.link_com[k], qq.data()));
    }
    w += model.payload.mass * model.gravity.dot(PointOnLink(model, n - 1, model.payload.com, qq.data()));
    return w;
  };
  const double h = model.joints[j].type == JointType::kRevolute ? kStepRad : 1e-4;
  q[j] += h;
  const double plus = work(q);
  q[j] -= 2 * h;
  const double minus = work(q);
  const double scale = model.joints[j].type == JointType::kRevolute ? 1e-3 : 1.0;  // N mm -> N m
  return scale * (plus - minus) / (2 * h);
}

TEST(JointErrors, LayoutIsContiguous) {
  for (int n : {1, 3, 6, 7}) {
    int expected = 0;
    for (int j = 0; j < n; ++j) {
      for (int k = j; k < n; ++k) {
        EXPECT_EQ(ComplianceLinkIndex(n, j, k), expected);
        expected += 4;
      }
      EXPECT_EQ(CompliancePayloadIndex(n, j), expected);
      ++expected;
    }
    EXPECT_EQ(NumComplianceParameters(n), expected);
  }
  const RobotModel model = MakeCobot6();
  EXPECT_EQ(JointErrorParameterNames(model, "compliance").size(), 90u);
  EXPECT_EQ(JointErrorParameterNames(model, "compliance")[4], "joint1.c*m_joint2");
  EXPECT_EQ(JointErrorParameterNames(model, "harmonics")[6], "joint2.sin2");
}

TEST(JointErrors, ParsesKindLists) {
  std::vector<std::string> kinds;
  std::string error;
  ASSERT_TRUE(ParseJointTermList("none", &kinds, &error));
  EXPECT_TRUE(kinds.empty());
  ASSERT_TRUE(ParseJointTermList("harmonics,compliance", &kinds, &error));
  ASSERT_EQ(kinds.size(), 2u);
  EXPECT_EQ(kinds[0], "harmonics");
  EXPECT_EQ(InRegistryOrder(kinds), (std::vector<std::string>{"compliance", "harmonics"}));
  EXPECT_FALSE(ParseJointTermList("compliance,compliance", &kinds, &error));
  EXPECT_FALSE(ParseJointTermList("compliance,", &kinds, &error));
  EXPECT_FALSE(ParseJointTermList("stiffness", &kinds, &error));
  // The message lists the registry's names.
  EXPECT_NE(error.find("unknown joint error term 'stiffness'"), std::string::npos) << error;
  for (const std::string& name : JointTermNames()) {
    EXPECT_NE(error.find(name), std::string::npos) << error;
    ASSERT_TRUE(ParseJointTermList(name, &kinds, &error)) << name;
    ASSERT_EQ(kinds.size(), 1u);
  }
}

// dq = c tau with c = 1: the regressor times the physical products is the gravity torque, for
// revolute (N m) and prismatic (N) joints, with a payload and a tilted gravity.
TEST(JointErrors, ComplianceIsTheGravityTorque) {
  for (const RobotModel& base : {MakeCobot6(), MakeArmWithPrismatic(), MakeSevenJointArm()}) {
    const Loaded l = MakeLoaded(base, 3);
    const std::vector<double> theta = CompliancePhysicsParameters(l.physics);
    const Eigen::Map<const Eigen::VectorXd> theta_map(theta.data(), theta.size());
    TestRandom rng(5);
    for (int t = 0; t < 5; ++t) {
      const std::vector<double> q = rng.Configuration(base);
      Eigen::MatrixXd Y;
      ComplianceRegressor(l.model, q.data(), &Y);
      const Eigen::VectorXd tau = Y * theta_map;
      for (int j = 0; j < base.num_joints(); ++j) {
        const double expected = TorqueFromPotential(l, q, j);
        EXPECT_NEAR(tau(j), expected, 1e-6 * (1 + std::abs(expected)))
            << base.name << " joint " << j + 1;
      }
      // Linear in gravity.
      Eigen::MatrixXd Y_axes[3];
      ComplianceRegressorGravityAxes(l.model, q.data(), Y_axes);
      const Eigen::Vector3d& g = l.model.gravity;
      EXPECT_LT((g(0) * Y_axes[0] + g(1) * Y_axes[1] + g(2) * Y_axes[2] - Y).norm(),
                1e-12 * Y.norm());
    }
  }
}

TEST(JointErrors, VerticalFirstJointFeelsNoTorque) {
  const Loaded l = MakeLoaded(MakeCobot6(), 4);
  RobotModel level = l.model;
  level.gravity = Eigen::Vector3d(0, 0, -kStandardGravity);
  Eigen::MatrixXd Y;
  ComplianceRegressor(level, TestRandom(1).Configuration(level).data(), &Y);
  EXPECT_LT(Y.row(0).norm(), 1e-12);
  EXPECT_GT(Y.row(1).norm(), 1e-3);
}

TEST(JointErrors, HarmonicsRegressor) {
  const RobotModel model = MakeArmWithPrismatic();
  const std::vector<double> q = TestRandom(2).Configuration(model);
  Eigen::MatrixXd Y;
  HarmonicsRegressor(model, q.data(), &Y);
  ASSERT_EQ(Y.cols(), 24);
  for (int j = 0; j < model.num_joints(); ++j) {
    const bool revolute = model.joints[j].type == JointType::kRevolute;
    const Eigen::Vector4d expected(std::sin(q[j]), std::cos(q[j]), std::sin(2 * q[j]),
                                   std::cos(2 * q[j]));
    for (int c = 0; c < 4; ++c) {
      EXPECT_NEAR(Y(j, 4 * j + c), revolute ? expected(c) : 0.0, 1e-15);
    }
    EXPECT_NEAR(Y.row(j).norm(), revolute ? expected.norm() : 0.0, 1e-15);
  }
}

TEST(JointErrors, JointJacobianMatchesFiniteDifferences) {
  for (const RobotModel& model : {MakeCobot6(), MakeArmWithPrismatic()}) {
    TestRandom rng(9);
    for (int t = 0; t < kTrials; ++t) {
      std::vector<double> q = rng.Configuration(model);
      Eigen::Matrix<double, 3, Eigen::Dynamic> J;
      const Eigen::Vector3d P = ToolPositionJointJacobian(model, q.data(), 0, &J);
      EXPECT_LT((P - ToolPosition(model, q.data(), 0)).norm(), 1e-9);
      for (int j = 0; j < model.num_joints(); ++j) {
        const double h = 1e-6;
        std::vector<double> qp = q, qm = q;
        qp[j] += h;
        qm[j] -= h;
        const Eigen::Vector3d fd =
            (ToolPosition(model, qp.data(), 0) - ToolPosition(model, qm.data(), 0)) / (2 * h);
        EXPECT_LT((fd - J.col(j)).norm(), kRelativeTolerance * (1 + fd.norm()));
      }
    }
  }
}

// The Jacobian the solvers use for a term, dP/dtheta = J_q(q_eff) Y(q), against central differences
// of the full prediction.
TEST(JointErrors, ParameterJacobianMatchesFiniteDifferences) {
  RobotModel model = MakeLoaded(MakeCobot6(), 6).model;
  SmallArmOptions options;
  ApplyJointErrorPhysics(SmallArmJointErrors(model, options), {"compliance", "harmonics"}, &model);
  TestRandom rng(10);
  for (int t = 0; t < 5; ++t) {
    const std::vector<double> q = rng.Configuration(model);
    std::vector<double> q_eff(model.num_joints());
    EffectiveJoints(model, q.data(), q_eff.data());
    Eigen::Matrix<double, 3, Eigen::Dynamic> J_q;
    ToolPositionJointJacobian(model, q_eff.data(), 0, &J_q);
    for (const std::string kind : {"compliance", "harmonics"}) {
      Eigen::MatrixXd Y;
      JointErrorRegressor(model, kind, q.data(), &Y);
      const Eigen::MatrixXd J = J_q * Y;
      std::vector<double>& theta = *model.joint_errors.MutableValues(kind);
      for (int c = 0; c < J.cols(); c += 3) {
        const double largest = Y.col(c).cwiseAbs().maxCoeff();
        if (largest == 0) continue;
        const double h = 1e-6 / largest;  // joints move by 1e-6 rad
        const double saved = theta[c];
        theta[c] = saved + h;
        const Eigen::Vector3d plus = PredictToolPosition(model, q.data(), 0);
        theta[c] = saved - h;
        const Eigen::Vector3d minus = PredictToolPosition(model, q.data(), 0);
        theta[c] = saved;
        const Eigen::Vector3d fd = (plus - minus) / (2 * h);
        EXPECT_LT((fd - J.col(c)).norm(), 1e-5 * (1 + J.col(c).norm()))
            << kind << " column " << c;
      }
    }
  }
}

// The bilinear tilt form, templated: Jets through TiltedGravity and ComplianceOffsets agree with
// central differences of the double evaluation, in the tilt and in the products.
TEST(JointErrors, TiltAutodiffMatchesFiniteDifferences) {
  using Jet = ceres::Jet<double, 2>;
  const Loaded l = MakeLoaded(MakeCobot6(), 8);
  const std::vector<double> theta = CompliancePhysicsParameters(l.physics);
  const std::vector<double> q = TestRandom(12).Configuration(l.model);
  Eigen::MatrixXd Y_axes[3];
  ComplianceRegressorGravityAxes(l.model, q.data(), Y_axes);
  const int n = l.model.num_joints();
  auto offsets = [&](double tx, double ty) {
    const double tilt[2] = {tx, ty};
    std::vector<double> dq(n);
    ComplianceOffsets<double>(Y_axes, TiltedGravity<double>(l.model.gravity, tilt), theta.data(),
                              dq.data());
    return dq;
  };
  const double tilt0[2] = {0.003, -0.002};
  const Jet tilt[2] = {Jet(tilt0[0], 0), Jet(tilt0[1], 1)};
  std::vector<Jet> theta_jet(theta.begin(), theta.end());
  std::vector<Jet> dq(n);
  ComplianceOffsets<Jet>(Y_axes, TiltedGravity<Jet>(l.model.gravity, tilt), theta_jet.data(),
                         dq.data());
  const std::vector<double> value = offsets(tilt0[0], tilt0[1]);
  const double h = 1e-6;
  for (int a = 0; a < 2; ++a) {
    const std::vector<double> plus = offsets(tilt0[0] + (a == 0 ? h : 0), tilt0[1] + (a == 1 ? h : 0));
    const std::vector<double> minus = offsets(tilt0[0] - (a == 0 ? h : 0), tilt0[1] - (a == 1 ? h : 0));
    for (int j = 0; j < n; ++j) {
      EXPECT_NEAR(dq[j].a, value[j], 1e-12 * (1 + std::abs(value[j])));
      const double fd = (plus[j] - minus[j]) / (2 * h);
      EXPECT_NEAR(dq[j].v(a), fd, 1e-6 * (1 + std::abs(fd))) << "joint " << j + 1 << " tilt " << a;
    }
  }
  // A tilt changes the torque of the vertical joint 1 (gravity no longer along its axis).
  EXPECT_GT(std::abs(dq[0].v(0)) + std::abs(dq[0].v(1)), 1e-3);
}

MeasurementSet RandomRows(const RobotModel& model, int count, uint64_t seed) {
  SimulationOptions options;
  options.count = count;
  options.seed = seed;
  options.all_tools = true;
  return SimulateMeasurements(model, {}, options);
}

int Rank(const Eigen::MatrixXd& A) {
  Eigen::MatrixXd scaled = A;
  const double largest = A.colwise().norm().maxCoeff();
  for (int c = 0; c < A.cols(); ++c) {
    if (scaled.col(c).norm() > kJointErrorRankTolerance * largest) {
      scaled.col(c).normalize();
    } else {
      scaled.col(c).setZero();
    }
  }
  Eigen::BDCSVD<Eigen::MatrixXd> svd(scaled);
  const Eigen::VectorXd& s = svd.singularValues();
  int r = 0;
  while (r < s.size() && s(r) > kJointErrorRankTolerance * s(0)) ++r;
  return r;
}

// The tool effects of the terms, stacked over the rows, for rank checks.
Eigen::MatrixXd Effects(const RobotModel& model, const MeasurementSet& data, const std::string& kind) {
  Eigen::MatrixXd A(3 * data.size(), NumJointErrorParameters(model, kind));
  Eigen::MatrixXd Y;
  for (int r = 0; r < data.size(); ++r) {
    Eigen::Matrix<double, 3, Eigen::Dynamic> J;
    ToolPositionJointJacobian(model, data.q(r), data.target(r), &J);
    JointErrorRegressor(model, kind, data.q(r), &Y);
    A.middleRows(3 * r, 3) = J * Y;
  }
  return A;
}

Eigen::MatrixXd Geometric(const RobotModel& model, const Parameterization& p,
                          const MeasurementSet& data) {
  Eigen::MatrixXd A(3 * data.size(), p.num_parameters);
  BasisJacobian bj(model, p);
  std::vector<FrameRt> scratch(model.num_joints() + 1);
  for (int r = 0; r < data.size(); ++r) {
    bj.Position(data.q(r), data.target(r), A.data() + 3 * r, 3 * data.size(), scratch.data());
  }
  return A;
}

// The kept combinations add exactly their number to the rank of what comes before them, and
// nothing left out adds anything: rank [geometry, compliance, harmonics] = geometry + kept.
TEST(JointErrors, ReductionKeepsExactlyTheIdentifiableCombinations) {
  RobotModel model = MakeCobot6();
  model.payload.mass = 0.8;
  const MeasurementSet data = RandomRows(model, 150, 3);
  const Parameterization p =
      MakeParameterization(model, ParameterizationKind::kIdentifiable, DataKind::kPosition);
  std::vector<JointErrorReduction> reductions;
  ASSERT_TRUE(ReduceJointErrorTerms(model, p, data,
                                    {"compliance", "harmonics"},
                                    &reductions)
                  .ok());
  ASSERT_EQ(reductions.size(), 2u);
  const Eigen::MatrixXd G = Geometric(model, p, data);
  const Eigen::MatrixXd C = Effects(model, data, "compliance");
  const Eigen::MatrixXd H = Effects(model, data, "harmonics");
  const int kept_c = static_cast<int>(reductions[0].basis.cols());
  const int kept_h = static_cast<int>(reductions[1].basis.cols());
  Eigen::MatrixXd GC(G.rows(), G.cols() + C.cols());
  GC << G, C;
  Eigen::MatrixXd GCH(G.rows(), GC.cols() + H.cols());
  GCH << GC, H;
  EXPECT_EQ(Rank(GC), p.num_parameters + kept_c);
  EXPECT_EQ(Rank(GCH), p.num_parameters + kept_c + kept_h);
  Eigen::MatrixXd reduced(G.rows(), G.cols() + kept_c + kept_h);
  reduced << G, C * reductions[0].basis, H * reductions[1].basis;
  EXPECT_EQ(Rank(reduced), reduced.cols());
  // Joint 1 is vertical: no compliance combination; with compliance first, the first harmonic of
  // the shoulder (joint 2) is its own link's gravity torque and is removed.
  EXPECT_EQ(reductions[0].per_joint[0], 0);
  EXPECT_LT(kept_h, 24);
  EXPECT_EQ(reductions[1].rank_alone, 24);
}

// A tool on joint 6's axis makes joint 6's harmonics invisible.
TEST(JointErrors, ReductionDropsInvisibleHarmonics) {
  const RobotModel model = MakeCobot6(Eigen::Vector3d(0, 0, 60));
  const MeasurementSet data = RandomRows(model, 100, 4);
  const Parameterization p =
      MakeParameterization(model, ParameterizationKind::kIdentifiable, DataKind::kPosition);
  std::vector<JointErrorReduction> reductions;
  ASSERT_TRUE(
      ReduceJointErrorTerms(model, p, data, {"harmonics"}, &reductions).ok());
  EXPECT_EQ(reductions[0].rank_alone, 20);
  EXPECT_EQ(reductions[0].per_joint[5], 0);
}

// The simulator's default small arm deflects as the issue describes: a few hundred arcsec peak to
// peak at the shoulder and elbow, tenths of a millimetre at the tool, harmonics of 5-30 arcsec.
TEST(JointErrors, SimulatedSmallArmHasRealisticMagnitudes) {
  const RobotModel nominal = MakeCobot6();
  RobotModel actual = nominal;
  const JointErrorPhysics physics = SmallArmJointErrors(nominal, SmallArmOptions());
  ApplyJointErrorPhysics(physics, {"compliance"}, &actual);
  for (const Eigen::Vector4d& h : physics.harmonics) {
    for (int order = 0; order < 2; ++order) {
      const double amplitude = std::hypot(h(2 * order), h(2 * order + 1)) * kArcsecPerRadian;
      EXPECT_GE(amplitude, 5.0 - 1e-9);
      EXPECT_LE(amplitude, 30.0 + 1e-9);
    }
  }
  const MeasurementSet data = RandomRows(nominal, 300, 5);
  std::vector<double> lo(6, 1e9), hi(6, -1e9);
  double sum_sq = 0;
  for (int r = 0; r < data.size(); ++r) {
    std::vector<double> dq(6);
    JointErrorOffsets(actual, data.q(r), dq.data());
    for (int j = 0; j < 6; ++j) {
      lo[j] = std::min(lo[j], dq[j] * kArcsecPerRadian);
      hi[j] = std::max(hi[j], dq[j] * kArcsecPerRadian);
    }
    sum_sq += (PredictToolPosition(actual, data.q(r), 0) - ToolPosition(actual, data.q(r), 0))
                  .squaredNorm();
  }
  EXPECT_EQ(hi[0] - lo[0], 0.0);  // vertical base joint
  for (int j = 1; j <= 2; ++j) {
    EXPECT_GT(hi[j] - lo[j], 100.0) << "joint " << j + 1;
    EXPECT_LT(hi[j] - lo[j], 900.0) << "joint " << j + 1;
  }
  EXPECT_GT(hi[3] - lo[3], 20.0);  // the wrist deflects too
  const double rms = std::sqrt(sum_sq / data.size());
  EXPECT_GT(rms, 0.2);
  EXPECT_LT(rms, 0.8);
}

// The simulator measures at q + joint zero + the terms' offsets there.
TEST(JointErrors, SimulationMeasuresTheEffectiveJoints) {
  RobotModel actual = MakeCobot6();
  ApplyJointErrorPhysics(SmallArmJointErrors(actual, SmallArmOptions()), {"compliance", "harmonics"}, &actual);
  const std::vector<double> zero = {0.01, -0.02, 0.005, 0.0, 0.01, -0.01};
  SimulationOptions options;
  options.count = 20;
  const MeasurementSet data = SimulateMeasurements(actual, zero, options);
  for (int r = 0; r < data.size(); ++r) {
    std::vector<double> q(data.q(r), data.q(r) + 6);
    for (int j = 0; j < 6; ++j) q[j] += zero[j];
    EXPECT_LT((data.position(r) - PredictToolPosition(actual, q.data(), 0)).norm(), 1e-12);
    EXPECT_GT((data.position(r) - ToolPosition(actual, q.data(), 0)).norm(), 1e-6);
    // The actual model as lpoe_simulate writes it predicts the data at the commanded q.
    EXPECT_LT((data.position(r) - PredictToolPosition(FoldJointZeros(actual, zero), data.q(r), 0))
                  .norm(),
              1e-9);
  }
}

TEST(JointErrors, YamlRoundTripReproducesPredictions) {
  for (const RobotModel& base : {MakeCobot6(), MakeArmWithPrismatic()}) {
    RobotModel model = MakeLoaded(base, 13).model;
    model.joints[1].name = "shoulder \"pitch\"";
    ApplyJointErrorPhysics(SmallArmJointErrors(model, SmallArmOptions()), {"compliance", "harmonics"}, &model);
    (*model.joint_errors.MutableValues("compliance"))[ComplianceLinkIndex(6, 2, 4) + 1] = 0;  // a partial row
    const std::string text = RobotModelToYaml(model);
    RobotModel back;
    const Status s = ParseRobotModelYaml(text, "model.yaml", &back);
    ASSERT_TRUE(s.ok()) << s.message() << "\n" << text;
    EXPECT_EQ(back.gravity, model.gravity);
    EXPECT_EQ(back.payload.mass, model.payload.mass);
    EXPECT_EQ(back.payload.com, model.payload.com);
    EXPECT_EQ(back.joint_errors.Values("compliance"), model.joint_errors.Values("compliance"));
    EXPECT_EQ(back.joint_errors.Values("harmonics"), model.joint_errors.Values("harmonics"));
    TestRandom rng(14);
    for (int t = 0; t < kTrials; ++t) {
      const std::vector<double> q = rng.Configuration(model);
      EXPECT_LT((PredictToolPosition(back, q.data(), 0) - PredictToolPosition(model, q.data(), 0))
                    .norm(),
                kRoundTripToleranceMm);
    }
  }
  // Defaults write nothing new: existing model files are unchanged.
  EXPECT_EQ(RobotModelToYaml(MakeCobot6()).find("gravity"), std::string::npos);
}

TEST(JointErrors, YamlErrorsNameLineAndReason) {
  const std::string head =
      "name: two\n"
      "joints:\n"
      "  - {name: a, type: revolute, origin: {xyz: [0, 0, 0], rpy: [0, 0, 0]}}\n"
      "  - {name: b, type: revolute, origin: {xyz: [0, 0, 100], rpy: [1.5707963, 0, 0]}}\n"
      "tools:\n"
      "  - {name: t, origin: {xyz: [50, 0, 0], rpy: [0, 0, 0]}}\n";
  struct Case {
    std::string tail, message;
  } cases[] = {
      {"gravity: [0, 0]\n", "m.yaml:7: 'gravity' is a list of 2"},
      {"gravity: [0, 0, .nan]\n", "m.yaml:7: 'gravity' entry 3 '.nan' is not a finite number"},
      {"payload: {mass: -1}\n", "m.yaml:7: 'mass' is out of range"},
      {"payload: {mass: 1, com: [0, 0, 1e9]}\n", "m.yaml:7: 'com' is out of range"},
      {"gravity: [0, 0, 1e5]\n", "m.yaml:7: 'gravity' has magnitude 100000 m/s^2"},
      // A gear-ratio error of 1e308 (NaN joints downstream), or one that moves joint b
      // by radians within its range, is not a joint-space error.
      {"joint_errors:\n  gear_ratio:\n    - {joint: b, s: 1e308}\n",
       "m.yaml:9: 's' '1e308' is out of range"},
      {"joint_errors:\n  gear_ratio:\n    - {joint: b, s: 0.3}\n",
       "m.yaml:7: 'joint_errors' move joint 'b' by"},
      {"joint_errors:\n  harmonics:\n    - {joint: a, coefficients: [0.5, 0, 0, 0]}\n",
       "m.yaml:7: 'joint_errors' move joint 'a' by"},
      {"payload: {com: [0, 0, 1]}\n", "m.yaml:7: 'payload' has no 'mass'"},
      {"joint_errors:\n  harmonics:\n    - {joint: c, coefficients: [0, 0, 0, 0]}\n",
       "m.yaml:9: 'joint' 'c' is not a joint of the model"},
      {"joint_errors:\n  compliance:\n    - joint: b\n      links: {a: [1, 2, 3, 4]}\n",
       "m.yaml:10: unknown key 'a' in 'links' of joint 'b'"},
      {"joint_errors:\n  harmonics:\n    - {joint: a, coefficients: [0, 0, 0]}\n"
       "    - {joint: a, coefficients: [0, 0, 0, 0]}\n",
       "'coefficients' is a list of 3"},
      {"joint_errors:\n  harmonics:\n    - {joint: a, coefficients: [0, 0, 0, 0]}\n"
       "    - {joint: a, coefficients: [0, 0, 0, 0]}\n",
       "m.yaml:10: joint 'a' appears twice in 'harmonics'"},
      {"gravity: [0, 0, -9.8]\ngravity: [0, 0, -9.8]\n", "m.yaml:8: duplicate key 'gravity'"},
      {"joint_errors: {stiffness: []}\n", "m.yaml:7: unknown key 'stiffness' in 'joint_errors'"},
  };
  for (const Case& c : cases) {
    RobotModel model;
    const Status s = ParseRobotModelYaml(head + c.tail, "m.yaml", &model);
    ASSERT_FALSE(s.ok()) << c.tail;
    EXPECT_NE(s.message().find(c.message), std::string::npos) << s.message();
  }
}

TEST(JointErrors, PredictPositionsChecksItsInput) {
  RobotModel model = MakeCobot6();
  model.tools.push_back(Tool{"smr2", SE3d(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0, 50, 60))});
  ApplyJointErrorPhysics(SmallArmJointErrors(model, SmallArmOptions()), {"compliance", "harmonics"}, &model);
  TestRandom rng(15);
  std::vector<double> q;
  for (int r = 0; r < 4; ++r) {
    const std::vector<double> row = rng.Configuration(model);
    q.insert(q.end(), row.begin(), row.end());
  }
  std::vector<Eigen::Vector3d> positions;
  ASSERT_TRUE(PredictPositions(model, q, {0, 1, 1, 0}, 0, &positions).ok());
  ASSERT_EQ(positions.size(), 4u);
  EXPECT_LT((positions[1] - PredictToolPosition(model, q.data() + 6, 1)).norm(), 1e-12);
  ASSERT_TRUE(PredictPositions(model, q, {}, 1, &positions).ok());
  EXPECT_LT((positions[0] - PredictToolPosition(model, q.data(), 1)).norm(), 1e-12);
  EXPECT_NE(PredictPositions(model, q, {0, 2, 0, 0}, 0, &positions).message().find("row 2: tool index 2"),
            std::string::npos);
  EXPECT_FALSE(PredictPositions(model, std::vector<double>(7, 0.0), {}, 0, &positions).ok());
  q[9] = NAN;
  EXPECT_NE(PredictPositions(model, q, {}, 0, &positions).message().find("row 2: joint 4"),
            std::string::npos);
}

}  // namespace joint_errors_test
}  // namespace
}  // namespace lpoe
