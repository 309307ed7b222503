// Python bindings: calibration through the library pipeline (register, solve, analyse,
// cross-validate, verdict), with keyword options named as lpoe_calibrate's flags and the same
// defaults, so that a script and the tool produce the same calibrated model (same YAML bytes) and
// the same JSON report.
#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <memory>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "lpoe/analysis.h"
#include "lpoe/contact_calibration.h"
#include "lpoe/contact_measurements.h"
#include "lpoe/contact_pipeline.h"
#include "lpoe/measurement_kinds.h"
#include "lpoe/registration.h"
#include "lpoe/io.h"
#include "lpoe/options.h"
#include "lpoe/pipeline.h"
#include "lpoe/recalibration.h"
#include "lpoe/refusals.h"
#include "fleet_prior_text.h"
#include "python_api.h"
#include "report/contact_layer_report.h"
#include "report/report.h"
#include "tool_common.h"

namespace py = pybind11;

namespace lpoe {
namespace python {

// What lpoe.calibrate returns.
struct Calibration {
  bool converged = false;
  std::string termination, message, verdict, verdict_reason;
  int iterations = 0;
  double final_cost = 0;
  RobotModel model;        // as lpoe_calibrate --output writes it (registration recorded)
  std::string report_json;  // as lpoe_calibrate --report writes it
  std::string yaml;         // as lpoe_calibrate --output writes it (the model, its covariance block)
  // The prior's part (docs/recalibration.md): per identified parameter the data's share of its
  // information (empty without a prior), and with prior= the groups the new data showed changed.
  std::vector<std::string> parameter_names;
  Eigen::VectorXd data_share;
  std::vector<ChangedGroup> changed;
};

// A prior read from a file or built by lpoe.fleet_prior: a model and its covariance block.
struct Prior {
  RobotModel model;
  ModelCovariance covariance;
  std::string source;  // the file, or "fleet prior of N models"
  std::string yaml;    // the file's text (lpoe_prior's for a fleet)
};

namespace {

// Keyword options named as lpoe_calibrate's flags: every Get names a known option (with its
// default); Finish() rejects the others, listing the known ones. A new CLI option is one Get here.
class KeywordOptions {
 public:
  explicit KeywordOptions(const py::kwargs& kwargs) : kwargs_(kwargs) {}

  template <typename T>
  T Get(const char* name, T fallback) {
    known_.push_back(name);
    if (!kwargs_.contains(name)) return fallback;
    const py::object value = kwargs_[name];
    if (value.is_none()) return fallback;
    try {
      return value.cast<T>();
    } catch (const py::cast_error&) {
      throw LpoeError(std::string(name) + ": cannot use " +
                      py::str(value.get_type().attr("__name__")).cast<std::string>() +
                      " value " + py::repr(value).cast<std::string>());
    }
  }
  bool Given(const char* name) const { return kwargs_.contains(name) && !kwargs_[name].is_none(); }

  void Finish(const char* function) const {
    for (const auto& item : kwargs_) {
      const std::string key = py::str(item.first);
      if (std::find(known_.begin(), known_.end(), key) == known_.end()) {
        std::string list;
        for (const std::string& k : known_) list += (list.empty() ? "" : ", ") + k;
        throw LpoeError(std::string(function) + ": unknown option '" + key + "' (options: " +
                        list + ")");
      }
    }
  }

