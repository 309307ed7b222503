#include "lpoe/pipeline.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <utility>

#include <Eigen/Cholesky>
#include <glog/logging.h>

#include "calibration/block_kind.h"
#include "identifiability/structural_identifiability.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/measurements/measurement_kind_dispatch.h"
#include "lpoe/problem_builder.h"
#include "calibration/solve_on_problem.h"
#include "lpoe/model/refusals.h"

namespace lpoe {
namespace {

// Copies the identified joint-error values of result.joint_terms into result.model.joint_errors,
// with the geometry their regressors were evaluated on (`start`'s joint origins).
CalibrationResult StoreJointErrors(CalibrationResult result, const RobotModel& start) {
  for (const JointTermValues& t : result.joint_terms) {
    // Every solver term is a registry entry (MakeJointTerm), so its name is the model's key.
    CHECK(IsJointTermName(t.term->name())) << t.term->name();
    *result.model.joint_errors.MutableValues(t.term->name()) =
        std::vector<double>(t.theta.data(), t.theta.data() + t.theta.size());
    result.model.joint_errors.regressor_origins.clear();
    for (const Joint& j : start.joints) {
      result.model.joint_errors.regressor_origins.push_back(j.origin);
    }
  }
  // The identified bilinear effects go into the model (block_kind.h: the tilt is the calibrated
  // model's gravity, the compliance values belong to it).
  for (const internal::BlockKind* kind : internal::BlockKinds()) {
    if (kind->bilinear() != nullptr) kind->bilinear()->ApplyToModel(result, &result.model);
  }
  return result;
}

// The model without its joint-error values.
RobotModel Geometric(const RobotModel& model) {
  RobotModel g = model;
  g.joint_errors = JointErrorTerms();
  g.residual_layer = nullptr;
  return g;
}

// True when a and b predict the same tool positions from the same joint values: the same joints
// (type, twist, local frame) and tool frames (joint-error terms and gravity aside).
bool SameGeometry(const RobotModel& a, const RobotModel& b) {
  auto same = [](const SE3d& x, const SE3d& y) { return x.R == y.R && x.t == y.t; };
  if (a.num_joints() != b.num_joints() || a.num_tools() != b.num_tools()) return false;
  for (int i = 0; i < a.num_joints(); ++i) {
    const Joint& x = a.joints[i];
    const Joint& y = b.joints[i];
    if (x.type != y.type || x.twist != y.twist || !same(x.origin, y.origin)) return false;
  }
  for (int t = 0; t < a.num_tools(); ++t) {
    if (!same(a.tools[t].origin, b.tools[t].origin)) return false;
  }
  return true;
}

// The verdict's measure of how far the data determine each frame's change (plausibility.h): the
// Mahalanobis norm of the change of the frame's identified parameters under the posterior
// covariance, and under the prior's standard deviations (a diagonal approximation of the prior).
void FrameChangeSigmas(const CalibrationResult& r, const RobotModel& start,
                       const RobotModel& calibrated, PlausibilityOptions* o) {
  const Parameterization& p = r.parameterization;
  if (r.covariance.rows() != p.num_parameters || p.basis.size() != start.tools.size() + start.joints.size()) {
    return;
  }
  const Eigen::VectorXd dx = ParameterDifference(p, start, calibrated);
  o->frame_change_sigmas.assign(p.basis.size(), 0.0);
  o->frame_prior_sigmas.assign(p.basis.size(), INFINITY);
  for (size_t f = 0; f < p.basis.size(); ++f) {
    const int k = static_cast<int>(p.basis[f].cols());
    if (k == 0) continue;
    const Eigen::VectorXd d = dx.segment(p.offset[f], k);
    const Eigen::MatrixXd C = r.covariance.block(p.offset[f], p.offset[f], k, k);
    const Eigen::LDLT<Eigen::MatrixXd> ldlt(C);
    const double z2 = d.dot(ldlt.solve(d));
    o->frame_change_sigmas[f] = std::isfinite(z2) && z2 >= 0 ? std::sqrt(z2) : INFINITY;
    if (r.has_prior()) {
      double zp2 = 0;
      for (int c = 0; c < k; ++c) {
        const double sd = r.prior_standard_deviation(p.offset[f] + c);
        if (std::isfinite(sd) && sd > 0) zp2 += (d(c) / sd) * (d(c) / sd);
      }
      o->frame_prior_sigmas[f] = std::sqrt(zp2);
    }
  }
}

// What the analysis would otherwise compute with passes of its own over the identification rows
// (docs/performance.md): the statistics of `before`, and the solver's errors at its result.
struct SolveErrors {
  LinearSolverErrors solver;
  bool have_before = false;
  ErrorStatistics before;
};

// A failed solve before any solver ran (registration or a term refused), at `model`.
CalibrationResult Refused(const RobotModel& model, const std::string& message) {
  CalibrationResult failed;
  failed.model = model;
  failed.termination = Termination::kNotIdentifiable;
  failed.message = message;
  return failed;
}

// One calibration of the pipeline (SolveCalibration): the start (registered), the structural
// decision, the prior's anchoring and the joint-space terms, made once here and handed to the
// solver chosen; the solve repeated while the decision at the solution differs; the gravity tilt
// solved from the compliance solution. Each stage a member function.
class PipelineSolve {
 public:
  PipelineSolve(const RobotModel& nominal, const MeasurementSet& data,
                const PipelineOptions& options, const std::string& stage, RobotModel* before,
                RobotModel* start_out, SolveErrors* errors)
      : nominal_(nominal),
        data_(data),
        options_(options),
        stage_(stage),
        before_(before),
        start_out_(start_out),
        errors_(errors),
        start_(nominal),
        measured_(nominal.num_tools(), false) {
    for (int r = 0; r < data.size(); ++r) measured_[data.target(r)] = true;
    orientation_weight_ = Chosen().orientation_weight;
  }
  CalibrationResult Run(RegistrationReport* registration);

