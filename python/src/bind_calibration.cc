// Python bindings: calibration through the library pipeline (register, solve, analyse,
// cross-validate, verdict), with keyword options named as lpoe_calibrate's flags and the same
// defaults, so that a script and the tool produce the same calibrated model (same YAML bytes) and
// the same JSON report.
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <string>
#include <vector>

#include "lpoe/io.h"
#include "lpoe/joint_errors.h"
#include "lpoe/pipeline.h"
#include "python_api.h"
#include "report.h"

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
};

namespace {

Calibration Calibrate(const RobotModel& nominal, const MeasurementSet& data,
                      const MeasurementSet* verify, const std::string& solver,
                      const std::string& parameterization, const std::string& data_kind,
                      bool register_frames, int kfold, uint64_t split_seed,
                      double outlier_threshold, int max_iterations, double step_tolerance,
                      double sd_fraction, double max_condition, double noise_sigma,
                      const std::string& loss, double loss_scale, const py::object& sigma,
                      int threads, const std::string& angle_unit,
                      const std::string& joint_errors) {
  if (Status s = nominal.Validate(); !s.ok()) throw LpoeError(s.message());
  if (data.num_joints() != nominal.num_joints() ||
      (verify != nullptr && verify->num_joints() != nominal.num_joints())) {
    throw LpoeError("the measurements have a different number of joints than the model");
  }
  PipelineOptions o;
  if (solver != "linear" && solver != "ceres") {
    throw LpoeError("solver: expected 'linear' or 'ceres', got '" + solver + "'");
  }
  o.solver = solver == "ceres" ? SolverKind::kCeres : SolverKind::kLinear;
  if (!ParseParameterization(parameterization, &o.parameterization)) {
    throw LpoeError("parameterization: expected 'identifiable' or 'full', got '" +
                    parameterization + "'");
  }
  if (data_kind == "auto") {
    o.use_orientation = data.has_orientation();
  } else if (data_kind == "position" || data_kind == "pose") {
    o.use_orientation = data_kind == "pose";
    if (o.use_orientation && !data.has_orientation()) {
      throw LpoeError("data_kind='pose' needs measured orientations");
    }
  } else {
    throw LpoeError("data_kind: expected 'auto', 'position' or 'pose', got '" + data_kind + "'");
  }
  if (angle_unit != "rad" && angle_unit != "deg") {
    throw LpoeError("angle_unit: expected 'rad' or 'deg', got '" + angle_unit + "'");
  }
  if (kfold != 0 && !(kfold >= 2 && kfold <= 100 && kfold <= data.size())) {
    throw LpoeError("kfold: expected 0 (off) or 2..100 and at most the rows, got " +
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
  // joint_errors: "none", a comma-separated list or "auto", as lpoe_calibrate --joint_errors.
  std::vector<JointErrorKind> kinds;
  o.joint_errors_auto = joint_errors == "auto";
  o.joint_error_folds = kfold >= 2 ? kfold : 5;
  if (!o.joint_errors_auto && !ParseJointErrorKinds(joint_errors, &kinds)) {
    throw LpoeError("joint_errors: expected 'none', 'compliance', 'harmonics', "
                    "'compliance,harmonics' or 'auto', got '" + joint_errors + "'");
  }
  for (JointErrorKind k : {JointErrorKind::kCompliance, JointErrorKind::kHarmonics}) {
    if (std::find(kinds.begin(), kinds.end(), k) != kinds.end()) {
      o.joint_errors.push_back(JointErrorKindName(k));
    }
  }
  o.register_frames = register_frames;
  o.kfold = kfold;
  o.split_seed = split_seed;
  o.outlier_threshold = outlier_threshold;
  o.plausibility.noise_sigma = noise_sigma;
  o.plausibility.joint_values_in_degrees = angle_unit == "deg";
  o.linear.max_iterations = max_iterations;
  o.linear.step_tolerance = step_tolerance;
  o.linear.max_condition_number = max_condition;
  o.linear.convergence.sd_fraction = sd_fraction;
  o.ceres.max_iterations = max_iterations;
  o.ceres.max_condition_number = max_condition;
  o.ceres.loss = loss;
  o.ceres.loss_scale = loss_scale;
  o.ceres.a_posteriori_covariance = sigma.is_none();
  o.ceres.sigma = sigma.is_none() ? 1.0 : sigma.cast<double>();
  o.ceres.convergence.sd_fraction = sd_fraction;
  if (threads > 0) o.ceres.num_threads = threads;
  if (Status s = ValidateCeresSolverOptions(o.ceres); !s.ok()) throw LpoeError(s.message());

  const MeasurementSet empty(nominal.num_joints());
  const MeasurementSet& verification = verify != nullptr ? *verify : empty;
  PipelineResult run;
  {
    py::gil_scoped_release release;
    run = RunCalibrationPipeline(nominal, data, verification, o);
  }
  const CalibrationResult& result = run.result;

  Calibration c;
  c.converged = result.converged();
  c.termination = TerminationName(result.termination);
  c.message = result.message;
  c.iterations = result.iterations;
  c.final_cost = result.final_cost;
  c.model = result.model;
  if (run.registered && run.registration.moved) {
    c.model.T_measurement_base = run.registration.T_measurement_base;
  }
  if (result.termination == Termination::kNotIdentifiable) return c;
  c.verdict = VerdictLevelName(run.verdict.level);
  c.verdict_reason = run.verdict.reason;

  // The JSON report, filled as lpoe_calibrate fills it.
  tools::RunSummary summary;
  summary.solver = solver;
  summary.parameterization = ParameterizationName(o.parameterization);
  summary.data_kind = o.use_orientation ? "pose" : "position";
  summary.angle_unit = angle_unit;
  summary.verification_source = verify != nullptr ? "array" : "";
  tools::AddPipelineResult(run, &summary);
  tools::AddPointResiduals(run.before, result.model, data, verification, &summary);
  summary.joint_errors_requested = joint_errors;
  summary.tool_name = "lpoe (Python)";
  c.report_json = tools::RunSummaryToJson(summary);
  return c;
}

}  // namespace

void BindCalibration(py::module_& m) {
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
      .def_readonly("report_json", &Calibration::report_json);

  m.def(
      "calibrate",
      [](const RobotModel& model, const MeasurementSet& data, const py::object& verify,
         const std::string& solver, const std::string& parameterization,
         const std::string& data_kind, bool register_frames, int kfold, uint64_t split_seed,
         double outlier_threshold, int max_iterations, double step_tolerance, double sd_fraction,
         double max_condition, double noise_sigma, const std::string& loss, double loss_scale,
         const py::object& sigma, int threads, const std::string& angle_unit,
         const std::string& joint_errors) {
        const MeasurementSet* v = verify.is_none() ? nullptr : verify.cast<const MeasurementSet*>();
        return Calibrate(model, data, v, solver, parameterization, data_kind, register_frames,
                         kfold, split_seed, outlier_threshold, max_iterations, step_tolerance,
                         sd_fraction, max_condition, noise_sigma, loss, loss_scale, sigma, threads,
                         angle_unit, joint_errors);
      },
      py::arg("model"), py::arg("data"), py::arg("verify") = py::none(),
      py::arg("solver") = "linear", py::arg("parameterization") = "identifiable",
      py::arg("data_kind") = "auto", py::arg("register") = true, py::arg("kfold") = 0,
      py::arg("split_seed") = 1, py::arg("outlier_threshold") = 5.0,
      py::arg("max_iterations") = 30, py::arg("step_tolerance") = 1e-10,
      py::arg("sd_fraction") = 1e-2, py::arg("max_condition") = 1e8,
      py::arg("noise_sigma") = 0.03, py::arg("loss") = "none", py::arg("loss_scale") = 1.0,
      py::arg("sigma") = py::none(), py::arg("threads") = 0, py::arg("angle_unit") = "rad",
      py::arg("joint_errors") = "none",
      "calibrates `model` from `data` (and verifies on `verify`) as lpoe_calibrate does; keyword "
      "options are named as its flags, with the same defaults");
}

}  // namespace python
}  // namespace lpoe