 private:
  const py::kwargs& kwargs_;
  std::vector<std::string> known_;
};

// prior=: a file (a calibrated model with its covariance block, or lpoe_prior's fleet prior) or an
// lpoe.Prior; null when not given.
std::shared_ptr<Prior> PriorArgument(const py::object& prior) {
  if (prior.is_none()) return nullptr;
  if (py::isinstance<Prior>(prior)) return std::make_shared<Prior>(prior.cast<Prior>());
  const py::object os_path = py::module_::import("os").attr("fspath");
  std::string path;
  try {
    path = os_path(prior).cast<std::string>();
  } catch (const py::error_already_set&) {
    throw LpoeError("prior: expected a file name or an lpoe.Prior, got " +
                    py::str(prior.get_type().attr("__name__")).cast<std::string>());
  }
  auto out = std::make_shared<Prior>();
  out->source = path;
  Check(ReadRobotModel(path, &out->model));
  Check(ReadModelCovariance(path, out->model, &out->covariance));
  return out;
}

Calibration Calibrate(const RobotModel& nominal, const MeasurementSet& given_data,
                      const MeasurementSet* given_verify, const py::kwargs& kwargs,
                      const Prior* prior_file = nullptr) {
  KeywordOptions k(kwargs);
  const std::string solver = k.Get<std::string>("solver", "linear");
  const std::string parameterization = k.Get<std::string>("parameterization", "identifiable");
  const std::string data_kind = k.Get<std::string>("data_kind", "auto");
  const std::string joint_errors = k.Get<std::string>("joint_errors", "none");
  const std::string residual_model = k.Get<std::string>("residual_model", "none");
  const bool register_frames = k.Get<bool>("register", true);
  const double holdout = k.Get<double>("holdout", 0.0);
  const int kfold = k.Get<int>("kfold", 0);
  const uint64_t split_seed = k.Get<uint64_t>("split_seed", 1);
  const std::string split_name = k.Get<std::string>("split", "random");
  const double outlier_threshold = k.Get<double>("outlier_threshold", 5.0);
  const int max_iterations = k.Get<int>("max_iterations", 30);
  const double step_tolerance = k.Get<double>("step_tolerance", 1e-10);
  const double sd_fraction = k.Get<double>("sd_fraction", 1e-2);
  const double max_condition = k.Get<double>("max_condition", 1e8);
  const double noise_sigma = k.Get<double>("noise_sigma", 0.03);
  const std::string loss = k.Get<std::string>("loss", "none");
  const double loss_scale = k.Get<double>("loss_scale", 1.0);
  const bool sigma_given = k.Given("sigma");
  const double sigma = k.Get<double>("sigma", 1.0);
  const int threads = k.Get<int>("threads", 0);
  const std::string angle_unit = k.Get<std::string>("angle_unit", "rad");
  // Known SMR nests: a list of tool names (or one comma-separated string, as --fixed_tools).
  const py::object fixed_tools = k.Get<py::object>("fixed_tools", py::none());
  // The default prior (docs/identifiability.md "The prior"), as lpoe_calibrate's --prior_* flags.
  const double prior_scale = k.Get<double>("prior_scale", 1.0);
  const double prior_translation = k.Get<double>("prior_translation", 5.0);
  const double prior_rotation = k.Get<double>("prior_rotation", 20.0);
  const double prior_tool_translation = k.Get<double>("prior_tool_translation", 20.0);
  const double prior_joint_terms = k.Get<double>("prior_joint_terms", 5.0);
  k.Finish("calibrate");
  // The ranges lpoe_calibrate's flags have (lpoe/options.h), with the same messages.
  for (const auto& [name, value] :
       std::vector<std::pair<const char*, double>>{{"max_iterations", max_iterations},
                                                   {"step_tolerance", step_tolerance},
                                                   {"sd_fraction", sd_fraction},
                                                   {"max_condition", max_condition},
                                                   {"outlier_threshold", outlier_threshold},
                                                   {"sigma", sigma},
                                                   {"loss_scale", loss_scale},
                                                   {"threads", threads},
                                                   {"noise_sigma", noise_sigma},
                                                   {"prior_scale", prior_scale},
                                                   {"prior_translation", prior_translation},
                                                   {"prior_rotation", prior_rotation},
                                                   {"prior_tool_translation", prior_tool_translation},
                                                   {"prior_joint_terms", prior_joint_terms}}) {
    if (Status s = CheckOption("lpoe_calibrate", name, value); !s.ok()) throw LpoeError(s.message());
  }

  if (Status s = nominal.Validate(); !s.ok()) throw LpoeError(s.message());
  std::vector<std::string> fixed_names;
  if (!fixed_tools.is_none()) {
    if (py::isinstance<py::str>(fixed_tools)) {
      if (Status s = ParseNameList(fixed_tools.cast<std::string>(), &fixed_names); !s.ok()) {
        throw LpoeError("fixed_tools: " + s.message());
      }
    } else {
      try {
        fixed_names = fixed_tools.cast<std::vector<std::string>>();
      } catch (const py::cast_error&) {
        throw LpoeError("fixed_tools: expected a list of tool names, got " +
                        py::repr(fixed_tools).cast<std::string>());
      }
    }
  }
  RobotModel with_fixed = nominal;
  if (Status s = SetFixedTools(fixed_names, &with_fixed); !s.ok()) {
    throw LpoeError("fixed_tools: " + s.message());
  }
  if (given_data.num_joints() != nominal.num_joints() ||
      (given_verify != nullptr && given_verify->num_joints() != nominal.num_joints())) {
    throw LpoeError("the measurements have a different number of joints than the model");
  }
  // Every row's tool a tool of the model (data read with another model): refused here, never the
  // solvers' internal check (an abort of the interpreter).
  for (const MeasurementSet* set : {&given_data, given_verify}) {
    if (set == nullptr) continue;
    for (int r = 0; r < set->size(); ++r) {
      if (set->target(r) < 0 || set->target(r) >= nominal.num_tools()) {
        throw LpoeError(std::string(set == &given_data ? "data" : "verify") + ": row " +
                        std::to_string(r) + " measures tool " + std::to_string(set->target(r)) +
                        ", the model has " + std::to_string(nominal.num_tools()) + " tools");
      }
    }
  }
  if (!(holdout >= 0 && holdout <= 0.95)) throw LpoeError("holdout: expected 0..0.95");
  SplitKind split = SplitKind::kRandom;
  if (!ParseSplitKind(split_name, &split)) {
    throw LpoeError("split: expected 'random' or 'sequential', got '" + split_name + "'");
  }
  if (holdout > 0 && given_verify != nullptr) {
    throw LpoeError("give either verify= or holdout=, not both");
  }
  // --holdout: the rows held out for verification, as lpoe_calibrate splits them.
  MeasurementSet held_data(nominal.num_joints()), held_verify(nominal.num_joints());
  if (holdout > 0) {
    std::vector<int> id_rows, ver_rows;
    HoldoutSplit(given_data, holdout, split_seed, &id_rows, &ver_rows, split);
    held_data = given_data.Subset(id_rows);
    held_verify = given_data.Subset(ver_rows);
    if (Status s = tools::CheckHoldoutSplit(holdout, held_data.size(), held_verify.size());
        !s.ok()) {
      throw LpoeError(s.message());
    }
  }
  const MeasurementSet& data = holdout > 0 ? held_data : given_data;
  const MeasurementSet* verify = holdout > 0 ? &held_verify : given_verify;

  PipelineOptions o;
  if (solver != "linear" && solver != "ceres") {
    throw LpoeError("solver: expected 'linear' or 'ceres', got '" + solver + "'");
  }
  o.solver = solver == "ceres" ? SolverKind::kCeres : SolverKind::kLinear;
  o.parameterization = ParseParameterizationOption(parameterization);
  o.use_orientation = ParseDataKindOption(data_kind, data);
  // joint_errors: "none", a comma-separated list or "auto" (chosen by cross-validation), as
  // lpoe_calibrate --joint_errors.
  o.joint_errors_auto = joint_errors == "auto";
  o.joint_error_folds = kfold >= 2 ? kfold : 5;
  if (!o.joint_errors_auto) o.joint_errors = JointErrorNames(joint_errors, true);
  if (!ParseResidualModelKind(residual_model, &o.residual_model)) {
    throw LpoeError("residual_model: expected 'none', 'gp' or 'auto', got '" + residual_model +
                    "'");
  }
  if (angle_unit != "rad" && angle_unit != "deg") {
    throw LpoeError("angle_unit: expected 'rad' or 'deg', got '" + angle_unit + "'");
  }
  std::vector<int> configuration_of_row;
  if (kfold != 0 && !(kfold >= 2 && kfold <= 100 &&
                      kfold <= ConfigurationGroups(data, &configuration_of_row))) {
    throw LpoeError("kfold: expected 0 (off) or 2..100 and at most the configurations, got " +
                    std::to_string(kfold));
  }
  if (!(max_iterations >= 1 && max_iterations <= 10000) || !(step_tolerance > 0) ||
      !(sd_fraction >= 0 && sd_fraction <= 0.5) || !(max_condition >= 10) ||
      !(noise_sigma > 0 && noise_sigma <= 100) || !(outlier_threshold >= 1) ||
      !(threads >= 0 && threads <= 256)) {
    throw LpoeError("an option is out of range (see lpoe_calibrate --help for the ranges)");
  }
  if (solver == "linear" && loss != "none") {
    throw LpoeError("loss needs solver='ceres' (the linear solver is plain least squares)");
  }
  o.register_frames = register_frames;
  o.kfold = kfold;
  o.split_seed = split_seed;
  o.residual_layer.seed = split_seed;
  o.split = split;
  o.outlier_threshold = outlier_threshold;
  o.plausibility.noise_sigma = noise_sigma;
  o.plausibility.joint_values_in_degrees = angle_unit == "deg";
  if (prior_scale > 0) {
    auto prior = std::make_shared<ParameterPrior>();
    prior->scale = prior_scale;
    prior->scales.frame_translation_mm = prior_translation;
    prior->scales.frame_rotation_mrad = prior_rotation;
    prior->scales.tool_translation_mm = prior_tool_translation;
    prior->scales.joint_term_mrad = prior_joint_terms;
    o.prior = prior;
  } else {
    o.prior = nullptr;
  }
  o.linear.max_iterations = max_iterations;
  o.linear.step_tolerance = step_tolerance;
  o.linear.max_condition_number = max_condition;
  o.linear.convergence.sd_fraction = sd_fraction;
  o.ceres.max_iterations = max_iterations;
  o.ceres.max_condition_number = max_condition;
  o.ceres.loss = loss;
  o.ceres.loss_scale = loss_scale;
  // Without a stated noise level, estimate it from the residuals (as lpoe_calibrate does).
  o.ceres.a_posteriori_covariance = !sigma_given;
  o.ceres.sigma = sigma;
  o.ceres.convergence.sd_fraction = sd_fraction;
  if (threads > 0) o.ceres.num_threads = threads;
  if (Status s = ValidateCeresSolverOptions(o.ceres); !s.ok()) throw LpoeError(s.message());

  const MeasurementSet empty(nominal.num_joints());
  const MeasurementSet& verification = verify != nullptr ? *verify : empty;
    RecalibrationResult recalibration;
  if (prior_file != nullptr) {
    // lpoe_calibrate --prior: the file's model and covariance, the --prior_* tolerances on the
    // directions it does not cover, every standard deviation times prior_scale; the groups the new
    // data show changed are freed (Recalibrate).
    if (!(prior_scale > 0)) throw LpoeError("prior needs prior_scale > 0");
    if (prior_file->model.num_frames() != nominal.num_frames() ||
        prior_file->model.num_joints() != nominal.num_joints()) {
      throw LpoeError("prior=" + prior_file->source + ": its chain (" +
                      std::to_string(prior_file->model.num_joints()) + " joints, " +
                      std::to_string(prior_file->model.num_tools()) + " tools) is not the model's");
    }
    ParameterPrior prior = PriorFromCovariance(prior_file->model, prior_file->covariance,
                                               o.prior ? o.prior->scales : PriorScales());
    prior.scale = prior_scale;
    o.prior = std::make_shared<const ParameterPrior>(prior);
  }
  {
    py::gil_scoped_release release;
    if (prior_file != nullptr) {
      recalibration = Recalibrate(with_fixed, data, verification, o);
    } else {
      recalibration.run = RunCalibrationPipeline(with_fixed, data, verification, o);
    }
  }
  PipelineResult& run = recalibration.run;
  const CalibrationResult& result = run.result;

  Calibration c;
  c.converged = result.converged();
  c.termination = TerminationName(result.termination);
  c.message = result.message;
  c.iterations = result.iterations;
  c.final_cost = result.final_cost;
  c.model = CalibratedModel(run);
  if (result.termination == Termination::kNotIdentifiable) return c;
  c.verdict = VerdictLevelName(run.verdict.level);
  c.verdict_reason = run.verdict.reason;
  c.changed = recalibration.changed;
  c.parameter_names = run.identifiability.parameter_names;
  c.data_share = run.identifiability.data_share;
  c.yaml = CalibratedModelYaml(c.model, result);

  // The JSON report, filled as lpoe_calibrate fills it.
  tools::RunSummary summary;
  summary.solver = solver;
  summary.parameterization = ParameterizationName(o.parameterization);
  summary.data_kind = o.use_orientation ? "pose" : "position";
  summary.angle_unit = angle_unit;
  summary.verification_source = holdout > 0 ? "holdout" : verify != nullptr ? "array" : "";
  tools::AddPipelineResult(run, &summary);
  tools::AddPointResiduals(run.before, result.model, data, verification, &summary);
  summary.joint_errors_requested = joint_errors;
  summary.residual_model_requested = residual_model;
  summary.tool_name = "lpoe (Python)";
  if (prior_file != nullptr) {
    summary.prior_path = prior_file->source;
    summary.changed_groups = recalibration.changed;
  }
  c.report_json = tools::RunSummaryToJson(summary);
  return c;
}


// ---- Ballbar distances and probe contacts (docs/measurements.md), as lpoe_calibrate runs them
// (tools/lpoe_calibrate_contact.cc): the same options, hold-out split and report table.

// The parts of `data` (one data set, or a list of them) as one contact set; tracker rows (an
// lpoe.Measurements) with noise `sigma` per axis, collected in `tracker` too. False when no part
// is a distance or plane set (the ordinary calibration then applies).
bool GatherContactData(const RobotModel& nominal, const py::object& data, double sigma,
                       bool sigma_given, ContactMeasurementSet* out, MeasurementSet* tracker) {
  std::vector<py::object> parts;
  if (py::isinstance<py::list>(data) || py::isinstance<py::tuple>(data)) {
    for (const py::handle& h : data) parts.push_back(py::reinterpret_borrow<py::object>(h));
  } else {
    parts.push_back(data);
  }
  bool any_contact = false;
  for (const py::object& part : parts) {
    if (py::isinstance<ContactMeasurementSet>(part)) any_contact = true;
  }
  if (!any_contact) return false;
  out->num_joints = nominal.num_joints();
  *tracker = MeasurementSet(nominal.num_joints());
  for (size_t i = 0; i < parts.size(); ++i) {
    const py::object& part = parts[i];
    if (py::isinstance<ContactMeasurementSet>(part)) {
      const ContactMeasurementSet& c = part.cast<const ContactMeasurementSet&>();
      if (c.num_joints != nominal.num_joints()) {
        throw LpoeError("data[" + std::to_string(i) + "]: " + std::to_string(c.num_joints) +
                        " joints, the model has " + std::to_string(nominal.num_joints()));
      }
      out->Append(c);
    } else if (py::isinstance<MeasurementSet>(part)) {
      const MeasurementSet& m = part.cast<const MeasurementSet&>();
      if (m.num_joints() != nominal.num_joints()) {
        throw LpoeError("data[" + std::to_string(i) + "]: " + std::to_string(m.num_joints()) +
                        " joints, the model has " + std::to_string(nominal.num_joints()));
      }
      if (!sigma_given) {
        throw LpoeError("data[" + std::to_string(i) +
                        "]: tracker rows with distances or planes need their noise: sigma= (mm "
                        "per axis), as lpoe_calibrate --sigma");
      }
      tracker->Append(m);
      out->Append(ContactSetFromPositions(m, sigma, "data[" + std::to_string(i) + "]"));
    } else {
      throw LpoeError("data[" + std::to_string(i) + "]: expected lpoe.Measurements or "
                      "lpoe.ContactMeasurements, got " +
                      py::str(part.get_type().attr("__name__")).cast<std::string>());
    }
  }
  for (int r = 0; r < out->size(); ++r) {
    if (out->rows[r].target < 0 || out->rows[r].target >= nominal.num_tools()) {
      throw LpoeError("data: row " + std::to_string(r) + " measures tool " +
                      std::to_string(out->rows[r].target) + ", the model has " +
                      std::to_string(nominal.num_tools()) + " tools");
    }
  }
  return true;
}

Calibration CalibrateContacts(const RobotModel& nominal, const ContactMeasurementSet& data,
                              const MeasurementSet& tracker, const py::kwargs& kwargs) {
  KeywordOptions k(kwargs);
  const std::string solver = k.Get<std::string>("solver", "linear");
  const std::string hold_scale = k.Get<std::string>("hold_scale", "auto");
  const double holdout = k.Get<double>("holdout", 0.0);
  const uint64_t split_seed = k.Get<uint64_t>("split_seed", 1);
  const int max_iterations = k.Get<int>("max_iterations", 30);
  const std::string data_kind = k.Get<std::string>("data_kind", "auto");
  k.Get<double>("sigma", 1.0);  // the tracker rows' noise (GatherContactData)
  // What lpoe_calibrate refuses with these kinds (docs/measurements.md), refused here too.
  const std::vector<std::pair<const char*, std::string>> defaults = {
      {"parameterization", "identifiable"}, {"loss", "none"}};
  const std::string joint_errors = k.Get<std::string>("joint_errors", "none");
  for (const auto& [name, fallback] : defaults) {
    if (k.Get<std::string>(name, fallback) != fallback) {
      throw LpoeError(std::string(name) + " is not available with distance or plane data: " +
                      ContactRefusalReason(name) + " (docs/measurements.md)");
    }
  }
  const std::string residual_model = k.Get<std::string>("residual_model", "none");
  ResidualModelKind residual_kind = ResidualModelKind::kNone;
  if (!ParseResidualModelKind(residual_model, &residual_kind)) {
    throw LpoeError("residual_model: expected 'none', 'gp' or 'auto', got '" + residual_model +
                    "'");
  }
  const int kfold = k.Get<int>("kfold", 0);
  if (kfold != 0 && !(kfold >= 2 && kfold <= 100)) {
    throw LpoeError("kfold: expected 0 (off) or 2..100, got " + std::to_string(kfold));
  }
  if (!k.Get<py::object>("fixed_tools", py::none()).is_none()) {
    throw LpoeError("fixed_tools is not available with distance or plane data: " +
                    ContactRefusalReason("fixed_tools") + " (docs/measurements.md)");
  }
  const py::object verify = k.Get<py::object>("verify", py::none());
  // Accepted and without effect here, as lpoe_calibrate's run for these kinds ignores them.
  for (const char* name : {"register", "split", "outlier_threshold", "step_tolerance",
                           "sd_fraction", "max_condition", "noise_sigma", "loss_scale", "threads",
                           "angle_unit", "prior_scale", "prior_translation", "prior_rotation",
                           "prior_tool_translation", "prior_joint_terms"}) {
    k.Get<py::object>(name, py::none());
  }
  k.Finish("calibrate");
  if (solver != "linear" && solver != "ceres") {
    throw LpoeError("solver: expected 'linear' or 'ceres', got '" + solver + "'");
  }
  ContactCalibrationOptions options;
  if (!ParseScaleHold(hold_scale, &options.hold_scale)) {
    throw LpoeError("hold_scale: expected 'auto', 'on' or 'off', got '" + hold_scale + "'");
  }
  if (!(max_iterations >= 1 && max_iterations <= 10000)) {
    throw LpoeError("max_iterations: expected 1..10000");
  }
  options.max_iterations = std::max(max_iterations, 30);
  if (!(holdout >= 0 && holdout < 1)) throw LpoeError("holdout: expected 0 <= holdout < 1");
  if (data_kind != "auto") {
    const MeasurementKindInfo* kind = FindMeasurementKind(data_kind);
    if (kind == nullptr || data.Count(kind->id) != data.size()) {
      throw LpoeError("data_kind: '" + data_kind + "' is not the kind of every row");
    }
  }
  if (data.Count(MeasurementKindId::kDistance) + data.Count(MeasurementKindId::kPlane) == 0) {
    throw LpoeError("data: no distance or plane rows");
  }
  if (Status s = nominal.Validate(); !s.ok()) throw LpoeError(s.message());

  RobotModel start = nominal;
  if (tracker.size() > 0) {
    RegistrationReport report;
    if (Status s = RegisterToMeasurements(nominal, tracker, &start, &report); !s.ok()) {
      throw LpoeError("registration to the tracker data: " + s.message());
    }
  }
  // joint_errors: the registry's terms on the start model, as lpoe_calibrate --joint_errors.
  if (Status s = ContactJointTerms(joint_errors, start, &options.joint_terms); !s.ok()) {
    throw LpoeError("joint_errors: " + s.message() + " (docs/measurements.md)");
  }
  // verify: distance and plane sets of the calibration's pivots and planes (as --verify).
  ContactMeasurementSet verification;
  if (!verify.is_none()) {
    if (holdout > 0) throw LpoeError("give either verify= or holdout=, not both");
    std::vector<py::object> parts;
    if (py::isinstance<py::list>(verify) || py::isinstance<py::tuple>(verify)) {
      for (const py::handle& h : verify) parts.push_back(py::reinterpret_borrow<py::object>(h));
    } else {
      parts.push_back(verify);
    }
    std::vector<ContactMeasurementSet> sets;
    for (const py::object& part : parts) {
      if (!py::isinstance<ContactMeasurementSet>(part)) {
        throw LpoeError("verify: with distance or plane data, expected lpoe.ContactMeasurements "
                        "(tracker rows: use holdout=), got " +
                        py::str(part.get_type().attr("__name__")).cast<std::string>());
      }
      const ContactMeasurementSet& c = part.cast<const ContactMeasurementSet&>();
      if (c.num_joints != nominal.num_joints()) {
        throw LpoeError("verify: a different number of joints than the model");
      }
      sets.push_back(c);
    }
    if (Status s = ContactVerificationSet(data, sets, &verification); !s.ok()) {
      throw LpoeError(
          "verify names a pivot or plane that data does not (its position is estimated from the "
          "calibration's rows): " +
          s.message());
    }
  }
  // The run as lpoe_calibrate's (lpoe/contact_pipeline.h): the same hold-out draw, k-fold and
  // figures per kind.
  ContactPipelineOptions run_options;
  run_options.solver = solver;
  run_options.calibration = options;
  run_options.holdout = holdout;
  run_options.split_seed = split_seed;
  run_options.kfold = kfold;
  run_options.residual_model = residual_kind;
  ContactPipelineResult run;
  {
    py::gil_scoped_release release;
    run = RunContactPipeline(start, data, verification, run_options);
  }
  const ContactCalibrationResult& result = run.calibration;
  const ContactMeasurementSet& identification = run.identification;
  Calibration c;
  c.converged = result.ok;
  c.iterations = result.iterations;
  c.final_cost = result.cost;
  c.message = result.message;
  c.model = result.model;
  if (!result.ok) {
    c.termination = result.iterations == 0 ? "not_identifiable" : "failed";
    return c;
  }
  c.termination = "converged";
  if (Status s = CheckModelFinite(result.model); !s.ok()) throw LpoeError(s.message());
  if (run.kfold_too_large) {
    throw LpoeError("kfold=" + std::to_string(kfold) + " " + run.message);
  }
  if (run.failed_fold >= 0) {
    throw LpoeError("kfold: fold " + std::to_string(run.failed_fold + 1) + " of " +
                    std::to_string(kfold) + ": " + run.message);
  }
  // The report: lpoe_calibrate's table per kind (tools/lpoe_calibrate_contact.cc), as JSON.
  py::list kinds;
  for (const ContactKindSummary& summary : run.kinds) {
    const MeasurementKindInfo& kind = *summary.kind;
    const ContactKindFigures& f = summary.fit;
    py::dict d;
    d["kind"] = kind.name;
    d["table"] = kind.report_table;
    d["rows"] = f.rows;
    d["rms_mm"] = f.rms;
    d["max_abs_mm"] = f.max_abs;
    d["expected_noise_mm"] = f.sigma;
    d["verdict"] = ContactKindVerdict(f);
    const ContactKindFigures& h = summary.held;
    if (h.rows > 0) {
      d["held_out_rows"] = h.rows;
      d["held_out_rms_mm"] = h.rms;
      py::dict v;
      v["source"] = verify.is_none() ? "holdout" : "verify";
      v["rows"] = h.rows;
      v["rms_mm"] = h.rms;
      v["max_abs_mm"] = h.max_abs;
      v["expected_noise_mm"] = h.sigma;
      v["verdict"] = ContactKindVerdict(h);
      d["verification"] = v;
    }
    if (kfold > 0) {
      const ContactKindFigures& cv = summary.kfold;
      py::dict k;
      k["folds"] = kfold;
      k["rows"] = cv.rows;
      k["rms_mm"] = cv.rms;
      k["max_abs_mm"] = cv.max_abs;
      d["kfold"] = k;
    }
    if (!summary.features.empty()) {
      // The kind's figures per pivot (distance) or per plane (plane), as the tool's report.
      py::list features;
      for (const ContactFeatureSummary& fs : summary.features) {
        py::dict e;
        e["name"] = fs.name;
        e["rows"] = fs.fit.rows;
        e["rms_mm"] = fs.fit.rms;
        e["max_abs_mm"] = fs.fit.max_abs;
        e["expected_noise_mm"] = fs.fit.sigma;
        e["verdict"] = ContactKindVerdict(fs.fit);
        if (fs.held.rows > 0) {
          e["held_out_rows"] = fs.held.rows;
          e["held_out_rms_mm"] = fs.held.rms;
        }
        if (kfold > 0) e["kfold_rms_mm"] = fs.kfold.rms;
        features.append(e);
      }
      d["features"] = features;
    }
    kinds.append(d);
  }
  const ContactParameterization& p = result.parameterization;
  py::list pivots, planes, left_out;
  for (size_t i = 0; i < result.features.pivots.size(); ++i) {
    const Eigen::Vector3d& x = result.features.pivots[i];
    py::dict d;
    d["name"] = identification.pivots[i];
    d["xyz_mm"] = std::vector<double>{x(0), x(1), x(2)};
    pivots.append(d);
  }
  for (size_t i = 0; i < result.features.planes.size(); ++i) {
    const Eigen::Vector4d& x = result.features.planes[i];
    py::dict d;
    d["name"] = identification.planes[i];
    d["normal"] = std::vector<double>{x(0), x(1), x(2)};
    d["offset_mm"] = x(3);
    planes.append(d);
  }
  for (const Direction& d : p.frames.unidentifiable) {
    py::dict e;
    e["name"] = d.name;
    e["reason"] = d.reason;
    left_out.append(e);
  }
  py::dict report;
  report["tool"] = "lpoe (Python)";
  report["solver"] = result.solver;
  report["iterations"] = result.iterations;
  report["cost_before"] = result.initial_cost;
  report["cost_after"] = result.cost;
  report["measurement_kinds"] = kinds;
  py::dict features;
  features["pivots"] = pivots;
  features["planes"] = planes;
  report["features"] = features;
  report["parameters"] = p.frames.num_parameters + 3 * p.num_pivots + 3 * p.num_planes;
  py::dict base, scale;
  base["directions_left_out"] = p.num_base_directions;
  base["reason"] = p.base_reason;
  report["base"] = base;
  scale["held"] = p.scale_held;
  scale["reason"] = p.scale_reason;
  scale["value"] = result.scale;
  report["scale"] = scale;
  report["left_out"] = left_out;
  py::list joint_terms;
  for (size_t b = 0; b < result.joint_terms.size(); ++b) {
    const JointTermValues& t = result.joint_terms[b];
    py::dict e, values;
    e["term"] = t.term->name();
    e["parameters"] = t.term->num_parameters();
    e["identified_combinations"] = static_cast<int>(p.frames.joint_blocks[b].basis.cols());
    for (int i = 0; i < t.theta.size(); ++i) values[py::str(t.term->ParameterName(i))] = t.theta(i);
    e["values"] = values;
    joint_terms.append(e);
  }
  report["joint_errors"] = joint_terms;
  // The residual layer as lpoe_calibrate's report gives it (report/contact_layer_report.h).
  report["residual_layer"] = py::module_::import("json").attr("loads")(
      tools::ContactLayerJsonText(run, residual_model));
  c.verdict = run.verdict;
  c.verdict_reason = "the worst of the kinds' verdicts (RMS within 2x the expected noise: pass, "
                     "5x: check)";
  c.report_json = py::module_::import("json").attr("dumps")(report, py::arg("indent") = 2)
                      .cast<std::string>();
  return c;
}

// lpoe.fleet_prior: lpoe_prior's fleet prior of calibrated models (files or lpoe.Model), with its
// refusals and warnings.
Prior FleetPriorOf(const py::sequence& models, const py::object& output) {
  std::vector<RobotModel> read;
  std::vector<std::string> names, paths;
  const py::object fspath = py::module_::import("os").attr("fspath");
  for (size_t k = 0; k < models.size(); ++k) {
    const py::object item = models[k];
    if (py::isinstance<RobotModel>(item)) {
      read.push_back(item.cast<RobotModel>());
      names.push_back("model " + std::to_string(k + 1));
      continue;
    }
    std::string path;
    try {
      path = fspath(item).cast<std::string>();
    } catch (const py::error_already_set&) {
      throw LpoeError("models: item " + std::to_string(k + 1) +
                      ": expected a file name or an lpoe.Model, got " +
                      py::str(item.get_type().attr("__name__")).cast<std::string>());
    }
    for (const std::string& p : paths) {
      if (tools::SameFile(p, path)) {
        throw LpoeError("models: " + path + " is listed twice: one robot would count twice");
      }
    }
    paths.push_back(path);
    RobotModel model;
    Check(ReadRobotModel(path, &model));
    read.push_back(std::move(model));
    names.push_back(path);
  }
  if (read.size() < 2) {
    throw LpoeError("models: a fleet prior needs at least 2 calibrated models (got " +
                    std::to_string(read.size()) + "); a frame's full 6x6 covariance needs " +
                    std::to_string(kRobotsForFullCovariance));
  }
  Prior out;
  if (Status s = FleetPrior(read, &out.model, &out.covariance); !s.ok()) {
    throw LpoeError(tools::FleetPriorRefusal(s, names));
  }
  const int robots = static_cast<int>(read.size());
  for (const std::string& w : tools::FleetPriorWarnings(robots, out.model, out.covariance)) {
    if (PyErr_WarnEx(PyExc_UserWarning, w.c_str(), 1) != 0) throw py::error_already_set();
  }
  out.yaml = tools::FleetPriorFileText(robots, out.model, out.covariance);
  out.source = "fleet prior of " + std::to_string(robots) + " models";
  if (!output.is_none()) {
    const std::string path = fspath(output).cast<std::string>();
    for (const std::string& p : paths) {
      if (tools::SameFile(p, path)) throw LpoeError("output: " + path + " is one of the models");
    }
    Check(WriteFileAtomically(path, out.yaml));
    out.source = path;
  }
  return out;
}

}  // namespace

void BindCalibration(py::module_& m) {
  py::class_<Prior>(m, "Prior",
                    "A prior for calibrate(prior=...): a model and its covariance block "
                    "(lpoe.fleet_prior, lpoe.read_prior; docs/recalibration.md).")
      .def_readonly("model", &Prior::model, "the prior's model (a fleet's mean)")
      .def_readonly("source", &Prior::source)
      .def_readonly("yaml", &Prior::yaml, "the file's text (for a fleet: what lpoe_prior writes)")
      .def_property_readonly("robots", [](const Prior& p) { return p.covariance.models; },
                             "how many robots the covariance was estimated from (1: one "
                             "calibration's own estimate)")
      .def_property_readonly(
          "covariance",
          [](const Prior& p) {
            py::dict d;
            const int n = p.model.num_joints();
            for (size_t f = 0; f < p.covariance.frames.size(); ++f) {
              if (p.covariance.frames[f].size() == 0) continue;
              const int i = static_cast<int>(f);
              d[py::str(i < n ? p.model.joints[i].name : p.model.tools[i - n].name)] =
                  Eigen::MatrixXd(p.covariance.frames[f]);
            }
            for (size_t b = 0; b < p.covariance.terms.size(); ++b) {
              d[py::str(p.covariance.term_names[b])] = Eigen::MatrixXd(p.covariance.terms[b]);
            }
            return d;
          },
          "{frame or joint term: covariance} (6x6 of xi = (omega rad, v mm) per frame, P x P per "
          "term), as the file's covariance block")
      .def(
          "write",
          [](const Prior& p, const py::object& path) {
            Check(WriteFileAtomically(
                py::module_::import("os").attr("fspath")(path).cast<std::string>(), p.yaml));
          },
          py::arg("path"), "writes the prior's file atomically")
      .def("__repr__", [](const Prior& p) {
        return "<lpoe.Prior: " + p.source + ", " + std::to_string(p.model.num_joints()) +
               " joints, " + std::to_string(p.model.num_tools()) + " tools>";
      });
  m.def(
      "read_prior",
      [](const py::object& path) {
        const std::shared_ptr<Prior> p = PriorArgument(path);
        if (!p) throw LpoeError("read_prior: a file name is needed");
        Prior out = *p;
        std::ifstream in(out.source);
        std::ostringstream ss;
        ss << in.rdbuf();
        out.yaml = ss.str();
        return out;
      },
      py::arg("path"),
      "reads a prior file (a calibrated model with its covariance block, lpoe_calibrate --output, "
      "or lpoe_prior's fleet prior)");
  m.def("fleet_prior", &FleetPriorOf, py::arg("models"), py::kw_only(),
        py::arg("output") = py::none(),
        "The fleet prior of calibrated robots of one type (lpoe_prior --models=... --output=...): "
        "`models` a list of calibrated model files (YAML) or lpoe.Model; returns an lpoe.Prior "
        "(their mean model and per-frame sample covariance) usable as calibrate(prior=...), and "
        "writes lpoe_prior's file to `output` when given. Refuses fewer than 2 models, a file "
        "listed twice and models of different chains or tools (lpoe_prior's message); warns "
        "(UserWarning) below 7 robots, where a frame's covariance cannot have full rank.");

  py::class_<Calibration>(m, "Calibration", "The result of lpoe.calibrate.")
      .def_readonly("converged", &Calibration::converged)
      .def_readonly("termination", &Calibration::termination)
      .def_readonly("message", &Calibration::message)
      .def_readonly("iterations", &Calibration::iterations)
      .def_readonly("final_cost", &Calibration::final_cost)
      .def_readonly("verdict", &Calibration::verdict, "pass | check | fail ('' when not solved)")
      .def_readonly("verdict_reason", &Calibration::verdict_reason)
      .def_readonly("model", &Calibration::model, "the calibrated model (as --output writes it)")
      .def_property_readonly(
          "report",
          [](const Calibration& c) -> py::object {
            if (c.report_json.empty()) return py::none();
            return py::module_::import("json").attr("loads")(c.report_json);
          },
          "the JSON report as a dict (None when the data could not identify the model)")
      .def_readonly("report_json", &Calibration::report_json)
      .def_readonly("yaml", &Calibration::yaml,
                    "the calibrated model with its covariance block, as lpoe_calibrate --output "
                    "writes it (a later calibration's prior=)")
      .def(
          "write",
          [](const Calibration& c, const py::object& path) {
            if (c.yaml.empty()) throw LpoeError("write: the calibration has no model");
            Check(WriteFileAtomically(py::module_::import("os").attr("fspath")(path).cast<std::string>(),
                                      c.yaml));
          },
          py::arg("path"),
          "writes `yaml` atomically (as lpoe_calibrate --output): usable as prior= and by "
          "lpoe.fleet_prior")
      .def_property_readonly(
          "data_share",
          [](const Calibration& c) {
            py::dict d;
            for (size_t k = 0; k < c.parameter_names.size(); ++k) {
              if (static_cast<Eigen::Index>(k) < c.data_share.size()) {
                d[py::str(c.parameter_names[k])] = c.data_share(static_cast<Eigen::Index>(k));
              }
            }
            return d;
          },
          "{parameter: the data's share of its information} (1: the data alone, 0: the prior "
          "alone; empty without a prior), as the report's identified[].data_share")
      .def_property_readonly(
          "changed",
          [](const Calibration& c) {
            py::list out;
            for (const ChangedGroup& g : c.changed) {
              py::dict d;
              d["name"] = g.name;
              d["chi2"] = g.chi2;
              d["dof"] = g.dof;
              out.append(d);
            }
            return out;
          },
          "with prior=: the groups the new data showed changed against the prior, freed (each "
          "{name, chi2, dof}, in the order found), as lpoe_calibrate --prior reports them")
      .def("__repr__", [](const Calibration& c) {
        std::string s = "<lpoe.Calibration: " + c.termination + " after " +
                        std::to_string(c.iterations) + " iterations";
        if (!c.verdict.empty()) s += ", verdict " + c.verdict;
        return s + ">";
      });

  // Explicit keyword-only arguments (visible in help() and inspect.signature), named as
  // lpoe_calibrate's flags with the same defaults; passed on as the options KeywordOptions reads.
  m.def(
      "calibrate",
      [](const py::object& model_arg, const py::object& data, const py::object& verify,
         const std::string& solver, const std::string& parameterization,
         const std::string& data_kind, const std::string& joint_errors,
         const std::string& residual_model, bool register_frames,
         double holdout, int kfold, const std::string& split, uint64_t split_seed,
         double outlier_threshold, int max_iterations, double step_tolerance, double sd_fraction,
         double max_condition, double noise_sigma, const std::string& loss, double loss_scale,
         const py::object& sigma, int threads, const std::string& angle_unit,
         const py::object& fixed_tools, double prior_scale, double prior_translation,
         double prior_rotation, double prior_tool_translation, double prior_joint_terms,
         const std::string& hold_scale, const py::object& prior_arg) {
        // prior=: the prior's model is the start unless a model is given (lpoe_calibrate --prior).
        const std::shared_ptr<Prior> prior = PriorArgument(prior_arg);
        if (model_arg.is_none() && !prior) {
          throw LpoeError("model: a model is needed (None only with prior=, whose model is then "
                          "the start)");
        }
        const RobotModel model =
            model_arg.is_none() ? prior->model : model_arg.cast<RobotModel>();
        py::kwargs k;
        k["solver"] = solver;
        k["parameterization"] = parameterization;
        k["data_kind"] = data_kind;
        k["joint_errors"] = joint_errors;
        k["residual_model"] = residual_model;
        k["register"] = register_frames;
        k["holdout"] = holdout;
        k["kfold"] = kfold;
        k["split"] = split;
        k["split_seed"] = split_seed;
        k["outlier_threshold"] = outlier_threshold;
        k["max_iterations"] = max_iterations;
        k["step_tolerance"] = step_tolerance;
        k["sd_fraction"] = sd_fraction;
        k["max_condition"] = max_condition;
        k["noise_sigma"] = noise_sigma;
        k["loss"] = loss;
        k["loss_scale"] = loss_scale;
        k["sigma"] = sigma;
        k["threads"] = threads;
        k["angle_unit"] = angle_unit;
        k["fixed_tools"] = fixed_tools;
        k["prior_scale"] = prior_scale;
        k["prior_translation"] = prior_translation;
        k["prior_rotation"] = prior_rotation;
        k["prior_tool_translation"] = prior_tool_translation;
        k["prior_joint_terms"] = prior_joint_terms;
        // Ballbar distances and probe contacts: one lpoe.ContactMeasurements or a list of data
        // sets (docs/measurements.md).
        ContactMeasurementSet contacts;
        MeasurementSet tracker(model.num_joints());
        if (GatherContactData(model, data, sigma.is_none() ? 0.0 : sigma.cast<double>(),
                              !sigma.is_none(), &contacts, &tracker)) {
          k["hold_scale"] = hold_scale;
          k["verify"] = verify;
          if (prior) {
            throw LpoeError("prior applies to tracker data (lpoe_calibrate --prior), not to "
                            "distance and plane data");
          }
          return CalibrateContacts(model, contacts, tracker, k);
        }
        if (hold_scale != "auto") {
          throw LpoeError("hold_scale applies to distance and plane data only");
        }
        if (!py::isinstance<MeasurementSet>(data)) {
          throw LpoeError("data: expected lpoe.Measurements, lpoe.ContactMeasurements or a list "
                          "of them, got " +
                          py::str(data.get_type().attr("__name__")).cast<std::string>());
        }
        const MeasurementSet* v = verify.is_none() ? nullptr : verify.cast<const MeasurementSet*>();
        return Calibrate(model, data.cast<const MeasurementSet&>(), v, k, prior.get());
      },
      py::arg("model"), py::arg("data"), py::arg("verify") = py::none(), py::kw_only(),
      py::arg("solver") = "linear", py::arg("parameterization") = "identifiable",
      py::arg("data_kind") = "auto", py::arg("joint_errors") = "none",
      py::arg("residual_model") = "none", py::arg("register") = true, py::arg("holdout") = 0.0, py::arg("kfold") = 0,
      py::arg("split") = "random", py::arg("split_seed") = 1,
      py::arg("outlier_threshold") = OptionDefault("lpoe_calibrate", "outlier_threshold"),
      py::arg("max_iterations") =
          static_cast<int>(OptionDefault("lpoe_calibrate", "max_iterations")),
      py::arg("step_tolerance") = OptionDefault("lpoe_calibrate", "step_tolerance"),
      py::arg("sd_fraction") = OptionDefault("lpoe_calibrate", "sd_fraction"),
      py::arg("max_condition") = OptionDefault("lpoe_calibrate", "max_condition"),
      py::arg("noise_sigma") = OptionDefault("lpoe_calibrate", "noise_sigma"),
      py::arg("loss") = "none", py::arg("loss_scale") = OptionDefault("lpoe_calibrate", "loss_scale"),
      py::arg("sigma") = py::none(),
      py::arg("threads") = static_cast<int>(OptionDefault("lpoe_calibrate", "threads")),
      py::arg("angle_unit") = "rad", py::arg("fixed_tools") = py::none(),
      py::arg("prior_scale") = OptionDefault("lpoe_calibrate", "prior_scale"),
      py::arg("prior_translation") = OptionDefault("lpoe_calibrate", "prior_translation"),
      py::arg("prior_rotation") = OptionDefault("lpoe_calibrate", "prior_rotation"),
      py::arg("prior_tool_translation") = OptionDefault("lpoe_calibrate", "prior_tool_translation"),
      py::arg("prior_joint_terms") = OptionDefault("lpoe_calibrate", "prior_joint_terms"),
      py::arg("hold_scale") = "auto", py::arg("prior") = py::none(),
      "Calibrates `model` from `data` (and verifies on `verify`) as lpoe_calibrate does, through "
      "the same pipeline (registration, solver, analysis, cross-validation, verdict). The keyword "
      "arguments are named as its flags, with the same defaults and ranges (lpoe/options.h):\n"
      "  solver='linear' | 'ceres'; parameterization='identifiable' | 'full';\n"
      "  data_kind='auto' | 'position' | 'pose'; joint_errors='none' | a comma-separated "
      "list of lpoe.joint_error_terms() (e.g. 'compliance,harmonics') | 'auto';\n"
      "  residual_model='none' | 'gp' | 'auto' (the learned residual layer, "
      "docs/residual_layer.md: the model carries it and predict uses it);\n"
      "  register: register the model to the measurement frame first; holdout: fraction held out "
      "(instead of verify); kfold: k-fold cross-validation (0: off); split: 'random' | "
      "'sequential' folds and hold-out, seeded by split_seed;\n"
      "  outlier_threshold (robust sigmas), max_iterations, step_tolerance, sd_fraction, "
      "max_condition: as the flags; noise_sigma: expected tracker noise (mm) of the plausibility "
      "verdict; loss='none' | 'huber' | 'cauchy' with loss_scale (mm);\n"
      "  sigma=None: Ceres noise per axis (mm), None estimates it from the residuals; threads "
      "(0: all); angle_unit: the unit the joint values were read in ('rad' | 'deg': the data "
      "are converted when read, lpoe.read_measurements(angle_unit=...); here it only names the "
      "unit in the report and enables the degrees hint of the verdict);\n"
      "  fixed_tools=None: tool names held as given (a list, or one comma-separated string): "
      "known SMR nests, so that the flange frame is identified in full; the model's fixed: true "
      "tools are held too;\n"
      "  prior_scale=1 (0: no prior, plain least squares), prior_translation (mm), prior_rotation "
      "(mrad), prior_tool_translation (mm), prior_joint_terms (mrad): the prior that holds weakly "
      "determined directions near the start model (docs/identifiability.md);\n"
      "  prior=None: a recalibration (docs/recalibration.md, lpoe_calibrate --prior): a file "
      "written by Calibration.write or lpoe_calibrate --output (a model with its covariance "
      "block), lpoe_prior's fleet prior, or an lpoe.Prior (lpoe.fleet_prior); its model is the "
      "start when `model` is None; the groups the new data show changed are freed "
      "(Calibration.changed), Calibration.data_share says per parameter how much came from the "
      "data; prior_scale multiplies its standard deviations.\n"
      "Ballbar distances and probe contacts (docs/measurements.md): `data` is an "
      "lpoe.ContactMeasurements or a list of data sets (distance, plane and tracker sets; tracker "
      "rows need sigma=, their noise per axis in mm), calibrated as lpoe_calibrate "
      "--measurements=a.csv,b.csv does: solver, holdout, split_seed, max_iterations and "
      "hold_scale='auto' | 'on' | 'off' (auto holds the robot's scale when no row measures a "
      "length), verify (distance or plane sets of the same pivots and planes) and kfold "
      "apply, and joint_errors (a list of the registry's terms; 'auto' and the gravity tilt are "
      "refused), and residual_model='gp' or 'auto' (a layer learned from the rows' projections, "
      "docs/residual_layer.md); loss, fixed_tools and "
      "parameterization='full' are refused.\n"
      "An unknown keyword raises lpoe.Error naming it.");
}

}  // namespace python
}  // namespace lpoe
