// lpoe_compare: runs the linear (paper) solver and the Ceres solver on the same model and data and
// prints one table side by side: iterations, final cost, held-out errors, wall time, and how far
// apart the two calibrations are (predicted held-out positions; parameters in the identifiable
// directions). Exits 0 when the predicted positions agree within --tolerance_mm, 7 otherwise.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <string>
#include <vector>

#include <gflags/gflags.h>
#include <nlohmann/json.hpp>
#include <glog/logging.h>

#include "lpoe/analysis.h"
#include "lpoe/ceres_solver.h"
#include "lpoe/io.h"
#include "lpoe/kinematics.h"
#include "lpoe/linear_solver.h"
#include "lpoe/pipeline.h"
#include "lpoe/registration.h"
#include "lpoe/statistics.h"
#include "output_files.h"
#include "progress.h"
#include "report/report.h"
#include "report/json_text.h"
#include "common_flags.h"
#include "input_flags.h"
#include "tool_common.h"

DEFINE_string(measurements, "",
              "Identification measurements (CSV). Default: data/section4/identification.csv.");
DEFINE_string(verify, "",
              "Held-out measurements (CSV). Default with the default measurements: "
              "data/section4/verification.csv.");
DEFINE_double(holdout, 0.0,
              "Instead of --verify: hold out this fraction of the measurements (0 <= f < 1).");
DEFINE_string(split, "random",
              "How --holdout splits the rows: random (seeded by --split_seed) | sequential (the "
              "last rows of the file are held out).");
DEFINE_uint64(split_seed, 1, "Seed of the --holdout split.");
DECLARE_string(joint_errors);  // lpoe_compare_contact.cc
DEFINE_string(parameterization, "identifiable", "identifiable | full (see lpoe_calibrate).");
DEFINE_bool(register, true,
            "Register the model to the measurement frame first (as lpoe_calibrate); both solvers "
            "start from the registered model.");
DEFINE_string(html_report, "",
              "Write a self-contained HTML report here: the comparison table and the Ceres "
              "calibration's statistics, plots and parameters.");
DEFINE_double(tolerance_mm, 1e-6,
              "The solvers agree when their predicted held-out positions differ by at most this "
              "(mm, at most 1000).");
DEFINE_double(noise_sigma, 0.03,
              "Expected tracker noise per axis (mm) for the plausibility verdict (see "
              "lpoe_calibrate).");
DEFINE_bool(force, false, "Compare even when a calibration fails the plausibility verdict.");

namespace lpoe {
namespace tools {
bool ContactCompareRequested();  // lpoe_compare_contact.cc
int RunContactCompare();
}  // namespace tools
}  // namespace lpoe

