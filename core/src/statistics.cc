#include "lpoe/statistics.h"

#include <algorithm>
#include <array>
#include <cmath>

#include "lpoe/kinematics.h"
#include "lpoe/parallel.h"

namespace lpoe {
namespace {

// Nearest-rank 95th percentile of `values` (reordered).
template <typename T>
double P95(std::vector<T>* values) {
  const size_t rank = static_cast<size_t>(std::ceil(0.95 * static_cast<double>(values->size())));
  const size_t k = rank == 0 ? 0 : rank - 1;
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

ErrorStatistics PositionErrorStatistics(const RobotModel& model, const MeasurementSet& data) {
  // One forward-kinematics pass. Max, mean and RMS are exact (double sums); the 95th percentiles
  // come from the absolute errors rounded to float (relative 6e-8, far below any reported digit),
  // which keeps the memory at 16 bytes a row: 10^7 rows must fit in 1 GB with their data. The rows
  // run in fixed chunks on the hardware's threads (parallel.h), their sums added in chunk order.
  ErrorStatistics out;
  const int n = data.size();
  out.count = n;
  if (n == 0) return out;
  std::vector<float> values[4];
  for (auto& v : values) v.resize(n);
  const RowChunks chunks = KinematicsRowChunks(n);
  std::vector<std::array<Moments, 4>> chunk_moments(chunks.chunks);
  const int threads = KinematicsThreads(chunks);
  ForEachTask(chunks.chunks, threads, [&](int c, int) {
    std::array<Moments, 4>& moments = chunk_moments[c];
    for (int r = chunks.begin(c); r < chunks.end(c); ++r) {
      const Eigen::Vector3d e = data.position(r) - ToolPosition(model, data.q(r), data.target(r));
      for (int a = 0; a < 3; ++a) {
        moments[a].Add(std::abs(e(a)));
        values[a][r] = static_cast<float>(std::abs(e(a)));
      }
      moments[3].Add(e.norm());
      values[3][r] = static_cast<float>(e.norm());
    }
  });
  Moments moments[4];
  for (const auto& m : chunk_moments) {
    for (int a = 0; a < 4; ++a) moments[a].Add(m[a]);
  }
  ForEachTask(4, std::min(threads, 4), [&](int a, int) {
    AxisStatistics& s = a < 3 ? out.axis[a] : out.norm;
    s = moments[a].Finish(n);
    s.p95_abs = P95(&values[a]);
    std::vector<float>().swap(values[a]);
  });
  return out;
}

}  // namespace lpoe
