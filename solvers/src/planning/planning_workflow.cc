#include "lpoe/joint_error_list.h"
#include "lpoe/planning_workflow.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/QR>

#include "lpoe/terms/joint_errors.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/options.h"
#include "lpoe/model/residual_layer.h"
#include "lpoe/model/refusals.h"

namespace lpoe {
namespace {

constexpr char kTool[] = "lpoe_plan";

Status Fail(PlanFailure kind, PlanFailure* failure, const std::string& message) {
  if (failure != nullptr) *failure = kind;
  return Status::Error(message);
}

}  // namespace

std::string PlanningResult::PlannedTerms() const {
  std::string text;
  for (const std::string& name : term_names) text += (text.empty() ? "" : ",") + name;
  if (tilt) text += std::string(",") + kGravityTiltName;
  return text.empty() ? "none" : text;
}

Status CheckPlanRequest(const PlanRequest& r) {
  if (r.count_auto) {
    if (!(r.target_accuracy > 0) || !(r.noise_sigma > 0)) {
      return Status::Error("--count=auto needs --target_accuracy > 0 and --noise_sigma > 0 (mm)");
    }
  } else if (r.count < 1 || r.count > 1000000) {
    return Status::Error("--count must be a number of poses from 1 to 1000000, or 'auto'");
  }
  const TrackerConstraint& t = r.constraints.tracker;
  for (const Status& s :
       {CheckOption(kTool, "noise_sigma", r.noise_sigma),
        CheckOption(kTool, "target_accuracy", r.target_accuracy),
        CheckOption(kTool, "candidate_count", r.candidate_count),
        CheckOption(kTool, "workspace_count", r.workspace_count),
        CheckOption(kTool, "random_draws", r.random_draws),
        CheckOption(kTool, "unmodelled_error", r.unmodelled_error),
        CheckOption(kTool, "unmodelled_length", r.unmodelled_length),
        CheckOption(kTool, "min_singularity", r.constraints.min_singularity),
        CheckOption(kTool, "acceptance_angle", t.acceptance_angle * 180.0 / kPi),
        CheckOption(kTool, "max_range", std::isinf(t.max_range) ? 0.0 : t.max_range)}) {
    if (!s.ok()) return s;
  }
  if (!t.enabled && (!t.facing.empty() || std::isfinite(t.max_range))) {
    return Status::Error("--smr_facing and --max_range need --tracker");
  }
  if (t.enabled && !t.position.allFinite()) {
    return Status::Error("--tracker must be x,y,z in mm (three finite numbers)");
  }
  if (!t.facing.empty() && static_cast<int>(t.facing.size()) != r.model.num_tools()) {
    return Status::Error("--smr_facing gives " + std::to_string(t.facing.size()) +
                         " directions; the model has " + std::to_string(r.model.num_tools()) +
                         " tools");
  }
  if (std::isnan(r.constraints.cell.min_z) ||
      r.constraints.cell.min_z == std::numeric_limits<double>::infinity()) {
    return Status::Error("--min_z must be a finite height in mm");
  }
  return Status::Ok();
}

Status NarrowJointRanges(const std::vector<std::pair<double, double>>& ranges, RobotModel* model) {
  if (static_cast<int>(ranges.size()) != model->num_joints()) {
    return Status::Error("--joint_ranges gives " + std::to_string(ranges.size()) +
                         " items; the model has " + std::to_string(model->num_joints()) +
                         " joints");
  }
  for (int j = 0; j < model->num_joints(); ++j) {
    const auto [lo, hi] = ranges[j];
    if (std::isnan(lo) && std::isnan(hi)) continue;  // the limits
    Joint& joint = model->joints[j];
    if (!std::isfinite(lo) || !std::isfinite(hi) || !(lo < hi)) {
      return Status::Error("--joint_ranges: the range for " + joint.name +
                           " is not lo:hi with lo < hi");
    }
    joint.lower = std::max(joint.lower, lo);
    joint.upper = std::min(joint.upper, hi);
    if (!(joint.lower < joint.upper)) {
      return Status::Error("--joint_ranges: the range for " + joint.name +
                           " does not overlap the joint's limits");
    }
  }
  return Status::Ok();
}

namespace {

// The joint-space terms, compliance first as lpoe_calibrate orders them (docs/joint_errors.md):
// out->term_names, and whether the gravity tilt was asked for.
Status PlannedTermNames(const PlanRequest& request, PlanningResult* out, bool* tilt,
                        PlanFailure* failure) {
  if (request.joint_errors == "auto") {
    out->term_names = JointTermNames();
    return Status::Ok();
  }
  std::vector<std::string> kinds, effects;
  std::string error;
  if (!ParseJointErrorList(request.joint_errors, &kinds, &effects, &error)) {
    return Fail(PlanFailure::kUsage, failure,
                "--joint_errors=" + request.joint_errors + ": " + error +
                    " (expected none, a comma-separated list of " + JointTermNameList() +
                    " or auto, " + BilinearEffectsHelp(/*example=*/false) + ")");
  }
  // The planning model accounts for the gravity tilt (PlanningModel), no other bilinear effect.
  *tilt = false;
  for (const std::string& e : effects) {
    if (e != kGravityTiltName) {
      return Fail(PlanFailure::kUsage, failure,
                  "--joint_errors=" + request.joint_errors + ": a plan cannot account for '" + e +
                      "' (of the bilinear effects, only the gravity tilt)");
    }
    *tilt = true;
  }
  out->term_names = InRegistryOrder(kinds);
  return Status::Ok();
}

// Candidates (out->candidates) and workspace, given or sampled.
Status PlanningConfigurations(const PlanRequest& request, const std::string& source,
                              PlanningResult* out, std::vector<double>* workspace,
                              PlanFailure* failure) {
  const RobotModel& model = request.model;
  if (request.has_candidates) {
    out->candidates = request.candidates;
  } else if (Status s = SampleConfigurations(model, request.candidate_count, request.seed,
                                             &out->candidates);
             !s.ok()) {
    return Fail(PlanFailure::kInput, failure, source + ": " + s.message());
  }
  if (request.has_workspace) {
    *workspace = request.workspace;
    // The accuracy over no configuration is no accuracy at all.
    if (workspace->empty()) {
      return Fail(PlanFailure::kInput, failure,
                  "workspace: no configurations (expected at least one)");
    }
  } else if (Status s = SampleConfigurations(model, request.workspace_count, request.seed + 1,
                                             workspace);
             !s.ok()) {
    return Fail(PlanFailure::kInput, failure, source + ": " + s.message());
  }
  const int n = model.num_joints();
  out->offered = static_cast<int>(out->candidates.size() / n);
  out->workspace_configurations = static_cast<int>(workspace->size() / n);
  return Status::Ok();
}

// The terms of out->term_names for the model, and the gravity tilt: planned for when asked
// (refused with the reason when the model carries no compliance values) and, with auto, whenever
// the model carries them (out->tilt, out->tilt_note).
Status PlanningTerms(const PlanRequest& request, const std::string& source, bool tilt,
                     PlanningResult* out, std::vector<std::shared_ptr<const JointTerm>>* terms,
                     PlanFailure* failure) {
  const RobotModel& model = request.model;
  for (const std::string& name : out->term_names) {
    std::shared_ptr<const JointTerm> term;
    if (Status s = MakeJointTerm(name, model, &term); !s.ok()) {
      return Fail(PlanFailure::kInput, failure, source + ": " + s.message());
    }
    terms->push_back(std::move(term));
  }
  if (const Status s = PlanningGravityTiltStatus(model, *terms); tilt && !s.ok()) {
    return Fail(PlanFailure::kUsage, failure,
                "--joint_errors=" + request.joint_errors + " with --model=" + source + ": " +
                    s.message());
  } else if (request.joint_errors == "auto") {
    tilt = s.ok();
    if (!tilt) {
      out->tilt_note = "the model carries no compliance values, so the gravity tilt's information "
                       "is zero (docs/planning.md)";
    }
  }
  out->tilt = tilt;
  return Status::Ok();
}

// A recalibration's data are registered anew (the tracker stands elsewhere): the rigid motions of
// the whole arm (the base frame's directions, and those of joint 1's centralizer that the
// parameterization leaves to joint 2's frame) are the registration's, not errors of the
// calibrated model. The predicted error over the workspace leaves them out, as a held-out check
// after a rigid fit does.
void LeaveOutRegistration(const PlanningModel& pm, Eigen::MatrixXd* workspace_moment) {
  const int P = pm.num_parameters();
  const Parameterization& par = pm.parameterization();
  const RobotModel& m = pm.model();
  std::vector<Eigen::VectorXd> rigid;
  if (m.num_joints() >= 1 && !par.basis.empty()) {
    for (int c = 0; c < par.basis[0].cols(); ++c) {
      rigid.push_back(Eigen::VectorXd::Unit(P, par.offset[0] + c));
    }
  }
  if (m.num_joints() >= 2 && par.basis.size() > 1 && par.basis[1].cols() > 0) {
    const Eigen::MatrixXd U =
        Adjoint(m.joints[1].origin.Inverse()) * TwistCentralizer(m.joints[0].twist);
    for (int c = 0; c < U.cols(); ++c) {
      Eigen::VectorXd v = Eigen::VectorXd::Zero(P);
      v.segment(par.offset[1], par.basis[1].cols()) = par.basis[1].transpose() * U.col(c);
      rigid.push_back(v);
    }
  }
  if (rigid.empty()) return;
  Eigen::MatrixXd R(P, static_cast<Eigen::Index>(rigid.size()));
  for (size_t k = 0; k < rigid.size(); ++k) R.col(static_cast<Eigen::Index>(k)) = rigid[k];
  const Eigen::HouseholderQR<Eigen::MatrixXd> qr(R);
  const Eigen::MatrixXd Q = (qr.householderQ() * Eigen::MatrixXd::Identity(P, P)).leftCols(R.cols());
  const Eigen::MatrixXd N = Eigen::MatrixXd::Identity(P, P) - Q * Q.transpose();
  *workspace_moment = N * *workspace_moment * N;
}

// What RunPlanning's steps share once the pool, the workspace moment and the prior are set.
struct PlanningContext {
  const PlanRequest& request;
  const PlanningModel& pm;
  const CandidatePool& pool;
  const Eigen::MatrixXd& L;   // the workspace moment
  const PlanOptions& options;
  const Eigen::MatrixXd& M0;  // the prior's information (empty: none)
  int P = 0;

