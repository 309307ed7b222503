#include "identifiability/structural_identifiability.h"

#include <glog/logging.h>

#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "identifiability/identifiability.h"
#include "lpoe/analysis.h"
#include "lpoe/kinematics/eigen_decompositions.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/measurements/measurement_kind_dispatch.h"
#include "linearization/normal_equations.h"

namespace lpoe {
namespace internal {
namespace {

// Range of the generic prismatic joint values (mm); any non-degenerate range does.
constexpr double kGenericStrokeMm = 500.0;
// The reasons StructurallyUnidentifiable gives (IsStructurallyLost recognizes them).
constexpr char kMovesNothing[] = "moves no measured target at any configuration";
constexpr char kNotSeparated[] = "no configuration separates it from";
// Names quoted in a reason: the kept directions a left-out one trades with.
constexpr int kTradeNames = 3;

// Random configurations measuring every tool that `data` measures (the measured values are the
// model's own: only the Jacobian is used).
MeasurementSet GenericMeasurements(const RobotModel& model, const std::vector<int>& tools,
                                   bool use_orientation, int configurations) {
  const int n = model.num_joints();
  MeasurementSet g(n);
  std::mt19937_64 rng(20220901);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  std::vector<double> q(n);
  VisitTrackerKind(TrackerKindId(use_orientation), [&](auto tag) {
    using Kind = typename decltype(tag)::type;
    for (int c = 0; c < configurations; ++c) {
      for (int i = 0; i < n; ++i) {
        q[i] = unit(rng) * (model.joints[i].type == JointType::kRevolute ? M_PI : kGenericStrokeMm);
      }
      for (int t : tools) Kind::MeasureExactly(model, q.data(), t, &g);
    }
  });
  return g;
}

bool RotationLike(const Direction& d) {
  return d.vector.head<3>().norm() > d.vector.tail<3>().norm();
}

// Distance (mm) of tool t's point from the axis of the last joint, when that joint is revolute;
// infinity otherwise.
double DistanceFromLastAxis(const RobotModel& model, int t) {
  const Joint& last = model.joints.back();
  if (last.type != JointType::kRevolute) return INFINITY;
  const Eigen::Vector3d w = last.twist.head<3>().normalized();
  const Eigen::Vector3d on_axis = w.cross(last.twist.tail<3>());
  const Eigen::Vector3d r = model.tools[t].origin.t - on_axis;
  return (r - w * w.dot(r)).norm();
}

}  // namespace

std::vector<Direction> StructurallyUnidentifiable(const RobotModel& model,
                                                  const MeasurementSet& data, bool use_orientation,
                                                  double orientation_weight) {
  std::vector<Direction> out;
  const int n = model.num_joints();
  if (data.empty() || n == 0) return out;
  std::vector<bool> measured(model.num_tools(), false);
  for (int r = 0; r < data.size(); ++r) measured[data.target(r)] = true;
  std::vector<int> tools;
  for (int t = 0; t < model.num_tools(); ++t) {
    if (measured[t]) tools.push_back(t);
  }
  const DataKind kind = TrackerDataKind(TrackerKindId(use_orientation));
  const Parameterization p = MakeParameterization(model, ParameterizationKind::kIdentifiable, kind);
  const MeasurementSet g = GenericMeasurements(model, tools, use_orientation,
                                               std::max(kGenericConfigurations, p.num_parameters));
  NormalEquationsOptions o;
  o.use_orientation = use_orientation;
  o.orientation_weight = orientation_weight;
  o.stack = true;
  const NormalEquations lin = NormalEquationsOf(model, g, p, Eigen::VectorXd(), o);
  if (!lin.finite || !lin.J.allFinite()) return out;  // the solvers report non-finite models

  // Candidates in the order they are kept: measured tools, joint translations, joint rotations.
  std::vector<int> order;
  for (int t : tools) {
    const int f = n + t;
    for (int c = 0; c < p.basis[f].cols(); ++c) order.push_back(p.offset[f] + c);
  }
  for (const bool rotations : {false, true}) {
    for (int f = 0; f < n; ++f) {
      for (int c = 0; c < p.basis[f].cols(); ++c) {
        const int k = p.offset[f] + c;
        if (RotationLike(p.parameters[k]) == rotations) order.push_back(k);
      }
    }
  }

  // Gram-Schmidt (two passes) on the unit columns in that order; columns of round-off size move
  // nothing.
  const Eigen::Index rows = lin.J.rows();
  const double zero_column = kRoundOffColumn * lin.J.colwise().norm().maxCoeff();
  // Q and the kept unit columns are allocated once for every candidate and filled from the left
  // (growing them column by column copied them each time).
  const Eigen::Index candidates = static_cast<Eigen::Index>(order.size());
  Eigen::MatrixXd Q_all(rows, candidates), kept_all(rows, candidates);
  std::vector<int> kept;
  std::vector<int> dropped;
  for (int k : order) {
    Eigen::VectorXd v = lin.J.col(k);
    const double norm = v.norm();
    if (!(norm > zero_column)) {
      dropped.push_back(k);
      continue;
    }
    v /= norm;
    const Eigen::VectorXd unit_column = v;
    const auto Q = Q_all.leftCols(static_cast<Eigen::Index>(kept.size()));
    for (int pass = 0; pass < 2; ++pass) v -= Q * (Q.transpose() * v);
    const double left = v.norm();
    if (left > kStructuralTolerance) {
      Q_all.col(static_cast<Eigen::Index>(kept.size())) = v / left;
      kept_all.col(static_cast<Eigen::Index>(kept.size())) = unit_column;
      kept.push_back(k);
    } else {
      dropped.push_back(k);
    }
  }
  if (dropped.empty()) return out;

  const Eigen::MatrixXd kept_columns = kept_all.leftCols(static_cast<Eigen::Index>(kept.size()));
  const Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(kept_columns);
  for (int k : dropped) {
    Direction d = p.parameters[k];
    std::ostringstream reason;
    const double norm = lin.J.col(k).norm();
    if (!(norm > zero_column)) {
      reason << kMovesNothing;
    } else {
      const Eigen::VectorXd c = qr.solve(Eigen::VectorXd(lin.J.col(k) / norm));
      std::vector<int> idx(c.size());
      for (int j = 0; j < c.size(); ++j) idx[j] = j;
      std::sort(idx.begin(), idx.end(),
                [&](int a, int b) { return std::abs(c(a)) > std::abs(c(b)); });
      reason << kNotSeparated;
      for (int j = 0; j < std::min<int>(kTradeNames, static_cast<int>(idx.size())); ++j) {
        if (std::abs(c(idx[j])) < 1e-3) break;
        reason << (j ? ", " : " ") << p.parameters[kept[idx[j]]].name;
      }
      reason << " with " << MeasurementKind(TrackerKindId(use_orientation)).name
             << " data on this chain";
    }
    reason << ": not identified, kept as given";
    // The common case named: a target on the last axis (a UR robot's tool0 measured directly).
    if (d.frame == n - 1 || d.frame >= n) {
      for (int t : tools) {
        const double scale = std::max(1.0, model.tools[t].origin.t.norm());
        if (DistanceFromLastAxis(model, t) <= kStructuralTolerance * scale) {
          reason << " (" << model.tools[t].name << " lies on " << model.joints[n - 1].name
                 << "'s axis, where these data put it within their noise, so turning that joint "
                    "never moves it: a target off the axis, or orientation data, would identify "
                    "it)";
          break;
        }
      }
    }
    d.reason = reason.str();
    out.push_back(d);
  }
  std::sort(out.begin(), out.end(),
            [&](const Direction& a, const Direction& b) { return a.frame < b.frame; });
  return out;
}

RobotModel StructureReference(const RobotModel& estimate, const MeasurementSet& data,
                              double rms_axis) {
  RobotModel reference = estimate;
  const int n = estimate.num_joints();
  if (n == 0 || estimate.joints.back().type != JointType::kRevolute) return reference;
  std::vector<int> rows(estimate.num_tools(), 0);
  for (int r = 0; r < data.size(); ++r) ++rows[data.target(r)];
  const Joint& last = estimate.joints.back();
  const Eigen::Vector3d w = last.twist.head<3>().normalized();
  const Eigen::Vector3d on_axis = w.cross(last.twist.tail<3>());
  const double sigma = std::isfinite(rms_axis) ? std::max(rms_axis, 0.0) : INFINITY;
  for (int t = 0; t < estimate.num_tools(); ++t) {
    if (rows[t] == 0 || estimate.tools[t].fixed) continue;  // a known nest stays where it is
    const double tolerance = kOnAxisSigmas * sigma * std::sqrt(2.0 / rows[t]);
    if (DistanceFromLastAxis(estimate, t) <= tolerance) {
      Eigen::Vector3d& p = reference.tools[t].origin.t;
      p = on_axis + w * w.dot(p - on_axis);
    }
  }
  return reference;
}

double RmsPerAxisOfCost(double cost, const MeasurementSet& data, bool use_orientation) {
  const double per_row = TrackerResiduals(TrackerKindId(use_orientation));
  if (data.empty() || !(cost >= 0)) return INFINITY;
  return std::sqrt(2.0 * cost / (per_row * data.size()));
}

bool SameDirections(const std::vector<Direction>& a, const std::vector<Direction>& b) {
  if (a.size() != b.size()) return false;
  std::vector<bool> used(b.size(), false);
  for (const Direction& x : a) {
    bool found = false;
    for (size_t k = 0; k < b.size() && !found; ++k) {
      if (used[k] || b[k].frame != x.frame || b[k].joint_block != x.joint_block) continue;
      if ((b[k].vector - x.vector).norm() < 1e-9) found = used[k] = true;
    }
    if (!found) return false;
  }
  return true;
}

void LeaveOutStructurallyUnidentifiable(const RobotModel& reference, const MeasurementSet& data,
                                        bool use_orientation, double orientation_weight,
                                        Parameterization* p) {
  CHECK(p->joint_blocks.empty()) << "frames are reduced before joint blocks are added";
  LeaveOutDirections(StructurallyUnidentifiable(reference, data, use_orientation,
                                                orientation_weight),
                     p);
}

void LeaveOutDirections(const std::vector<Direction>& lost, Parameterization* p) {
  CHECK(p->joint_blocks.empty()) << "frames are reduced before joint blocks are added";
  if (lost.empty()) return;
  p->unidentifiable.insert(p->unidentifiable.end(), lost.begin(), lost.end());
  Parameterization out = *p;
  out.parameters.clear();
  out.num_parameters = 0;
  for (size_t f = 0; f < p->basis.size(); ++f) {
    // The frame's basis projected off its lost directions (columns of an identifiable basis drop
    // out exactly; a full basis keeps the orthogonal complement), orthonormalized.
    Eigen::MatrixXd L(6, 0);
    for (const Direction& d : lost) {
      if (d.frame != static_cast<int>(f)) continue;
      L.conservativeResize(Eigen::NoChange, L.cols() + 1);
      L.col(L.cols() - 1) = d.vector;
    }
    const Eigen::MatrixXd& B = p->basis[f];
    Eigen::MatrixXd basis(6, 0);
    for (int c = 0; c < B.cols(); ++c) {
      Vector6d v = B.col(c);
      for (int pass = 0; pass < 2; ++pass) {
        v -= L * (L.transpose() * v);
        v -= basis * (basis.transpose() * v);
      }
      if (v.norm() < 0.5) continue;
      v.normalize();
      basis.conservativeResize(Eigen::NoChange, basis.cols() + 1);
      basis.col(basis.cols() - 1) = v;
      Direction d = p->parameters[p->offset[f] + c];
      if ((v - B.col(c)).norm() > 1e-12) {  // a mixture: named after its dominant component
        static const char* const kAxes[6] = {"rx", "ry", "rz", "tx", "ty", "tz"};
        int best = 0;
        v.cwiseAbs().maxCoeff(&best);
        d.name = d.name.substr(0, d.name.rfind('.')) + "." + kAxes[best] + "~";
      }
      d.vector = v;
      out.parameters.push_back(d);
    }
    out.basis[f] = basis;
    out.offset[f] = out.num_parameters;
    out.num_parameters += static_cast<int>(basis.cols());
  }
  *p = std::move(out);
}

}  // namespace internal

bool IsStructurallyLost(const Direction& d) {
  return d.joint_block < 0 && (d.reason.rfind(internal::kMovesNothing, 0) == 0 ||
                               d.reason.rfind(internal::kNotSeparated, 0) == 0);
}

}  // namespace lpoe
