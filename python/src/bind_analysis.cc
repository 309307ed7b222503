// Python bindings: the problem builder (normal equations, identifiability), compensation (inverse
// kinematics) and measurement planning. Keyword options are named as the flags of lpoe_calibrate,
// lpoe_compensate and lpoe_plan, with their defaults; angles in rad unless a flag says degrees.
#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "lpoe/joint_error_list.h"
#include "lpoe/analysis.h"
#include "lpoe/compensation.h"
#include "lpoe/contact_planning.h"
#include "lpoe/inverse_kinematics.h"
#include "lpoe/options.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/io/csv_rules.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/planning.h"
#include "lpoe/planning_workflow.h"
#include "lpoe/model/refusals.h"
#include "lpoe/problem_builder.h"
#include "lpoe/recalibration.h"
#include "python_api.h"

namespace py = pybind11;

namespace lpoe {
namespace python {
namespace {

// Finite values of magnitude at most `limit`: the limits of the CSV readers (lpoe/io/csv_rules.h),
// the same for arrays as for the tools' files.
void CheckFinite(const RowArray& a, const std::string& what, double limit) {
  const double* d = a.data();
  for (py::ssize_t k = 0; k < a.size(); ++k) {
    if (!std::isfinite(d[k])) {
      throw LpoeError(what + ": non-finite value at flat index " + std::to_string(k));
    }
    if (std::abs(d[k]) > limit) {
      throw LpoeError(what + ": value of magnitude above " +
                      (limit == kMaxAbsCsvPositionMm ? std::string("1e6 mm") : std::string("1e4")) +
                      " at flat index " + std::to_string(k));
    }
  }
}

// ---- The problem builder.

struct PyProblem {
  std::unique_ptr<CalibrationProblem> problem;
};

struct PyNormalEquations {
  Eigen::MatrixXd H;
  Eigen::VectorXd g;
  double cost = 0;
  std::vector<std::string> names;
};

struct PyIdentifiability {
  ProblemAnalysis a;
};

std::string Repr(const PyIdentifiability& r) {
  // The fixed tools' directions are held by the user, not unidentifiable: counted apart.
  size_t held = 0;
  for (const Direction& d : r.a.unidentifiable) held += IsHeldFixedTool(d);
  std::ostringstream os;
  os << "<lpoe.Identifiability: rank " << r.a.rank << " of " << r.a.num_parameters
     << ", condition " << r.a.condition_number << ", " << r.a.unidentifiable.size() - held
     << " directions not identifiable"
     << (held > 0 ? ", " + std::to_string(held) + " held (fixed tools)" : std::string())
     << (r.a.identifiable ? "" : "; NOT IDENTIFIABLE") << ">";
  return os.str();
}

PyProblem MakeProblem(const RobotModel& model, const MeasurementSet& data,
                      const std::string& parameterization, const std::string& data_kind,
                      double sigma, double orientation_weight, const std::string& joint_errors,
                      const std::string& loss, double loss_scale) {
  Check(model.Validate());
  CalibrationProblemOptions o;
  o.parameterization = ParseParameterizationOption(parameterization);
  o.use_orientation = ParseDataKindOption(data_kind, data);
  o.sigma = sigma;
  o.orientation_weight = orientation_weight;
  o.loss = loss;
  o.loss_scale = loss_scale;
  // A bilinear effect ("tilt", after compliance: the gravity tilt's block of 2) with its partner
  // term built on the same model; the terms start from the values the model carries (zero when
  // none: the tilt's columns are then zero, so identify the compliance first,
  // docs/joint_errors.md).
  for (const std::string& name : JointErrorNames(joint_errors, /*allow_bilinear=*/true)) {
    if (auto effect = MakeBilinearEffect(name, model)) {
      o.bilinear_effects.push_back(std::move(effect));
      continue;
    }
    std::shared_ptr<const JointTerm> term;
    Check(MakeJointTerm(name, model, &term));
    o.joint_terms.push_back(term);
  }
  const bool bilinear = !o.bilinear_effects.empty();
  if (bilinear) {
    for (const auto& term : o.joint_terms) {
      JointTermValues v;
      v.term = term;
      const std::vector<double>& carried = model.joint_errors.Values(term->name());
      v.theta = static_cast<int>(carried.size()) == term->num_parameters()
                    ? Eigen::VectorXd(Eigen::Map<const Eigen::VectorXd>(
                          carried.data(), static_cast<Eigen::Index>(carried.size())))
                    : Eigen::VectorXd::Zero(term->num_parameters());
      o.initial_joint_terms.push_back(std::move(v));
    }
  }
  Check(ValidateCalibrationProblem(model, data, o));
  PyProblem p;
  py::gil_scoped_release release;
  p.problem = std::make_unique<CalibrationProblem>(model, data, o);
  if (bilinear) Check(p.problem->block_status());
  return p;
}

// ---- Compensation.

struct PyCompensation {
  Eigen::MatrixXd q;
  std::vector<std::string> status;
  Eigen::VectorXd position_error, orientation_error, sigma_min, correction;
  Eigen::MatrixXd corrected;              // (M, 3) nominal tool positions at q; empty without nominal
  Eigen::MatrixXd corrected_quaternions;  // (M, 4) [x y z w]; empty unless pose targets
};

std::string Repr(const PyCompensation& c) {
  int ok = 0;
  for (const std::string& s : c.status) ok += s == "ok";
  std::ostringstream os;
  os << "<lpoe.Compensation: " << c.status.size() << " rows, " << ok << " ok";
  if (c.position_error.size() > 0) os << ", largest residual " << c.position_error.maxCoeff() << " mm";
  os << ">";
  return os.str();
}

PyCompensation Compensate(const RobotModel& model, const py::object& targets_obj,
                          const py::object& seeds_obj, const py::object& orientations_obj,
                          const py::object& joints_obj, const py::object& nominal_obj,
                          const std::string& joints_target, const py::object& tool_obj,
                          const std::string& frame, const py::object& tcp_obj,
                          const std::string& flange, int threads,
                          int max_iterations, int restarts, double position_tolerance,
                          double orientation_tolerance, double singular_threshold) {
  // The workflow of lpoe_compensate (lpoe/compensation.h): the same request, checks and solve.
  CompensationRequest request;
  request.model = model;
  request.joints_mode = !joints_obj.is_none();
  if (request.joints_mode == !targets_obj.is_none()) {
    throw LpoeError("compensate: give either targets= (with seeds=) or joints= (with nominal=)");
  }
  if (joints_target != "pose" && joints_target != "position") {
    throw LpoeError("joints_target: expected 'pose' or 'position', got '" + joints_target + "'");
  }
  request.joints_target_pose = joints_target == "pose";
  if (!ParseTargetFrame(frame, &request.frame, &request.frame_link)) {
    throw LpoeError("frame: expected 'base', 'measurement' or 'link:NAME', got '" + frame + "'");
  }
  request.flange = flange;
  if (!nominal_obj.is_none()) {
    request.has_nominal = true;
    request.nominal = nominal_obj.cast<const RobotModel&>();
  }
  if (py::isinstance<py::str>(tcp_obj)) {
    request.tcp = tcp_obj.cast<std::string>();
  } else if (!tcp_obj.is_none()) {
    const RowArray t = tcp_obj.cast<RowArray>();
    if (t.ndim() != 1 || (t.size() != 3 && t.size() != 6)) {
      throw LpoeError("tcp: expected a tool name or [x, y, z] / [x, y, z, roll, pitch, yaw] (mm, "
                      "rad), got shape " + ShapeText(t));
    }
    request.tcp_offset.assign(t.data(), t.data() + t.size());
  }
  const bool per_row_tool = !tool_obj.is_none() && !IsOneTool(tool_obj);
  if (!tool_obj.is_none() && !per_row_tool) {
    request.tool = py::isinstance<py::str>(tool_obj) ? tool_obj.cast<std::string>()
                                                     : std::to_string(ToolIndexOf(model, tool_obj));
  }
  request.threads = threads;
  request.ik.max_iterations = max_iterations;
  request.ik.restarts = restarts;
  request.ik.position_tolerance = position_tolerance;
  request.ik.orientation_tolerance = orientation_tolerance;
  request.ik.singular_threshold = singular_threshold;
  std::unique_ptr<Compensator> compensator;
  Check(Compensator::Create(request, &compensator));
  const RobotModel& solved_model = compensator->model();
  const int n = solved_model.num_joints();
  const bool joints_mode = request.joints_mode;
  if (!joints_mode && seeds_obj.is_none()) {
    throw LpoeError("compensate: targets= needs seeds= (the program's joints, one row per target)");
  }
  const RowArray seeds = (joints_mode ? joints_obj : seeds_obj).cast<RowArray>();
  const py::ssize_t m = RowsOf(seeds, n, joints_mode ? "joints" : "seeds");
  CheckFinite(seeds, joints_mode ? "joints" : "seeds", kMaxAbsCsvJointValue);
  // The tool of every row: the request's (tool=, tcp=), or one name or index per row.
  std::vector<int> tools(m, compensator->default_tool());
  if (per_row_tool) tools = ToolsPerRow(solved_model, tool_obj, m, "tool");
  std::vector<IkTarget> targets(m);
  for (py::ssize_t r = 0; r < m; ++r) targets[r].tool = tools[r];
  if (!joints_mode) {
    const RowArray p = targets_obj.cast<RowArray>();
    if (RowsOf(p, 3, "targets") != m) {
      throw LpoeError("targets: " + std::to_string(p.ndim() == 1 ? 1 : p.shape(0)) +
                      " rows, seeds: " + std::to_string(m));
    }
    CheckFinite(p, "targets", kMaxAbsCsvPositionMm);
    RowArray quat;
    if (!orientations_obj.is_none()) {
      quat = orientations_obj.cast<RowArray>();
      if (RowsOf(quat, 4, "orientations") != m) {
        throw LpoeError("orientations: expected (" + std::to_string(m) + ", 4) [x, y, z, w], got " +
                        ShapeText(quat));
      }
    }
    for (py::ssize_t r = 0; r < m; ++r) {
      targets[r].position = Eigen::Vector3d(p.data()[3 * r], p.data()[3 * r + 1], p.data()[3 * r + 2]);
      if (quat.size() > 0) {
        const double* v = quat.data() + 4 * r;
        const Eigen::Quaterniond qq(v[3], v[0], v[1], v[2]);
        if (!(std::abs(qq.norm() - 1.0) < 1e-6)) {
          throw LpoeError("orientations: row " + std::to_string(r) + ": not a unit quaternion");
        }
        targets[r].has_orientation = true;
        targets[r].rotation = qq.toRotationMatrix();
      }
    }
  }
  bool any_orientation = false;
  for (const IkTarget& t : targets) any_orientation |= t.has_orientation;
  any_orientation |= joints_mode && request.joints_target_pose;
  CompensatedRows solved;
  CompensationSummary summary;
  {
    py::gil_scoped_release release;
    compensator->Solve(seeds.data(), &targets, &solved);
    summary.Add(solved);
  }
  // Targets in another frame: refused as lpoe_compensate refuses them.
  Check(summary.CheckFrame(request, "targets"));
  Check(CheckCompensatedFinite(solved, nullptr, 0, joints_mode ? "joints" : "targets"));
  PyCompensation c;
  c.q = Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
      solved.q.data(), m, n);
  c.position_error.resize(m);
  c.orientation_error.resize(m);
  c.sigma_min.resize(m);
  c.correction.resize(m);
  if (request.has_nominal) {
    c.corrected.resize(m, 3);
    if (any_orientation) c.corrected_quaternions.setConstant(m, 4, NAN);
  }
  for (py::ssize_t k = 0; k < m; ++k) {
    const IkResult& r = solved.results[k];
    c.status.push_back(IkStatusName(r.status));
    c.position_error(k) = r.position_error;
    c.orientation_error(k) = r.orientation_error;
    c.sigma_min(k) = r.sigma_min;
    c.correction(k) = r.correction;
    if (request.has_nominal) {
      const SE3d& T = solved.corrected[k];
      c.corrected.row(k) = T.t.transpose();
      if (targets[k].has_orientation) {
        c.corrected_quaternions.row(k) = RotationToQuaternion<double>(T.R).transpose();
      }
    }
  }
  return c;
}

// ---- Planning.

struct PyPlan {
  Eigen::MatrixXd q;
  std::vector<int> candidate_rows;  // rows of the candidates (given or sampled)
  Eigen::MatrixXd candidates;
  std::string criterion;
  PlanQuality quality;
  double random_predicted_rms = 0;  // RMS over the random plans of the same size
  // With the unmodelled error (docs/planning.md): the predicted error in mm, plan and random plans.
  double predicted_error = 0;
  double random_predicted_error = 0;
  int offered = 0, feasible = 0, outside_limits = 0, near_singular = 0, nothing_visible = 0;
  int outside_cell = 0;
  std::vector<std::vector<std::string>> visible;  // the tools counted at each planned pose
  int num_parameters = 0, exchanges = 0;
  bool gravity_tilt = false;  // the gravity tilt planned for (its 2 parameters are the last)
};

py::dict QualityDict(const PlanQuality& q) {
  py::dict d;
  d["num_poses"] = q.num_poses;
  d["num_rows"] = q.num_rows;
  d["rank"] = q.rank;
  d["condition_number"] = q.condition_number;
  d["predicted_rms"] = q.predicted_rms;
  d["D"] = q.d;
  d["A"] = q.a;
  d["E"] = q.e;
  d["I"] = q.i;
  d["O1"] = q.o1;
  d["O3"] = q.o3;
  return d;
}

std::vector<double> RowMajor(const RowArray& a, int n, const std::string& what) {
  const py::ssize_t m = RowsOf(a, n, what);
  CheckFinite(a, what, kMaxAbsCsvJointValue);
  return std::vector<double>(a.data(), a.data() + m * n);
}

// lpoe_plan --prior and --prior_free: the prior's information (ReadPrior's: the file's
// covariance, the default tolerances elsewhere), the freed frames at the nominal tolerances.
std::shared_ptr<const ParameterPrior> PlanPrior(const RobotModel& model, const Prior& file,
                                                const std::vector<std::string>& freed) {
  const RobotModel& prior_model = file.model;
  if (prior_model.num_joints() != model.num_joints() ||
      prior_model.num_tools() != model.num_tools()) {
    throw LpoeError("prior=" + file.source + ": its chain (" +
                    std::to_string(prior_model.num_joints()) + " joints, " +
                    std::to_string(prior_model.num_tools()) + " tools) is not the model's");
  }
  auto prior = std::make_shared<ParameterPrior>(
      PriorFromCovariance(prior_model, file.covariance, PriorScales()));
  for (const std::string& name : freed) {
    int frame = -1;
    for (int f = 0; f < prior_model.num_frames(); ++f) {
      const int n = prior_model.num_joints();
      if ((f < n ? prior_model.joints[f].name : prior_model.tools[f - n].name) == name) frame = f;
    }
    if (frame < 0) {
      throw LpoeError("prior_free: '" + name + "' is no joint or tool of " + file.source);
    }
    prior->frame_information[frame] =
        DefaultFrameInformation(prior_model, frame, prior->scales, 1.0);
  }
  return prior;
}

// prior_free: a list of names or "a,b" (as --prior_free).
std::vector<std::string> NameList(const py::object& obj, const std::string& what) {
  std::vector<std::string> out;
  if (obj.is_none()) return out;
  if (py::isinstance<py::str>(obj)) {
    std::stringstream ss(obj.cast<std::string>());
    for (std::string name; std::getline(ss, name, ',');) out.push_back(name);
    return out;
  }
  try {
    return obj.cast<std::vector<std::string>>();
  } catch (const py::cast_error&) {
    throw LpoeError(what + ": expected a list of names or 'a,b'");
  }
}

PyPlan TrackerPlan(const RobotModel& model, int count, const py::object& candidates_obj,
                   int candidate_count, const py::object& workspace_obj, int workspace_count,
                   uint64_t seed, const std::string& criterion, const py::object& tracker_obj,
                   double max_range, double acceptance_angle, const py::object& smr_facing_obj,
                   double min_singularity, int random_draws, const std::string& joint_errors,
                   const py::object& min_z_obj, const py::object& box_obj,
                   const py::object& keep_out_obj, const py::object& joint_ranges_obj,
                   const std::shared_ptr<Prior>& prior_file, const py::object& prior_free_obj,
                   double noise_sigma, const py::object& unmodelled_error_obj,
                   const py::object& unmodelled_length_obj) {
  // The workflow of lpoe_plan (lpoe/planning_workflow.h): the same request, checks and plan.
  Check(model.Validate());
  PlanRequest request;
  request.model = model;
  request.model_source = "model '" + model.name + "'";
  request.noise_sigma = noise_sigma;
  request.count = count;
  request.candidate_count = candidate_count;
  request.workspace_count = workspace_count;
  request.seed = seed;
  request.random_draws = random_draws;
  request.joint_errors = joint_errors;
  // As lpoe_plan's --unmodelled_error/--unmodelled_length: either given overrides the residual
  // layer's (or the default) unmodelled error.
  if (!unmodelled_error_obj.is_none()) request.unmodelled_error = unmodelled_error_obj.cast<double>();
  if (!unmodelled_length_obj.is_none()) {
    request.unmodelled_length = unmodelled_length_obj.cast<double>();
  }
  request.unmodelled_given = !unmodelled_error_obj.is_none() || !unmodelled_length_obj.is_none();
  if (!ParsePlanCriterion(criterion, &request.options.criterion)) {
    throw LpoeError("criterion: expected one of D, A, E, I, O1, O3, got '" + criterion + "'");
  }
  const int n = model.num_joints();
  PlanConstraints& constraints = request.constraints;
  constraints.min_singularity = min_singularity;
  TrackerConstraint& tracker = constraints.tracker;
  tracker.acceptance_angle = acceptance_angle * 3.14159265358979323846 / 180.0;
  if (max_range > 0) tracker.max_range = max_range;
  if (!(max_range >= 0) || !std::isfinite(max_range)) {
    throw LpoeError("max_range must be >= 0 (mm; 0 = unlimited)");
  }
  if (!tracker_obj.is_none()) {
    const RowArray t = tracker_obj.cast<RowArray>();
    if (t.size() != 3) throw LpoeError("tracker: expected three finite numbers (mm)");
    tracker.enabled = true;
    tracker.position = Eigen::Vector3d(t.data()[0], t.data()[1], t.data()[2]);
  }
  if (!smr_facing_obj.is_none()) {
    const RowArray f = smr_facing_obj.cast<RowArray>();
    const py::ssize_t k = RowsOf(f, 3, "smr_facing");
    if (k != 1 && k != model.num_tools()) {
      throw LpoeError("smr_facing: one direction for all tools or one per tool (" +
                      std::to_string(model.num_tools()) + "), got " + std::to_string(k));
    }
    for (py::ssize_t r = 0; r < k; ++r) {
      const Eigen::Vector3d v(f.data()[3 * r], f.data()[3 * r + 1], f.data()[3 * r + 2]);
      if (!v.allFinite() || v.norm() == 0) {
        throw LpoeError("smr_facing: row " + std::to_string(r) + " is not a direction");
      }
      tracker.facing.push_back(v.normalized());
    }
    if (tracker.facing.size() == 1) tracker.facing.resize(model.num_tools(), tracker.facing[0]);
  }
  // The cell, as lpoe_plan's --min_z, --box, --keep_out (mm, base frame) and --joint_ranges.
  auto box_of = [](const double* v, const std::string& what) {
    const Eigen::Vector3d lo(v[0], v[1], v[2]), hi(v[3], v[4], v[5]);
    if (!lo.allFinite() || !hi.allFinite() || !(lo.array() <= hi.array()).all()) {
      throw LpoeError(what + ": expected finite xmin, ymin, zmin, xmax, ymax, zmax with min <= max");
    }
    return Eigen::AlignedBox3d(lo, hi);
  };
  if (!min_z_obj.is_none()) {
    constraints.cell.min_z = min_z_obj.cast<double>();
    if (!std::isfinite(constraints.cell.min_z)) throw LpoeError("min_z must be a finite height in mm");
  }
  if (!box_obj.is_none()) {
    const RowArray b = box_obj.cast<RowArray>();
    if (b.size() != 6) throw LpoeError("box: expected 6 numbers, got shape " + ShapeText(b));
    constraints.cell.box = box_of(b.data(), "box");
  }
  if (!keep_out_obj.is_none()) {
    const RowArray b = keep_out_obj.cast<RowArray>();
    const py::ssize_t k = RowsOf(b, 6, "keep_out");
    for (py::ssize_t r = 0; r < k; ++r) {
      constraints.cell.keep_out.push_back(box_of(b.data() + 6 * r, "keep_out row " + std::to_string(r)));
    }
  }
  if (!joint_ranges_obj.is_none()) {
    const RowArray j = joint_ranges_obj.cast<RowArray>();
    if (j.ndim() != 2 || j.shape(0) != n || j.shape(1) != 2) {
      throw LpoeError("joint_ranges: expected (" + std::to_string(n) +
                      ", 2) [lo, hi] per joint (NaN, NaN keeps the limits), got " + ShapeText(j));
    }
    std::vector<std::pair<double, double>> ranges;
    for (int r = 0; r < n; ++r) ranges.emplace_back(j.data()[2 * r], j.data()[2 * r + 1]);
    Check(NarrowJointRanges(ranges, &request.model));
  }
  Check(CheckPlanRequest(request));
  if (prior_file != nullptr) {
    request.prior = PlanPrior(model, *prior_file, NameList(prior_free_obj, "prior_free"));
  } else if (!prior_free_obj.is_none()) {
    throw LpoeError("prior_free needs prior");
  }
  if (!candidates_obj.is_none()) {
    request.has_candidates = true;
    request.candidates = RowMajor(candidates_obj.cast<RowArray>(), n, "candidates");
  }
  if (!workspace_obj.is_none()) {
    request.has_workspace = true;
    request.workspace = RowMajor(workspace_obj.cast<RowArray>(), n, "workspace");
  }
  PlanningResult planned;
  Status status;
  {
    py::gil_scoped_release release;
    status = RunPlanning(request, &planned);
  }
  Check(status);
  PyPlan out;
  const CandidatePool& pool = planned.pool;
  out.gravity_tilt = planned.tilt;
  out.offered = planned.offered;
  out.feasible = pool.size();
  out.outside_limits = pool.outside_limits;
  out.near_singular = pool.near_singular;
  out.nothing_visible = pool.nothing_visible;
  out.outside_cell = pool.outside_cell;
  out.num_parameters = planned.planning->num_parameters();
  out.quality = planned.quality;
  out.exchanges = planned.plan.exchanges;
  out.q.resize(planned.count, n);
  for (int k = 0; k < planned.count; ++k) {
    const int c = planned.plan.selected[k];
    out.candidate_rows.push_back(pool.source[c]);
    for (int j = 0; j < n; ++j) out.q(k, j) = pool.q[size_t(c) * n + j];
    std::vector<std::string> names;
    for (int t : pool.visible[c]) names.push_back(model.tools[t].name);
    out.visible.push_back(names);
  }
  out.random_predicted_rms = planned.random_rms_mean;
  out.predicted_error = planned.prediction.total_rms;
  out.random_predicted_error = planned.random_total_rms_mean;
  out.candidates = Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
      planned.candidates.data(), out.offered, n);
  out.criterion = PlanCriterionName(request.options.criterion);
  return out;
}

// ---- Ballbar and probe plans (lpoe_plan --measurement=ballbar|plane; lpoe/contact_planning.h).

struct PyContactPlan {
  std::string measurement;
  Eigen::MatrixXd q;                  // (count, N) the planned configurations
  std::vector<std::string> features;  // the pivot or plane of each planned pose
  std::vector<int> candidate_rows;    // rows of `candidates`
  Eigen::MatrixXd candidates;         // (C, N) the feasible candidates
  std::vector<std::string> candidate_features;
  int num_parameters = 0, exchanges = 0;
  double log_det = 0, random_mean_log_det = 0, random_best_log_det = 0;
  std::vector<double> random_log_det;
  int sampled = 0, feasible = 0, not_reached = 0, outside_limits = 0, outside_cell = 0;
  int near_singular = 0, outside_stroke = 0;
};

// (K, cols) rows of a finite array as vectors.
template <int Cols>
std::vector<Eigen::Matrix<double, Cols, 1>> FixedRows(const py::object& obj, const std::string& what) {
  std::vector<Eigen::Matrix<double, Cols, 1>> out;
  if (obj.is_none()) return out;
  const RowArray a = obj.cast<RowArray>();
  const py::ssize_t k = RowsOf(a, Cols, what);
  for (py::ssize_t r = 0; r < k; ++r) {
    out.push_back(Eigen::Map<const Eigen::Matrix<double, Cols, 1>>(a.data() + Cols * r));
    if (!out.back().allFinite()) throw LpoeError(what + ": row " + std::to_string(r) + " is not finite");
  }
  return out;
}

PyContactPlan ContactPlan(const RobotModel& model, int count, const std::string& measurement,
                          const ContactPlanOptions& given, const py::object& pivots_obj,
                          const py::object& planes_obj, const py::object& face_centres_obj,
                          int random_draws) {
  Check(model.Validate());
  const bool ballbar = measurement == "ballbar";
  ContactPlanRequest request;
  request.count = count;
  request.random_draws = random_draws;
  ContactPlanOptions& o = request.options;
  o = given;
  if (ballbar) {
    if (!planes_obj.is_none() || !face_centres_obj.is_none()) {
      throw LpoeError("planes and face_centres are for measurement='plane'");
    }
    if (pivots_obj.is_none()) {
      throw LpoeError("measurement='ballbar' needs pivots: (K, 3) the pivots' positions (mm, "
                      "the model's base frame)");
    }
    for (const Eigen::Vector3d& c : FixedRows<3>(pivots_obj, "pivots")) o.pivots.push_back(c);
  } else {
    if (!pivots_obj.is_none()) throw LpoeError("pivots is for measurement='ballbar'");
    if (planes_obj.is_none()) {
      throw LpoeError("measurement='plane' needs planes: (K, 4) [nx, ny, nz, d] per plane "
                      "(outward unit normal, n.x = d in mm)");
    }
    for (const Eigen::Vector4d& v : FixedRows<4>(planes_obj, "planes")) o.planes.push_back(v);
    for (const Eigen::Vector3d& c : FixedRows<3>(face_centres_obj, "face_centres")) {
      o.plane_centres.push_back(c);
    }
  }
  ContactPlanningResult planned;
  Status status;
  {
    py::gil_scoped_release release;
    status = RunContactPlanning(model, request, &planned);
  }
  Check(status);
  PyContactPlan out;
  out.measurement = measurement;
  const ContactCandidates& candidates = planned.candidates;
  const ContactMeasurementSet& set = candidates.set;
  const int n = model.num_joints();
  auto feature_name = [&](int c) {
    const ContactRow& row = set.rows[c];
    return ballbar ? set.pivots[row.feature] : set.planes[row.feature];
  };
  out.candidates.resize(set.size(), n);
  for (int c = 0; c < set.size(); ++c) {
    for (int j = 0; j < n; ++j) out.candidates(c, j) = set.joints(c)[j];
    out.candidate_features.push_back(feature_name(c));
  }
  out.q.resize(static_cast<int>(planned.plan.selected.size()), n);
  for (size_t k = 0; k < planned.plan.selected.size(); ++k) {
    const int c = planned.plan.selected[k];
    out.q.row(k) = out.candidates.row(c);
    out.candidate_rows.push_back(c);
    out.features.push_back(feature_name(c));
  }
  out.num_parameters = planned.plan.num_parameters;
  out.exchanges = planned.plan.exchanges;
  out.log_det = planned.plan.log_det;
  out.random_log_det = planned.random_log_det;
  out.random_mean_log_det = planned.random_mean_log_det;
  out.random_best_log_det = planned.random_best_log_det;
  out.sampled = o.samples_per_feature * static_cast<int>(o.pivots.size() + o.planes.size());
  out.feasible = set.size();
  out.not_reached = candidates.not_converged;
  out.outside_limits = candidates.outside_limits;
  out.outside_cell = candidates.outside_cell;
  out.near_singular = candidates.near_singular;
  out.outside_stroke = candidates.outside_stroke;
  return out;
}

// lpoe.plan: a tracker plan (measurement='position') or a ballbar / probe plan; each refuses the
// other's options by name, as lpoe_plan does.
py::object Plan(const RobotModel* model_arg, int count, const py::object& candidates_obj,
                int candidate_count, const py::object& workspace_obj, int workspace_count,
                uint64_t seed, const std::string& criterion, const py::object& tracker_obj,
                double max_range, double acceptance_angle, const py::object& smr_facing_obj,
                double min_singularity, int random_draws, const std::string& joint_errors,
                const py::object& min_z_obj, const py::object& box_obj,
                const py::object& keep_out_obj, const py::object& joint_ranges_obj,
                const std::string& measurement, const py::object& pivots_obj, double bar_length,
                double stroke, const py::object& planes_obj, const py::object& face_centres_obj,
                double face_radius, double probe_radius, int samples_per_feature,
                const py::object& contact_tool_obj, const py::object& prior_obj,
                const py::object& prior_free_obj, double noise_sigma,
                const py::object& unmodelled_error_obj, const py::object& unmodelled_length_obj) {
  if (measurement != "position" && (!prior_obj.is_none() || !prior_free_obj.is_none())) {
    throw LpoeError("prior and prior_free plan a recalibration from tracker (position) "
                    "measurements; a measurement='" + measurement + "' plan takes no prior");
  }
  const std::shared_ptr<Prior> prior_file = PriorArgument(prior_obj);
  if (model_arg == nullptr && prior_file == nullptr) {
    throw LpoeError("model: None needs prior= (the prior's model is then the model)");
  }
  const RobotModel& model = model_arg != nullptr ? *model_arg : prior_file->model;
  const ContactPlanOptions defaults;
  if (measurement == "position") {
    // The ballbar and probe options, not used by a tracker plan: refused by name.
    const std::vector<std::pair<const char*, bool>> contact_only = {
        {"pivots", !pivots_obj.is_none()},
        {"planes", !planes_obj.is_none()},
        {"face_centres", !face_centres_obj.is_none()},
        {"bar_length", bar_length != defaults.bar_length},
        {"stroke", stroke != defaults.stroke},
        {"face_radius", face_radius != defaults.face_radius},
        {"probe_radius", probe_radius != defaults.probe_radius},
        {"samples_per_feature", samples_per_feature != defaults.samples_per_feature},
        {"contact_tool", !contact_tool_obj.is_none()}};
    for (const auto& [name, given] : contact_only) {
      if (given) {
        throw LpoeError(std::string(name) +
                        " is for measurement='ballbar' or 'plane' (docs/measurements.md)");
      }
    }
    return py::cast(TrackerPlan(model, count, candidates_obj, candidate_count, workspace_obj,
                                workspace_count, seed, criterion, tracker_obj, max_range,
                                acceptance_angle, smr_facing_obj, min_singularity, random_draws,
                                joint_errors, min_z_obj, box_obj, keep_out_obj, joint_ranges_obj,
                                prior_file, prior_free_obj, noise_sigma, unmodelled_error_obj,
                                unmodelled_length_obj));
  }
  if (measurement != "ballbar" && measurement != "plane") {
    throw LpoeError("measurement must be position, ballbar or plane, got '" + measurement + "'");
  }
  const char* kPlanTool = "lpoe_plan";
  // The tracker plan's options that this plan does not use: refused by name (as lpoe_plan).
  const std::vector<std::pair<const char*, bool>> tracker_only = {
      {"candidates", !candidates_obj.is_none()},
      {"candidate_count", candidate_count != OptionDefault(kPlanTool, "candidate_count")},
      {"workspace", !workspace_obj.is_none()},
      {"workspace_count", workspace_count != OptionDefault(kPlanTool, "workspace_count")},
      {"criterion", criterion != OptionDefaultText(kPlanTool, "criterion")},
      {"tracker", !tracker_obj.is_none()},
      {"max_range", max_range != OptionDefault(kPlanTool, "max_range")},
      {"acceptance_angle", acceptance_angle != OptionDefault(kPlanTool, "acceptance_angle")},
      {"smr_facing", !smr_facing_obj.is_none()},
      {"joint_errors", joint_errors != OptionDefaultText(kPlanTool, "joint_errors")},
      {"keep_out", !keep_out_obj.is_none()},
      {"joint_ranges", !joint_ranges_obj.is_none()},
      {"noise_sigma", noise_sigma != OptionDefault(kPlanTool, "noise_sigma")},
      {"unmodelled_error", !unmodelled_error_obj.is_none()},
      {"unmodelled_length", !unmodelled_length_obj.is_none()}};
  for (const auto& [name, given] : tracker_only) {
    if (given) {
      throw LpoeError(std::string(name) + " is for tracker plans; with measurement='" +
                      measurement + "' the plan is D-optimal over candidates projected onto the " +
                      (measurement == "ballbar" ? "pivots' spheres" : "planes") +
                      " (docs/measurements.md)");
    }
  }
  ContactPlanOptions o;
  o.bar_length = bar_length;
  o.stroke = stroke;
  o.face_radius = face_radius;
  o.probe_radius = probe_radius;
  o.samples_per_feature = samples_per_feature;
  o.seed = seed;
  o.min_singularity = min_singularity;
  o.target = contact_tool_obj.is_none() ? 0 : ToolIndexOf(model, contact_tool_obj);
  if (!min_z_obj.is_none()) {
    o.cell.min_z = min_z_obj.cast<double>();
    if (!std::isfinite(o.cell.min_z)) throw LpoeError("min_z must be a finite height in mm");
  }
  if (!box_obj.is_none()) {
    const RowArray b = box_obj.cast<RowArray>();
    if (b.size() != 6) throw LpoeError("box: expected 6 numbers, got shape " + ShapeText(b));
    const Eigen::Vector3d lo(b.data()[0], b.data()[1], b.data()[2]);
    const Eigen::Vector3d hi(b.data()[3], b.data()[4], b.data()[5]);
    if (!lo.allFinite() || !hi.allFinite() || !(lo.array() <= hi.array()).all()) {
      throw LpoeError("box: expected finite xmin, ymin, zmin, xmax, ymax, zmax with min <= max");
    }
    o.cell.box = Eigen::AlignedBox3d(lo, hi);
  }
  return py::cast(ContactPlan(model, count, measurement, o, pivots_obj, planes_obj,
                              face_centres_obj, random_draws));
}

// lpoe.ContactPlan: what lpoe.plan(measurement='ballbar' | 'plane') returns.
void BindContactPlanClass(py::module_& m) {
  py::class_<PyContactPlan>(m, "ContactPlan",
                            "The result of lpoe.plan(measurement='ballbar' | 'plane').")
      .def_readonly("measurement", &PyContactPlan::measurement)
      .def_readonly("q", &PyContactPlan::q, "(count, N) the planned configurations (rad / mm)")
      .def_readonly("features", &PyContactPlan::features,
                    "the pivot (ballbar) or plane (probe) of each planned pose, as lpoe_plan names "
                    "them: pivot1, ... in the order given; face_x, face_y, face_z for three "
                    "planes, else plane1, ...")
      .def_readonly("candidate_rows", &PyContactPlan::candidate_rows,
                    "row of each planned pose in `candidates`")
      .def_readonly("candidates", &PyContactPlan::candidates,
                    "(C, N) the feasible candidates (random configurations projected onto the "
                    "pivots' spheres or the planes)")
      .def_readonly("candidate_features", &PyContactPlan::candidate_features)
      .def_readonly("num_parameters", &PyContactPlan::num_parameters,
                    "the parameters the calibration would estimate from such rows")
      .def_readonly("exchanges", &PyContactPlan::exchanges)
      .def_readonly("log_det", &PyContactPlan::log_det,
                    "log det of the plan's column-scaled information")
      .def_readonly("random_log_det", &PyContactPlan::random_log_det,
                    "the random plans' log det, ascending (seeds seed + 1000 + k)")
      .def_readonly("random_mean_log_det", &PyContactPlan::random_mean_log_det)
      .def_readonly("random_best_log_det", &PyContactPlan::random_best_log_det)
      .def_property_readonly(
          "pool",
          [](const PyContactPlan& p) {
            py::dict d;
            d["sampled"] = p.sampled;
            d["feasible"] = p.feasible;
            d["not_reached"] = p.not_reached;
            d["outside_limits"] = p.outside_limits;
            d["outside_cell"] = p.outside_cell;
            d["near_singular"] = p.near_singular;
            d["outside_stroke"] = p.outside_stroke;
            return d;
          },
          "how many candidates were sampled, kept and why the others were dropped (lpoe_plan's "
          "report: candidates)")
      .def("__len__", [](const PyContactPlan& p) { return static_cast<size_t>(p.q.rows()); })
      .def("__repr__", [](const PyContactPlan& p) {
        std::ostringstream os;
        os << "<lpoe.ContactPlan: " << p.q.rows() << " " << p.measurement << " poses of "
           << p.feasible << " candidates, log det " << p.log_det << " (random best "
           << p.random_best_log_det << ")>";
        return os.str();
      });

}

}  // namespace

