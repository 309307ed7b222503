// The hand-written kernels (lpoe/kernels.h, core/src/kernels/) run both ways: every kernel's result
// on the AVX2/FMA path equals the reference path's (plain C++ and Eigen) to a tolerance, on data of
// realistic magnitudes. The reference path is forced with kernels::SetForTesting, so it runs here
// even on an AVX2 machine; the test is registered a second time with LPOE_KERNELS=reference
// (tests/CMakeLists.txt), where the switch itself is checked (KernelsSwitch).
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <memory>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "lpoe/joint_errors.h"
#include "lpoe/joint_term.h"
#include "lpoe/kernels.h"
#include "lpoe/kinematics.h"
#include "lpoe/parameterization.h"
#include "lpoe/residual_layer.h"
#include "lpoe/simulation.h"
#include "normal_equations.h"

namespace lpoe {
namespace {

// Runs `f` with the kernel path forced to `path`, then restores the previous one.
template <typename F>
auto With(kernels::Path path, const F& f) {
  const kernels::Path previous = kernels::SetForTesting(path);
  auto result = f();
  kernels::SetForTesting(previous);
  return result;
}

double RelativeDifference(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  return (a - b).cwiseAbs().maxCoeff() / b.cwiseAbs().maxCoeff();
}

// The environment switch: LPOE_KERNELS=reference forces the reference path; unset or "auto" takes
// what the processor has.
TEST(KernelsSwitch, EnvironmentSelectsThePath) {
  const char* env = std::getenv("LPOE_KERNELS");
  if (env != nullptr && std::strcmp(env, "reference") == 0) {
    EXPECT_EQ(kernels::Active(), kernels::Path::kReference);
  } else {
    EXPECT_EQ(kernels::Active(), kernels::ProcessorHasAvx2Fma() ? kernels::Path::kAvx2Fma
                                                                : kernels::Path::kReference);
  }
  // Forcing and restoring.
  const kernels::Path before = kernels::Active();
  EXPECT_EQ(kernels::SetForTesting(kernels::Path::kReference), before);
  EXPECT_EQ(kernels::Active(), kernels::Path::kReference);
  EXPECT_FALSE(kernels::Avx2Fma());
  kernels::SetForTesting(before);
  EXPECT_EQ(kernels::Active(), before);
}

// The two paths of a kernel can only be compared where the processor has AVX2 and FMA.
#define LPOE_REQUIRE_AVX2()                                                       \
  if (!kernels::ProcessorHasAvx2Fma()) GTEST_SKIP() << "no AVX2/FMA: one path only"

// SinCosMany: within 2 ulp of libm's sincos (the reference path) for joint values, the reduction's
// edge cases (multiples of pi/2, values near 2^19), large and non-finite values and tails of 1-3.
TEST(Kernels, SinCosManyBothWays) {
  LPOE_REQUIRE_AVX2();
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> joint(-6.5, 6.5), wide(-6e5, 6e5);
  std::vector<double> x;
  for (int k = 0; k < 20000; ++k) x.push_back(joint(rng));
  for (int k = 0; k < 2000; ++k) x.push_back(wide(rng));
  for (int k = -40; k <= 40; ++k) x.push_back(k * 1.5707963267948966);  // multiples of pi/2
  for (double v : {0.0, -0.0, 1e-300, 524288.0, 524288.5, -524289.0, 1e10, 1e300,
                   std::numeric_limits<double>::infinity(), std::numeric_limits<double>::quiet_NaN()}) {
    x.push_back(v);
  }
  x.push_back(0.25);  // a count that is not a multiple of four: the padded tail
  if (x.size() % 4 == 0) x.push_back(-1.75);
  const int count = static_cast<int>(x.size());
  ASSERT_NE(count % 4, 0);
  std::vector<double> s_ref(count), c_ref(count), s_vec(count), c_vec(count);
  With(kernels::Path::kReference, [&] {
    SinCosMany(x.data(), count, s_ref.data(), c_ref.data());
    return 0;
  });
  With(kernels::Path::kAvx2Fma, [&] {
    SinCosMany(x.data(), count, s_vec.data(), c_vec.data());
    return 0;
  });
  auto ulps = [](double a, double b) {
    if (std::isnan(a) || std::isnan(b)) return std::isnan(a) && std::isnan(b) ? 0.0 : HUGE_VAL;
    const double ulp = std::nextafter(std::abs(b), HUGE_VAL) - std::abs(b);
    return std::abs(a - b) / ulp;
  };
  double worst = 0;
  for (int k = 0; k < count; ++k) {
    worst = std::max({worst, ulps(s_vec[k], s_ref[k]), ulps(c_vec[k], c_ref[k])});
    ASSERT_LE(ulps(s_vec[k], s_ref[k]), 2.0) << "sin " << x[k];
    ASSERT_LE(ulps(c_vec[k], c_ref[k]), 2.0) << "cos " << x[k];
  }
  // The vector path is not libm itself (else this test compared nothing).
  int differ = 0;
  for (int k = 0; k < count; ++k) differ += s_vec[k] != s_ref[k] || c_vec[k] != c_ref[k];
  EXPECT_GT(differ, 0);
  RecordProperty("worst_ulps", std::to_string(worst));
}

// Simulated laser-tracker data on cobot6: SMRs tens of mm off the flange, noise 0.02 mm.
struct Data {
  RobotModel nominal = MakeCobot6();
  RobotModel model;
  MeasurementSet data;
  explicit Data(int count) {
    const KinematicErrors errors = RandomErrors(nominal, 2e-3, 0.5, 1e-3, 2e-3, 21);
    RobotModel actual = ApplyErrors(nominal, errors);
    ApplyJointErrorPhysics(SmallArmJointErrors(nominal, SmallArmOptions()), {"compliance", "harmonics"},
                           &actual);
    SimulationOptions options;
    options.count = count;
    options.noise_sigma = 0.02;
    options.seed = 5;
    data = SimulateMeasurements(actual, errors.joint_zero, options);
    // A linearization point away from nominal as the solver's iterations reach it (the frames
    // move, the joints stay revolute about z: the four-row path applies).
    model = nominal;
    const Parameterization p =
        MakeParameterization(nominal, ParameterizationKind::kIdentifiable, DataKind::kPosition);
    std::mt19937 rng(9);
    std::normal_distribution<double> normal;
    Eigen::VectorXd step(p.num_parameters);
    for (int k = 0; k < step.size(); ++k) step(k) = 1e-3 * normal(rng);
    ApplyUpdate(p, step, &model);
  }
};

void ExpectSame(const internal::NormalEquations& vec, const internal::NormalEquations& ref,
                double tolerance) {
  ASSERT_TRUE(vec.finite && ref.finite);
  EXPECT_LE(RelativeDifference(vec.H, ref.H), tolerance);
  EXPECT_LE(RelativeDifference(vec.g, ref.g), tolerance);
  EXPECT_NEAR(vec.cost, ref.cost, tolerance * ref.cost);
  EXPECT_NEAR(vec.max_error, ref.max_error, tolerance * ref.max_error);
  EXPECT_NEAR(vec.mean_error, ref.mean_error, tolerance * ref.mean_error);
}

// PositionRows4 and SyrkLowerAvx2 (the geometric normal equations four rows at a time) against the
// reference rows (BasisJacobian one row at a time, Eigen's rank update). 1003 rows: a tail of 3.
TEST(Kernels, GeometricNormalEquationsBothWays) {
  LPOE_REQUIRE_AVX2();
  const Data d(1003);
  const Parameterization p = MakeParameterization(d.nominal, ParameterizationKind::kIdentifiable,
                                                  DataKind::kPosition);
  auto run = [&] {
    return internal::NormalEquationsOf(d.model, d.data, p, Eigen::VectorXd(), false, 1.0, false);
  };
  const internal::NormalEquations vec = With(kernels::Path::kAvx2Fma, run);
  const internal::NormalEquations ref = With(kernels::Path::kReference, run);
  EXPECT_TRUE(vec.four_rows);
  EXPECT_FALSE(ref.four_rows);
  ExpectSame(vec, ref, 1e-11);
}

// PositionRows4 with J_q, PoseProducts4 and DotProductsAvx2 (the joint-space slots' blocks) against
// the reference (slot columns row by row, Eigen's products), with the joint state away from zero.
TEST(Kernels, JointSpaceNormalEquationsBothWays) {
  LPOE_REQUIRE_AVX2();
  const Data d(1003);
  Parameterization p = MakeParameterization(d.nominal, ParameterizationKind::kIdentifiable,
                                            DataKind::kPosition);
  for (const char* name : {"compliance", "harmonics"}) {
    std::shared_ptr<const JointTerm> t;
    ASSERT_TRUE(MakeJointTerm(name, d.nominal, &t).ok());
    AddJointBlock(t, &p);
  }
  const int K = p.num_joint_parameters();
  Eigen::VectorXd state(K);
  std::mt19937 rng(7);
  std::normal_distribution<double> normal;
  for (int k = 0; k < K; ++k) state(k) = 1e-4 * normal(rng);
  for (const bool gradient_only : {false, true}) {
    SCOPED_TRACE(gradient_only ? "gradient only" : "with joint blocks");
    internal::JointColumnsOptions options;
    options.gradient_only = gradient_only;
    auto run = [&] {
      return internal::NormalEquationsOf(d.model, d.data, p, state, false, 1.0, false, nullptr,
                                         nullptr, options);
    };
    const internal::NormalEquations vec = With(kernels::Path::kAvx2Fma, run);
    const internal::NormalEquations ref = With(kernels::Path::kReference, run);
    EXPECT_TRUE(vec.four_rows);
    EXPECT_FALSE(ref.four_rows);
    ExpectSame(vec, ref, 1e-9);
  }
}


// ExpAvx2: within 4 ulp of std::exp (the reference path) over the kernel's arguments (-d^2/2 and a
// log signal) and beyond, tails of 1-3, and 0 below -708 where std::exp gives at most a subnormal.
TEST(Kernels, ExpBothWays) {
  LPOE_REQUIRE_AVX2();
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> kernel(-60.0, 5.0), wide(-720.0, 709.0);
  std::vector<double> x;
  for (int k = 0; k < 20000; ++k) x.push_back(kernel(rng));
  for (int k = 0; k < 5000; ++k) x.push_back(wide(rng));
  for (double v : {0.0, -0.0, 1e-300, -1e-300, 1.0, -1.0, 0.5 * 0.6931471805599453, -707.9, 708.9,
                   -709.0, -745.0, -1e300}) {
    x.push_back(v);
  }
  if (x.size() % 4 == 0) x.push_back(-2.5);  // a padded tail
  const int count = static_cast<int>(x.size());
  std::vector<double> vec = x;
  kernels::ExpAvx2(vec.data(), count);
  for (int k = 0; k < count; ++k) {
    const double ref = std::exp(x[k]);
    if (x[k] < -708.0) {
      ASSERT_EQ(vec[k], 0.0) << x[k];
      ASSERT_LT(ref, 1e-307) << x[k];
      continue;
    }
    const double ulp = std::nextafter(ref, HUGE_VAL) - ref;
    ASSERT_LE(std::abs(vec[k] - ref), 4 * ulp) << "exp " << x[k];
  }
}

// The residual layer's kernel vector, the kernel's caller, is the same both ways.
TEST(Kernels, ResidualLayerKernelVectorBothWays) {
  LPOE_REQUIRE_AVX2();
  std::mt19937_64 rng(6);
  std::uniform_real_distribution<double> joint(-3.0, 3.0);
  ResidualLayer layer;
  layer.num_joints = 6;
  layer.num_tools = 2;
  layer.length_scales = Eigen::VectorXd::Constant(6, 0.8);
  layer.tool_correlation = 0.7;
  layer.signal_std = 0.02;
  layer.noise_std = 0.005;
  const int m = 37;  // not a multiple of four
  layer.inducing_q.resize(m, 6);
  for (int i = 0; i < m; ++i) {
    for (int j = 0; j < 6; ++j) layer.inducing_q(i, j) = joint(rng);
    layer.inducing_tool.push_back(i % 2);
  }
  for (int trial = 0; trial < 200; ++trial) {
    double q[6];
    for (double& v : q) v = joint(rng);
    Eigen::VectorXd k_ref, k_vec;
    With(kernels::Path::kReference, [&] {
      layer.KernelVector(q, trial % 2, &k_ref);
      return 0;
    });
    With(kernels::Path::kAvx2Fma, [&] {
      layer.KernelVector(q, trial % 2, &k_vec);
      return 0;
    });
    ASSERT_EQ(k_ref.size(), m);
    ASSERT_LE((k_vec - k_ref).cwiseAbs().maxCoeff(), 1e-15 * k_ref.cwiseAbs().maxCoeff() + 1e-300);
  }
}

}  // namespace
}  // namespace lpoe
