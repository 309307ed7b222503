// A set of tracker measurements: one row per robot configuration, stored column-wise (struct of
// arrays) so that 10^6 rows cost 8 * (n + 3) bytes each and no allocation per row.
#ifndef LPOE_MEASUREMENTS_H_
#define LPOE_MEASUREMENTS_H_

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "lpoe/se3.h"

namespace lpoe {

class MeasurementSet {
 public:
  MeasurementSet() = default;
  explicit MeasurementSet(int num_joints) : num_joints_(num_joints) {}

  int num_joints() const { return num_joints_; }
  int size() const { return static_cast<int>(position_.size()); }
  bool empty() const { return position_.empty(); }
  // True when every row carries a measured orientation (pose data, paper section 3.2).
  bool has_orientation() const { return !empty() && orientation_.size() == position_.size(); }

  // Appends a row. `q` has num_joints() values (radians / mm). `source_line` is the line of the input
  // file the row came from (0 when generated), kept for error messages and outlier reports.
  void Add(const double* q, const Eigen::Vector3d& position, int target = 0, int source_line = 0);
  void AddPose(const double* q, const SE3d& pose, int target = 0, int source_line = 0);
  void Reserve(int rows);

  const double* q(int row) const { return q_.data() + static_cast<size_t>(row) * num_joints_; }
  double* mutable_q(int row) { return q_.data() + static_cast<size_t>(row) * num_joints_; }
  const Eigen::Vector3d& position(int row) const { return position_[row]; }
  Eigen::Vector3d& mutable_position(int row) { return position_[row]; }
  // Measured orientation (rotation of the tool frame in the measurement frame); pose data only.
  const Eigen::Matrix3d& orientation(int row) const { return orientation_[row]; }
  SE3d pose(int row) const { return SE3d(orientation_[row], position_[row]); }
  int target(int row) const { return target_[row]; }
  int source_line(int row) const { return line_[row]; }

  // The rows whose indices are listed, in that order.
  MeasurementSet Subset(const std::vector<int>& rows) const;
  // Splits off the first `first_count` rows (the shipped data keep identification rows first).
  void SplitAt(int first_count, MeasurementSet* first, MeasurementSet* rest) const;

 private:
  int num_joints_ = 0;
  std::vector<double> q_;
  std::vector<Eigen::Vector3d> position_;
  std::vector<Eigen::Matrix3d> orientation_;
  std::vector<int> target_;
  std::vector<int> line_;
};

}  // namespace lpoe

#endif  // LPOE_MEASUREMENTS_H_