void BindAnalysis(py::module_& m) {
  const char* kCompensate = "lpoe_compensate";
  const char* kPlan = "lpoe_plan";
  const char* kCalibrate = "lpoe_calibrate";
  py::class_<PyNormalEquations>(
      m, "NormalEquations",
      "Normal equations of the calibration at the problem's current values: H = J^T W J, "
      "g = J^T W y (W = I / sigma^2, y = measured - predicted), so the Gauss-Newton step is "
      "x = solve(H, g); add your own terms to H and g before solving.")
      .def_readonly("H", &PyNormalEquations::H, "(P, P) J^T W J")
      .def_readonly("g", &PyNormalEquations::g, "(P,) J^T W y")
      .def_readonly("cost", &PyNormalEquations::cost, "0.5 y^T W y")
      .def_readonly("names", &PyNormalEquations::names, "the P parameters, in column order")
      .def("__repr__", [](const PyNormalEquations& e) {
        return "<lpoe.NormalEquations: " + std::to_string(e.names.size()) +
               " parameters, cost " + std::to_string(e.cost) + ">";
      });

  py::class_<PyIdentifiability>(
      m, "Identifiability",
      "Whether the data determine the parameters: rank and condition number of the column-scaled "
      "Jacobian, and the directions no data of this kind can determine, with the reason.")
      .def_property_readonly("identifiable", [](const PyIdentifiability& r) { return r.a.identifiable; })
      .def_property_readonly("rank", [](const PyIdentifiability& r) { return r.a.rank; })
      .def_property_readonly("num_parameters",
                             [](const PyIdentifiability& r) { return r.a.num_parameters; })
      .def_property_readonly("num_equations",
                             [](const PyIdentifiability& r) { return r.a.num_equations; })
      .def_property_readonly("condition_number",
                             [](const PyIdentifiability& r) { return r.a.condition_number; })
      .def_property_readonly("singular_values",
                             [](const PyIdentifiability& r) { return r.a.singular_values; })
      .def_property_readonly("parameter_names",
                             [](const PyIdentifiability& r) { return r.a.parameter_names; })
      .def_property_readonly(
          "not_identifiable",
          [](const PyIdentifiability& r) {
            std::vector<std::pair<std::string, std::string>> v;
            for (const Direction& d : r.a.unidentifiable) v.emplace_back(d.name, d.reason);
            return v;
          },
          "[(name, reason)] of the directions left out")
      .def_property_readonly("weakest", [](const PyIdentifiability& r) { return r.a.weakest; },
                             "the parameters carrying most of the weakest direction")
      .def_property_readonly("message", [](const PyIdentifiability& r) { return r.a.message; },
                             "why the data cannot identify the model ('' when they can)")
      .def("__repr__", [](const PyIdentifiability& r) { return Repr(r); });

  py::class_<PyProblem>(
      m, "Problem",
      "The calibration problem (lpoe/problem_builder.h) for another estimator: normal equations at "
      "the current parameters, updates, identifiability. Keyword options as lpoe_calibrate's "
      "flags.")
      .def(py::init(&MakeProblem), py::arg("model"), py::arg("data"), py::kw_only(),
           py::arg("parameterization") = OptionDefaultText(kCalibrate, "parameterization"),
           py::arg("data_kind") = OptionDefaultText(kCalibrate, "data_kind"),
           py::arg("sigma") = OptionDefault(kCalibrate, "sigma"),
           py::arg("orientation_weight") = CalibrationProblemOptions().orientation_weight,
           py::arg("joint_errors") = OptionDefaultText(kCalibrate, "joint_errors"),
           py::arg("loss") = OptionDefaultText(kCalibrate, "loss"),
           py::arg("loss_scale") = OptionDefault(kCalibrate, "loss_scale"),
           py::keep_alive<1, 3>())
      .def(
          "normal_equations",
          [](const PyProblem& p) {
            ProblemNormalEquations ne;
            {
              py::gil_scoped_release release;
              ne = p.problem->NormalEquations();
            }
            if (!ne.finite) throw LpoeError("non-finite residuals or Jacobian (check the input values)");
            PyNormalEquations out;
            out.H = std::move(ne.H);
            out.g = std::move(ne.g);
            out.cost = ne.cost;
            out.names = std::move(ne.names);
            return out;
          },
          "the normal equations at the current parameters (lpoe.NormalEquations)")
      .def(
          "update",
          [](PyProblem& p, const Eigen::VectorXd& x) {
            const int P = p.problem->SolvedParameterization().num_parameters;
            if (x.size() != P || !x.allFinite()) {
              throw LpoeError("update: expected " + std::to_string(P) + " finite values, got " +
                              std::to_string(x.size()));
            }
            p.problem->Update(x);
          },
          py::arg("x"), "applies a step x (normal_equations() order) to the parameters")
      .def_property_readonly(
          "names",
          [](const PyProblem& p) {
            std::vector<std::string> v;
            for (const Direction& d : p.problem->SolvedParameterization().parameters) {
              v.push_back(d.name);
            }
            return v;
          },
          "the solved parameters, in the order of normal_equations() and update()")
      .def_property_readonly("model", [](const PyProblem& p) { return p.problem->Model(); },
                             "the model at the current parameters (geometry; see joint_terms)")
      .def_property_readonly(
          "joint_terms",
          [](const PyProblem& p) {
            py::dict d;
            for (const JointTermValues& t : p.problem->JointTerms()) {
              d[py::str(t.term->name())] = t.theta;
            }
            return d;
          },
          "{term name: theta} of the joint-space terms at the current parameters")
      .def(
          "identifiability",
          [](const PyProblem& p, double max_condition) {
            PyIdentifiability r;
            py::gil_scoped_release release;
            r.a = p.problem->Analyze(max_condition);
            return r;
          },
          py::arg("max_condition") = OptionDefault(kCalibrate, "max_condition"),
          "identifiability at the current parameters")
      .def("__repr__", [](const PyProblem& p) {
        return "<lpoe.Problem: " + std::to_string(p.problem->data().size()) + " rows, " +
               std::to_string(p.problem->SolvedParameterization().num_parameters) +
               " parameters>";
      });

  m.def(
      "identifiability",
      [](const RobotModel& model, const MeasurementSet& data, const std::string& parameterization,
         const std::string& data_kind, const std::string& joint_errors, double max_condition) {
        // The problem's other options at lpoe_calibrate's defaults.
        const char* calibrate = "lpoe_calibrate";
        const PyProblem p = MakeProblem(
            model, data, parameterization, data_kind, OptionDefault(calibrate, "sigma"),
            CalibrationProblemOptions().orientation_weight, joint_errors,
            OptionDefaultText(calibrate, "loss"), OptionDefault(calibrate, "loss_scale"));
        PyIdentifiability r;
        py::gil_scoped_release release;
        r.a = p.problem->Analyze(max_condition);
        return r;
      },
      py::arg("model"), py::arg("data"), py::kw_only(),
      py::arg("parameterization") = OptionDefaultText(kCalibrate, "parameterization"),
      py::arg("data_kind") = OptionDefaultText(kCalibrate, "data_kind"),
      py::arg("joint_errors") = OptionDefaultText(kCalibrate, "joint_errors"),
      py::arg("max_condition") = OptionDefault(kCalibrate, "max_condition"),
      "identifiability of `model`'s parameters by `data` (at the model as given: register it "
      "first when the data are in another frame): rank, condition number, and the directions "
      "not identifiable, named, with the reason");

  py::class_<PyCompensation>(m, "Compensation", "The result of lpoe.compensate.")
      .def_readonly("q", &PyCompensation::q, "(M, N) compensated joints (rad / mm)")
      .def_readonly("status", &PyCompensation::status,
                    "per row: ok | unreachable | limit | singular | branch")
      .def_readonly("position_error", &PyCompensation::position_error,
                    "(M,) |target - reached| in mm")
      .def_readonly("orientation_error", &PyCompensation::orientation_error, "(M,) rad")
      .def_readonly("sigma_min", &PyCompensation::sigma_min,
                    "(M,) smallest singular value of the task Jacobian")
      .def_readonly("correction", &PyCompensation::correction, "(M,) |q - seed|")
      .def_property_readonly(
          "corrected",
          [](const PyCompensation& c) -> py::object {
            if (c.corrected.size() == 0) return py::none();
            return py::cast(c.corrected);
          },
          "(M, 3) the nominal model's tool position at q: the target to send to a controller "
          "that uses nominal kinematics (None without nominal=)")
      .def_property_readonly(
          "corrected_quaternions",
          [](const PyCompensation& c) -> py::object {
            if (c.corrected_quaternions.size() == 0) return py::none();
            return py::cast(c.corrected_quaternions);
          },
          "(M, 4) [x, y, z, w] of the corrected pose targets (NaN for position-only rows)")
      .def("__len__", [](const PyCompensation& c) { return c.status.size(); })
      .def("__repr__", [](const PyCompensation& c) { return Repr(c); });

  m.def("compensate", &Compensate, py::arg("model"), py::arg("targets") = py::none(),
        py::kw_only(), py::arg("seeds") = py::none(), py::arg("orientations") = py::none(),
        py::arg("joints") = py::none(), py::arg("nominal") = py::none(),
        py::arg("joints_target") = OptionDefaultText(kCompensate, "joints_target"),
        py::arg("tool") = py::none(), py::arg("frame") = OptionDefaultText(kCompensate, "frame"),
        py::arg("tcp") = py::none(), py::arg("flange") = "",
        py::arg("threads") = static_cast<int>(OptionDefault(kCompensate, "threads")),
        py::arg("max_iterations") = static_cast<int>(OptionDefault(kCompensate, "max_iterations")),
        py::arg("restarts") = static_cast<int>(OptionDefault(kCompensate, "restarts")),
        py::arg("position_tolerance") = OptionDefault(kCompensate, "position_tolerance"),
        py::arg("orientation_tolerance") = OptionDefault(kCompensate, "orientation_tolerance"),
        py::arg("singular_threshold") = OptionDefault(kCompensate, "singular_threshold"),
        "the joints that make the calibrated `model` reach its targets (as lpoe_compensate, "
        "through the same library workflow, lpoe/compensation.h):\n"
        "  targets mode: targets (M, 3) mm in `frame` ('base': the model's base frame, carried "
        "into the calibrated model's frame by its recorded registration, as the tool's default; "
        "'measurement': the tracker's frame; 'link:NAME': a base frame of the model such as "
        "ur_description's 'base'), seeds (M, N) the program's joints, optional "
        "orientations (M, 4) [x, y, z, w] for pose targets;\n"
        "  joints mode: joints (M, N) a program planned with `nominal`: reach the nominal tool "
        "pose (joints_target='pose') or position there.\n"
        "tool: a tool name or index for every row, or one per row (a list or array of names or "
        "indices); tcp: a TCP that was not measured, a tool name or [x, y, z(, roll, pitch, yaw)] "
        "in mm and rad relative to the flange (as --tcp), for rows without a tool of their own; "
        "flange: the flange a tcp offset is relative to, a tool or flange frame of the models "
        "(as --flange; default tool0, else flange, else the last joint's frame).\n"
        "The IK options' defaults and ranges are lpoe_compensate's (lpoe/options.h).\n"
        "With nominal=, also the corrected targets for a controller using nominal kinematics. "
        "Targets mostly metres from anything the robot reaches raise lpoe.Error naming the frame "
        "assumed.");

  py::class_<PyPlan>(m, "Plan", "The result of lpoe.plan.")
      .def_readonly("q", &PyPlan::q, "(count, N) the planned configurations")
      .def_readonly("candidate_rows", &PyPlan::candidate_rows,
                    "row of each planned pose in `candidates`")
      .def_readonly("candidates", &PyPlan::candidates, "the candidates offered (given or sampled)")
      .def_readonly("criterion", &PyPlan::criterion)
      .def_readonly("num_parameters", &PyPlan::num_parameters)
      .def_readonly("gravity_tilt", &PyPlan::gravity_tilt,
                    "whether the gravity tilt was planned for (joint_errors with 'tilt', or 'auto' "
                    "with a model that carries compliance values)")
      .def_readonly("exchanges", &PyPlan::exchanges)
      .def_readonly("visible", &PyPlan::visible,
                    "the tools (SMR names) to measure at each planned pose: the tracker's visible "
                    "ones with tracker=, else every tool")
      .def_property_readonly("quality", [](const PyPlan& p) { return QualityDict(p.quality); },
                             "rank, condition number, predicted RMS per mm of noise, criteria")
      .def_readonly("predicted_error", &PyPlan::predicted_error,
                    "predicted RMS error (mm) of the calibrated tool positions over the workspace "
                    "with the noise and the unmodelled error (lpoe_plan --unmodelled_error's "
                    "default, or the model's residual layer; docs/planning.md)")
      .def_readonly("random_predicted_error", &PyPlan::random_predicted_error,
                    "the same, RMS over the random plans of the same size (mm)")
      .def_readonly("random_predicted_rms", &PyPlan::random_predicted_rms,
                    "predicted RMS of random plans of the same size (RMS over the draws)")
      .def_property_readonly(
          "pool",
          [](const PyPlan& p) {
            py::dict d;
            d["offered"] = p.offered;
            d["feasible"] = p.feasible;
            d["outside_limits"] = p.outside_limits;
            d["near_singular"] = p.near_singular;
            d["nothing_visible"] = p.nothing_visible;
            d["outside_cell"] = p.outside_cell;
            return d;
          },
          "how many candidates were offered, kept and why the others were dropped")
      .def("__len__", [](const PyPlan& p) { return static_cast<size_t>(p.q.rows()); })
      .def("__repr__", [](const PyPlan& p) {
        std::ostringstream os;
        os << "<lpoe.Plan: " << p.q.rows() << " poses, criterion " << p.criterion
           << ", predicted RMS " << p.quality.predicted_rms << " per mm of noise (random "
           << p.random_predicted_rms << ")>";
        return os.str();
      });

  BindContactPlanClass(m);
  const ContactPlanOptions contact;
  m.def("plan", &Plan, py::arg("model").none(true), py::arg("count"), py::kw_only(),
        py::arg("candidates") = py::none(),
        py::arg("candidate_count") = static_cast<int>(OptionDefault(kPlan, "candidate_count")),
        py::arg("workspace") = py::none(),
        py::arg("workspace_count") = static_cast<int>(OptionDefault(kPlan, "workspace_count")),
        py::arg("seed") = static_cast<uint64_t>(OptionDefault(kPlan, "seed")),
        py::arg("criterion") = OptionDefaultText(kPlan, "criterion"),
        py::arg("tracker") = py::none(),
        py::arg("max_range") = OptionDefault(kPlan, "max_range"),
        py::arg("acceptance_angle") = OptionDefault(kPlan, "acceptance_angle"),
        py::arg("smr_facing") = py::none(),
        py::arg("min_singularity") = OptionDefault(kPlan, "min_singularity"),
        py::arg("random_draws") = static_cast<int>(OptionDefault(kPlan, "random_draws")),
        py::arg("joint_errors") = OptionDefaultText(kPlan, "joint_errors"),
        py::arg("min_z") = py::none(),
        py::arg("box") = py::none(), py::arg("keep_out") = py::none(),
        py::arg("joint_ranges") = py::none(),
        py::arg("measurement") = OptionDefaultText(kPlan, "measurement"),
        py::arg("pivots") = py::none(), py::arg("bar_length") = contact.bar_length,
        py::arg("stroke") = contact.stroke, py::arg("planes") = py::none(),
        py::arg("face_centres") = py::none(), py::arg("face_radius") = contact.face_radius,
        py::arg("probe_radius") = contact.probe_radius,
        py::arg("samples_per_feature") = contact.samples_per_feature,
        py::arg("contact_tool") = py::none(), py::arg("prior") = py::none(),
        py::arg("prior_free") = py::none(),
        py::arg("noise_sigma") = OptionDefault(kPlan, "noise_sigma"),
        py::arg("unmodelled_error") = py::none(), py::arg("unmodelled_length") = py::none(),
        "chooses `count` poses to measure (as lpoe_plan): candidates (C, N) rad/mm or "
        "candidate_count sampled within the limits; criterion D | A | E | I | O1 | O3; optional "
        "tracker (3,) mm with max_range (mm), acceptance_angle (degrees), smr_facing (3,) or "
        "(tools, 3); joint_errors as lpoe_plan's (the terms' identifiable combinations join the "
        "parameters to determine; 'tilt' after compliance needs a model that carries compliance "
        "values); the cell: min_z (mm), box [xmin, ymin, zmin, xmax, ymax, zmax] (mm), keep_out "
        "(K, 6) boxes, joint_ranges (N, 2) [lo, hi] per joint (NaN, NaN: the limits), all in the "
        "base frame as lpoe_plan's flags. prior= (a file or an lpoe.Prior; model=None: its "
        "model) and prior_free (joint or tool names) plan a recalibration as --prior and "
        "--prior_free, the prior's information weighed against noise_sigma (mm; 0: the "
        "prior's). unmodelled_error (mm per axis; 0: none) and unmodelled_length (rad or mm per "
        "joint) as --unmodelled_error and --unmodelled_length: the error the calibrated model "
        "will not explain, which the plan's predicted error includes and its exchange lowers "
        "(default: the model's residual layer, else 0.03 mm over 1 rad; docs/planning.md). "
        "The same workflow as lpoe_plan (lpoe/planning_workflow.h): the same seeds "
        "give the same plan. measurement='ballbar' (pivots (K, 3) mm, bar_length, stroke) or "
        "'plane' (planes (K, 4) [nx, ny, nz, d], face_centres (K, 3), face_radius, probe_radius) "
        "plans ballbar or probe poses as lpoe_plan --measurement (samples_per_feature, "
        "contact_tool, seed, min_singularity, min_z, box, random_draws as its flags; "
        "lpoe/contact_planning.h) and returns an lpoe.ContactPlan; the tracker options are "
        "refused there by name.");
}

}  // namespace python
}  // namespace lpoe
