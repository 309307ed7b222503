// Error statistics of predicted versus measured positions, per axis and for the norm.
#ifndef LPOE_STATISTICS_H_
#define LPOE_STATISTICS_H_

#include <string>
#include <vector>

#include <Eigen/Core>

#include "lpoe/measurements.h"
#include "lpoe/robot_model.h"

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

// Statistics of errors e_k (measured minus predicted), one 3-vector per row.
ErrorStatistics ComputeStatistics(const std::vector<Eigen::Vector3d>& errors);

// Position errors of `model` on `data`: measured - predicted, row by row.
std::vector<Eigen::Vector3d> PositionErrors(const RobotModel& model, const MeasurementSet& data);

// The same without storing the errors: one forward-kinematics pass, 16 bytes a row; the 95th
// percentiles are those of the errors rounded to float (relative 6e-8).
ErrorStatistics PositionErrorStatistics(const RobotModel& model, const MeasurementSet& data);

}  // namespace lpoe

#endif  // LPOE_STATISTICS_H_
