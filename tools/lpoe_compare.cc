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
#include "lpoe/io/io.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/linear_solver.h"
#include "lpoe/measurements/measurement_kind_dispatch.h"
#include "lpoe/pipeline.h"
#include "lpoe/registration.h"
#include "lpoe/solver_comparison.h"
#include "lpoe/model/statistics.h"
#include "common/output_files.h"
#include "common/progress.h"
#include "report/report.h"
#include "report/json_text.h"
#include "common/common_flags.h"
#include "common/input_flags.h"
#include "common/tool_common.h"

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
DEFINE_string(joint_errors, "none",
              "Distance or plane data: joint-space terms identified with the geometry by both "
              "solvers, none or a comma-separated list of the registry's terms (as "
              "lpoe_calibrate's; compliance, harmonics, ...).");
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

// The inputs (model, identification and held-out rows), the outputs checked against them.
int LoadCompareInputs(const tools::InputPaths& paths, const tools::InputSettings& settings,
                      tools::OutputSet* outputs, tools::Inputs* in) {
  // --tolerance_mm and --noise_sigma: their ranges (lpoe/options.h) were checked by InitTool.
  tools::AddInputs(paths, outputs);
  outputs->AddOutput("--html_report", FLAGS_html_report);
  outputs->AddOutput("--output", FLAGS_output);
  if (Status s = outputs->Check(); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitUsage;
  }
  UrdfOptions urdf_options;
  if (!tools::UrdfOptionsFromFlags(paths.model, &urdf_options)) {
    std::cerr << "error: --base_link, --tip_link and --tool_links need a URDF --model\n";
    return kExitUsage;
  }
  if (Status s = tools::LoadInputs(paths.model, paths.measurements, paths.verify, settings.csv,
                                   FLAGS_holdout, FLAGS_split_seed, in, urdf_options,
                                   settings.split);
      !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitInput;
  }
  if (Status s = tools::CheckHoldoutSplit(FLAGS_holdout, *in); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitUsage;
  }
  return kExitOk;
}

// Both solvers through the calibration pipeline (same registration, same start, same data) and
// their models compared: the one library call.
SolverComparison CompareBothSolvers(const tools::InputSettings& settings, const tools::Inputs& in,
                                    bool use_orientation) {
  PipelineOptions options;
  options.parameterization = settings.parameterization;
  options.use_orientation = use_orientation;
  options.register_frames = FLAGS_register;
  options.plausibility.noise_sigma = FLAGS_noise_sigma;
  options.plausibility.joint_values_in_degrees = settings.angle_unit == AngleUnit::kDegrees;
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
  return CompareSolvers(in.nominal, in.identification, in.verification, options, ceres_options);
}

// Both converged and (unless --force) plausible; else the exit code.
int CheckBothSolved(const SolverComparison& runs) {
  for (const PipelineResult* r : {&runs.linear, &runs.ceres}) {
    if (!r->result.converged()) {
      std::cerr << "error: " << (r == &runs.linear ? "linear" : "ceres")
                << " solver: " << r->result.message << "\n";
      return tools::ExitCodeFor(r->result.termination);
    }
  }
  for (const PipelineResult* r : {&runs.linear, &runs.ceres}) {
    if (r->verdict.level == VerdictLevel::kFail && !FLAGS_force) {
      std::cerr << "error: " << (r == &runs.linear ? "linear" : "ceres")
                << " solver: the calibration is not plausible (" << r->verdict.reason
                << "); --force compares anyway\n";
      return tools::kExitImplausible;
    }
  }
  return kExitOk;
}

// The comparison's rows, as printed and written (no wall time: the HTML report must be the same
// for the same input).
std::vector<tools::RunSummary::ComparisonRow> ComparisonRows(const SolverComparison& c) {
  const CalibrationResult& lin = c.linear.result;
  const CalibrationResult& cer = c.ceres.result;
  const ErrorStatistics& ls = c.linear_errors;
  const ErrorStatistics& cs = c.ceres_errors;
  const char* mm = "%.6f";
  return {
      {"iterations", Num(lin.iterations, "%.0f"), Num(cer.iterations, "%.0f"), ""},
      {"final cost (mm^2)", Num(lin.final_cost), Num(cer.final_cost),
       Num(std::abs(lin.final_cost - cer.final_cost), "%.3g")},
      {"held-out max error (mm)", Num(ls.norm.max_abs, mm), Num(cs.norm.max_abs, mm),
       Num(std::abs(ls.norm.max_abs - cs.norm.max_abs), "%.3g")},
      {"held-out mean error (mm)", Num(ls.norm.mean_abs, mm), Num(cs.norm.mean_abs, mm),
       Num(std::abs(ls.norm.mean_abs - cs.norm.mean_abs), "%.3g")},
      {"held-out RMS error (mm)", Num(ls.norm.rms, mm), Num(cs.norm.rms, mm),
       Num(std::abs(ls.norm.rms - cs.norm.rms), "%.3g")},
      {"predicted positions (mm)", "", "", Num(c.position_difference, "%.3g")},
      {"parameters (rad or mm)", "", "", Num(c.parameter_difference, "%.3g")},
  };
}

