// A set of tracker measurements: one row per robot configuration, stored column-wise (struct of
// arrays) so that a position row costs 8 * (n + 3) bytes and no allocation: targets are stored only
// once a row measures another tool than the first (2 bytes a row), and source lines as runs of
// consecutive lines (a few bytes per comment or skipped line of the input, not per row).
#ifndef LPOE_MEASUREMENTS_H_
#define LPOE_MEASUREMENTS_H_

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "lpoe/kinematics/se3.h"

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
  // `target` is a tool index below kMaxTargets.
  void Add(const double* q, const Eigen::Vector3d& position, int target = 0,
           int64_t source_line = 0);
  void AddPose(const double* q, const SE3d& pose, int target = 0, int64_t source_line = 0);
  void Reserve(int rows);
  // Appends the rows of `other` (same joint count and data kind, or `this` empty), their targets
  // and source lines included.
  void Append(const MeasurementSet& other);
  // Removes every row, keeping the capacity.
  void Clear();
  // Frees capacity beyond size() (one reallocation of each column).
  void ShrinkToFit();
  // Keeps the rows for which `move_out[row]` is false (in order, in place) and moves the others,
  // in order, into `moved` (replaced). Peak memory is this set plus `moved`, not two copies.
  void MoveRowsOut(const std::vector<bool>& move_out, MeasurementSet* moved);

  static constexpr int kMaxTargets = 65536;

  const double* q(int row) const { return q_.data() + static_cast<size_t>(row) * num_joints_; }
  double* mutable_q(int row) { return q_.data() + static_cast<size_t>(row) * num_joints_; }
  const Eigen::Vector3d& position(int row) const { return position_[row]; }
  Eigen::Vector3d& mutable_position(int row) { return position_[row]; }
  // Measured orientation (rotation of the tool frame in the measurement frame); pose data only.
  const Eigen::Matrix3d& orientation(int row) const { return orientation_[row]; }
  SE3d pose(int row) const { return SE3d(orientation_[row], position_[row]); }
  int target(int row) const { return target_.empty() ? 0 : target_[row]; }
  // The 1-based line of the input file the row came from, 0 when generated.
  int64_t source_line(int row) const;

  // The rows whose indices are listed, in that order.
  MeasurementSet Subset(const std::vector<int>& rows) const;
  // Splits off the first `first_count` rows (the shipped data keep identification rows first).
  void SplitAt(int first_count, MeasurementSet* first, MeasurementSet* rest) const;

 private:
  int num_joints_ = 0;
  std::vector<double> q_;
  std::vector<Eigen::Vector3d> position_;
  std::vector<Eigen::Matrix3d> orientation_;
  // Empty while every row measures target 0.
  std::vector<uint16_t> target_;
  // Source lines: row r of a run starting at (first_row, first_line) came from line
  // first_line + (r - first_row), or 0 when first_line is 0 (generated rows).
  struct LineRun {
    int first_row;
    int64_t first_line;
  };
  std::vector<LineRun> line_runs_;

  static void AppendTargetAndLine(int row, int target, int64_t source_line,
                                  std::vector<uint16_t>* targets, std::vector<LineRun>* runs);
};

}  // namespace lpoe

#endif  // LPOE_MEASUREMENTS_H_