 private:
  // The start: registered to the data (or the nominal model), joint-error terms and a residual
  // layer dropped. False with *failed set when the registration refuses the data.
  bool Register(RegistrationReport* registration, CalibrationResult* failed);
  // The structurally unidentifiable directions decided at the start with the measured tool points
  // where the fit put them (reference_, lost_), and the start's tool points moved there when its
  // own would decide otherwise.
  void DecideStructure();
  // The measured, free tools' points of the start from `from`'s.
  void StartToolsFrom(const RobotModel& from);
  // The prior anchored at the start (its reference this start, or its own with this registration).
  void AnchorPrior();
  // The joint-space terms asked for, on the start; false with *failed set when one is refused.
  bool MakeTerms(CalibrationResult* failed);
  // The chosen solver's share of the options (problem_options.h): where the problem's decisions
  // the pipeline does not make itself (orientation_weight, joint_term_tolerance) are read.
  const ProblemDefinitionOptions& Chosen() const {
    if (options_.solver == SolverKind::kCeres) return options_.ceres;
    return options_.linear;
  }
  // Every decision of one solve, in one place: Chosen() with the pipeline's own (parameterization,
  // orientation, terms, structure reference, prior; with `effects` those bilinear effects from
  // the joint values `initial`). Both the problem and the solver's options take it whole.
  ProblemDefinitionOptions Decisions(const BilinearEffects& effects,
                                     const std::vector<JointTermValues>& initial) const;
  // One solve; with `effects` those bilinear effects from the joint values `initial`.
  CalibrationResult Once(const BilinearEffects& effects,
                         const std::vector<JointTermValues>& initial);
  // The one problem of a solve, for either solver (null when the options do not pass
  // ValidateCalibrationProblem: the solver's own entry then reports why, as it always did).
  std::unique_ptr<CalibrationProblem> Problem(const ProblemDefinitionOptions& decisions) const;
  CalibrationResult OnceLinear(CalibrationProblem* problem, LinearSolverOptions o, bool bilinear);
  // Rounds of the decision at the solution, solved again while it differs.
  void SettleStructure(CalibrationResult* result);
  // A bilinear kind (block_kind.h: the gravity tilt): its rule at the solution with its partner
  // term (`result`), then solved from there when the data determine it.
  CalibrationResult SolveBilinear(const internal::BilinearBlockKind& kind,
                                  CalibrationResult result);

