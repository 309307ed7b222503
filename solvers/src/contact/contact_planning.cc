// Planning ballbar and touch-probe poses (lpoe/contact_planning.h).
#include "lpoe/contact_planning.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <sstream>
#include <string>

#include <Eigen/Dense>

#include "lpoe/inverse_kinematics.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/options.h"

namespace lpoe {

namespace {

bool ContactPlanWithinLimits(const RobotModel& model, const double* q) {
  for (int j = 0; j < model.num_joints(); ++j) {
    const Joint& joint = model.joints[j];
    if ((std::isfinite(joint.lower) && q[j] < joint.lower) ||
        (std::isfinite(joint.upper) && q[j] > joint.upper)) {
      return false;
    }
  }
  return true;
}

}  // namespace

Status ContactPlanCandidates(const RobotModel& model, const ContactPlanOptions& options,
                             ContactCandidates* out) {
  if (options.pivots.empty() && options.planes.empty()) {
    return Status::Error("contact planning: give pivots (ballbar) or planes (probe)");
  }
  if (!(options.bar_length > 0) || !(options.stroke >= 0) || !(options.probe_radius >= 0) ||
      !(options.sigma > 0) || !(options.face_radius > 0) || options.samples_per_feature < 1) {
    return Status::Error(
        "contact planning: the bar's length, the noise and the face's radius must be positive, "
        "the stroke and the probe's radius not negative, and at least one sample per feature");
  }
  if (options.target < 0 || options.target >= model.num_tools()) {
    return Status::Error("contact planning: the model has no tool " +
                         std::to_string(options.target));
  }
  if (!options.plane_centres.empty() && options.plane_centres.size() != options.planes.size()) {
    return Status::Error("contact planning: one face centre per plane");
  }
  for (const Eigen::Vector4d& pl : options.planes) {
    if (!(std::abs(pl.head<3>().norm() - 1) < 1e-6)) {
      return Status::Error("contact planning: a plane's normal must have unit length");
    }
  }
  if (Status s = InverseKinematics::CheckModel(model); !s.ok()) return s;
  ContactCandidates c;
  c.set.num_joints = model.num_joints();
  c.set.files.push_back("(planned candidates)");
  c.features.pivots = options.pivots;
  c.features.planes = options.planes;
  for (size_t k = 0; k < options.pivots.size(); ++k) {
    c.set.Feature(MeasurementKindId::kDistance, "pivot" + std::to_string(k + 1));
  }
  const char* faces[] = {"face_x", "face_y", "face_z"};
  for (size_t k = 0; k < options.planes.size(); ++k) {
    c.set.Feature(MeasurementKindId::kPlane,
                  options.planes.size() == 3 ? faces[k] : "plane" + std::to_string(k + 1));
  }
  IkOptions ik_options;
  ik_options.position_tolerance = 1e-6;
  ik_options.check_branch = false;
  ik_options.restarts = 2;
  const InverseKinematics ik(model, ik_options);
  const int n = model.num_joints();
  const int features = static_cast<int>(options.pivots.size() + options.planes.size());
  std::vector<double> samples;
  if (Status s = SampleConfigurations(model, options.samples_per_feature * features, options.seed,
                                      &samples);
      !s.ok()) {
    return s;
  }
  std::vector<double> q(n);
  std::mt19937_64 rng(options.seed + 1);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (int i = 0; i < options.samples_per_feature * features; ++i) {
    const int k = i % features;
    const double* seed = samples.data() + static_cast<size_t>(i) * n;
    const Eigen::Vector3d p = ToolPosition(model, seed, options.target);
    IkTarget target;
    target.tool = options.target;
    ContactRow row;
    row.target = options.target;
    row.sigma = options.sigma;
    if (k < static_cast<int>(options.pivots.size())) {
      // The ball onto the sphere: the radially nearest point, reflected into the upper part when
      // it is more than 0.2 bar lengths below the pivot's equator (the bar would run through the
      // pivot's stand).
      const Eigen::Vector3d& pivot = options.pivots[k];
      Eigen::Vector3d u = p - pivot;
      if (u.norm() < 1e-9) u = Eigen::Vector3d::UnitZ();
      u.normalize();
      if (u(2) < -0.2) u(2) = -u(2);
      target.position = pivot + options.bar_length * u;
      row.kind = MeasurementKindId::kDistance;
      row.feature = k;
      row.value = options.bar_length;
    } else {
      // The probe's tip onto the plane offset by its radius, within the face.
      const int f = k - static_cast<int>(options.pivots.size());
      const Eigen::Vector3d normal = options.planes[f].head<3>();
      const double d = options.planes[f](3) + options.probe_radius;
      const Eigen::Vector3d centre_in = options.plane_centres.empty()
                                            ? Eigen::Vector3d(Eigen::Vector3d::Zero())
                                            : options.plane_centres[f];
      const Eigen::Vector3d centre = centre_in - (normal.dot(centre_in) - d) * normal;
      // The orthogonal projection; outside the face's circle, drawn in along the same direction
      // from the centre to a random radius within it (uniform over the circle's area).
      Eigen::Vector3d t = p - (normal.dot(p) - d) * normal;
      const double off = (t - centre).norm();
      if (off > options.face_radius) {
        t = centre + (t - centre) * (options.face_radius * std::sqrt(unit(rng)) / off);
      }
      target.position = t;
      row.kind = MeasurementKindId::kPlane;
      row.feature = f;
      row.value = options.probe_radius;
    }
    const IkResult r = ik.Solve(target, seed, q.data());
    if (r.status != IkStatus::kOk && r.status != IkStatus::kBranch) {
      ++c.not_converged;
      continue;
    }
    if (!ContactPlanWithinLimits(model, q.data())) {
      ++c.outside_limits;
      continue;
    }
    if (options.cell.enabled() && !InsideCell(model, options.cell, q.data())) {
      ++c.outside_cell;
      continue;
    }
    if (options.min_singularity > 0 && SingularityMeasure(model, q.data()) < options.min_singularity) {
      ++c.near_singular;
      continue;
    }
    const Eigen::Vector3d reached = ToolPosition(model, q.data(), options.target);
    if (row.kind == MeasurementKindId::kDistance) {
      const Eigen::Vector3d u = reached - options.pivots[row.feature];
      if (u(2) < -0.2 * u.norm()) {
        ++c.below_pivot;
        continue;
      }
      if (std::abs(u.norm() - options.bar_length) > options.stroke) {
        ++c.outside_stroke;
        continue;
      }
    }
    c.set.rows.push_back(row);
    c.set.q.insert(c.set.q.end(), q.begin(), q.end());
  }
  *out = std::move(c);
  return Status::Ok();
}

Status ContactInformationRows(const RobotModel& model, const ContactCandidates& candidates,
                              Eigen::MatrixXd* rows) {
  const ContactMeasurementSet& set = candidates.set;
  if (set.size() == 0) return Status::Error("contact planning: no candidate poses");
  ContactCalibrationOptions options;
  ContactParameterization p;
  if (Status s = MakeContactParameterization(model, candidates.features, set, options, &p); !s.ok()) {
    return s;
  }
  Eigen::VectorXd r;
  Eigen::MatrixXd J;
  ContactLinearize(model, candidates.features, p, model, set, options, &r, &J);
  // The rows after the candidates' (gauge, scale hold) fix directions exactly: their null space
  // is what the candidates must determine.
  const int m = set.size();
  const Eigen::MatrixXd G = J.bottomRows(J.rows() - m);
  Eigen::MatrixXd Z = Eigen::MatrixXd::Identity(J.cols(), J.cols());
  if (G.rows() > 0) {
    Eigen::JacobiSVD<Eigen::MatrixXd> svd(G, Eigen::ComputeFullV);
    int rank = 0;
    const Eigen::VectorXd& s = svd.singularValues();
    while (rank < s.size() && s(rank) > 1e-9 * s(0)) ++rank;
    Z = svd.matrixV().rightCols(J.cols() - rank);
  }
  *rows = J.topRows(m) * Z;
  return Status::Ok();
}

namespace {

// The column scale of the pool's information (Jacobi): 1 / the column norms of all rows.
Eigen::MatrixXd ScaledContactRows(const Eigen::MatrixXd& rows) {
  Eigen::MatrixXd out = rows;
  for (int c = 0; c < out.cols(); ++c) {
    const double norm = out.col(c).norm() / std::sqrt(static_cast<double>(out.rows()));
    if (norm > 0) out.col(c) /= norm;
  }
  return out;
}

double LogDetOfRows(const Eigen::MatrixXd& A, const std::vector<int>& selected) {
  Eigen::MatrixXd M = Eigen::MatrixXd::Zero(A.cols(), A.cols());
  for (int i : selected) M.noalias() += A.row(i).transpose() * A.row(i);
  Eigen::LDLT<Eigen::MatrixXd> ldlt(M);
  double log_det = 0;
  const Eigen::VectorXd d = ldlt.vectorD();
  for (int i = 0; i < d.size(); ++i) {
    if (!(d(i) > 1e-12 * std::max(1.0, M.diagonal().maxCoeff()))) {
      return -std::numeric_limits<double>::infinity();
    }
    log_det += std::log(d(i));
  }
  return log_det;
}

}  // namespace

double ContactPlanLogDet(const Eigen::MatrixXd& rows, const std::vector<int>& selected) {
  return LogDetOfRows(ScaledContactRows(rows), selected);
}

Status PlanContacts(const RobotModel& model, const ContactCandidates& candidates, int count,
                    int max_exchange_passes, ContactPlanResult* result) {
  Eigen::MatrixXd rows;
  if (Status s = ContactInformationRows(model, candidates, &rows); !s.ok()) return s;
  const int pool = static_cast<int>(rows.rows());
  const int P = static_cast<int>(rows.cols());
  if (count <= P) {
    return Status::Error("a plan of " + std::to_string(count) + " poses cannot identify the " +
                         std::to_string(P) +
                         " parameters with rows to spare: plan more poses than parameters");
  }
  if (count > pool) {
    return Status::Error("only " + std::to_string(pool) + " candidate poses for a plan of " +
                         std::to_string(count) + ": sample more");
  }
  const Eigen::MatrixXd A = ScaledContactRows(rows);
  // Greedy: from a small ridge (the scaled information of the whole pool, per row, 1e-6 of it),
  // each step the candidate of the largest variance a^T M^-1 a (the largest gain of log det).
  const double ridge = 1e-6;
  Eigen::MatrixXd Minv = Eigen::MatrixXd::Identity(P, P) / ridge;
  std::vector<char> used(pool, 0);
  std::vector<int> selected;
  for (int step = 0; step < count; ++step) {
    int best = -1;
    double best_v = -1;
    for (int c = 0; c < pool; ++c) {
      if (used[c]) continue;
      const double v = A.row(c) * Minv * A.row(c).transpose();
      if (v > best_v) {
        best_v = v;
        best = c;
      }
    }
    used[best] = 1;
    selected.push_back(best);
    const Eigen::VectorXd w = Minv * A.row(best).transpose();
    Minv -= w * w.transpose() / (1 + best_v);
  }
  // Exchange: each member against the candidate that adds most to the plan without it.
  int exchanges = 0;
  for (int pass = 0; pass < max_exchange_passes; ++pass) {
    bool improved = false;
    for (size_t i = 0; i < selected.size(); ++i) {
      Eigen::MatrixXd M = ridge * Eigen::MatrixXd::Identity(P, P);
      for (size_t k = 0; k < selected.size(); ++k) {
        if (k != i) M.noalias() += A.row(selected[k]).transpose() * A.row(selected[k]);
      }
      const Eigen::MatrixXd without = M.ldlt().solve(Eigen::MatrixXd::Identity(P, P));
      const double own = A.row(selected[i]) * without * A.row(selected[i]).transpose();
      int best = -1;
      double best_v = own * (1 + 1e-9);
      for (int c = 0; c < pool; ++c) {
        if (used[c]) continue;
        const double v = A.row(c) * without * A.row(c).transpose();
        if (v > best_v) {
          best_v = v;
          best = c;
        }
      }
      if (best < 0) continue;
      used[selected[i]] = 0;
      used[best] = 1;
      selected[i] = best;
      ++exchanges;
      improved = true;
    }
    if (!improved) break;
  }
  std::sort(selected.begin(), selected.end());
  result->selected = selected;
  result->num_parameters = P;
  result->exchanges = exchanges;
  result->log_det = LogDetOfRows(A, selected);
  return Status::Ok();
}

}  // namespace lpoe

