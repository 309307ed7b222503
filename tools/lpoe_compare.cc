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
#include <glog/logging.h>

#include "lpoe/analysis.h"
#include "lpoe/ceres_solver.h"
#include "lpoe/io.h"
#include "lpoe/kinematics.h"
#include "lpoe/linear_solver.h"
#include "lpoe/registration.h"
#include "lpoe/statistics.h"
#include "report.h"
#include "tool_common.h"

DEFINE_string(model, "",
              "Nominal robot model: YAML, or URDF when the name ends in .urdf. Default: "
              "data/cobot6.yaml.");
DEFINE_string(measurements, "",
              "Identification measurements (CSV). Default: data/section4/identification.csv.");
DEFINE_string(verify, "",
              "Held-out measurements (CSV). Default with the default measurements: "
              "data/section4/verification.csv.");
DEFINE_double(holdout, 0.0,
              "Instead of --verify: hold out this fraction of the measurements (0 <= f < 1).");
DEFINE_uint64(split_seed, 1, "Seed of the --holdout split.");
DEFINE_string(parameterization, "identifiable", "identifiable | full (see lpoe_calibrate).");
DEFINE_string(angle_unit, "rad", "Unit of revolute joint values in the CSV files: rad | deg.");
DEFINE_string(length_unit, "mm",
              "Unit of x, y, z (and prismatic joint values) in the CSV files: mm | m.");
DEFINE_bool(register, true,
            "Register the model to the measurement frame first (as lpoe_calibrate); both solvers "
            "start from the registered model.");
DEFINE_string(html_report, "",
              "Write a self-contained HTML report here: the comparison table and the Ceres "
              "calibration's statistics, plots and parameters.");
DEFINE_double(tolerance_mm, 1e-6,
              "The solvers agree when their predicted held-out positions differ by at most this.");

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
    "  lpoe_compare --model=robot.yaml --measurements=points.csv --holdout=0.3\n\n"
    "Exit codes: 0 the predicted held-out positions agree within --tolerance_mm, 1 bad flags,\n"
    "2 bad input file, 3 data cannot identify the model, 4 iteration limit, 5 numerical\n"
    "failure, 6 output not written, 7 the solvers disagree.";

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
  const tools::InputPaths paths =
      tools::ResolveInputPaths(FLAGS_model, FLAGS_measurements, FLAGS_verify, FLAGS_holdout != 0.0);
  const std::string& model_path = paths.model;
  const std::string& meas_path = paths.measurements;
  const std::string& verify_path = paths.verify;

  AngleUnit unit;
  if (!tools::ParseAngleUnit(FLAGS_angle_unit, &unit)) {
    std::cerr << "error: --angle_unit must be rad or deg, got '" << FLAGS_angle_unit << "'\n";
    return kExitUsage;
  }
  CsvOptions csv;
  csv.angle_unit = unit;
  if (!ParseLengthUnit(FLAGS_length_unit, &csv.length_unit)) {
    std::cerr << "error: --length_unit must be mm or m, got '" << FLAGS_length_unit << "'\n";
    return kExitUsage;
  }
  ParameterizationKind kind;
  if (!ParseParameterization(FLAGS_parameterization, &kind)) {
    std::cerr << "error: --parameterization must be identifiable or full, got '"
              << FLAGS_parameterization << "'\n";
    return kExitUsage;
  }
  if (!(FLAGS_holdout >= 0.0 && FLAGS_holdout < 1.0)) {
    std::cerr << "error: --holdout must be in [0, 1), got " << FLAGS_holdout << "\n";
    return kExitUsage;
  }
  if (FLAGS_holdout > 0.0 && !FLAGS_verify.empty()) {
    std::cerr << "error: give either --verify or --holdout, not both\n";
    return kExitUsage;
  }
  if (!(FLAGS_tolerance_mm >= 0.0)) {
    std::cerr << "error: --tolerance_mm must be >= 0\n";
    return kExitUsage;
  }

  for (const std::string& in : {model_path, meas_path, verify_path}) {
    if (!FLAGS_html_report.empty() && tools::SameFile(FLAGS_html_report, in)) {
      std::cerr << "error: --html_report would overwrite the input file " << in << "\n";
      return kExitUsage;
    }
  }

  // ---- Inputs.
  tools::Inputs in;
  UrdfOptions urdf_options;
  if (!tools::UrdfOptionsFromFlags(model_path, &urdf_options)) {
    std::cerr << "error: --base_link, --tip_link and --tool_links need a URDF --model\n";
    return kExitUsage;
  }
  if (Status s = tools::LoadInputs(model_path, meas_path, verify_path, csv, FLAGS_holdout,
                                   FLAGS_split_seed, &in, urdf_options);
      !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitInput;
  }
  const RobotModel& nominal = in.nominal;
  const MeasurementSet& identification = in.identification;
  const MeasurementSet& verification = in.verification;
  // Without held-out data, the comparison is made on the identification rows.
  const bool held_out = !verification.empty();
  const MeasurementSet& check = held_out ? verification : identification;
  const bool use_orientation = identification.has_orientation();

  RobotModel start = nominal;
  RegistrationReport report;
  if (FLAGS_register) {
    if (Status s = RegisterToMeasurements(nominal, identification, &start, &report); !s.ok()) {
      std::cerr << "error: " << s.message() << "\n";
      return tools::ExitCodeFor(Termination::kNotIdentifiable);
    }
    if (!report.moved) start = nominal;  // already in the base frame, as lpoe_calibrate does
  }

  // ---- Both solvers, same start, same data.
  LinearSolverOptions lo;
  lo.parameterization = kind;
  lo.use_orientation = use_orientation;
  CeresSolverOptions co;
  co.parameterization = kind;
  co.use_orientation = use_orientation;
  const CalibrationResult lin = CalibrateLinear(start, identification, lo);
  const CalibrationResult cer = CalibrateCeres(start, identification, co);

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

  if (!FLAGS_html_report.empty()) {
    tools::ComparisonRun run{model_path, meas_path, in.verification_source, FLAGS_angle_unit,
                             ParameterizationName(kind), &nominal, &start, &identification,
                             &verification, FLAGS_register ? &report : nullptr, &lin, &cer,
                             rows, position_difference <= FLAGS_tolerance_mm};
    if (Status s = tools::WriteComparisonHtmlReport(FLAGS_html_report, run); !s.ok()) {
      std::cerr << "error: " << s.message() << "\n";
      return tools::kExitOutput;
    }
    std::cout << "wrote " << FLAGS_html_report << "\n";
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
