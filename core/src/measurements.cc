#include "lpoe/measurements.h"

#include <glog/logging.h>

namespace lpoe {

void MeasurementSet::Reserve(int rows) {
  q_.reserve(static_cast<size_t>(rows) * num_joints_);
  position_.reserve(rows);
  target_.reserve(rows);
  line_.reserve(rows);
}

void MeasurementSet::Add(const double* q, const Eigen::Vector3d& position, int target,
                         int source_line) {
  CHECK(orientation_.empty()) << "cannot mix position-only rows into a pose data set";
  q_.insert(q_.end(), q, q + num_joints_);
  position_.push_back(position);
  target_.push_back(target);
  line_.push_back(source_line);
}

void MeasurementSet::AddPose(const double* q, const SE3d& pose, int target, int source_line) {
  CHECK_EQ(orientation_.size(), position_.size()) << "cannot mix pose rows into position-only data";
  q_.insert(q_.end(), q, q + num_joints_);
  position_.push_back(pose.t);
  orientation_.push_back(pose.R);
  target_.push_back(target);
  line_.push_back(source_line);
}

MeasurementSet MeasurementSet::Subset(const std::vector<int>& rows) const {
  MeasurementSet out(num_joints_);
  out.Reserve(static_cast<int>(rows.size()));
  for (int r : rows) {
    CHECK(r >= 0 && r < size()) << "row " << r << " out of range";
    if (has_orientation()) {
      out.AddPose(q(r), pose(r), target_[r], line_[r]);
    } else {
      out.Add(q(r), position_[r], target_[r], line_[r]);
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

}  // namespace lpoe