namespace lpoe {

Status CheckContactPlanRequest(const ContactPlanRequest& request) {
  const ContactPlanOptions& o = request.options;
  if (o.pivots.empty() == o.planes.empty()) {
    return Status::Error(o.pivots.empty() ? "give --pivots (ballbar) or --planes (probe)"
                                          : "--pivots (ballbar) and --planes (probe): give one");
  }
  if (!o.pivots.empty()) {
    if (!(o.bar_length > 0 && o.bar_length < 1e5) || !(o.stroke >= 0 && o.stroke < o.bar_length)) {
      return Status::Error("--bar_length must be positive (mm) and --stroke in [0, bar length)");
    }
    for (const Eigen::Vector3d& c : o.pivots) {
      if (!c.allFinite()) return Status::Error("--pivots: expected finite x,y,z (mm) per pivot");
    }
  } else {
    for (const Eigen::Vector4d& v : o.planes) {
      if (!v.allFinite()) return Status::Error("--planes: expected finite nx,ny,nz,d per plane");
      if (std::abs(v.head<3>().norm() - 1) > 1e-6) {
        std::ostringstream os;
        os << "--planes: a normal of length " << v.head<3>().norm() << "; give unit normals";
        return Status::Error(os.str());
      }
    }
    bool centres_finite = true;
    for (const Eigen::Vector3d& c : o.plane_centres) centres_finite = centres_finite && c.allFinite();
    if ((!o.plane_centres.empty() && o.plane_centres.size() != o.planes.size()) || !centres_finite) {
      return Status::Error("--face_centres: 'x,y,z' (mm) per plane separated by ';', one per plane");
    }
    if (!(o.face_radius > 0) || !(o.probe_radius >= 0)) {
      return Status::Error("--face_radius must be positive and --probe_radius not negative (mm)");
    }
  }
  if (o.samples_per_feature < 1 || o.samples_per_feature > 100000) {
    return Status::Error("--samples_per_feature must be in [1, 100000]");
  }
  if (std::isnan(o.cell.min_z) || o.cell.min_z == std::numeric_limits<double>::infinity()) {
    return Status::Error("--min_z must be a finite height in mm");
  }
  if (Status s = CheckOption("lpoe_plan", "random_draws", request.random_draws); !s.ok()) return s;
  if (request.count < 1) return Status::Error("--count must be a number of poses (1 or more)");
  return Status::Ok();
}

Status RunContactPlanning(const RobotModel& model, const ContactPlanRequest& request,
                          ContactPlanningResult* result, PlanFailure* failure) {
  PlanFailure ignored;
  PlanFailure& why = failure != nullptr ? *failure : ignored;
  why = PlanFailure::kUsage;
  if (Status s = CheckContactPlanRequest(request); !s.ok()) return s;
  const ContactPlanOptions& o = request.options;
  if (o.target < 0 || o.target >= model.num_tools()) {
    return Status::Error("--contact_tool=" + std::to_string(o.target) + ": the model has " +
                         std::to_string(model.num_tools()) + " tools");
  }
  why = PlanFailure::kNoPlan;
  ContactPlanningResult out;
  ContactCandidates& candidates = out.candidates;
  if (Status s = ContactPlanCandidates(model, o, &candidates); !s.ok()) return s;
  if (Status s = PlanContacts(model, candidates, request.count, 4, &out.plan); !s.ok()) {
    return Status::Error(
        s.message() + " (" + std::to_string(candidates.set.size()) + " candidates; dropped: " +
        std::to_string(candidates.not_converged) + " not reached, " +
        std::to_string(candidates.outside_limits) + " outside the joint limits, " +
        std::to_string(candidates.outside_cell) + " outside the cell, " +
        std::to_string(candidates.near_singular) + " near a singularity, " +
        std::to_string(candidates.outside_stroke) + " outside the stroke)");
  }
  Eigen::MatrixXd rows;
  if (Status s = ContactInformationRows(model, candidates, &rows); !s.ok()) return s;
  for (int d = 0; d < request.random_draws; ++d) {
    out.random_log_det.push_back(ContactPlanLogDet(
        rows, RandomPlan(candidates.set.size(), request.count, o.seed + 1000 + d)));
  }
  std::sort(out.random_log_det.begin(), out.random_log_det.end());
  if (!out.random_log_det.empty()) out.random_best_log_det = out.random_log_det.back();
  for (double v : out.random_log_det) out.random_mean_log_det += v / out.random_log_det.size();
  *result = std::move(out);
  why = PlanFailure::kNone;
  return Status::Ok();
}

}  // namespace lpoe
