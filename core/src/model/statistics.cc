#include "lpoe/model/statistics.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>

#include "lpoe/kinematics/kinematics.h"
#include "lpoe/parallel.h"

namespace lpoe {
namespace {

uint32_t Bits(float f) {
  uint32_t b;
  std::memcpy(&b, &f, sizeof(b));
  return b;
}

float FromBits(uint32_t b) {
  float f;
  std::memcpy(&f, &b, sizeof(f));
  return f;
}

// The bit patterns of non-negative floats order like their values, so two counting passes over
// the high and the low 16 bits find the k-th smallest exactly.
template <typename Count>
float KthSmallestByCounting(const float* v, size_t n, size_t k) {
  std::vector<Count> count(size_t{1} << 16, 0);
  for (size_t i = 0; i < n; ++i) ++count[Bits(v[i]) >> 16];
  uint32_t high = 0;
  for (; k >= count[high]; ++high) k -= count[high];
  std::fill(count.begin(), count.end(), Count(0));
  for (size_t i = 0; i < n; ++i) {
    const uint32_t b = Bits(v[i]);
    if ((b >> 16) == high) ++count[b & 0xFFFFu];
  }
  uint32_t low = 0;
  for (; k >= count[low]; ++low) k -= count[low];
  return FromBits((high << 16) | low);
}

}  // namespace

namespace internal {

float KthSmallestNonNegativeByCounting(const float* v, size_t n, size_t k) {
  return n <= UINT32_MAX ? KthSmallestByCounting<uint32_t>(v, n, k)
                         : KthSmallestByCounting<uint64_t>(v, n, k);
}

float KthSmallestNonNegativeBySelection(const float* v, size_t n, size_t k) {
  std::vector<uint32_t> bits(n);
  for (size_t i = 0; i < n; ++i) bits[i] = Bits(v[i]);
  std::nth_element(bits.begin(), bits.begin() + static_cast<std::ptrdiff_t>(k), bits.end());
  return FromBits(bits[k]);
}

float KthSmallestNonNegative(const float* v, size_t n, size_t k) {
  return n < kKthSmallestByCounting ? KthSmallestNonNegativeBySelection(v, n, k)
                                    : KthSmallestNonNegativeByCounting(v, n, k);
}

}  // namespace internal

namespace {

using internal::KthSmallestNonNegative;

// Index of the nearest-rank 95th percentile among n values.
size_t P95Index(size_t n) {
  const size_t rank = static_cast<size_t>(std::ceil(0.95 * static_cast<double>(n)));
  return rank == 0 ? 0 : rank - 1;
}

// Nearest-rank 95th percentile of `values` (reordered).
template <typename T>
double P95(std::vector<T>* values) {
  const size_t k = P95Index(values->size());
  std::nth_element(values->begin(), values->begin() + k, values->end());
  return static_cast<double>((*values)[k]);
}

// Max, mean and RMS of absolute values, accumulated one value at a time.
struct Moments {
  double max = 0, sum = 0, sum_sq = 0;
  void Add(double v) {
    max = std::max(max, v);
    sum += v;
    sum_sq += v * v;
  }
  void Add(const Moments& m) {
    max = std::max(max, m.max);
    sum += m.sum;
    sum_sq += m.sum_sq;
  }
  AxisStatistics Finish(size_t n) const {
    AxisStatistics s;
    s.max_abs = max;
    s.mean_abs = sum / static_cast<double>(n);
    s.rms = std::sqrt(sum_sq / static_cast<double>(n));
    return s;
  }
};

// `abs_values` is reordered.
AxisStatistics Summarize(std::vector<double>* abs_values) {
  if (abs_values->empty()) return AxisStatistics();
  Moments m;
  for (double v : *abs_values) m.Add(v);
  AxisStatistics s = m.Finish(abs_values->size());
  s.p95_abs = P95(abs_values);
  return s;
}

}  // namespace

ErrorStatistics ComputeStatistics(const std::vector<Eigen::Vector3d>& errors) {
  ErrorStatistics out;
  out.count = static_cast<int>(errors.size());
  std::vector<double> values(errors.size());
  for (int a = 0; a < 3; ++a) {
    for (size_t k = 0; k < errors.size(); ++k) values[k] = std::abs(errors[k](a));
    out.axis[a] = Summarize(&values);
  }
  for (size_t k = 0; k < errors.size(); ++k) values[k] = errors[k].norm();
  out.norm = Summarize(&values);
  return out;
}

std::vector<Eigen::Vector3d> PositionErrors(const RobotModel& model, const MeasurementSet& data) {
  std::vector<Eigen::Vector3d> errors(data.size());
  for (int r = 0; r < data.size(); ++r) {
    errors[r] = data.position(r) - ToolPosition(model, data.q(r), data.target(r));
  }
  return errors;
}

void PositionErrorRows::Reset(int rows, int chunks) {
  rows_ = rows;
  values_.resize(4 * static_cast<size_t>(rows));
  moments_.assign(chunks, ChunkMoments());
}

void PositionErrorRows::Clear() {
  rows_ = 0;
  std::vector<float>().swap(values_);
  std::vector<ChunkMoments>().swap(moments_);
}

ErrorStatistics PositionErrorRows::Statistics() const {
  ErrorStatistics out;
  const size_t n = static_cast<size_t>(rows_);
  out.count = rows_;
  if (n == 0) return out;
  Moments total[4];
  for (const ChunkMoments& m : moments_) {
    for (int a = 0; a < 4; ++a) {
      Moments c;
      c.max = m.max[a];
      c.sum = m.sum[a];
      c.sum_sq = m.sum_sq[a];
      total[a].Add(c);
    }
  }
  const int threads = n < 20000 ? 1 : std::min(4, ThreadsFor(4));
  ForEachTask(4, threads, [&](int a, int) {
    AxisStatistics& s = a < 3 ? out.axis[a] : out.norm;
    s = total[a].Finish(n);
    s.p95_abs = KthSmallestNonNegative(values_.data() + a * n, n, P95Index(n));
  });
  return out;
}

AxisStatistics PositionErrorRows::NormMoments() const {
  if (rows_ == 0) return AxisStatistics();
  Moments total;
  for (const ChunkMoments& m : moments_) {
    Moments c;
    c.max = m.max[3];
    c.sum = m.sum[3];
    c.sum_sq = m.sum_sq[3];
    total.Add(c);
  }
  return total.Finish(static_cast<size_t>(rows_));
}

double PositionErrorRows::MedianAbsComponent() const {
  const size_t m = 3 * static_cast<size_t>(rows_);
  if (m == 0) return 0;
  // The element nth_element puts at m / 2 (the upper median for an even count).
  return KthSmallestNonNegative(values_.data(), m, m / 2);
}

namespace {

// CollectPositionErrors at the joint values q (rows x joints, row-major).
void CollectPositionErrorsAt(const RobotModel& model, const MeasurementSet& data, const double* q,
                             PositionErrorRows* rows) {
  // One forward-kinematics pass in fixed chunks on the hardware's threads (parallel.h); sin and cos
  // of a block of rows at once (SinCosMany).
  constexpr int kBlockRows = 64;
  const int n = data.size();
  const RowChunks chunks = KinematicsRowChunks(n);
  rows->Reset(n, chunks.chunks);
  if (n == 0) return;
  const KinematicChain chain(model);
  const int joints = data.num_joints();
  const int threads = KinematicsThreads(chunks);
  std::vector<std::vector<double>> sin_q(threads), cos_q(threads);
  ForEachTask(chunks.chunks, threads, [&](int c, int thread) {
    std::vector<double>& s = sin_q[thread];
    std::vector<double>& co = cos_q[thread];
    s.resize(static_cast<size_t>(kBlockRows) * joints);
    co.resize(s.size());
    for (int r0 = chunks.begin(c); r0 < chunks.end(c); r0 += kBlockRows) {
      const int count = std::min(kBlockRows, chunks.end(c) - r0);
      SinCosMany(q + static_cast<size_t>(r0) * joints, count * joints, s.data(), co.data());
      for (int k = 0; k < count; ++k) {
        const int r = r0 + k;
        const size_t at = static_cast<size_t>(k) * joints;
        const double* q_r = q + static_cast<size_t>(r) * joints;
        rows->Record(c, r,
                     data.position(r) -
                         chain.Position(q_r, s.data() + at, co.data() + at, data.target(r)));
      }
    }
  });
}

}  // namespace

void CollectPositionErrors(const RobotModel& model, const MeasurementSet& data,
                           PositionErrorRows* rows) {
  CollectPositionErrorsAt(model, data, data.size() > 0 ? data.q(0) : nullptr, rows);
}

ErrorStatistics PositionErrorStatistics(const RobotModel& model, const MeasurementSet& data) {
  // One forward-kinematics pass. Max, mean and RMS are exact (double sums); the 95th percentiles
  // come from the absolute errors rounded to float (relative 6e-8, far below any reported digit),
  // which keeps the memory at 16 bytes a row: 10^7 rows must fit in 1 GB with their data.
  PositionErrorRows rows;
  CollectPositionErrors(model, data, &rows);
  return rows.Statistics();
}

AxisStatistics PositionErrorNormMoments(const RobotModel& model, const MeasurementSet& data,
                                        const double* q) {
  PositionErrorRows rows;
  CollectPositionErrorsAt(model, data, q, &rows);
  return rows.NormMoments();
}

}  // namespace lpoe
