// lpoe_calibrate: identify the local frames of a robot from tracker measurements.
//
// Reads a nominal model (YAML) and measurements (CSV), runs the chosen solver, prints the convergence
// table and before/after errors on the identification and verification sets, and writes the
// calibrated model. With no arguments it calibrates the shipped section-4 data set.
#include <algorithm>
#include <cmath>
#include <iostream>
#include <numeric>
#include <random>
#include <string>

#include <gflags/gflags.h>
#include <glog/logging.h>

#include "lpoe/io.h"
#include "lpoe/linear_solver.h"
#include "lpoe/statistics.h"
#include "tool_common.h"

DEFINE_string(model, "", "Nominal robot model (YAML). Default: data/cobot6.yaml.");
DEFINE_string(measurements, "",
              "Identification measurements (CSV: q1..qN,x,y,z[,target][,quat_x..quat_w]). "
              "Default: data/section4/identification.csv.");
DEFINE_string(verify, "",
              "Verification measurements (CSV), never used for identification. Default with the "
              "default measurements: data/section4/verification.csv.");
DEFINE_double(holdout, 0.0,
              "Instead of --verify: hold out this fraction of the measurements (0 <= f < 1), "
              "chosen at random with --holdout_seed, for verification.");
DEFINE_uint64(holdout_seed, 1, "Seed of the --holdout split.");
DEFINE_string(output, "", "Write the calibrated model here (YAML). Nothing is written on failure.");
DEFINE_string(solver, "linear", "linear: the paper's iterative least squares.");
DEFINE_string(parameterization, "identifiable",
              "identifiable: only the directions the data can see (27 for a 6R arm with position "
              "data); full: 6 per local frame, solved as a minimum-norm pseudo-inverse (the "
              "paper's 42).");
DEFINE_string(data_kind, "auto",
              "position | pose | auto: pose-based calibration (paper eqs. 17-24) uses the measured "
              "orientations; auto picks pose when the CSV has quat_* columns.");
DEFINE_string(angle_unit, "rad", "Unit of revolute joint values in the CSV files: rad | deg.");
DEFINE_int32(max_iterations, 30, "Iteration limit.");
DEFINE_double(step_tolerance, 1e-10, "Convergence: stop when |x| falls below this.");
DEFINE_double(max_condition, 1e8,
              "Refuse data whose column-scaled Jacobian has a larger condition number.");

