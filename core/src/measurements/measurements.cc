#include "lpoe/measurements/measurements.h"

#include <glog/logging.h>

#include <algorithm>

namespace lpoe {

void MeasurementSet::Reserve(int rows) {
  q_.reserve(static_cast<size_t>(rows) * num_joints_);
  position_.reserve(rows);
}

void MeasurementSet::Append(const MeasurementSet& other) {
  CHECK_EQ(other.num_joints_, num_joints_);
  if (other.empty()) return;
  CHECK(empty() || other.has_orientation() == has_orientation())
      << "cannot mix pose rows and position-only rows";
  const int offset = size();
  q_.insert(q_.end(), other.q_.begin(), other.q_.end());
  position_.insert(position_.end(), other.position_.begin(), other.position_.end());
  orientation_.insert(orientation_.end(), other.orientation_.begin(), other.orientation_.end());
  if (!other.target_.empty() || !target_.empty()) {
    if (target_.empty()) target_.assign(offset, 0);
    if (other.target_.empty()) {
      target_.resize(target_.size() + other.size(), 0);
    } else {
      target_.insert(target_.end(), other.target_.begin(), other.target_.end());
    }
  }
  for (const LineRun& run : other.line_runs_) {
    const int row = offset + run.first_row;
    if (!line_runs_.empty()) {
      const LineRun& last = line_runs_.back();
      const int64_t expected =
          last.first_line == 0 ? 0 : last.first_line + (row - last.first_row);
      if (run.first_line == expected) continue;
    }
    line_runs_.push_back({row, run.first_line});
  }
}

void MeasurementSet::Clear() {
  q_.clear();
  position_.clear();
  orientation_.clear();
  target_.clear();
  line_runs_.clear();
}

void MeasurementSet::ShrinkToFit() {
  q_.shrink_to_fit();
  position_.shrink_to_fit();
  orientation_.shrink_to_fit();
  target_.shrink_to_fit();
  line_runs_.shrink_to_fit();
}

void MeasurementSet::AppendTargetAndLine(int row, int target, int64_t source_line,
                                         std::vector<uint16_t>* targets,
                                         std::vector<LineRun>* runs) {
  CHECK(target >= 0 && target < kMaxTargets) << "target " << target << " out of range";
  if (target != 0 || !targets->empty()) {
    // The first row of another tool than the first: zeros for the rows before it (none when it is
    // row 0, whose target must be stored all the same).
    targets->resize(row, 0);
    targets->push_back(static_cast<uint16_t>(target));
  }
  if (!runs->empty()) {
    const LineRun& last = runs->back();
    const int64_t expected = last.first_line == 0 ? 0 : last.first_line + (row - last.first_row);
    if (source_line == expected) return;
  }
  runs->push_back({row, source_line});
}

int64_t MeasurementSet::source_line(int row) const {
  CHECK(row >= 0 && row < size()) << "row " << row << " out of range";
  // The last run starting at or before `row`.
  const auto it = std::upper_bound(line_runs_.begin(), line_runs_.end(), row,
                                   [](int r, const LineRun& run) { return r < run.first_row; });
  const LineRun& run = *(it - 1);
  return run.first_line == 0 ? 0 : run.first_line + (row - run.first_row);
}

void MeasurementSet::Add(const double* q, const Eigen::Vector3d& position, int target,
                         int64_t source_line) {
  CHECK(orientation_.empty()) << "cannot mix position-only rows into a pose data set";
  q_.insert(q_.end(), q, q + num_joints_);
  position_.push_back(position);
  AppendTargetAndLine(size() - 1, target, source_line, &target_, &line_runs_);
}

void MeasurementSet::AddPose(const double* q, const SE3d& pose, int target,
                             int64_t source_line) {
  CHECK_EQ(orientation_.size(), position_.size()) << "cannot mix pose rows into position-only data";
  q_.insert(q_.end(), q, q + num_joints_);
  position_.push_back(pose.t);
  orientation_.push_back(pose.R);
  AppendTargetAndLine(size() - 1, target, source_line, &target_, &line_runs_);
}

MeasurementSet MeasurementSet::Subset(const std::vector<int>& rows) const {
  MeasurementSet out(num_joints_);
  out.Reserve(static_cast<int>(rows.size()));
  for (int r : rows) {
    CHECK(r >= 0 && r < size()) << "row " << r << " out of range";
    if (has_orientation()) {
      out.AddPose(q(r), pose(r), target(r), source_line(r));
    } else {
      out.Add(q(r), position_[r], target(r), source_line(r));
    }
  }
  return out;
}

void MeasurementSet::SplitAt(int first_count, MeasurementSet* first, MeasurementSet* rest) const {
  CHECK(first_count >= 0 && first_count <= size());
  std::vector<int> a, b;
  for (int r = 0; r < size(); ++r) (r < first_count ? a : b).push_back(r);
  *first = Subset(a);
  *rest = Subset(b);
}

void MeasurementSet::MoveRowsOut(const std::vector<bool>& move_out, MeasurementSet* moved) {
  CHECK_EQ(static_cast<int>(move_out.size()), size());
  CHECK(moved != this);
  const bool pose = has_orientation();
  MeasurementSet out(num_joints_);
  std::vector<uint16_t> kept_targets;
  std::vector<LineRun> kept_runs;
  const int rows = size();
  int kept = 0;
  for (int r = 0; r < rows; ++r) {
    const int64_t line = source_line(r);
    const int t = target(r);
    if (move_out[r]) {
      if (pose) {
        out.AddPose(q(r), this->pose(r), t, line);
      } else {
        out.Add(q(r), position_[r], t, line);
      }
      continue;
    }
    // Compact in place: row r moves to row `kept` (kept <= r, so nothing unread is overwritten).
    if (kept != r) {
      std::copy(q(r), q(r) + num_joints_, mutable_q(kept));
      position_[kept] = position_[r];
      if (pose) orientation_[kept] = orientation_[r];
    }
    AppendTargetAndLine(kept, t, line, &kept_targets, &kept_runs);
    ++kept;
  }
  q_.resize(static_cast<size_t>(kept) * num_joints_);
  position_.resize(kept);
  if (pose) orientation_.resize(kept);
  target_ = std::move(kept_targets);
  line_runs_ = std::move(kept_runs);
  *moved = std::move(out);
}

}  // namespace lpoe
