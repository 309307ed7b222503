// Python bindings: calibration through the library pipeline (register, solve, analyse,
// cross-validate, verdict), with keyword options named as lpoe_calibrate's flags and the same
// defaults, so that a script and the tool produce the same calibrated model (same YAML bytes) and
// the same JSON report.
#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <memory>
#include <random>
#include <sstream>
#include <string>
#include <type_traits>
#include <vector>

#include "lpoe/analysis.h"
#include "lpoe/contact_calibration.h"
#include "lpoe/measurements/contact_measurements.h"
#include "lpoe/contact_pipeline.h"
#include "lpoe/measurements/measurement_kind_dispatch.h"
#include "lpoe/measurements/measurement_kinds.h"
#include "lpoe/registration.h"
#include "lpoe/io/io.h"
#include "lpoe/options.h"
#include "lpoe/pipeline.h"
#include "lpoe/recalibration.h"
#include "lpoe/model/refusals.h"
#include "common/fleet_prior_text.h"
#include "python_api.h"
#include "report/contact_layer_report.h"
#include "report/report.h"
#include "common/tool_common.h"

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

// prior= (python_api.h): a file (a calibrated model with its covariance block, or lpoe_prior's
// fleet prior) or an lpoe.Prior; null when not given.
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

namespace {

constexpr const char* kCalibrateTool = "lpoe_calibrate";

// The default of lpoe_calibrate's option `name` in the option table, as T.
template <typename T>
T TableDefault(const char* name) {
  if constexpr (std::is_same_v<T, std::string>) {
    return OptionDefaultText(kCalibrateTool, name);
  } else if constexpr (std::is_same_v<T, bool>) {
    return OptionDefaultBool(kCalibrateTool, name);
  } else {
    return static_cast<T>(OptionDefault(kCalibrateTool, name));
  }
}

// Keyword options named as lpoe_calibrate's flags: every Get names a known option (with its
// default; Option: the table's); Finish() rejects the others, listing the known ones. A new CLI
// option is one entry in the table and one Option here.
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
  // An option of lpoe_calibrate's: the option table's default when not given (lpoe/options.h).
  template <typename T>
  T Option(const char* name) {
    return Get<T>(name, TableDefault<T>(name));
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


// The keyword options of lpoe.calibrate, read with the option table's defaults (lpoe/options.h).
struct CalibrateSettings {
  std::string solver, parameterization, data_kind, joint_errors, residual_model, split_name, loss,
      angle_unit;
  bool register_frames = true;
  double holdout = 0;
  int kfold = 0;
  uint64_t split_seed = 1;
  double outlier_threshold = 0, step_tolerance = 0, sd_fraction = 0, max_condition = 0,
         noise_sigma = 0, loss_scale = 0, sigma = 0;
  int max_iterations = 0, threads = 0;
  bool sigma_given = false;
  py::object fixed_tools;
  double prior_scale = 0;
  PriorScales prior_scales;
};

CalibrateSettings ReadCalibrateSettings(const py::kwargs& kwargs) {
  KeywordOptions k(kwargs);
  CalibrateSettings s;
  s.solver = k.Option<std::string>("solver");
  s.parameterization = k.Option<std::string>("parameterization");
  s.data_kind = k.Option<std::string>("data_kind");
  s.joint_errors = k.Option<std::string>("joint_errors");
  s.residual_model = k.Option<std::string>("residual_model");
  s.register_frames = k.Option<bool>("register");
  s.holdout = k.Option<double>("holdout");
  s.kfold = k.Option<int>("kfold");
  s.split_seed = k.Option<uint64_t>("split_seed");
  s.split_name = k.Option<std::string>("split");
  s.outlier_threshold = k.Option<double>("outlier_threshold");
  s.max_iterations = k.Option<int>("max_iterations");
  s.step_tolerance = k.Option<double>("step_tolerance");
  s.sd_fraction = k.Option<double>("sd_fraction");
  s.max_condition = k.Option<double>("max_condition");
  s.noise_sigma = k.Option<double>("noise_sigma");
  s.loss = k.Option<std::string>("loss");
  s.loss_scale = k.Option<double>("loss_scale");
  s.sigma_given = k.Given("sigma");
  s.sigma = k.Option<double>("sigma");
  s.threads = k.Option<int>("threads");
  s.angle_unit = k.Option<std::string>("angle_unit");
  // Known SMR nests: a list of tool names (or one comma-separated string, as --fixed_tools).
  s.fixed_tools = k.Get<py::object>("fixed_tools", py::none());
  // The default prior (docs/identifiability.md "The prior"), as lpoe_calibrate's --prior_* flags.
  s.prior_scale = k.Option<double>("prior_scale");
  s.prior_scales.frame_translation_mm = k.Option<double>("prior_translation");
  s.prior_scales.frame_rotation_mrad = k.Option<double>("prior_rotation");
  s.prior_scales.tool_translation_mm = k.Option<double>("prior_tool_translation");
  s.prior_scales.joint_term_mrad = k.Option<double>("prior_joint_terms");
  k.Finish("calibrate");
  // The ranges lpoe_calibrate's flags have (lpoe/options.h), with the same messages.
  const PriorScales& p = s.prior_scales;
  for (const auto& [name, value] : std::vector<std::pair<const char*, double>>{
           {"max_iterations", s.max_iterations},
           {"step_tolerance", s.step_tolerance},
           {"sd_fraction", s.sd_fraction},
           {"max_condition", s.max_condition},
           {"outlier_threshold", s.outlier_threshold},
           {"sigma", s.sigma},
           {"loss_scale", s.loss_scale},
           {"threads", s.threads},
           {"noise_sigma", s.noise_sigma},
           {"prior_scale", s.prior_scale},
           {"prior_translation", p.frame_translation_mm},
           {"prior_rotation", p.frame_rotation_mrad},
           {"prior_tool_translation", p.tool_translation_mm},
           {"prior_joint_terms", p.joint_term_mrad}}) {
    if (Status st = CheckOption(kCalibrateTool, name, value); !st.ok()) {
      throw LpoeError(st.message());
    }
  }
  return s;
}

// fixed_tools=: a list of tool names or one comma-separated string, held on a copy of `nominal`.
RobotModel WithFixedTools(const RobotModel& nominal, const py::object& fixed_tools) {
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
  return with_fixed;
}

// The data's joint count and every row's tool a tool of the model (data read with another model):
// refused here, never the solvers' internal check (an abort of the interpreter).
void CheckRowsFitModel(const RobotModel& nominal, const MeasurementSet& data,
                       const MeasurementSet* verify) {
  if (data.num_joints() != nominal.num_joints() ||
      (verify != nullptr && verify->num_joints() != nominal.num_joints())) {
    throw LpoeError("the measurements have a different number of joints than the model");
  }
  for (const MeasurementSet* set : {&data, verify}) {
    if (set == nullptr) continue;
    for (int r = 0; r < set->size(); ++r) {
      if (set->target(r) < 0 || set->target(r) >= nominal.num_tools()) {
        throw LpoeError(std::string(set == &data ? "data" : "verify") + ": row " +
                        std::to_string(r) + " measures tool " + std::to_string(set->target(r)) +
                        ", the model has " + std::to_string(nominal.num_tools()) + " tools");
      }
    }
  }
}

// The pipeline's options from the keyword options (as lpoe_calibrate's PipelineOptionsFromFlags),
// with the refusals of the values the table's ranges do not cover.
PipelineOptions CalibratePipelineOptions(const CalibrateSettings& s, SplitKind split,
                                         const MeasurementSet& data) {
  PipelineOptions o;
  if (s.solver != "linear" && s.solver != "ceres") {
    throw LpoeError("solver: expected 'linear' or 'ceres', got '" + s.solver + "'");
  }
  o.solver = s.solver == "ceres" ? SolverKind::kCeres : SolverKind::kLinear;
  o.parameterization = ParseParameterizationOption(s.parameterization);
  o.use_orientation = ParseDataKindOption(s.data_kind, data);
  // joint_errors: "none", a comma-separated list or "auto" (chosen by cross-validation), as
  // lpoe_calibrate --joint_errors.
  o.joint_errors_auto = s.joint_errors == "auto";
  o.joint_error_folds = s.kfold >= 2 ? s.kfold : 5;
  if (!o.joint_errors_auto) o.joint_errors = JointErrorNames(s.joint_errors, true);
  if (!ParseResidualModelKind(s.residual_model, &o.residual_model)) {
    throw LpoeError("residual_model: expected 'none', 'gp' or 'auto', got '" + s.residual_model +
                    "'");
  }
  if (s.angle_unit != "rad" && s.angle_unit != "deg") {
    throw LpoeError("angle_unit: expected 'rad' or 'deg', got '" + s.angle_unit + "'");
  }
  std::vector<int> configuration_of_row;
  if (s.kfold != 0 && !(s.kfold >= 2 && s.kfold <= 100 &&
                        s.kfold <= ConfigurationGroups(data, &configuration_of_row))) {
    throw LpoeError("kfold: expected 0 (off) or 2..100 and at most the configurations, got " +
                    std::to_string(s.kfold));
  }
  if (s.solver == "linear" && s.loss != "none") {
    throw LpoeError("loss needs solver='ceres' (the linear solver is plain least squares)");
  }
  o.register_frames = s.register_frames;
  o.kfold = s.kfold;
  o.split_seed = s.split_seed;
  o.residual_layer.seed = s.split_seed;
  o.split = split;
  o.outlier_threshold = s.outlier_threshold;
  o.plausibility.noise_sigma = s.noise_sigma;
  o.plausibility.joint_values_in_degrees = s.angle_unit == "deg";
  if (s.prior_scale > 0) {
    auto prior = std::make_shared<ParameterPrior>();
    prior->scale = s.prior_scale;
    prior->scales = s.prior_scales;
    o.prior = prior;
  } else {
    o.prior = nullptr;
  }
  o.linear.max_iterations = s.max_iterations;
  o.linear.step_tolerance = s.step_tolerance;
  o.linear.max_condition_number = s.max_condition;
  o.linear.convergence.sd_fraction = s.sd_fraction;
  o.ceres.max_iterations = s.max_iterations;
  o.ceres.max_condition_number = s.max_condition;
  o.ceres.loss = s.loss;
  o.ceres.loss_scale = s.loss_scale;
  // Without a stated noise level, estimate it from the residuals (as lpoe_calibrate does).
  o.ceres.a_posteriori_covariance = !s.sigma_given;
  o.ceres.sigma = s.sigma;
  o.ceres.convergence.sd_fraction = s.sd_fraction;
  if (s.threads > 0) o.ceres.num_threads = s.threads;
  if (Status st = ValidateCeresSolverOptions(o.ceres); !st.ok()) throw LpoeError(st.message());
  return o;
}

// lpoe_calibrate --prior: the file's model and covariance, the --prior_* tolerances on the
// directions it does not cover, every standard deviation times prior_scale.
std::shared_ptr<const ParameterPrior> RecalibrationPrior(const RobotModel& nominal,
                                                         const Prior& prior_file,
                                                         const PipelineOptions& o,
                                                         double prior_scale) {
  if (!(prior_scale > 0)) throw LpoeError("prior needs prior_scale > 0");
  if (prior_file.model.num_frames() != nominal.num_frames() ||
      prior_file.model.num_joints() != nominal.num_joints()) {
    throw LpoeError("prior=" + prior_file.source + ": its chain (" +
                    std::to_string(prior_file.model.num_joints()) + " joints, " +
                    std::to_string(prior_file.model.num_tools()) + " tools) is not the model's");
  }
  ParameterPrior prior = PriorFromCovariance(prior_file.model, prior_file.covariance,
                                             o.prior ? o.prior->scales : PriorScales());
  prior.scale = prior_scale;
  return std::make_shared<const ParameterPrior>(prior);
}

// What lpoe.calibrate returns from the run, with the JSON report filled as lpoe_calibrate fills it.
Calibration CalibrationOf(const RecalibrationResult& recalibration, const CalibrateSettings& s,
                          const PipelineOptions& o, const MeasurementSet& data,
                          const MeasurementSet& verification, const char* verification_source,
                          const Prior* prior_file) {
  const PipelineResult& run = recalibration.run;
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

  tools::RunSummary summary;
  summary.solver = s.solver;
  summary.parameterization = ParameterizationName(o.parameterization);
  summary.data_kind = MeasurementKind(TrackerKindId(o.use_orientation)).name;
  summary.angle_unit = s.angle_unit;
  summary.verification_source = verification_source;
  tools::AddPipelineResult(run, &summary);
  tools::AddPointResiduals(run.before, result.model, data, verification, &summary);
  summary.joint_errors_requested = s.joint_errors;
  summary.residual_model_requested = s.residual_model;
  summary.tool_name = "lpoe (Python)";
  if (prior_file != nullptr) {
    summary.prior_path = prior_file->source;
    summary.changed_groups = recalibration.changed;
  }
  c.report_json = tools::RunSummaryToJson(summary);
  return c;
}

Calibration Calibrate(const RobotModel& nominal, const MeasurementSet& given_data,
                      const MeasurementSet* given_verify, const py::kwargs& kwargs,
                      const Prior* prior_file = nullptr) {
  const CalibrateSettings s = ReadCalibrateSettings(kwargs);
  if (Status st = nominal.Validate(); !st.ok()) throw LpoeError(st.message());
  const RobotModel with_fixed = WithFixedTools(nominal, s.fixed_tools);
  CheckRowsFitModel(nominal, given_data, given_verify);
  if (!(s.holdout >= 0 && s.holdout <= 0.95)) throw LpoeError("holdout: expected 0..0.95");
  SplitKind split = SplitKind::kRandom;
  if (!ParseSplitKind(s.split_name, &split)) {
    throw LpoeError("split: expected 'random' or 'sequential', got '" + s.split_name + "'");
  }
  if (s.holdout > 0 && given_verify != nullptr) {
    throw LpoeError("give either verify= or holdout=, not both");
  }
  // holdout=: the rows held out for verification, as lpoe_calibrate splits them.
  MeasurementSet held_data(nominal.num_joints()), held_verify(nominal.num_joints());
  if (s.holdout > 0) {
    std::vector<int> id_rows, ver_rows;
    HoldoutSplit(given_data, s.holdout, s.split_seed, &id_rows, &ver_rows, split);
    held_data = given_data.Subset(id_rows);
    held_verify = given_data.Subset(ver_rows);
    if (Status st = tools::CheckHoldoutSplit(s.holdout, held_data.size(), held_verify.size());
        !st.ok()) {
      throw LpoeError(st.message());
    }
  }
  const MeasurementSet& data = s.holdout > 0 ? held_data : given_data;
  const MeasurementSet* verify = s.holdout > 0 ? &held_verify : given_verify;
  PipelineOptions o = CalibratePipelineOptions(s, split, data);

  const MeasurementSet empty(nominal.num_joints());
  const MeasurementSet& verification = verify != nullptr ? *verify : empty;
  // prior=: the groups the new data show changed are freed (Recalibrate).
  if (prior_file != nullptr) o.prior = RecalibrationPrior(nominal, *prior_file, o, s.prior_scale);
  RecalibrationResult recalibration;
  {
    py::gil_scoped_release release;
    if (prior_file != nullptr) {
      recalibration = Recalibrate(with_fixed, data, verification, o);
    } else {
      recalibration.run = RunCalibrationPipeline(with_fixed, data, verification, o);
    }
  }
  const char* source = s.holdout > 0 ? "holdout" : verify != nullptr ? "array" : "";
  return CalibrationOf(recalibration, s, o, data, verification, source, prior_file);
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

// The keyword options of lpoe.calibrate that apply to distance and plane data (defaults from the
// option table), with lpoe_calibrate's refusals for these kinds.
struct ContactSettings {
  std::string solver, hold_scale, data_kind, joint_errors, residual_model;
  ResidualModelKind residual_kind = ResidualModelKind::kNone;
  double holdout = 0;
  uint64_t split_seed = 1;
  int max_iterations = 0, kfold = 0;
  py::object verify;
};

ContactSettings ReadContactSettings(const py::kwargs& kwargs) {
  KeywordOptions k(kwargs);
  ContactSettings s;
  s.solver = k.Option<std::string>("solver");
  s.hold_scale = k.Option<std::string>("hold_scale");
  s.holdout = k.Option<double>("holdout");
  s.split_seed = k.Option<uint64_t>("split_seed");
  s.max_iterations = k.Option<int>("max_iterations");
  s.data_kind = k.Option<std::string>("data_kind");
  k.Option<double>("sigma");  // the tracker rows' noise (GatherContactData)
  s.joint_errors = k.Option<std::string>("joint_errors");
  // What lpoe_calibrate refuses with these kinds (docs/measurements.md), refused here too.
  for (const char* name : {"parameterization", "loss"}) {
    if (k.Option<std::string>(name) != TableDefault<std::string>(name)) {
      throw LpoeError(std::string(name) + " is not available with distance or plane data: " +
                      ContactRefusalReason(name) + " (docs/measurements.md)");
    }
  }
  s.residual_model = k.Option<std::string>("residual_model");
  if (!ParseResidualModelKind(s.residual_model, &s.residual_kind)) {
    throw LpoeError("residual_model: expected 'none', 'gp' or 'auto', got '" + s.residual_model +
                    "'");
  }
  s.kfold = k.Option<int>("kfold");
  if (s.kfold != 0 && !(s.kfold >= 2 && s.kfold <= 100)) {
    throw LpoeError("kfold: expected 0 (off) or 2..100, got " + std::to_string(s.kfold));
  }
  if (!k.Get<py::object>("fixed_tools", py::none()).is_none()) {
    throw LpoeError("fixed_tools is not available with distance or plane data: " +
                    ContactRefusalReason("fixed_tools") + " (docs/measurements.md)");
  }
  s.verify = k.Get<py::object>("verify", py::none());
  // Accepted and without effect here, as lpoe_calibrate's run for these kinds ignores them.
  for (const char* name : {"register", "split", "outlier_threshold", "step_tolerance",
                           "sd_fraction", "max_condition", "noise_sigma", "loss_scale", "threads",
                           "angle_unit", "prior_scale", "prior_translation", "prior_rotation",
                           "prior_tool_translation", "prior_joint_terms"}) {
    k.Get<py::object>(name, py::none());
  }
  k.Finish("calibrate");
  if (s.solver != "linear" && s.solver != "ceres") {
    throw LpoeError("solver: expected 'linear' or 'ceres', got '" + s.solver + "'");
  }
  return s;
}

// verify=: distance and plane sets of the calibration's pivots and planes (as --verify).
ContactMeasurementSet ContactVerificationOf(const py::object& verify, double holdout,
                                            const RobotModel& nominal,
                                            const ContactMeasurementSet& data) {
  ContactMeasurementSet verification;
  if (verify.is_none()) return verification;
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
  return verification;
}

// The JSON report of a contact calibration: lpoe_calibrate's (report/contact_layer_report.h), the
// tool named "lpoe (Python)".
std::string ContactReportJson(const ContactPipelineResult& run, bool verify_given, int kfold,
                              const std::string& residual_model) {
  py::module_ json = py::module_::import("json");
  py::dict report;
  report["tool"] = "lpoe (Python)";
  report.attr("update")(json.attr("loads")(
      tools::ContactReportJsonText(run, verify_given, kfold, residual_model)));
  return json.attr("dumps")(report, py::arg("indent") = 2).cast<std::string>();
}

Calibration CalibrateContacts(const RobotModel& nominal, const ContactMeasurementSet& data,
                              const MeasurementSet& tracker, const py::kwargs& kwargs) {
  const ContactSettings s = ReadContactSettings(kwargs);
  ContactCalibrationOptions options;
  if (!ParseScaleHold(s.hold_scale, &options.hold_scale)) {
    throw LpoeError("hold_scale: expected 'auto', 'on' or 'off', got '" + s.hold_scale + "'");
  }
  if (!(s.max_iterations >= 1 && s.max_iterations <= 10000)) {
    throw LpoeError("max_iterations: expected 1..10000");
  }
  options.max_iterations = std::max(s.max_iterations, 30);
  if (!(s.holdout >= 0 && s.holdout < 1)) throw LpoeError("holdout: expected 0 <= holdout < 1");
  if (s.data_kind != "auto") {
    const MeasurementKindInfo* kind = FindMeasurementKind(s.data_kind);
    if (kind == nullptr || data.Count(kind->id) != data.size()) {
      throw LpoeError("data_kind: '" + s.data_kind + "' is not the kind of every row");
    }
  }
  if (data.Count(MeasurementKindId::kDistance) + data.Count(MeasurementKindId::kPlane) == 0) {
    throw LpoeError("data: no distance or plane rows");
  }
  if (Status st = nominal.Validate(); !st.ok()) throw LpoeError(st.message());

  RobotModel start = nominal;
  if (tracker.size() > 0) {
    RegistrationReport report;
    if (Status st = RegisterToMeasurements(nominal, tracker, &start, &report); !st.ok()) {
      throw LpoeError("registration to the tracker data: " + st.message());
    }
  }
  // joint_errors: the registry's terms on the start model, or "auto" (chosen by cross-validation
  // on the identification rows), as lpoe_calibrate --joint_errors.
  const bool auto_terms = s.joint_errors == "auto";
  if (Status st = ContactJointTerms(auto_terms ? "none" : s.joint_errors, start,
                                    &options.joint_terms);
      !st.ok()) {
    throw LpoeError("joint_errors: " + st.message() + " (docs/measurements.md)");
  }
  const ContactMeasurementSet verification =
      ContactVerificationOf(s.verify, s.holdout, nominal, data);
  // The run as lpoe_calibrate's (lpoe/contact_pipeline.h): the same hold-out draw, k-fold and
  // figures per kind.
  ContactPipelineOptions run_options;
  run_options.solver = s.solver;
  run_options.calibration = options;
  run_options.holdout = s.holdout;
  run_options.split_seed = s.split_seed;
  run_options.kfold = s.kfold;
  run_options.joint_errors_auto = auto_terms;
  run_options.residual_model = s.residual_kind;
  ContactPipelineResult run;
  {
    py::gil_scoped_release release;
    run = RunContactPipeline(start, data, verification, run_options);
  }
  const ContactCalibrationResult& result = run.calibration;
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
  if (Status st = CheckModelFinite(result.model); !st.ok()) throw LpoeError(st.message());
  if (run.kfold_too_large) {
    throw LpoeError("kfold=" + std::to_string(s.kfold) + " " + run.message);
  }
  if (run.failed_fold >= 0) {
    throw LpoeError("kfold: fold " + std::to_string(run.failed_fold + 1) + " of " +
                    std::to_string(s.kfold) + ": " + run.message);
  }
  c.verdict = run.verdict;
  c.verdict_reason = "the worst of the kinds' verdicts (RMS within 2x the expected noise: pass, "
                     "5x: check)";
  c.report_json = ContactReportJson(run, !s.verify.is_none(), s.kfold, s.residual_model);
  return c;
}

// lpoe.calibrate's keyword arguments that are lpoe_calibrate's flags, in the signature's order.
constexpr const char* kCalibrateKeywords[] = {
    "solver", "parameterization", "data_kind", "joint_errors", "residual_model", "register",
    "holdout", "kfold", "split", "split_seed", "outlier_threshold", "max_iterations",
    "step_tolerance", "sd_fraction", "max_condition", "noise_sigma", "loss", "loss_scale", "sigma",
    "threads", "angle_unit", "fixed_tools", "prior_scale", "prior_translation", "prior_rotation",
    "prior_tool_translation", "prior_joint_terms", "hold_scale"};

// lpoe.calibrate's docstring: every keyword argument that is a flag with its default, range and
// help from the option table (what lpoe_calibrate --help prints), then what Python adds.
std::string CalibrateDoc() {
  std::string doc =
      "Calibrates `model` from `data` (and verifies on `verify`) as lpoe_calibrate does, through "
      "the same pipeline (registration, solver, analysis, cross-validation, verdict). The keyword "
      "arguments are its flags, with the defaults, ranges and help of the one option table "
      "(lpoe/options.h; lpoe.options('lpoe_calibrate')):\n";
  for (const char* name : kCalibrateKeywords) {
    const OptionSpec& spec = *FindOption(kCalibrateTool, name);
    // As Python writes the default: a number as it is, True / False, a string quoted.
    const std::string text = spec.default_text;
    char* end = nullptr;
    std::strtod(text.c_str(), &end);
    const bool number = !text.empty() && *end == '\0';
    std::string value = number ? text : "'" + text + "'";
    if (text == "true" || text == "false") value = text == "true" ? "True" : "False";
    if (name == std::string("sigma") || name == std::string("fixed_tools")) value = "None";
    const std::string range = OptionRangeText(spec);
    doc += std::string("  ") + name + "=" + value + (range.empty() ? "" : " " + range) + ": " +
           spec.help + "\n";
  }
  doc +=
      "In Python: sigma=None is the flag not given (the noise estimated from the residuals); "
      "fixed_tools=None holds no tool, a list of names or one comma-separated string; angle_unit "
      "names the unit the joint values were read in (the data are converted when read, "
      "lpoe.read_measurements(angle_unit=...); here it names the unit in the report and enables "
      "the degrees hint of the verdict); the option table's ranges are checked with the tool's "
      "messages.\n"
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
      "hold_scale, verify (distance or plane sets of the same pivots and planes) and kfold "
      "apply, and joint_errors (a list of the registry's terms or 'auto', chosen by cross-"
      "validation on the contact rows; the gravity tilt is refused), and residual_model='gp' or "
      "'auto' (a layer learned from the rows' projections, docs/residual_layer.md); loss, fixed_tools and "
      "parameterization='full' are refused.\n"
      "An unknown keyword raises lpoe.Error naming it.";
  return doc;
}

// lpoe.options(tool): the option table's entries `tool` has (its own and the shared ones), as
// dicts of name, scope, default (as written), range (as the tools print it) and help.
py::list OptionTable(const std::string& tool) {
  py::list out;
  for (const OptionSpec& spec : Options()) {
    if (FindOption(tool, spec.name) != &spec) continue;
    py::dict d;
    d["name"] = spec.name;
    d["scope"] = spec.scope;
    d["default"] = spec.default_text;
    d["range"] = OptionRangeText(spec);
    d["help"] = spec.help;
    out.append(d);
  }
  return out;
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
    throw LpoeError("models: " + tools::FleetPriorCountRefusal(static_cast<int>(read.size())));
  }
  tools::FleetPriorFile prior;
  if (Status s = tools::MakeFleetPriorFile(read, names, &prior); !s.ok()) {
    throw LpoeError(s.message());
  }
  for (const std::string& w : prior.warnings) {
    if (PyErr_WarnEx(PyExc_UserWarning, w.c_str(), 1) != 0) throw py::error_already_set();
  }
  const int robots = static_cast<int>(read.size());
  Prior out;
  out.model = std::move(prior.mean);
  out.covariance = std::move(prior.covariance);
  out.yaml = std::move(prior.text);
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
  // lpoe_calibrate's flags with the option table's defaults and help (CalibrateDoc); passed on as
  // the options KeywordOptions reads.
  m.def("options", &OptionTable, py::arg("tool"),
        "The option table's entries of `tool` (e.g. 'lpoe_calibrate'; its own and the shared "
        "ones): a list of dicts {name, scope, default (as written), range, help}, the defaults "
        "and help of the tool's flags and of the lpoe function's keyword arguments.");
  static const std::string doc = CalibrateDoc();
  const auto text_default = [](const char* name) { return TableDefault<std::string>(name); };
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
        if (hold_scale != TableDefault<std::string>("hold_scale")) {
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
      py::arg("solver") = text_default("solver"),
      py::arg("parameterization") = text_default("parameterization"),
      py::arg("data_kind") = text_default("data_kind"),
      py::arg("joint_errors") = text_default("joint_errors"),
      py::arg("residual_model") = text_default("residual_model"),
      py::arg("register") = TableDefault<bool>("register"),
      py::arg("holdout") = TableDefault<double>("holdout"),
      py::arg("kfold") = TableDefault<int>("kfold"), py::arg("split") = text_default("split"),
      py::arg("split_seed") = TableDefault<uint64_t>("split_seed"),
      py::arg("outlier_threshold") = TableDefault<double>("outlier_threshold"),
      py::arg("max_iterations") = TableDefault<int>("max_iterations"),
      py::arg("step_tolerance") = TableDefault<double>("step_tolerance"),
      py::arg("sd_fraction") = TableDefault<double>("sd_fraction"),
      py::arg("max_condition") = TableDefault<double>("max_condition"),
      py::arg("noise_sigma") = TableDefault<double>("noise_sigma"),
      py::arg("loss") = text_default("loss"),
      py::arg("loss_scale") = TableDefault<double>("loss_scale"), py::arg("sigma") = py::none(),
      py::arg("threads") = TableDefault<int>("threads"),
      py::arg("angle_unit") = text_default("angle_unit"), py::arg("fixed_tools") = py::none(),
      py::arg("prior_scale") = TableDefault<double>("prior_scale"),
      py::arg("prior_translation") = TableDefault<double>("prior_translation"),
      py::arg("prior_rotation") = TableDefault<double>("prior_rotation"),
      py::arg("prior_tool_translation") = TableDefault<double>("prior_tool_translation"),
      py::arg("prior_joint_terms") = TableDefault<double>("prior_joint_terms"),
      py::arg("hold_scale") = text_default("hold_scale"), py::arg("prior") = py::none(),
      doc.c_str());
}

}  // namespace python
}  // namespace lpoe