namespace lpoe {
namespace {

using tools::kExitDisagree;
using tools::kExitInput;
using tools::kExitOk;
using tools::kExitUsage;

constexpr char kUsage[] =
    "Runs the paper's linear iterative least squares and the Ceres solver on the same model and\n"
    "data and prints one comparison table.\n\n"
    "  lpoe_compare                            # the shipped section-4 data set\n"
    "  lpoe_compare --model=robot.yaml --measurements=points.csv --holdout=0.3 \\\n"
    "      --output=comparison.json\n\n"
    "--model: the nominal model (default: the shipped cobot6); --output: the comparison table "
    "as JSON (the rows printed, the largest differences, agree or not).\n\n"
    "Exit codes: 0 the predicted held-out positions agree within --tolerance_mm, 1 bad flags,\n"
    "2 bad input file, 3 data cannot identify the model, 4 iteration limit, 5 numerical\n"
    "failure, 6 output not written, 7 the solvers disagree, 8 a calibration is not plausible (see lpoe_calibrate).";

double MaxPredictionDifference(const RobotModel& a, const RobotModel& b, const MeasurementSet& data) {
  double worst = 0;
  for (int r = 0; r < data.size(); ++r) {
    worst = std::max(worst, (ToolPosition(a, data.q(r), data.target(r)) -
                             ToolPosition(b, data.q(r), data.target(r)))
                                .norm());
  }
  return worst;
}

void Row(const char* name, const std::string& linear, const std::string& ceres,
         const std::string& difference) {
  char line[200];
  std::snprintf(line, sizeof(line), "%-28s %18s %18s %18s\n", name, linear.c_str(), ceres.c_str(),
                difference.c_str());
  std::cout << line;
}

std::string Num(double v, const char* format = "%.6g") {
  char buf[64];
  std::snprintf(buf, sizeof(buf), format, v);
  return buf;
}

int Run() {
  // Ballbar distances and probe contacts: both contact solvers (lpoe_compare_contact.cc).
  if (tools::ContactCompareRequested()) return tools::RunContactCompare();
  if (FLAGS_joint_errors != "none") {
    std::cerr << "error: --joint_errors is for distance or plane data only (tracker data: "
                 "compare with lpoe_calibrate --joint_errors and each --solver)\n";
    return kExitUsage;
  }
  tools::InputPaths paths;
  tools::InputSettings settings;
  if (!tools::InputsFromFlags(&paths, &settings)) return kExitUsage;
  const std::string& model_path = paths.model;
  const std::string& meas_path = paths.measurements;
  const std::string& verify_path = paths.verify;

  const AngleUnit unit = settings.angle_unit;
  const CsvOptions& csv = settings.csv;
  const ParameterizationKind kind = settings.parameterization;
  // --tolerance_mm and --noise_sigma: their ranges (lpoe/options.h) were checked by InitTool.

  tools::OutputSet outputs;
  tools::AddInputs(paths, &outputs);
  outputs.AddOutput("--html_report", FLAGS_html_report);
  outputs.AddOutput("--output", FLAGS_output);
  if (Status s = outputs.Check(); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitUsage;
  }

  // ---- Inputs.
  tools::Inputs in;
  UrdfOptions urdf_options;
  if (!tools::UrdfOptionsFromFlags(model_path, &urdf_options)) {
    std::cerr << "error: --base_link, --tip_link and --tool_links need a URDF --model\n";
    return kExitUsage;
  }
  if (Status s = tools::LoadInputs(model_path, meas_path, verify_path, csv, FLAGS_holdout,
                                   FLAGS_split_seed, &in, urdf_options, settings.split);
      !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitInput;
  }
  const RobotModel& nominal = in.nominal;
  const MeasurementSet& identification = in.identification;
  const MeasurementSet& verification = in.verification;
  if (Status s = tools::CheckHoldoutSplit(FLAGS_holdout, in); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitUsage;
  }
  // Without held-out data, the comparison is made on the identification rows.
  const bool held_out = !verification.empty();
  const MeasurementSet& check = held_out ? verification : identification;
  const bool use_orientation = identification.has_orientation();

  // ---- Both solvers through the calibration pipeline: same registration, same start, same data.
  PipelineOptions options;
  options.parameterization = kind;
  options.use_orientation = use_orientation;
  options.register_frames = FLAGS_register;
  options.plausibility.noise_sigma = FLAGS_noise_sigma;
  options.plausibility.joint_values_in_degrees = unit == AngleUnit::kDegrees;
  // Tight stopping rules: the comparison is of the two solvers' minima, not of their stopping.
  options.linear.convergence.sd_fraction = 0;
  options.ceres.convergence.sd_fraction = 0;
  PipelineOptions ceres_options = options;
  ceres_options.solver = SolverKind::kCeres;
  tools::Progress progress(FLAGS_quiet, options.ceres.max_iterations);
  options.on_iteration = [&progress](const std::string&, const IterationRecord& r) {
    progress.Iteration("linear", r);
  };
  ceres_options.on_iteration = [&progress](const std::string&, const IterationRecord& r) {
    progress.Iteration("ceres", r);
  };
  const PipelineResult lin_run =
      RunCalibrationPipeline(nominal, identification, verification, options);
  const PipelineResult cer_run =
      RunCalibrationPipeline(nominal, identification, verification, ceres_options);
  const CalibrationResult& lin = lin_run.result;
  const CalibrationResult& cer = cer_run.result;
  const RobotModel& start = lin_run.start;

  std::cout << "model:          " << model_path << "\n"
            << "identification: " << meas_path << " (" << identification.size() << " rows)\n"
            << "held out:       "
            << (held_out ? (verify_path.empty() ? std::string("--holdout split") : verify_path)
                         : std::string("none: predictions compared on the identification rows"))
            << " (" << check.size() << " rows)\n"
            << "parameters:     " << lin.parameterization.num_parameters << " ("
            << ParameterizationName(kind) << "), " << (use_orientation ? "pose" : "position")
            << " data\n\n";
  for (const CalibrationResult* r : {&lin, &cer}) {
    if (!r->converged()) {
      std::cerr << "error: " << (r == &lin ? "linear" : "ceres") << " solver: " << r->message
                << "\n";
      return tools::ExitCodeFor(r->termination);
    }
  }
  for (const PipelineResult* r : {&lin_run, &cer_run}) {
    if (r->verdict.level == VerdictLevel::kFail && !FLAGS_force) {
      std::cerr << "error: " << (r == &lin_run ? "linear" : "ceres")
                << " solver: the calibration is not plausible (" << r->verdict.reason
                << "); --force compares anyway\n";
      return tools::kExitImplausible;
    }
  }

  const ErrorStatistics ls = PositionErrorStatistics(lin.model, check);
  const ErrorStatistics cs = PositionErrorStatistics(cer.model, check);
  const double position_difference = MaxPredictionDifference(lin.model, cer.model, check);
  // Parameters in the identifiable directions (with the full parameterization the frames also
  // differ along the gauge directions, which no data see; those are not compared).
  const Parameterization pi = MakeParameterization(
      start, ParameterizationKind::kIdentifiable,
      use_orientation ? DataKind::kPose : DataKind::kPosition);
  const Eigen::VectorXd dx = ParameterDifference(pi, lin.model, cer.model);
  Eigen::Index worst = 0;
  const double parameter_difference = dx.size() ? dx.cwiseAbs().maxCoeff(&worst) : 0.0;

  const char* mm = "%.6f";
  const std::vector<tools::RunSummary::ComparisonRow> rows = {
      {"iterations", Num(lin.iterations, "%.0f"), Num(cer.iterations, "%.0f"), ""},
      {"final cost (mm^2)", Num(lin.final_cost), Num(cer.final_cost),
       Num(std::abs(lin.final_cost - cer.final_cost), "%.3g")},
      {"held-out max error (mm)", Num(ls.norm.max_abs, mm), Num(cs.norm.max_abs, mm),
       Num(std::abs(ls.norm.max_abs - cs.norm.max_abs), "%.3g")},
      {"held-out mean error (mm)", Num(ls.norm.mean_abs, mm), Num(cs.norm.mean_abs, mm),
       Num(std::abs(ls.norm.mean_abs - cs.norm.mean_abs), "%.3g")},
      {"held-out RMS error (mm)", Num(ls.norm.rms, mm), Num(cs.norm.rms, mm),
       Num(std::abs(ls.norm.rms - cs.norm.rms), "%.3g")},
      {"predicted positions (mm)", "", "", Num(position_difference, "%.3g")},
      {"parameters (rad or mm)", "", "", Num(parameter_difference, "%.3g")},
  };  // (no wall time: the HTML report must be the same for the same input)
  Row("", "linear", "ceres", "|difference|");
  for (const auto& r : rows) Row(r.quantity.c_str(), r.linear, r.ceres, r.difference);
  Row("wall time (ms)", Num(lin.wall_time_seconds * 1e3, "%.3f"),
      Num(cer.wall_time_seconds * 1e3, "%.3f"), "");
  if (dx.size()) {
    std::cout << "\nlargest parameter difference: " << pi.parameters[worst].name
              << " (frames are compared direction by direction; a shift along an unidentifiable\n"
                 "direction of one frame absorbed by the next moves these coordinates at second\n"
                 "order without changing any prediction)\n";
  }

  const bool agree = position_difference <= FLAGS_tolerance_mm;
  Status staged;
  if (!FLAGS_output.empty()) {  // the comparison as JSON, for a script
    nlohmann::json j = {{"tool", "lpoe_compare"},
                        {"model", model_path},
                        {"measurements", meas_path},
                        {"held_out", held_out ? in.verification_source : std::string()},
                        {"tolerance_mm", FLAGS_tolerance_mm},
                        {"position_difference_mm", position_difference},
                        {"parameter_difference", parameter_difference},
                        {"agree", agree}};
    nlohmann::json table = nlohmann::json::array();
    for (const auto& r : rows) {
      table.push_back({{"quantity", r.quantity}, {"linear", r.linear}, {"ceres", r.ceres},
                       {"difference", r.difference}});
    }
    j["rows"] = table;
    staged = outputs.Stage(FLAGS_output, tools::JsonText(j));
  }
  if (!FLAGS_html_report.empty() && staged.ok()) {
    const tools::ComparisonPage page{model_path, meas_path, in.verification_source,
                                     FLAGS_angle_unit, ParameterizationName(kind), &cer_run,
                                     &identification, &verification, rows,
                                     position_difference <= FLAGS_tolerance_mm};
    std::string html;
    staged = tools::ComparisonHtml(page, &html);
    if (staged.ok()) staged = outputs.Stage(FLAGS_html_report, html);
  }
  if (tools::CommitOutputs(staged, &outputs, FLAGS_quiet) != tools::kExitOk) {
    return tools::kExitOutput;
  }
  if (!(position_difference <= FLAGS_tolerance_mm)) {
    std::cout << "\nresult: DISAGREE: predicted positions differ by up to " << position_difference
              << " mm (tolerance " << FLAGS_tolerance_mm << " mm)\n";
    return kExitDisagree;
  }
  std::cout << "\nresult: agree: predicted positions within " << position_difference
            << " mm (tolerance " << FLAGS_tolerance_mm << " mm)\n";
  return kExitOk;
}

}  // namespace
}  // namespace lpoe

int main(int argc, char** argv) {
  lpoe::tools::InitTool(lpoe::kUsage, &argc, &argv);
  return lpoe::Run();
}
