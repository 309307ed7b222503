#include "lpoe/statistics.h"

#include <algorithm>
#include <cmath>

#include "lpoe/kinematics.h"

namespace lpoe {
namespace {

AxisStatistics Summarize(std::vector<double> abs_values) {
  AxisStatistics s;
  if (abs_values.empty()) return s;
  double sum = 0, sum_sq = 0;
  for (double v : abs_values) {
    s.max_abs = std::max(s.max_abs, v);
    sum += v;
    sum_sq += v * v;
  }
  const double n = static_cast<double>(abs_values.size());
  s.mean_abs = sum / n;
  s.rms = std::sqrt(sum_sq / n);
  // Nearest-rank 95th percentile.
  const size_t rank = static_cast<size_t>(std::ceil(0.95 * n));
  const size_t k = rank == 0 ? 0 : rank - 1;
  std::nth_element(abs_values.begin(), abs_values.begin() + k, abs_values.end());
  s.p95_abs = abs_values[k];
  return s;
}

}  // namespace

ErrorStatistics ComputeStatistics(const std::vector<Eigen::Vector3d>& errors) {
  ErrorStatistics out;
  out.count = static_cast<int>(errors.size());
  std::vector<double> values(errors.size());
  for (int a = 0; a < 3; ++a) {
    for (size_t k = 0; k < errors.size(); ++k) values[k] = std::abs(errors[k](a));
    out.axis[a] = Summarize(values);
  }
  for (size_t k = 0; k < errors.size(); ++k) values[k] = errors[k].norm();
  out.norm = Summarize(std::move(values));
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
  return ComputeStatistics(PositionErrors(model, data));
}

}  // namespace lpoe
