// Error statistics of predicted versus measured positions, per axis and for the norm.
#ifndef LPOE_STATISTICS_H_
#define LPOE_STATISTICS_H_

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "lpoe/measurements/measurements.h"
#include "lpoe/model/robot_model.h"

namespace lpoe {

struct AxisStatistics {
  double max_abs = 0;   // mm
  double mean_abs = 0;  // mm
  double rms = 0;       // mm
  double p95_abs = 0;   // mm, 95th percentile of |error|
};

struct ErrorStatistics {
  int count = 0;
  AxisStatistics axis[3];  // x, y, z
  AxisStatistics norm;     // Euclidean distance
};

// Position errors of one model on one data set as a pass over the rows collects them, so that the
// statistics and the outlier search need no forward-kinematics pass of their own when another pass
// computes the errors anyway (the linear solver's linearization, docs/performance.md). 16 bytes a
// row: |e_x|, |e_y|, |e_z| and |e| rounded to float (for the percentiles and the robust sigma,
// relative 6e-8), and exact double moments (max, sum, sum of squares) per chunk of rows, added in
// chunk order: the result does not depend on which thread records which chunk.
class PositionErrorRows {
 public:
  // Room for `rows` rows recorded in `chunks` chunks (a partition of the rows into contiguous
  // ranges; chunk c is recorded in row order). Forgets what was recorded.
  void Reset(int rows, int chunks);
  // Frees everything (empty() afterwards).
  void Clear();
  bool empty() const { return rows_ == 0; }
  int size() const { return rows_; }

  // Row `row` of chunk `chunk` has the error e (measured minus predicted). Distinct chunks may be
  // recorded at the same time on different threads.
  void Record(int chunk, int row, const Eigen::Vector3d& e) {
    const double a[4] = {std::abs(e(0)), std::abs(e(1)), std::abs(e(2)), e.norm()};
    ChunkMoments& m = moments_[chunk];
    for (int k = 0; k < 4; ++k) {
      values_[static_cast<size_t>(k) * rows_ + row] = static_cast<float>(a[k]);
      m.max[k] = std::max(m.max[k], a[k]);
      m.sum[k] += a[k];
      m.sum_sq[k] += a[k] * a[k];
    }
  }

  // |e| of a row, rounded to float.
  float norm(int row) const { return values_[3 * static_cast<size_t>(rows_) + row]; }
  // Max, mean, RMS and 95th percentile per axis and of the norm (those of PositionErrorStatistics
  // on the same model and data, to round-off). Changes nothing.
  ErrorStatistics Statistics() const;
  // The norm's max, mean and RMS of Statistics() without its percentile (p95_abs = 0).
  AxisStatistics NormMoments() const;
  // The median of the 3 * size() absolute components (rounded to float). Changes nothing.
  double MedianAbsComponent() const;

 private:
  struct ChunkMoments {
    double max[4] = {0, 0, 0, 0};
    double sum[4] = {0, 0, 0, 0};
    double sum_sq[4] = {0, 0, 0, 0};
  };
  int rows_ = 0;
  std::vector<float> values_;  // |e_x| of every row, then |e_y|, |e_z|, |e|
  std::vector<ChunkMoments> moments_;
};

// Statistics of errors e_k (measured minus predicted), one 3-vector per row.
ErrorStatistics ComputeStatistics(const std::vector<Eigen::Vector3d>& errors);

// Position errors of `model` on `data`: measured - predicted, row by row.
std::vector<Eigen::Vector3d> PositionErrors(const RobotModel& model, const MeasurementSet& data);

// The same without storing the errors: one forward-kinematics pass, 16 bytes a row; the 95th
// percentiles are those of the errors rounded to float (relative 6e-8).
ErrorStatistics PositionErrorStatistics(const RobotModel& model, const MeasurementSet& data);

// Max, mean and RMS of the error norms |e| at the joint values `q` (data.size() x
// data.num_joints(), row-major) in place of the data's own, without the percentile's pass: what a
// solver's per-iteration record keeps, for a model with joint-space terms at its effective joint
// values without a copy of the data (CalibrationProblem::EffectiveJointValues).
AxisStatistics PositionErrorNormMoments(const RobotModel& model, const MeasurementSet& data,
                                        const double* q);

// The errors of `model` on `data` (tool positions, the model's own frames) collected by one
// forward-kinematics pass on the hardware's threads into `rows` (replaced).
void CollectPositionErrors(const RobotModel& model, const MeasurementSet& data,
                           PositionErrorRows* rows);

namespace internal {

// The k-th smallest (0-based, k < n) of v[0..n), all non-negative or NaN (a NaN counts as larger
// than every number), without reordering v: the value std::nth_element finds when the values are
// ordered by their bit patterns, which for non-negative floats is their order. What the
// percentiles and the median of PositionErrorRows use. From kKthSmallestByCounting values on, two
// counting passes over the high and the low 16 bits (linear in n, a table of 2^16 counts, 256 KB);
// below, std::nth_element on a copy of the bit patterns (the table, allocated and cleared at each
// call, cost more than the selection there). Both are exact, so both give the same value.
float KthSmallestNonNegative(const float* v, size_t n, size_t k);
constexpr size_t kKthSmallestByCounting = size_t{1} << 14;
// The two ways, each for any n (tests/model/statistics_test.cc compares them).
float KthSmallestNonNegativeByCounting(const float* v, size_t n, size_t k);
float KthSmallestNonNegativeBySelection(const float* v, size_t n, size_t k);

}  // namespace internal
}  // namespace lpoe

#endif  // LPOE_STATISTICS_H_
