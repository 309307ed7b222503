// Measurement planning, the candidates (lpoe/planning.h): the cell, the tracker's visibility,
// singularity, sampling within the joint ranges, and the pool of feasible candidates with their rows.
#include "lpoe/planning.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <memory>
#include <numeric>
#include <random>
#include <sstream>
#include <string>
#include <utility>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <Eigen/SVD>
#include <glog/logging.h>

#include "identifiability/identifiability.h"
#include "planning/planning_internal.h"
#include "lpoe/analysis.h"
#include "lpoe/kinematics/eigen_decompositions.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/linear_solver.h"
#include "lpoe/measurements/measurements.h"
#include "io/parse_util.h"

namespace lpoe {
using planning_internal::kLimitTolerance;

std::vector<int> VisibleTools(const RobotModel& model, const TrackerConstraint& tracker,
                              const double* q) {
  std::vector<int> visible;
  const double cos_accept = std::cos(tracker.acceptance_angle);
  for (int t = 0; t < model.num_tools(); ++t) {
    if (!tracker.enabled) {
      visible.push_back(t);
      continue;
    }
    const SE3d pose = ToolPose(model, q, t);
    const Eigen::Vector3d to_tracker = tracker.position - pose.t;
    const double distance = to_tracker.norm();
    if (distance > tracker.max_range || distance == 0) continue;
    const Eigen::Vector3d facing =
        t < static_cast<int>(tracker.facing.size()) ? tracker.facing[t] : Eigen::Vector3d::UnitZ();
    if ((pose.R * facing).normalized().dot(to_tracker) >= cos_accept * distance) {
      visible.push_back(t);
    }
  }
  return visible;
}

double CharacteristicLength(const RobotModel& model) {
  double length = model.num_tools() > 0 ? model.tools[0].origin.t.norm() : 0.0;
  for (int i = 1; i < model.num_joints(); ++i) length += model.joints[i].origin.t.norm();
  return length > 0 ? length : 1.0;
}

double SingularityMeasure(const RobotModel& model, const double* q) {
  const int n = model.num_joints();
  Eigen::MatrixXd J_p, J_pose;
  ToolPositionJointJacobian(model, q, 0, &J_p);
  ToolPoseJointJacobian(model, q, 0, &J_pose);
  Eigen::MatrixXd G(6, n);
  G.topRows<3>() = J_pose.topRows<3>();
  G.bottomRows<3>() = J_p / CharacteristicLength(model);
  const Eigen::VectorXd sv = G.jacobiSvd().singularValues();
  return sv(std::min(6, n) - 1);
}

Status JointRanges(const RobotModel& model, std::vector<double>* lower, std::vector<double>* upper) {
  lower->clear();
  upper->clear();
  for (const Joint& j : model.joints) {
    double lo = j.lower, hi = j.upper;
    if (j.type == JointType::kPrismatic) {
      if (!std::isfinite(lo) || !std::isfinite(hi)) {
        return Status::Error("prismatic joint '" + j.name +
                             "' has no limits: give `limits: [lo, hi]` (mm) in the model so that "
                             "its poses can be sampled");
      }
    } else if (!std::isfinite(lo) && !std::isfinite(hi)) {
      lo = -kPi;
      hi = kPi;
    } else if (!std::isfinite(lo)) {
      lo = hi - 2 * kPi;
    } else if (!std::isfinite(hi)) {
      hi = lo + 2 * kPi;
    }
    lower->push_back(lo);
    upper->push_back(hi);
  }
  return Status::Ok();
}

Status SampleConfigurations(const RobotModel& model, int count, uint64_t seed,
                            std::vector<double>* q) {
  std::vector<double> lo, hi;
  if (Status s = JointRanges(model, &lo, &hi); !s.ok()) return s;
  const int n = model.num_joints();
  std::mt19937_64 rng(seed);
  q->resize(static_cast<size_t>(count) * n);
  for (int r = 0; r < count; ++r) {
    for (int i = 0; i < n; ++i) {
      const double u = static_cast<double>(rng() >> 11) * 0x1.0p-53;  // [0, 1), portable
      (*q)[static_cast<size_t>(r) * n + i] = lo[i] + (hi[i] - lo[i]) * u;
    }
  }
  return Status::Ok();
}

std::unique_ptr<PlanningModel> BuildPlanningPool(
    const RobotModel& model, const std::vector<std::shared_ptr<const JointTerm>>& terms,
    const std::vector<double>& candidates, const PlanConstraints& constraints,
    CandidatePool* pool, bool gravity_tilt) {
  auto geometric = std::make_unique<PlanningModel>(model);
  *pool = BuildCandidatePool(*geometric, candidates, constraints);
  if (terms.empty()) return geometric;
  auto with_terms = std::make_unique<PlanningModel>(model, terms, pool->q, gravity_tilt);
  CandidatePool full = BuildCandidatePool(*with_terms, pool->q, constraints);
  CHECK_EQ(full.size(), pool->size());
  full.source = pool->source;
  full.outside_limits = pool->outside_limits;
  full.near_singular = pool->near_singular;
  full.nothing_visible = pool->nothing_visible;
  full.outside_cell = pool->outside_cell;
  *pool = std::move(full);
  return with_terms;
}

bool InsideCell(const RobotModel& model, const CellConstraint& cell, const double* q,
                std::string* why) {
  if (!cell.enabled()) return true;
  auto check = [&](const Eigen::Vector3d& p, const std::string& what, bool tool) {
    std::ostringstream os;
    if (p.z() < cell.min_z) {
      os << what << " at z = " << p.z() << " mm, below the floor at " << cell.min_z << " mm";
    } else if (tool && !cell.box.isEmpty() && !cell.box.contains(p)) {
      os << what << " at (" << p.x() << ", " << p.y() << ", " << p.z()
         << ") mm, outside the box";
    } else {
      for (size_t k = 0; k < cell.keep_out.size(); ++k) {
        if (cell.keep_out[k].contains(p)) {
          os << what << " at (" << p.x() << ", " << p.y() << ", " << p.z()
             << ") mm, inside keep-out box " << k + 1;
          break;
        }
      }
    }
    if (os.tellp() == 0) return true;
    if (why) *why = os.str();
    return false;
  };
  // The joint frames: joint i's origin in the base frame is the product of the earlier joints'
  // origins and motions with its own origin.
  SE3d T = SE3d();
  for (int i = 0; i < model.num_joints(); ++i) {
    T = T * model.joints[i].origin;
    if (i > 0 && !check(T.t, model.joints[i].name + " origin", false)) return false;
    T = T * JointMotion(model.joints[i], q[i]);
  }
  for (int t = 0; t < model.num_tools(); ++t) {
    if (!check(ToolPosition(model, q, t), model.tools[t].name, true)) return false;
  }
  return true;
}

Status ParseBox(const std::string& text, Eigen::AlignedBox3d* box) {
  std::vector<double> v;
  if (!internal::ParseNumberList(text, ',', &v)) {
    return Status::Error("expected six finite numbers xmin,ymin,zmin,xmax,ymax,zmax (mm), got '" +
                         text + "'");
  }
  if (v.size() != 6) {
    return Status::Error("expected six numbers xmin,ymin,zmin,xmax,ymax,zmax (mm), got " +
                         std::to_string(v.size()) + " in '" + text + "'");
  }
  const Eigen::Vector3d lo(v[0], v[1], v[2]), hi(v[3], v[4], v[5]);
  if (!(lo.array() <= hi.array()).all()) {
    return Status::Error("a box's minimum must not exceed its maximum on any axis: '" + text + "'");
  }
  *box = Eigen::AlignedBox3d(lo, hi);
  return Status::Ok();
}

CandidatePool BuildCandidatePool(const PlanningModel& pm, const std::vector<double>& q,
                                 const PlanConstraints& constraints) {
  const RobotModel& model = pm.model();
  const int n = model.num_joints();
  CHECK_EQ(q.size() % std::max(n, 1), 0u);
  const int count = static_cast<int>(q.size() / n);
  CandidatePool pool;
  pool.num_joints = n;
  pool.num_parameters = pm.num_parameters();
  pool.row_offset.push_back(0);
  std::vector<Eigen::MatrixXd> rows;
  int total = 0;
  for (int r = 0; r < count; ++r) {
    const double* qr = q.data() + static_cast<size_t>(r) * n;
    bool inside = true;
    for (int i = 0; i < n; ++i) {
      const Joint& j = model.joints[i];
      inside &= qr[i] >= j.lower - kLimitTolerance && qr[i] <= j.upper + kLimitTolerance;
    }
    if (!inside) {
      ++pool.outside_limits;
      continue;
    }
    if (!InsideCell(model, constraints.cell, qr)) {
      ++pool.outside_cell;
      continue;
    }
    if (constraints.min_singularity > 0 &&
        SingularityMeasure(model, qr) < constraints.min_singularity) {
      ++pool.near_singular;
      continue;
    }
    std::vector<int> visible = VisibleTools(model, constraints.tracker, qr);
    if (visible.empty()) {
      ++pool.nothing_visible;
      continue;
    }
    Eigen::MatrixXd J;
    pm.Rows(qr, visible, &J);
    total += static_cast<int>(J.rows());
    pool.row_offset.push_back(total);
    rows.push_back(std::move(J));
    pool.q.insert(pool.q.end(), qr, qr + n);
    pool.source.push_back(r);
    pool.visible.push_back(std::move(visible));
  }
  pool.J.resize(total, pool.num_parameters);
  for (size_t c = 0; c < rows.size(); ++c) {
    pool.J.middleRows(pool.row_offset[c], rows[c].rows()) = rows[c];
  }
  return pool;
}

Eigen::MatrixXd WorkspaceMoment(const PlanningModel& pm, const std::vector<double>& workspace) {
  const int n = pm.model().num_joints();
  const int P = pm.num_parameters();
  std::vector<int> all(pm.model().num_tools());
  std::iota(all.begin(), all.end(), 0);
  const int count = static_cast<int>(workspace.size() / n);
  Eigen::MatrixXd L = Eigen::MatrixXd::Zero(P, P);
  Eigen::MatrixXd J;
  for (int r = 0; r < count; ++r) {
    pm.Rows(workspace.data() + static_cast<size_t>(r) * n, all, &J);
    L.selfadjointView<Eigen::Lower>().rankUpdate(J.transpose());
  }
  L = L.selfadjointView<Eigen::Lower>();
  if (count > 0) L /= static_cast<double>(count) * pm.model().num_tools();
  return L;
}


}  // namespace lpoe