// The table printed (with the wall times) and the largest parameter difference.
void PrintComparison(const SolverComparison& c,
                     const std::vector<tools::RunSummary::ComparisonRow>& rows) {
  Row("", "linear", "ceres", "|difference|");
  for (const auto& r : rows) Row(r.quantity.c_str(), r.linear, r.ceres, r.difference);
  Row("wall time (ms)", Num(c.linear.result.wall_time_seconds * 1e3, "%.3f"),
      Num(c.ceres.result.wall_time_seconds * 1e3, "%.3f"), "");
  if (!c.worst_parameter.empty()) {
    std::cout << "\nlargest parameter difference: " << c.worst_parameter
              << " (frames are compared direction by direction; a shift along an unidentifiable\n"
                 "direction of one frame absorbed by the next moves these coordinates at second\n"
                 "order without changing any prediction)\n";
  }
}

// --output (the comparison as JSON, for a script) and --html_report, staged.
Status StageCompareOutputs(const tools::InputPaths& paths, const tools::InputSettings& settings,
                           const tools::Inputs& in, const SolverComparison& c,
                           const std::vector<tools::RunSummary::ComparisonRow>& rows,
                           tools::OutputSet* outputs) {
  const bool held_out = !in.verification.empty();
  const bool agree = c.position_difference <= FLAGS_tolerance_mm;
  Status staged;
  if (!FLAGS_output.empty()) {
    nlohmann::json j = {{"tool", "lpoe_compare"},
                        {"model", paths.model},
                        {"measurements", paths.measurements},
                        {"held_out", held_out ? in.verification_source : std::string()},
                        {"tolerance_mm", FLAGS_tolerance_mm},
                        {"position_difference_mm", c.position_difference},
                        {"parameter_difference", c.parameter_difference},
                        {"agree", agree}};
    nlohmann::json table = nlohmann::json::array();
    for (const auto& r : rows) {
      table.push_back({{"quantity", r.quantity}, {"linear", r.linear}, {"ceres", r.ceres},
                       {"difference", r.difference}});
    }
    j["rows"] = table;
    staged = outputs->Stage(FLAGS_output, tools::JsonText(j));
  }
  if (!FLAGS_html_report.empty() && staged.ok()) {
    const std::string parameterization = ParameterizationName(settings.parameterization);
    const tools::ComparisonPage page{paths.model, paths.measurements, in.verification_source,
                                     FLAGS_angle_unit, parameterization, &c.ceres,
                                     &in.identification, &in.verification, rows, agree};
    std::string html;
    staged = tools::ComparisonHtml(page, &html);
    if (staged.ok()) staged = outputs->Stage(FLAGS_html_report, html);
  }
  return staged;
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
  tools::OutputSet outputs;
  tools::Inputs in;
  if (int rc = LoadCompareInputs(paths, settings, &outputs, &in); rc != kExitOk) return rc;
  // Without held-out data, the comparison is made on the identification rows.
  const bool held_out = !in.verification.empty();
  const MeasurementSet& check = held_out ? in.verification : in.identification;
  const bool use_orientation = in.identification.has_orientation();

  const SolverComparison c = CompareBothSolvers(settings, in, use_orientation);
  std::cout << "model:          " << paths.model << "\n"
            << "identification: " << paths.measurements << " (" << in.identification.size()
            << " rows)\n"
            << "held out:       "
            << (held_out ? (paths.verify.empty() ? std::string("--holdout split") : paths.verify)
                         : std::string("none: predictions compared on the identification rows"))
            << " (" << check.size() << " rows)\n"
            << "parameters:     " << c.linear.result.parameterization.num_parameters << " ("
            << ParameterizationName(settings.parameterization) << "), "
            << MeasurementKind(TrackerKindId(use_orientation)).name << " data\n\n";
  if (int rc = CheckBothSolved(c); rc != kExitOk) return rc;

  const std::vector<tools::RunSummary::ComparisonRow> rows = ComparisonRows(c);
  PrintComparison(c, rows);
  const Status staged = StageCompareOutputs(paths, settings, in, c, rows, &outputs);
  if (tools::CommitOutputs(staged, &outputs, FLAGS_quiet) != tools::kExitOk) {
    return tools::kExitOutput;
  }
  if (!(c.position_difference <= FLAGS_tolerance_mm)) {
    std::cout << "\nresult: DISAGREE: predicted positions differ by up to "
              << c.position_difference << " mm (tolerance " << FLAGS_tolerance_mm << " mm)\n";
    return kExitDisagree;
  }
  std::cout << "\nresult: agree: predicted positions within " << c.position_difference
            << " mm (tolerance " << FLAGS_tolerance_mm << " mm)\n";
  return kExitOk;
}

}  // namespace
}  // namespace lpoe

int main(int argc, char** argv) {
  lpoe::tools::InitTool(lpoe::kUsage, &argc, &argv);
  return lpoe::Run();
}
