// Tests of the error statistics (statistics.h): the one-pass, 16-bytes-a-row statistics of large data
// sets against a direct recomputation from the stored double errors, and the percentile selection
// against nth_element, and its two ways against each other and a sort.
#include "lpoe/model/statistics.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "lpoe/parallel.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/model/simulation.h"

namespace lpoe {
namespace {
namespace statistics_test {

// Enough rows for several chunks on several threads (parallel.h: 20,000 rows and more).
constexpr int kRows = 50000;
// Max, mean and RMS: exact double sums in another order and another forward-kinematics pass.
constexpr double kMomentTolerance = 1e-12;
// Percentiles: of the errors rounded to float (relative 6e-8).
constexpr double kPercentileTolerance = 1e-7;

MeasurementSet Data(uint64_t seed) {
  SimulationOptions o;
  o.count = kRows;
  o.noise_sigma = 0.03;
  o.seed = seed;
  const RobotModel actual = ApplyErrors(MakeCobot6(), PaperTable2Errors());
  return SimulateMeasurements(actual, PaperTable2Errors().joint_zero, o);
}

void ExpectAxisNear(const AxisStatistics& got, const AxisStatistics& want, const char* what) {
  SCOPED_TRACE(what);
  EXPECT_NEAR(got.max_abs, want.max_abs, kMomentTolerance * want.max_abs);
  EXPECT_NEAR(got.mean_abs, want.mean_abs, kMomentTolerance * want.mean_abs);
  EXPECT_NEAR(got.rms, want.rms, kMomentTolerance * want.rms);
  EXPECT_NEAR(got.p95_abs, want.p95_abs, kPercentileTolerance * want.p95_abs);
}

TEST(Statistics, OnePassStatisticsEqualADirectRecomputation) {
  const RobotModel nominal = MakeCobot6();
  const MeasurementSet data = Data(3);
  const ErrorStatistics direct = ComputeStatistics(PositionErrors(nominal, data));
  for (int threads : {1, 2, 3}) {
    ThreadCountOverride() = threads;
    const ErrorStatistics s = PositionErrorStatistics(nominal, data);
    EXPECT_EQ(s.count, kRows);
    ExpectAxisNear(s.axis[0], direct.axis[0], "x");
    ExpectAxisNear(s.axis[1], direct.axis[1], "y");
    ExpectAxisNear(s.axis[2], direct.axis[2], "z");
    ExpectAxisNear(s.norm, direct.norm, "norm");
  }
  ThreadCountOverride() = 0;
}

// The norm's moments at other joint values than the data's (a model with joint-space terms at its
// effective joint values): those of a direct recomputation on a copy of the data with those values.
TEST(Statistics, NormMomentsAtGivenJointValuesEqualADirectRecomputation) {
  const RobotModel nominal = MakeCobot6();
  const MeasurementSet data = Data(4);
  MeasurementSet shifted = data;
  std::vector<double> q(data.q(0), data.q(0) + static_cast<size_t>(data.size()) * 6);
  for (size_t i = 0; i < q.size(); ++i) q[i] += 1e-3 * std::sin(0.7 * static_cast<double>(i));
  for (int r = 0; r < data.size(); ++r) std::copy_n(q.data() + 6 * r, 6, shifted.mutable_q(r));
  const AxisStatistics direct = ComputeStatistics(PositionErrors(nominal, shifted)).norm;
  const AxisStatistics unshifted = ComputeStatistics(PositionErrors(nominal, data)).norm;
  ASSERT_GT(std::abs(direct.mean_abs - unshifted.mean_abs), 1e-6 * direct.mean_abs);
  for (int threads : {1, 2}) {
    ThreadCountOverride() = threads;
    const AxisStatistics got = PositionErrorNormMoments(nominal, data, q.data());
    EXPECT_NEAR(got.max_abs, direct.max_abs, kMomentTolerance * direct.max_abs);
    EXPECT_NEAR(got.mean_abs, direct.mean_abs, kMomentTolerance * direct.mean_abs);
    EXPECT_NEAR(got.rms, direct.rms, kMomentTolerance * direct.rms);
    EXPECT_EQ(got.p95_abs, 0.0);  // no percentile pass
  }
  ThreadCountOverride() = 0;
}

TEST(Statistics, CollectedErrorsDoNotDependOnTheThreadCount) {
  const RobotModel nominal = MakeCobot6();
  const MeasurementSet data = Data(4);
  ThreadCountOverride() = 1;
  PositionErrorRows one;
  CollectPositionErrors(nominal, data, &one);
  const ErrorStatistics a = one.Statistics();
  for (int threads : {2, 3}) {
    ThreadCountOverride() = threads;
    PositionErrorRows many;
    CollectPositionErrors(nominal, data, &many);
    const ErrorStatistics b = many.Statistics();
    for (int axis = 0; axis < 3; ++axis) {
      EXPECT_EQ(a.axis[axis].mean_abs, b.axis[axis].mean_abs);
      EXPECT_EQ(a.axis[axis].rms, b.axis[axis].rms);
      EXPECT_EQ(a.axis[axis].p95_abs, b.axis[axis].p95_abs);
    }
    EXPECT_EQ(a.norm.max_abs, b.norm.max_abs);
    EXPECT_EQ(one.MedianAbsComponent(), many.MedianAbsComponent());
    for (int r = 0; r < kRows; r += 997) EXPECT_EQ(one.norm(r), many.norm(r));
  }
  ThreadCountOverride() = 0;
}

// The percentile and median selection (two counting passes, nothing reordered) finds the element
// nth_element finds, and leaves the rows in order.
TEST(Statistics, SelectionIsNthElement) {
  const RobotModel nominal = MakeCobot6();
  const MeasurementSet data = Data(5);
  PositionErrorRows rows;
  CollectPositionErrors(nominal, data, &rows);
  const std::vector<Eigen::Vector3d> e = PositionErrors(nominal, data);
  std::vector<float> comps, norms;
  for (const Eigen::Vector3d& v : e) {
    for (int a = 0; a < 3; ++a) comps.push_back(static_cast<float>(std::abs(v(a))));
    norms.push_back(static_cast<float>(v.norm()));
  }
  std::vector<float> sorted = comps;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  EXPECT_NEAR(rows.MedianAbsComponent(), sorted[sorted.size() / 2],
              kPercentileTolerance * sorted[sorted.size() / 2]);
  const size_t k = static_cast<size_t>(std::ceil(0.95 * kRows)) - 1;
  sorted = norms;
  std::nth_element(sorted.begin(), sorted.begin() + k, sorted.end());
  EXPECT_NEAR(rows.Statistics().norm.p95_abs, sorted[k], kPercentileTolerance * sorted[k]);
  for (int r = 0; r < kRows; r += 101) {
    EXPECT_NEAR(rows.norm(r), norms[r], kPercentileTolerance * norms[r]) << "row " << r;
  }
}

// The two ways of selecting (counting passes from kKthSmallestByCounting values on, a selection on
// the bit patterns below) give the same value for every k tried, on values with repeats, zeros,
// infinity and NaN (which counts as the largest), on either side of the switch, and that value is
// the k-th of the values sorted (NaN last).
TEST(Statistics, BothSelectionsAgreeWithSorting) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> uniform(0.0f, 2.0f);
  const size_t at = internal::kKthSmallestByCounting;
  for (const size_t n : {size_t{1}, size_t{2}, size_t{7}, size_t{1000}, at - 1, at, at + 5}) {
    std::vector<float> v(n);
    for (size_t i = 0; i < n; ++i) {
      const unsigned kind = rng() % 20;
      v[i] = kind == 0   ? 0.0f
             : kind == 1 ? std::numeric_limits<float>::infinity()
             : kind == 2 ? std::numeric_limits<float>::quiet_NaN()
             : kind < 6  ? 0.25f  // repeats
                         : uniform(rng);
    }
    std::vector<float> sorted = v;
    std::sort(sorted.begin(), sorted.end(), [](float a, float b) {
      return std::isnan(b) ? !std::isnan(a) : (!std::isnan(a) && a < b);
    });
    const std::vector<float> before = v;
    for (const size_t k : {size_t{0}, n / 2, n - 1, (n * 95) / 100, n / 3}) {
      const float counting = internal::KthSmallestNonNegativeByCounting(v.data(), n, k);
      const float selection = internal::KthSmallestNonNegativeBySelection(v.data(), n, k);
      const float used = internal::KthSmallestNonNegative(v.data(), n, k);
      const auto same = [](float a, float b) { return (std::isnan(a) && std::isnan(b)) || a == b; };
      EXPECT_TRUE(same(counting, selection)) << "n " << n << " k " << k << ": " << counting
                                             << " against " << selection;
      EXPECT_TRUE(same(used, sorted[k])) << "n " << n << " k " << k << ": " << used << " against "
                                         << sorted[k];
    }
    EXPECT_EQ(std::memcmp(v.data(), before.data(), n * sizeof(float)), 0);  // v not reordered
  }
}

}  // namespace statistics_test
}  // namespace
}  // namespace lpoe