  // The refusals: full rank (with the prior's information), and without a prior more rows than
  // parameters (lpoe/model/refusals.h).
  Status Refusal(const PlanQuality& quality, int count) const {
    if (!request.prior) return PlanRefusal(quality, P, count);
    return CheckFullRank(quality.rank, P, "the plan of " + std::to_string(count) +
                                              " poses with the prior");
  }
  Status PlanOf(int count, PlanningResult* out) const {
    if (Status s = SelectPlan(pm, pool, count, L, options, &out->plan); !s.ok()) return s;
    out->quality = EvaluatePlan(pm, pool, out->plan.selected, L, M0);
    return Status::Ok();
  }
};

// The plan of request.count poses, or for count_auto the smallest plan predicted to reach the
// target (out->count, out->plan, out->quality), refused as PlanningContext::Refusal says.
Status PlanOfTheCount(const PlanningContext& c, PlanningResult* out, PlanFailure* failure) {
  const PlanRequest& request = c.request;
  const CandidatePool& pool = c.pool;
  int count = request.count;
  if (request.count_auto) {
    const double sigma = request.noise_sigma, target = request.target_accuracy;
    std::vector<int> all(pool.size());
    for (int k = 0; k < pool.size(); ++k) all[k] = k;
    const double best = sigma * EvaluatePlan(c.pm, pool, all, c.L, c.M0).predicted_rms;
    if (pool.size() == 0 || !(best <= target)) {
      char text[200];
      std::snprintf(text, sizeof(text),
                    "even all %d feasible candidates are predicted to reach %g mm, not %g mm: "
                    "offer more candidates or accept a larger target",
                    pool.size(), best, target);
      return Fail(PlanFailure::kNoPlan, failure, text);
    }
    auto reaches = [&](int k) {
      return c.PlanOf(k, out).ok() && c.Refusal(out->quality, k).ok() &&
             sigma * out->quality.predicted_rms <= target;
    };
    int max_rows = 3;
    for (int k = 0; k < pool.size(); ++k) max_rows = std::max(max_rows, pool.rows(k));
    // Without a prior fewer than P rows fail; with one a single pose may do.
    int lo = request.prior ? 0 : std::max(1, (c.P + max_rows - 1) / max_rows) - 1;  // fails
    int hi = std::min(pool.size(), std::max(lo + 1, 2 * lo));
    while (!reaches(hi)) {
      if (hi >= pool.size()) {  // even every feasible candidate: refused, never a loop
        const Status refused = c.PlanOf(hi, out).ok() ? c.Refusal(out->quality, hi)
                                                      : Status::Error("no plan of all candidates");
        return Fail(PlanFailure::kNoPlan, failure,
                    "all " + std::to_string(pool.size()) + " feasible candidates: " +
                        (refused.ok() ? "the target accuracy is out of reach" : refused.message()) +
                        ": offer more candidates");
      }
      lo = hi;
      hi = std::min(pool.size(), 2 * hi);
    }
    while (hi - lo > 1) {  // reaches(hi), not reaches(lo)
      const int mid = lo + (hi - lo) / 2;
      (reaches(mid) ? hi : lo) = mid;
    }
    count = hi;
    if (Status s = c.PlanOf(count, out); !s.ok()) {
      return Fail(PlanFailure::kNoPlan, failure, s.message());
    }
  } else if (Status s = c.PlanOf(count, out); !s.ok()) {
    return Fail(PlanFailure::kNoPlan, failure,
                s.message() + " (" + std::to_string(pool.outside_limits) +
                    " outside the limits, " + std::to_string(pool.outside_cell) +
                    " outside the cell, " + std::to_string(pool.near_singular) +
                    " near a singularity, " + std::to_string(pool.nothing_visible) +
                    " with no SMR visible)");
  }
  out->count = count;
  if (Status s = c.Refusal(out->quality, count); !s.ok()) {
    return Fail(PlanFailure::kNoPlan, failure, s.message());
  }
  return Status::Ok();
}

// The unmodelled error (docs/planning.md, "Unmodelled error"): the residual layer's, given, or
// the default (out->unmodelled, out->unmodelled_source, out->prediction_sigma).
void UnmodelledErrorOfRequest(const PlanRequest& request, PlanningResult* out) {
  const RobotModel& model = request.model;
  UnmodelledErrorModel& u = out->unmodelled;
  if (model.residual_layer && !request.unmodelled_given) {
    u.std = model.residual_layer->signal_std;
    u.length_scales = model.residual_layer->length_scales;
    u.tool_correlation = model.residual_layer->tool_correlation;
    out->unmodelled_source = "residual layer";
  } else {
    u.std = request.unmodelled_error;
    u.length_scales = Eigen::VectorXd::Constant(model.num_joints(), request.unmodelled_length);
    out->unmodelled_source = request.unmodelled_given ? "given" : "default";
  }
  out->prediction_sigma = request.noise_sigma > 0 ? request.noise_sigma : kPlanDefaultNoiseSigma;
}

// Random plans of the same size, for comparison; with an unmodelled error the plan is the best,
// by the predicted error, of the criterion's plan and the random plans, improved by swaps while
// the predicted error decreases. --count=auto keeps the smallest plan whose noise part reaches the
// target: the exchange, which trades noise for bias, would undo that; its prediction is still
// reported.
Status CompareWithRandomPlans(const PlanningContext& c, const UnmodelledPlanning& unmodelled,
                              PlanningResult* out, PlanFailure* failure) {
  const PlanRequest& request = c.request;
  std::vector<std::vector<int>> random_plans;
  for (int k = 0; k < request.random_draws; ++k) {
    random_plans.push_back(RandomPlan(c.pool.size(), out->count, request.seed + 1000 + k));
  }
  out->unmodelled_start = "criterion";
  if (out->unmodelled.std > 0 && !request.count_auto && !request.prior) {
    std::vector<int> start = out->plan.selected;
    double best = unmodelled.Predict(start).total_rms;
    for (size_t k = 0; k < random_plans.size(); ++k) {
      const double t = unmodelled.Predict(random_plans[k]).total_rms;
      if (t < best) {
        best = t;
        start = random_plans[k];
        out->unmodelled_start = "random draw " + std::to_string(k + 1);
      }
    }
    out->unmodelled_swaps = unmodelled.Exchange(&start, request.options.max_exchange_passes,
                                                32, request.seed + 2);
    out->plan.selected = start;
    out->quality = EvaluatePlan(c.pm, c.pool, out->plan.selected, c.L, c.M0);
    if (Status s = c.Refusal(out->quality, out->count); !s.ok()) {
      return Fail(PlanFailure::kNoPlan, failure, s.message());
    }
  }
  // With a prior the predicted error is the posterior's noise part (the unmodelled error's
  // prediction is that of a least-squares calibration): the same figure for the random plans.
  auto predict = [&](const std::vector<int>& plan, const PlanQuality& quality) {
    if (!request.prior) return unmodelled.Predict(plan);
    PlanErrorPrediction e;
    e.noise_rms = e.total_rms = out->prediction_sigma * quality.predicted_rms;
    e.unmodelled_rms = 0;
    return e;
  };
  if (request.prior) out->prediction_sigma = out->prior_sigma;
  out->prediction = predict(out->plan.selected, out->quality);
  for (size_t k = 0; k < random_plans.size(); ++k) {
    const PlanQuality r = EvaluatePlan(c.pm, c.pool, random_plans[k], c.L, c.M0);
    if (k == 0) out->random_quality = r;
    out->random_rms.push_back(r.predicted_rms);
    out->random_total_rms.push_back(predict(random_plans[k], r).total_rms);
  }
  auto rms_of_finite = [](std::vector<double>* values) {
    std::sort(values->begin(), values->end());
    double mean_sq = 0;
    int finite = 0;
    for (double v : *values) {
      if (std::isfinite(v)) {
        mean_sq += v * v;
        ++finite;
      }
    }
    return finite > 0 ? std::sqrt(mean_sq / finite) : std::numeric_limits<double>::infinity();
  };
  out->random_rms_mean = rms_of_finite(&out->random_rms);
  out->random_total_rms_mean = rms_of_finite(&out->random_total_rms);
  return Status::Ok();
}

// The gravity tilt's predicted standard deviations with the plan (the last two parameters of
// M^-1, at the model's compliance values): what the calibration's a-posteriori ones will be.
void PredictTiltDeviations(const PlanningContext& c, PlanningResult* out) {
  if (c.pm.num_tilt_parameters() == 0) return;
  const int P = c.P;
  Eigen::MatrixXd M = Information(c.pool, out->plan.selected);
  if (c.M0.rows() == P) M += c.M0;
  const Eigen::VectorXd d = M.diagonal().cwiseMax(1e-300).cwiseSqrt().cwiseInverse();
  const Eigen::MatrixXd Ms = d.asDiagonal() * M * d.asDiagonal();
  const Eigen::MatrixXd Cs = Ms.ldlt().solve(Eigen::MatrixXd::Identity(P, P));
  for (int a = 0; a < 2; ++a) {
    const int k = P - 2 + a;
    out->tilt_sd_deg_per_unit[a] = std::sqrt(std::max(0.0, Cs(k, k))) * d(k) * 180.0 / kPi;
  }
}

}  // namespace

Status RunPlanning(const PlanRequest& request, PlanningResult* result, PlanFailure* failure) {
  PlanningResult& out = *result;
  out = PlanningResult();
  if (failure != nullptr) *failure = PlanFailure::kNone;
  if (Status s = CheckPlanRequest(request); !s.ok()) {
    return Fail(PlanFailure::kUsage, failure, s.message());
  }
  const RobotModel& model = request.model;
  const std::string& source = request.model_source.empty() ? model.name : request.model_source;
  if (Status s = model.Validate(); !s.ok()) {
    return Fail(PlanFailure::kInput, failure, source + ": " + s.message());
  }
  bool tilt = false;  // the gravity tilt, asked for
  if (Status s = PlannedTermNames(request, &out, &tilt, failure); !s.ok()) return s;
  std::vector<double> workspace;
  if (Status s = PlanningConfigurations(request, source, &out, &workspace, failure); !s.ok()) {
    return s;
  }
  std::vector<std::shared_ptr<const JointTerm>> terms;
  if (Status s = PlanningTerms(request, source, tilt, &out, &terms, failure); !s.ok()) return s;

  // The feasible candidates; with joint-space terms, their identifiable combinations are those the
  // feasible candidates separate from the geometry (the solvers' reduction), and the pool's rows
  // gain their columns.
  out.planning =
      BuildPlanningPool(model, terms, out.candidates, request.constraints, &out.pool, out.tilt);
  const PlanningModel& pm = *out.planning;
  out.workspace_moment = WorkspaceMoment(pm, workspace);
  if (request.prior) LeaveOutRegistration(pm, &out.workspace_moment);
  // A prior (lpoe_plan --prior): the plan's information is added to its own (the posterior).
  PlanOptions options = request.options;
  if (request.prior) {
    out.prior_sigma = request.noise_sigma > 0             ? request.noise_sigma
                      : request.prior->data_sigma_mm > 0 ? request.prior->data_sigma_mm
                                                         : kPlanDefaultNoiseSigma;
    options.prior_information = PlanningPriorInformation(pm, *request.prior, out.prior_sigma);
  }
  const PlanningContext c{request, pm, out.pool, out.workspace_moment, options,
                          options.prior_information, pm.num_parameters()};
  if (Status s = PlanOfTheCount(c, &out, failure); !s.ok()) return s;
  UnmodelledErrorOfRequest(request, &out);
  const UnmodelledPlanning unmodelled(pm, out.pool, workspace, c.L, out.unmodelled,
                                      out.prediction_sigma);
  if (Status s = CompareWithRandomPlans(c, unmodelled, &out, failure); !s.ok()) return s;
  PredictTiltDeviations(c, &out);
  return Status::Ok();
}

}  // namespace lpoe
