// The vector kernels (lpoe/kinematics/kernels.h, core/src/kernels/: hand-written ones and the adapters to
// SLEEF) run both ways: every kernel's result on the AVX2/FMA path equals the reference path's
// (plain C++, Eigen, libm) to a tolerance, on data of realistic magnitudes and at the edges. The
// reference path is forced with kernels::SetForTesting, so it runs here even on an AVX2 machine;
// the test is registered a second time with LPOE_KERNELS=reference (tests/CMakeLists.txt), where
// the switch itself is checked (KernelsSwitch).
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <memory>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "lpoe/terms/joint_errors.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/kinematics/kernels.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/model/parameterization.h"
#include "lpoe/model/residual_layer.h"
#include "lpoe/model/simulation.h"
#include "linearization/normal_equations.h"

namespace lpoe {
namespace {
namespace kernels_test {

// Position rows, with the given joint-block options.
internal::NormalEquationsOptions PositionRows(const internal::JointColumnsOptions& joint = {}) {
  internal::NormalEquationsOptions o;
  o.joint = joint;
  return o;
}

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

// Units in the last place of `got` from `want` (the spacing of doubles at |want|; the smallest
// subnormal for 0); NaN against NaN is 0, NaN against a number infinite.
double Ulps(double got, long double want) {
  if (std::isnan(got) || std::isnan(want)) {
    return std::isnan(got) && std::isnan(want) ? 0.0 : HUGE_VAL;
  }
  const double w = std::abs(static_cast<double>(want));
  const double ulp =
      std::max(std::nextafter(w, HUGE_VAL) - w, std::numeric_limits<double>::denorm_min());
  return static_cast<double>(std::abs(static_cast<long double>(got) - want) / ulp);
}

// The vector kernels are SLEEF's "u10" functions, documented within 1.0 ulp of the exact value;
// glibc's sin, cos and exp (the reference paths) are within 1 ulp too (its manual's table for
// x86-64), so the two paths differ by at most 2 ulp. The exact value: long double (64-bit
// significand) sinl, cosl, expl, whose own error (about 2^-11 ulp of a double) is far below these
// bounds.
constexpr double kSleefU10Ulps = 1.0;
constexpr double kPathsUlps = 2.0;

// SinCosMany both ways: joint values, multiples of pi/2 (where the reduction cancels), values up to
// 6e5 rad and beyond (SLEEF reduces every double), tails of 1-3.
TEST(Kernels, SinCosManyBothWays) {
  LPOE_REQUIRE_AVX2();
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> joint(-6.5, 6.5), wide(-6e5, 6e5), huge(-1e15, 1e15);
  std::vector<double> x;
  for (int k = 0; k < 20000; ++k) x.push_back(joint(rng));
  for (int k = 0; k < 2000; ++k) x.push_back(wide(rng));
  for (int k = 0; k < 500; ++k) x.push_back(huge(rng));
  for (int k = -40; k <= 40; ++k) x.push_back(k * 1.5707963267948966);  // multiples of pi/2
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
  double worst_exact = 0, worst_paths = 0;
  for (int k = 0; k < count; ++k) {
    const long double s_exact = std::sin(static_cast<long double>(x[k]));
    const long double c_exact = std::cos(static_cast<long double>(x[k]));
    ASSERT_LE(Ulps(s_vec[k], s_exact), kSleefU10Ulps) << "sin " << x[k];
    ASSERT_LE(Ulps(c_vec[k], c_exact), kSleefU10Ulps) << "cos " << x[k];
    ASSERT_LE(Ulps(s_vec[k], s_ref[k]), kPathsUlps) << "sin " << x[k];
    ASSERT_LE(Ulps(c_vec[k], c_ref[k]), kPathsUlps) << "cos " << x[k];
    worst_exact = std::max({worst_exact, Ulps(s_vec[k], s_exact), Ulps(c_vec[k], c_exact)});
    worst_paths = std::max({worst_paths, Ulps(s_vec[k], s_ref[k]), Ulps(c_vec[k], c_ref[k])});
  }
  // The vector path is not libm itself (else this test compared nothing).
  int differ = 0;
  for (int k = 0; k < count; ++k) differ += s_vec[k] != s_ref[k] || c_vec[k] != c_ref[k];
  EXPECT_GT(differ, 0);
  RecordProperty("worst_ulps_from_exact", std::to_string(worst_exact));
  RecordProperty("worst_ulps_between_paths", std::to_string(worst_paths));
}

// The edges, both ways: signed zeros, subnormal and huge arguments (up to the largest double),
// NaN and infinities for sin and cos; for exp the overflow to +inf and the underflow (0 below -708
// on the vector path, where std::exp gives at most 3.3e-308, subnormal below -708.4).
TEST(Kernels, EdgesBothWays) {
  LPOE_REQUIRE_AVX2();
  const double inf = std::numeric_limits<double>::infinity();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double max = std::numeric_limits<double>::max();
  const double tiny = std::numeric_limits<double>::denorm_min();
  const std::vector<double> x = {0.0,  -0.0,  tiny,  -tiny,  1e-300, 524288.0, -524289.0, 1e10,
                                 1e15, -1e22, 1e300, -1e300, max,    -max,     inf,       -inf,
                                 nan,  -nan,  0.5,   -2.0,   3.0};  // 21: a padded tail
  const int count = static_cast<int>(x.size());
  std::vector<double> s_ref(count), c_ref(count), s_vec(count), c_vec(count);
  With(kernels::Path::kReference, [&] {
    SinCosMany(x.data(), count, s_ref.data(), c_ref.data());
    return 0;
  });
  With(kernels::Path::kAvx2Fma, [&] {
    SinCosMany(x.data(), count, s_vec.data(), c_vec.data());
    return 0;
  });
  for (int k = 0; k < count; ++k) {
    if (!std::isfinite(x[k])) {  // NaN both ways
      EXPECT_TRUE(std::isnan(s_vec[k]) && std::isnan(c_vec[k])) << x[k];
      EXPECT_TRUE(std::isnan(s_ref[k]) && std::isnan(c_ref[k])) << x[k];
      continue;
    }
    const long double s_exact = std::sin(static_cast<long double>(x[k]));
    const long double c_exact = std::cos(static_cast<long double>(x[k]));
    EXPECT_LE(Ulps(s_vec[k], s_exact), kSleefU10Ulps) << "sin " << x[k];
    EXPECT_LE(Ulps(c_vec[k], c_exact), kSleefU10Ulps) << "cos " << x[k];
    EXPECT_LE(Ulps(s_vec[k], s_ref[k]), kPathsUlps) << "sin " << x[k];
    EXPECT_LE(Ulps(c_vec[k], c_ref[k]), kPathsUlps) << "cos " << x[k];
  }
  // sin keeps the sign of zero and returns tiny arguments themselves; cos of them is 1.
  for (int k : {0, 1, 2, 3}) {
    EXPECT_EQ(s_vec[k], x[k]);
    EXPECT_EQ(std::signbit(s_vec[k]), std::signbit(x[k])) << x[k];
    EXPECT_EQ(c_vec[k], 1.0);
  }

  // exp: the kernel's own entry point against std::exp and expl.
  const std::vector<double> e = {0.0,    -0.0,   1.0,    -1.0,         709.78, 709.79, 710.0,
                                 1e300,  inf,    -707.9, -708.0,       -708.5, -720.0, -745.1,
                                 -746.0, -1e300, -inf,   -708.0000001, nan,    -60.0,  -0.5};
  std::vector<double> v = e;
  kernels::ExpAvx2(v.data(), static_cast<int>(v.size()));
  for (size_t k = 0; k < e.size(); ++k) {
    const double ref = std::exp(e[k]);
    if (std::isnan(e[k])) {
      EXPECT_TRUE(std::isnan(v[k])) << "exp(NaN) = " << v[k];
    } else if (e[k] < -708.0) {  // 0, where std::exp gives at most exp(-708)
      EXPECT_EQ(v[k], 0.0) << e[k];
      EXPECT_FALSE(std::signbit(v[k])) << e[k];
      EXPECT_LT(ref, std::exp(-708.0)) << e[k];
    } else if (e[k] > 709.7828) {  // above log(DBL_MAX)
      EXPECT_EQ(v[k], inf) << e[k];
      EXPECT_EQ(ref, inf) << e[k];
    } else {
      EXPECT_LE(Ulps(v[k], std::exp(static_cast<long double>(e[k]))), kSleefU10Ulps) << e[k];
      EXPECT_LE(Ulps(v[k], ref), kPathsUlps) << e[k];
      EXPECT_TRUE(std::isfinite(v[k]) && v[k] > 0) << e[k];
    }
  }
  EXPECT_EQ(v[0], 1.0);
  EXPECT_EQ(v[1], 1.0);
  EXPECT_GT(v[4], 1.79e308);  // exp(709.78): the largest finite results stay finite
  EXPECT_GT(v[10], 3.3e-308);  // exp(-708.0) itself is not flushed
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
    return internal::NormalEquationsOf(d.model, d.data, p, Eigen::VectorXd(), PositionRows());
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
      return internal::NormalEquationsOf(d.model, d.data, p, state, PositionRows(options));
    };
    const internal::NormalEquations vec = With(kernels::Path::kAvx2Fma, run);
    const internal::NormalEquations ref = With(kernels::Path::kReference, run);
    EXPECT_TRUE(vec.four_rows);
    EXPECT_FALSE(ref.four_rows);
    ExpectSame(vec, ref, 1e-9);
  }
}


// ExpAvx2 against std::exp (the reference path) and the exact value over the kernel's arguments
// (-d^2/2 and a log signal) and beyond, tails of 1-3, and 0 below -708 where std::exp gives at most
// 3.3e-308.
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
  double worst_exact = 0;
  int differ = 0;
  for (int k = 0; k < count; ++k) {
    const double ref = std::exp(x[k]);
    if (x[k] < -708.0) {
      ASSERT_EQ(vec[k], 0.0) << x[k];
      ASSERT_LT(ref, std::exp(-708.0)) << x[k];
      continue;
    }
    const double exact = Ulps(vec[k], std::exp(static_cast<long double>(x[k])));
    ASSERT_LE(exact, kSleefU10Ulps) << "exp " << x[k];
    ASSERT_LE(Ulps(vec[k], ref), kPathsUlps) << "exp " << x[k];
    worst_exact = std::max(worst_exact, exact);
    differ += vec[k] != ref;
  }
  EXPECT_GT(differ, 0);  // not std::exp itself
  RecordProperty("worst_ulps_from_exact", std::to_string(worst_exact));
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

}  // namespace kernels_test
}  // namespace
}  // namespace lpoe