namespace lpoe {
namespace {

constexpr char kUsage[] =
    "Calibrates the local frames of a serial robot (Local Product of Exponentials, Gao et al. "
    "2022) from measured tool positions.\n\n"
    "  lpoe_calibrate                          # the shipped section-4 data set\n"
    "  lpoe_calibrate --model=robot.yaml --measurements=points.csv --holdout=0.3 \\\n"
    "                 --output=calibrated.yaml\n\n"
    "Units: mm and rad (joint values may be given in degrees with --angle_unit=deg).\n"
    "Exit codes: 0 converged, 1 bad flags, 2 bad input file, 3 data cannot identify the model,\n"
    "4 iteration limit reached, 5 numerical failure, 6 output not written.";

// Deterministic shuffle (the standard distributions are implementation-defined).
std::vector<int> ShuffledRows(int n, uint64_t seed) {
  std::vector<int> rows(n);
  std::iota(rows.begin(), rows.end(), 0);
  std::mt19937_64 rng(seed);
  for (int i = n - 1; i > 0; --i) {
    const int j = static_cast<int>(rng() % static_cast<uint64_t>(i + 1));
    std::swap(rows[i], rows[j]);
  }
  return rows;
}

int Run() {
  using tools::kExitInput;
  using tools::kExitOutput;
  using tools::kExitUsage;
  const std::string data_dir = tools::DataDir();
  const bool default_data = FLAGS_measurements.empty();
  const std::string model_path = FLAGS_model.empty() ? data_dir + "/cobot6.yaml" : FLAGS_model;
  const std::string meas_path =
      default_data ? data_dir + "/section4/identification.csv" : FLAGS_measurements;
  std::string verify_path = FLAGS_verify;
  if (default_data && verify_path.empty() && FLAGS_holdout == 0.0) {
    verify_path = data_dir + "/section4/verification.csv";
  }

  // ---- Flags.
  AngleUnit unit;
  if (!tools::ParseAngleUnit(FLAGS_angle_unit, &unit)) {
    std::cerr << "error: --angle_unit must be rad or deg, got '" << FLAGS_angle_unit << "'\n";
    return kExitUsage;
  }
  ParameterizationKind kind;
  if (!ParseParameterization(FLAGS_parameterization, &kind)) {
    std::cerr << "error: --parameterization must be identifiable or full, got '"
              << FLAGS_parameterization << "'\n";
    return kExitUsage;
  }
  if (FLAGS_solver != "linear") {
    std::cerr << "error: --solver must be linear, got '" << FLAGS_solver << "'\n";
    return kExitUsage;
  }
  if (FLAGS_data_kind != "auto" && FLAGS_data_kind != "position" && FLAGS_data_kind != "pose") {
    std::cerr << "error: --data_kind must be auto, position or pose, got '" << FLAGS_data_kind
              << "'\n";
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
  if (FLAGS_max_iterations < 1 || !(FLAGS_step_tolerance > 0) || !(FLAGS_max_condition > 1)) {
    std::cerr << "error: --max_iterations must be >= 1, --step_tolerance > 0, --max_condition > 1\n";
    return kExitUsage;
  }
  for (const std::string& in : {model_path, meas_path, verify_path}) {
    if (!FLAGS_output.empty() && FLAGS_output == in) {
      std::cerr << "error: --output would overwrite the input file " << in << "\n";
      return kExitUsage;
    }
  }

  // ---- Inputs.
  RobotModel nominal;
  if (Status s = ReadRobotModel(model_path, &nominal); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitInput;
  }
  MeasurementSet all;
  CsvReadReport report;
  if (Status s = ReadMeasurements(meas_path, nominal, unit, &all, &report); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitInput;
  }
  if (report.skipped_zero_rows > 0) {
    std::cerr << "warning: " << meas_path << ": skipped " << report.skipped_zero_rows
              << " row(s) of zeros (lost beam)\n";
  }
  MeasurementSet identification, verification;
  if (!verify_path.empty()) {
    identification = std::move(all);
    if (Status s = ReadMeasurements(verify_path, nominal, unit, &verification, nullptr); !s.ok()) {
      std::cerr << "error: " << s.message() << "\n";
      return kExitInput;
    }
  } else if (FLAGS_holdout > 0.0) {
    const std::vector<int> rows = ShuffledRows(all.size(), FLAGS_holdout_seed);
    const int held = static_cast<int>(std::lround(FLAGS_holdout * all.size()));
    std::vector<int> id_rows(rows.begin() + held, rows.end());
    std::vector<int> ver_rows(rows.begin(), rows.begin() + held);
    std::sort(id_rows.begin(), id_rows.end());
    std::sort(ver_rows.begin(), ver_rows.end());
    identification = all.Subset(id_rows);
    verification = all.Subset(ver_rows);
  } else {
    identification = std::move(all);
  }

  bool use_orientation = identification.has_orientation();
  if (FLAGS_data_kind == "position") use_orientation = false;
  if (FLAGS_data_kind == "pose" && !identification.has_orientation()) {
    std::cerr << "error: --data_kind=pose needs quat_x,quat_y,quat_z,quat_w columns in "
              << meas_path << "\n";
    return kExitUsage;
  }

  std::cout << "model:          " << model_path << " (" << nominal.num_joints() << " joints, "
            << nominal.num_tools() << " tool" << (nominal.num_tools() > 1 ? "s" : "") << ")\n"
            << "identification: " << meas_path << " (" << identification.size() << " rows)\n";
  if (!verification.empty()) {
    std::cout << "verification:   "
              << (verify_path.empty() ? "held out from the identification file" : verify_path)
              << " (" << verification.size() << " rows)\n";
  }
  std::cout << "solver:         " << FLAGS_solver << ", " << ParameterizationName(kind)
            << " parameterization, " << (use_orientation ? "pose" : "position") << " data\n\n";

  // ---- Solve.
  LinearSolverOptions options;
  options.parameterization = kind;
  options.use_orientation = use_orientation;
  options.max_iterations = FLAGS_max_iterations;
  options.step_tolerance = FLAGS_step_tolerance;
  options.max_condition_number = FLAGS_max_condition;
  const CalibrationResult result = CalibrateLinear(nominal, identification, options);

  if (result.termination == Termination::kNotIdentifiable) {
    std::cerr << "error: " << result.message << "\n";
    return tools::ExitCodeFor(result.termination);
  }
  std::cout << "parameters:     " << result.parameterization.num_parameters << " ("
            << result.rank << " identifiable by the data, condition number of the scaled "
            << "Jacobian " << result.condition_number << ")\n\n";
  tools::PrintIterationTable(std::cout, result);
  std::cout << "\n";
  tools::PrintBeforeAfter(std::cout, "identification set", PositionErrorStatistics(nominal, identification),
                          PositionErrorStatistics(result.model, identification));
  if (!verification.empty()) {
    std::cout << "\n";
    tools::PrintBeforeAfter(std::cout, "verification set", PositionErrorStatistics(nominal, verification),
                            PositionErrorStatistics(result.model, verification));
  }
  std::cout << "\nresult: " << TerminationName(result.termination) << " after " << result.iterations
            << " iteration(s), " << result.wall_time_seconds * 1e3 << " ms";
  if (!result.converged()) {
    std::cout << "\n";
    std::cerr << "error: " << result.message << "; no output written\n";
    return tools::ExitCodeFor(result.termination);
  }
  if (FLAGS_output.empty()) {
    std::cout << " (use --output=FILE to save the calibrated model)\n";
    return tools::kExitOk;
  }
  if (Status s = WriteRobotModel(FLAGS_output, result.model); !s.ok()) {
    std::cout << "\n";
    std::cerr << "error: " << s.message() << "\n";
    return kExitOutput;
  }
  std::cout << "; calibrated model written to " << FLAGS_output << "\n";
  return tools::kExitOk;
}

}  // namespace
}  // namespace lpoe

int main(int argc, char** argv) {
  lpoe::tools::InitTool(lpoe::kUsage, &argc, &argv);
  return lpoe::Run();
}