  const RobotModel& nominal_;
  const MeasurementSet& data_;
  const PipelineOptions& options_;
  const std::string& stage_;
  RobotModel* before_;
  RobotModel* start_out_;
  SolveErrors* errors_;
  RobotModel start_;
  // The tool points fitted to the data with the nominal joints (registration's stage 2) and the
  // RMS residual per axis of that fit: where the structural decision starts.
  RobotModel fitted_;
  double fitted_rms_ = 0;
  bool have_fitted_ = false;
  bool start_is_fitted_ = false;  // the start is the registered model (tool points fitted)
  double orientation_weight_ = 0;
  std::vector<bool> measured_;
  RobotModel reference_;
  std::vector<Direction> lost_;
  std::shared_ptr<const ParameterPrior> prior_;
  std::vector<std::shared_ptr<const JointTerm>> terms_;
  // The bilinear kinds asked for in the joint errors, in their order.
  std::vector<const internal::BilinearBlockKind*> bilinear_;
  std::function<void(const IterationRecord&)> progress_;
};

bool PipelineSolve::Register(RegistrationReport* registration, CalibrationResult* failed) {
  if (before_) *before_ = nominal_;
  if (options_.register_frames) {
    if (options_.on_stage) options_.on_stage("registering");
    RegistrationReport local;
    RegistrationReport& rep = registration ? *registration : local;
    if (Status s = RegisterToMeasurements(nominal_, data_, &start_, &rep); !s.ok()) {
      *failed = Refused(nominal_, s.message());
      if (start_out_) *start_out_ = nominal_;
      return false;
    }
    fitted_ = start_;
    fitted_rms_ = rep.rms_base_tools / std::sqrt(3.0);
    have_fitted_ = true;
    start_is_fitted_ = rep.moved;
    if (!rep.moved) {
      // The data are in the base frame already: start from the nominal model, as the paper does.
      start_ = nominal_;
    } else {
      // Gravity stays attached to the robot: turned with joint 1's frame as the registration left
      // it (rigid fit and base refit), so that an axis parallel to gravity in the nominal model
      // stays parallel (a vertical joint 1 keeps a zero compliance regressor instead of columns of
      // 1e-5 relative size that the column-scaled solvers would fit with huge cancelling values).
      start_.gravity = start_.joints[0].origin.R * nominal_.joints[0].origin.R.transpose() *
                       nominal_.gravity;
      if (before_) before_->joints[0].origin = rep.T_measurement_base * nominal_.joints[0].origin;
    }
  }
  // The solvers fit the geometry (and the terms asked for) on the commanded joints: joint-error
  // terms the nominal model carries are not part of that cost, so they are not carried into the
  // calibrated model either (they would count twice, on a geometry they were not identified on).
  start_.joint_errors = JointErrorTerms();
  // Likewise a residual layer (it was fitted on another model's residuals).
  start_.residual_layer = nullptr;
  if (before_) before_->residual_layer = nullptr;
  if (!options_.register_frames) {
    // The start stays the nominal model; the tool points are fitted only for the decision below.
    RegistrationReport rep;
    if (RegisterToMeasurements(nominal_, data_, &fitted_, &rep).ok()) {
      fitted_rms_ = rep.rms_base_tools / std::sqrt(3.0);
      have_fitted_ = true;
    }
  }
  return true;
}

void PipelineSolve::StartToolsFrom(const RobotModel& from) {
  for (int t = 0; t < start_.num_tools(); ++t) {
    if (measured_[t] && !start_.tools[t].fixed) start_.tools[t].origin.t = from.tools[t].origin.t;
  }
}

// Which frame directions no data can determine is decided at an estimate, never at the nominal
// tool points alone (structural_identifiability.h, docs/identifiability.md): first at the start
// with the measured tool points where the fit put them, then again at each solution; when the
// decision there differs, the calibration is solved again with it (from the solution's tool
// points), until the decision a model was solved with is the one at that model.
void PipelineSolve::DecideStructure() {
  const bool use_orientation = options_.use_orientation;
  reference_ = start_;
  if (have_fitted_) {
    for (int t = 0; t < start_.num_tools(); ++t) {
      if (measured_[t] && !start_.tools[t].fixed) {
        reference_.tools[t].origin.t = fitted_.tools[t].origin.t;
      }
    }
  }
  reference_ = internal::StructureReference(reference_, data_, fitted_rms_);
  lost_ = internal::StructurallyUnidentifiable(reference_, data_, use_orientation,
                                               orientation_weight_);
  // The start must let the solver see what the decision keeps: when its own tool points would
  // decide otherwise (a nominal tool0 on the axis for an SMR off it), it starts from the
  // reference's (the fitted ones, those within the noise of the axis on it). A registered start
  // has the fitted tool points already: those put on the axis start there too.
  if (have_fitted_ &&
      (start_is_fitted_ ||
       !internal::SameDirections(internal::StructurallyUnidentifiable(
                                     start_, data_, use_orientation, orientation_weight_),
                                 lost_))) {
    StartToolsFrom(reference_);
  }
  if (start_out_) *start_out_ = start_;
}

void PipelineSolve::AnchorPrior() {
  // The prior's reference: this start (registered, tool points fitted), for every solve below.
  if (!options_.prior || options_.parameterization != ParameterizationKind::kIdentifiable) return;
  if (options_.prior->reference) {
    // A prior of its own (a previous calibration, a fleet): its base frame is this data's
    // registration (the tracker stood elsewhere), held by the tolerances only.
    auto anchored = std::make_shared<ParameterPrior>(*options_.prior);
    auto reference = std::make_shared<RobotModel>(*options_.prior->reference);
    if (reference->num_frames() == start_.num_frames() && start_.num_joints() > 0) {
      reference->joints[0].origin = start_.joints[0].origin;
      FreeRegistrationDirections(*reference, anchored.get());
    }
    anchored->reference = reference;
    prior_ = anchored;
  } else {
    auto anchored = std::make_shared<ParameterPrior>(*options_.prior);
    anchored->reference = std::make_shared<const RobotModel>(start_);
    prior_ = anchored;
  }
}

bool PipelineSolve::MakeTerms(CalibrationResult* failed) {
  const std::vector<std::string>& names = options_.joint_errors;
  for (const std::string& name : names) {
    // A bilinear kind (block_kind.h: the tilt) needs its partner term in the list.
    const internal::BilinearBlockKind* kind = internal::FindBilinearBlockKind(name);
    if (kind != nullptr) {
      if (std::find(names.begin(), names.end(), kind->partner_term()) == names.end()) {
        *failed = Refused(start_, kind->needs_partner_message());
        return false;
      }
      // One bilinear effect per calibration: its stage checks it at the solution with its partner
      // and solves from there; a second one's stage would check it at the first's start values.
      if (!bilinear_.empty()) {
        *failed = Refused(start_, std::string("one bilinear effect per calibration: '") +
                                      bilinear_.front()->name() + "' and '" + name + "' are both "
                                      "listed");
        return false;
      }
      bilinear_.push_back(kind);
      continue;
    }
    std::shared_ptr<const JointTerm> term;
    if (Status s = MakeJointTerm(name, start_, &term); !s.ok()) {
      *failed = Refused(start_, s.message());
      return false;
    }
    terms_.push_back(term);
  }
  return true;
}

// A bilinear block (the tilt) is a curved direction: Gauss-Newton converges on it linearly, so the
// statistical stopping rule (convergence.h) is tightened 100x there, which keeps the two solvers'
// tilts within 1e-4 of its standard deviation of each other (as the linear terms' one-step
// convergence does without it).
constexpr double kBilinearSdFraction = 1e-2;

CalibrationResult PipelineSolve::Once(const BilinearEffects& effects,
                                      const std::vector<JointTermValues>& initial) {
  // Every decision once, in one problem, whichever solver takes it; the solver's options carry the
  // same decisions (their ProblemDefinitionOptions base), for a solver's own entry when the problem
  // is refused.
  const ProblemDefinitionOptions decisions = Decisions(effects, initial);
  auto common = [&](auto& o) {
    static_cast<ProblemDefinitionOptions&>(o) = decisions;
    o.on_iteration = progress_;
    if (!effects.empty()) o.convergence.sd_fraction *= kBilinearSdFraction;
  };
  const std::unique_ptr<CalibrationProblem> problem = Problem(decisions);
  if (options_.solver == SolverKind::kCeres) {
    CeresSolverOptions o = options_.ceres;
    common(o);
    return problem ? internal::CalibrateCeresOn(problem.get(), o) : CalibrateCeres(start_, data_, o);
  }
  LinearSolverOptions o = options_.linear;
  common(o);
  return OnceLinear(problem.get(), std::move(o), !effects.empty());
}

ProblemDefinitionOptions PipelineSolve::Decisions(
    const BilinearEffects& effects, const std::vector<JointTermValues>& initial) const {
  ProblemDefinitionOptions d = Chosen();
  d.parameterization = options_.parameterization;
  d.use_orientation = options_.use_orientation;
  d.joint_terms = terms_;
  d.structure_reference = &reference_;
  d.bilinear_effects = effects;
  d.initial_joint_terms = initial;
  d.prior = prior_;
  return d;
}

std::unique_ptr<CalibrationProblem> PipelineSolve::Problem(
    const ProblemDefinitionOptions& decisions) const {
  // Ceres's share (sigma, loss, rows per block) is read by the Ceres solver only.
  CalibrationProblemOptions o = internal::CeresProblemOptions(options_.ceres, data_.size());
  static_cast<ProblemDefinitionOptions&>(o) = decisions;
  if (!ValidateCalibrationProblem(start_, data_, o).ok()) return nullptr;
  return std::make_unique<CalibrationProblem>(start_, data_, o);
}

CalibrationResult PipelineSolve::OnceLinear(CalibrationProblem* problem, LinearSolverOptions o,
                                            bool bilinear) {
  if (errors_ != nullptr && before_ != nullptr && !options_.use_orientation && terms_.empty() &&
      !bilinear) {
    // The errors before calibration come from the solver's first linearization when it starts
    // there; otherwise from a pass of their own now, so that its 16 bytes a row are freed
    // before the solver keeps its own.
    if (SameGeometry(*before_, start_)) {
      errors_->solver.want_start_statistics = true;
    } else {
      errors_->before = PositionErrorStatistics(*before_, data_);
      errors_->have_before = true;
    }
    o.errors = &errors_->solver;
  }
  CalibrationResult r =
      problem != nullptr ? internal::CalibrateLinearOn(problem, o) : CalibrateLinear(start_, data_, o);
  if (errors_ != nullptr && errors_->solver.have_start_statistics) {
    errors_->before = errors_->solver.start_statistics;
    errors_->have_before = true;
  }
  return r;
}

void PipelineSolve::SettleStructure(CalibrationResult* result) {
  // Rounds of the decision at the solution: one more solve is the rule (a tool point the fit left
  // on the axis that the calibration moves off it, or back); the limit only bounds a cycle.
  constexpr int kMaxDecisionRounds = 4;
  const bool use_orientation = options_.use_orientation;
  for (int round = 1; round <= kMaxDecisionRounds; ++round) {
    if (result->termination != Termination::kConverged &&
        result->termination != Termination::kMaxIterations) {
      break;
    }
    const RobotModel at = internal::StructureReference(
        Geometric(result->model), data_,
        internal::RmsPerAxisOfCost(result->final_cost, data_, use_orientation));
    std::vector<Direction> lost_at =
        internal::StructurallyUnidentifiable(at, data_, use_orientation, orientation_weight_);
    if (internal::SameDirections(lost_at, lost_)) break;
    if (round == kMaxDecisionRounds) {
      result->message += (result->message.empty() ? "" : "; ") +
                         std::string("the directions left out did not settle after ") +
                         std::to_string(kMaxDecisionRounds) +
                         " solves: the data barely separate a tool point from the last axis";
      break;
    }
    reference_ = at;
    lost_ = std::move(lost_at);
    // From the solution's tool points, those within the noise of the axis on it (exactly what was
    // decided: a full parameterization must not find the left-out tilt weakly present at its
    // start).
    StartToolsFrom(reference_);
    if (start_out_) *start_out_ = start_;
    if (options_.on_stage) options_.on_stage(stage_ + " (directions decided at the solution)");
    *result = Once({}, {});
  }
}

CalibrationResult PipelineSolve::SolveBilinear(const internal::BilinearBlockKind& kind,
                                                CalibrationResult result) {
  const double tolerance = Chosen().joint_term_tolerance;
  // The kind's rule at the solution with its partner (block_kind.h).
  CalibrationResult check;
  const bool identifiable =
      kind.Identifiable(start_, data_, result, options_.use_orientation, orientation_weight_,
                        tolerance, options_.gravity_tilt_max_sigma, &check);
  if (!identifiable) {
    kind.Record(check, nullptr, "", &result);
    return result;
  }
  CalibrationResult solved = Once({kind.MakeEffect(start_)}, result.joint_terms);
  if (!solved.converged()) {
    kind.Record(check, nullptr,
                std::string(kind.description()) + ": the solve with the " + kind.name() +
                    " did not converge (" + TerminationName(solved.termination) + ": " +
                    solved.message + ")",
                &result);
    return result;
  }
  kind.Record(check, &solved, "", &solved);
  return solved;
}

CalibrationResult PipelineSolve::Run(RegistrationReport* registration) {
  CalibrationResult failed;
  if (!Register(registration, &failed)) return failed;
  DecideStructure();
  AnchorPrior();
  if (!MakeTerms(&failed)) return failed;
  if (options_.on_iteration) {
    progress_ = [this](const IterationRecord& r) { options_.on_iteration(stage_, r); };
  }
  CalibrationResult result = Once({}, {});
  SettleStructure(&result);
  // A data set with no more rows than parameters cannot check itself (lpoe/model/refusals.h, the check
  // lpoe_plan and lpoe.plan make on a plan): the fit is exact whatever the errors, every residual
  // zero and no standard deviation estimable. Refused as not identifiable (exit 3), not passed.
  if (result.converged()) {
    const MeasurementKindId kind =
        TrackerKindId(options_.use_orientation && data_.has_orientation());
    const int64_t rows = int64_t{data_.size()} * MeasurementKind(kind).residuals;
    const int parameters = result.parameterization.num_parameters;
    // An informative prior (a previous calibration, a fleet) checks what the rows alone cannot.
    if (rows <= parameters && !(prior_ && prior_->informative)) {
      result.termination = Termination::kNotIdentifiable;
      result.message = CheckRedundancy(static_cast<int>(rows), parameters,
                                       "the data set of " + std::to_string(data_.size()) +
                                           " points")
                           .message();
      return StoreJointErrors(std::move(result), start_);
    }
  }
  for (const internal::BilinearBlockKind* kind : bilinear_) {
    if (!result.converged()) break;
    result = SolveBilinear(*kind, std::move(result));
  }
  return StoreJointErrors(std::move(result), start_);
}

// SolveCalibration; with `errors`, also fills them (the linear solver on position data without
// joint-space terms; otherwise they stay empty).
CalibrationResult Solve(const RobotModel& nominal, const MeasurementSet& data,
                        const PipelineOptions& options, const std::string& stage,
                        RegistrationReport* registration, RobotModel* before,
                        RobotModel* start_out, SolveErrors* errors) {
  return PipelineSolve(nominal, data, options, stage, before, start_out, errors).Run(registration);
}

}  // namespace

CalibrationResult SolveCalibration(const RobotModel& nominal, const MeasurementSet& data,
                                   const PipelineOptions& options, const std::string& stage,
                                   RegistrationReport* registration, RobotModel* before,
                                   RobotModel* start) {
  return Solve(nominal, data, options, stage, registration, before, start, nullptr);
}

namespace {

// Which tools some row of `data` measures.
std::vector<bool> MeasuredTools(const RobotModel& model, const MeasurementSet& data) {
  std::vector<bool> measured(model.num_tools(), false);
  for (int r = 0; r < data.size(); ++r) measured[data.target(r)] = true;
  return measured;
}

// Known SMR nests (Tool::fixed) the data never measure identify nothing: said, not refused. The
// calibrated model does not record them as fixed (it would claim the flange identified,
// docs/programs.md).
void UnmeasuredFixedTools(const RobotModel& nominal, const MeasurementSet& identification,
                          PipelineResult* out) {
  const std::vector<bool> measured = MeasuredTools(nominal, identification);
  for (int t = 0; t < out->result.model.num_tools(); ++t) {
    if (out->result.model.tools[t].fixed && !measured[t]) out->result.model.tools[t].fixed = false;
  }
}

void WarnUnmeasuredFixedTools(const RobotModel& nominal, const MeasurementSet& identification,
                              PipelineResult* out) {
  const std::vector<bool> measured = MeasuredTools(nominal, identification);
  bool any_measured = false;
  std::string unmeasured;
  for (int t = 0; t < nominal.num_tools(); ++t) {
    if (!nominal.tools[t].fixed) continue;
    any_measured = any_measured || measured[t];
    if (!measured[t]) unmeasured += (unmeasured.empty() ? "" : ", ") + nominal.tools[t].name;
  }
  if (unmeasured.empty()) return;
  out->identifiability.warnings.push_back(
      "fixed tool(s) " + unmeasured +
      " not measured in these data (recorded as not fixed in the calibrated model): held as "
      "given, they " +
      (any_measured ? "add nothing to the calibration"
                    : "identify nothing, and the last joint's zero and its translation along "
                      "the axis stay a convention traded against the other tools' offsets"));
}

// The statistics before and after, the identifiability at the solution and the outliers; the
// solver's kept errors (SolveErrors) serve them when they are those of the result.
// `identification_eff`: the identification rows at the effective joint values of the result.
void AnalyseSolution(const RobotModel& nominal, const MeasurementSet& identification,
                     const MeasurementSet& identification_eff, const MeasurementSet& verification,
                     const PipelineOptions& options, SolveErrors* errors, PipelineResult* out) {
  const CalibrationResult& result = out->result;
  out->geometric = Geometric(result.model);
  out->identifiability = AnalyzeIdentifiability(nominal, identification_eff, result);
  WarnUnmeasuredFixedTools(nominal, identification, out);
  // The solver's last linearization is that of result.model, i.e. of `geometric` on the measured
  // joint values (no joint terms): its errors serve the statistics and the outlier search.
  PositionErrorRows& final_errors = errors->solver.final_errors;
  const bool have_final = !final_errors.empty() && result.joint_terms.empty() &&
                          final_errors.size() == identification.size();
  out->identification_before = errors->have_before
                                   ? errors->before
                                   : PositionErrorStatistics(out->before, identification);
  out->identification_after = have_final
                                  ? final_errors.Statistics()
                                  : PositionErrorStatistics(out->geometric, identification_eff);
  if (!verification.empty()) {
    out->has_verification = true;
    out->verification_before = PositionErrorStatistics(out->before, verification);
    out->verification_after = PositionErrorStatistics(
        out->geometric, WithEffectiveJointValues(result.joint_terms, verification));
  }
  out->outliers = have_final ? FindOutliers(out->geometric, identification_eff, final_errors,
                                            options.outlier_threshold, &out->robust_sigma)
                             : FindOutliers(out->geometric, identification_eff,
                                            options.outlier_threshold, &out->robust_sigma);
  final_errors.Clear();
}

// The same calibration without the joint-space terms, for comparison.
void GeometryOnlyRefit(const RobotModel& nominal, const MeasurementSet& identification,
                       const MeasurementSet& verification, const PipelineOptions& chosen,
                       PipelineResult* out) {
  PipelineOptions geometric = chosen;
  geometric.joint_errors.clear();
  CalibrationResult g = SolveCalibration(nominal, identification, geometric,
                                         "geometry-only re-fit", nullptr, nullptr, nullptr);
  if (!g.converged()) return;
  out->has_geometry_only = true;
  g.model = Geometric(g.model);
  out->geometry_only_identification = PositionErrorStatistics(g.model, identification);
  if (!verification.empty()) {
    out->geometry_only_verification = PositionErrorStatistics(g.model, verification);
  }
  out->geometry_only = std::move(g);
}

// The residual layer (docs/residual_layer.md): chosen by cross-validation (auto) or asked for
// (gp), fitted on the identification residuals of the calibrated model; the verification errors
// are then those of the model with its layer.
void ResidualLayerStage(const RobotModel& nominal, const MeasurementSet& identification,
                        const MeasurementSet& verification, const PipelineOptions& options,
                        const PipelineOptions& chosen, PipelineResult* out) {
  ResidualModelKind residual = options.residual_model;
  out->residual_layer.requested = residual != ResidualModelKind::kNone;
  if (residual == ResidualModelKind::kAuto) {
    out->residual_model_selection = SelectResidualModel(nominal, identification, chosen);
    const ResidualModelSelection& sel = out->residual_model_selection;
    residual = sel.chosen >= 0 && sel.candidates[sel.chosen].label == "gp" ? ResidualModelKind::kGp
                                                                          : ResidualModelKind::kNone;
    if (residual == ResidualModelKind::kNone) {
      out->residual_layer.message = "auto chose none (" + sel.reason + ")";
    }
  }
  if (residual != ResidualModelKind::kGp) return;
  if (options.on_stage) options.on_stage("fitting the residual layer");
  auto layer = std::make_shared<ResidualLayer>();
  const Status s = FitResidualLayerOn(out->result, identification, options.residual_layer,
                                      layer.get(), &out->residual_layer.fit);
  if (!s.ok()) {
    out->residual_layer.message = "residual layer not fitted: " + s.message();
    return;
  }
  out->residual_layer.fitted = true;
  out->residual_layer.inducing = layer->num_inducing();
  std::vector<Eigen::Vector3d> e = ParametricResiduals(out->result, identification);
  for (int r = 0; r < identification.size(); ++r) {
    e[r] -= layer->Mean(identification.q(r), identification.target(r));
  }
  out->residual_layer.identification_with_layer = ComputeStatistics(e);
  if (!verification.empty()) {
    out->residual_layer.verification_parametric = out->verification_after;
    std::vector<Eigen::Vector3d> v = ParametricResiduals(out->result, verification);
    for (int r = 0; r < verification.size(); ++r) {
      v[r] -= layer->Mean(verification.q(r), verification.target(r));
    }
    out->verification_after = ComputeStatistics(v);
  }
  out->result.model.residual_layer = std::move(layer);
}

// Do the data agree with the fixed tools (`fixed`: their names)? The same calibration with them
// free: holding them costs about chi^2(k) noise variances when they are right (k: the parameters
// the free fit has more), much more when a nest is off. Significant: "check"; and when holding
// them also costs more than the tracker noise per axis: "fail" (the flange then carries the nests'
// error).
void FixedToolsCheck(const RobotModel& nominal, const MeasurementSet& identification,
                     const PipelineOptions& options, const PipelineOptions& chosen,
                     const std::string& fixed, PipelineResult* out) {
  const CalibrationResult& result = out->result;
  RobotModel free_nominal = nominal;
  for (Tool& t : free_nominal.tools) t.fixed = false;
  PipelineOptions free_options = chosen;
  free_options.kfold = 0;
  const CalibrationResult g = SolveCalibration(free_nominal, identification, free_options,
                                               "fixed tools against free ones", nullptr, nullptr,
                                               nullptr);
  const int per_row =
      MeasurementKind(TrackerKindId(options.use_orientation && identification.has_orientation()))
          .residuals;
  const long rows = static_cast<long>(per_row) * identification.size();
  const int k = g.parameterization.num_parameters - result.parameterization.num_parameters;
  if (!(g.converged() && k > 0 && rows > g.parameterization.num_parameters && g.final_cost > 0)) {
    return;
  }
  const double s2 =
      2.0 * g.final_cost / static_cast<double>(rows - g.parameterization.num_parameters);
  const double chi2 = 2.0 * (result.final_cost - g.final_cost) / s2;
  const double rms_fixed =
      internal::RmsPerAxisOfCost(result.final_cost, identification, per_row == 6);
  const double rms_free = internal::RmsPerAxisOfCost(g.final_cost, identification, per_row == 6);
  // About 5 standard deviations of chi^2(k) above its mean.
  const double significant = k + 5.0 * std::sqrt(2.0 * k);
  VerdictCheck c;
  c.name = "fixed_tools";
  c.value = chi2;
  c.limit = significant;
  const bool costly = rms_fixed - rms_free > options.plausibility.noise_sigma;
  c.level = !(chi2 > significant) ? VerdictLevel::kPass
            : costly               ? VerdictLevel::kFail
                                   : VerdictLevel::kCheck;
  char buf[512];
  std::snprintf(buf, sizeof(buf),
                "the fixed tools (%s) %s the data: held as given the fit is %.4g mm per axis, "
                "with them free %.4g mm (%.3g noise variances for %d parameters)%s",
                fixed.c_str(), c.level == VerdictLevel::kPass ? "agree with" : "disagree with",
                rms_fixed, rms_free, chi2, k,
                c.level == VerdictLevel::kPass
                    ? ""
                    : ": a nest is not where the model puts it (check the drawing or CMM "
                      "values; the flange frame takes that error)");
  c.message = buf;
  out->verdict.checks.push_back(c);
  if (c.level > out->verdict.level) {
    out->verdict.level = c.level;
    out->verdict.reason = c.message;
  }
}

// Appends `cause` to the residual check's message when it did not pass.
void NameLikelyCause(const std::string& cause, Verdict* verdict) {
  for (VerdictCheck& c : verdict->checks) {
    if (c.name != "residual" || c.level == VerdictLevel::kPass) continue;
    const bool was_reason = verdict->reason == c.message;
    c.message += cause;
    if (was_reason) verdict->reason = c.message;
  }
}

// The plausibility verdict, with the fixed tools' check and the likely causes of a poor fit.
void VerdictStage(const RobotModel& nominal, const MeasurementSet& identification,
                  const MeasurementSet& identification_eff, const PipelineOptions& options,
                  const PipelineOptions& chosen, PipelineResult* out) {
  const CalibrationResult& result = out->result;
  PlausibilityOptions plausibility = options.plausibility;
  plausibility.use_orientation = options.use_orientation;
  FrameChangeSigmas(out->result, out->start, out->geometric, &plausibility);
  out->verdict = AssessPlausibility(out->start, out->geometric, identification_eff,
                                    out->identification_after, plausibility);
  // A fit much worse than the noise after directions were left out: name them as the likely cause
  // (they are kept as given; if the data do determine them after all, the model is wrong there).
  std::string left_out;
  for (const Direction& d : result.parameterization.unidentifiable) {
    if (IsStructurallyLost(d)) left_out += (left_out.empty() ? "" : ", ") + d.name;
  }
  // Fixed tools are held as given: a nest position that is wrong leaves an error nothing can take.
  std::string fixed;
  const std::vector<bool> measured = MeasuredTools(nominal, identification);
  for (int t = 0; t < nominal.num_tools(); ++t) {
    if (nominal.tools[t].fixed && measured[t]) {
      fixed += (fixed.empty() ? "" : ", ") + nominal.tools[t].name;
    }
  }
  if (!fixed.empty()) {
    FixedToolsCheck(nominal, identification, options, chosen, fixed, out);
    NameLikelyCause("; likely cause: the fixed tools (" + fixed +
                        ") are held where the model puts them, and the data may not agree (a "
                        "nest position off its drawing or CMM value shows here; calibrate "
                        "without --fixed_tools to see where the data put them)",
                    &out->verdict);
  }
  if (!left_out.empty()) {
    NameLikelyCause("; likely cause: directions left out as not identifiable (" + left_out +
                        ") are kept as given, and the data may not agree with them (a measured "
                        "point off where the model puts it, or an axis the data cannot see)",
                    &out->verdict);
  }
}

// k-fold cross-validation: each fold calibrated on the others (with its own residual layer when
// the pipeline fitted one) and predicted.
void CrossValidate(const RobotModel& nominal, const MeasurementSet& identification,
                   const PipelineOptions& options, const PipelineOptions& chosen,
                   PipelineResult* out) {
  const auto folds = KFolds(identification, options.kfold, options.split_seed, options.split);
  std::vector<Eigen::Vector3d> pooled;
  for (int f = 0; f < options.kfold; ++f) {
    const MeasurementSet train =
        identification.Subset(Complement(identification.size(), folds[f]));
    const MeasurementSet test = identification.Subset(folds[f]);
    const CalibrationResult r = SolveCalibration(nominal, train, chosen,
                                                 "fold " + std::to_string(f + 1), nullptr,
                                                 nullptr, nullptr);
    FoldSummary fs;
    fs.fold = f + 1;
    fs.identification_rows = train.size();
    fs.termination = r.termination;
    std::vector<Eigen::Vector3d> e =
        PositionErrors(Geometric(r.model), WithEffectiveJointValues(r.joint_terms, test));
    if (out->residual_layer.fitted && r.converged()) {
      // The fold's own layer, fitted on its training rows only.
      ResidualLayer layer;
      if (FitResidualLayerOn(r, train, options.residual_layer, &layer, nullptr).ok()) {
        for (int row = 0; row < test.size(); ++row) {
          e[row] -= layer.Mean(test.q(row), test.target(row));
        }
      }
    }
    pooled.insert(pooled.end(), e.begin(), e.end());
    fs.verification_after = ComputeStatistics(e);
    out->folds.push_back(fs);
  }
  out->folds_pooled = ComputeStatistics(pooled);
}

}  // namespace

PipelineResult RunCalibrationPipeline(const RobotModel& nominal,
                                      const MeasurementSet& identification,
                                      const MeasurementSet& verification,
                                      const PipelineOptions& options) {
  PipelineResult out;
  out.registered = options.register_frames;
  PipelineOptions chosen = options;
  if (options.joint_errors_auto) {
    out.joint_error_selection = SelectJointErrors(nominal, identification, options);
    const JointErrorSelection& sel = out.joint_error_selection;
    chosen.joint_errors = sel.candidates[sel.chosen].terms;
    chosen.joint_errors_auto = false;
  }
  SolveErrors errors;
  out.result = Solve(nominal, identification, chosen, "calibrating", &out.registration, &out.before,
                     &out.start, &errors);
  if (out.result.termination == Termination::kNotIdentifiable) return out;

  if (options.on_stage) options.on_stage("analysing");
  UnmeasuredFixedTools(nominal, identification, &out);
  // Without joint terms the effective joint values are the measured ones: no copy (72 B a row).
  MeasurementSet with_joint_terms;
  if (!out.result.joint_terms.empty()) {
    with_joint_terms = WithEffectiveJointValues(out.result.joint_terms, identification);
  }
  const MeasurementSet& identification_eff =
      out.result.joint_terms.empty() ? identification : with_joint_terms;
  AnalyseSolution(nominal, identification, identification_eff, verification, options, &errors,
                  &out);
  if (!out.result.converged()) return out;
  if (options.refit_geometry && !out.result.joint_terms.empty()) {
    GeometryOnlyRefit(nominal, identification, verification, chosen, &out);
  }
  ResidualLayerStage(nominal, identification, verification, options, chosen, &out);
  VerdictStage(nominal, identification, identification_eff, options, chosen, &out);
  if (options.kfold >= 2) CrossValidate(nominal, identification, options, chosen, &out);
  return out;
}

}  // namespace lpoe
