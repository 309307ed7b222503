// lpoe_plan: chooses the joint configurations to measure (docs/planning.md).
//
// Every tool of the model (SMR) is measured at every planned pose, or only those the tracker sees
// when --tracker is given. Writes the plan as a CSV of joint values (editable; accepted by
// lpoe_simulate --joints and easy to read from a robot program) and a JSON report with the
// predicted accuracy of the plan and of a random plan of the same size.
#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <limits>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include <gflags/gflags.h>
#include <glog/logging.h>
#include <nlohmann/json.hpp>

#include "lpoe/io.h"
#include "lpoe/joint_errors.h"
#include "lpoe/joint_table.h"
#include "lpoe/joint_term.h"
#include "lpoe/planning.h"
#include "lpoe/refusals.h"
#include "json_text.h"
#include "output_files.h"
#include "tool_common.h"

DEFINE_string(count, "",
              "Number of poses to plan, or 'auto': the smallest plan predicted to reach "
              "--target_accuracy with --noise_sigma. Required.");
DEFINE_string(report, "", "JSON report (default: --output with its extension replaced by .json).");
DEFINE_string(candidates, "",
              "Candidate configurations, CSV with q1..qN (other columns are kept): choose rows of "
              "this file. Default: sample --candidate_count configurations within the joint limits.");
DEFINE_int32(candidate_count, 5000, "Configurations sampled when no --candidates file is given.");
DEFINE_string(workspace, "",
              "Configurations where the accuracy matters (CSV with q1..qN), for criterion I and "
              "the predicted accuracy. Default: --workspace_count samples within the joint limits.");
DEFINE_int32(workspace_count, 1000, "Configurations sampled when no --workspace file is given.");
DEFINE_uint64(seed, 1, "Seed of the sampled candidates, workspace and random comparison plans.");
DEFINE_string(criterion, "D",
              "D (default: parameters) | A | E | I (average position variance over the workspace) "
              "| O1 | O3 (observability indices; see docs/planning.md).");
DEFINE_string(tracker, "", "Tracker position x,y,z in the model's base frame (mm). Enables the "
                           "visibility constraints (--max_range, --acceptance_angle, --smr_facing).");
DEFINE_double(max_range, 0, "Maximum tracker-to-SMR distance (mm); 0: unlimited.");
DEFINE_double(acceptance_angle, 30.0,
              "Half-angle (degrees) of the cone around an SMR's facing direction within which the "
              "tracker must lie, in (0, 90].");
DEFINE_string(smr_facing, "",
              "Facing direction of the SMRs in their tool frames: 'x,y,z' for all, or one 'x,y,z' "
              "per tool separated by ';'. Default: +z of each tool frame.");
DEFINE_double(min_singularity, 0.01,
              "Drop candidates whose singularity measure (smallest singular value of the "
              "length-normalized geometric Jacobian, docs/planning.md) is below this; 0: keep all.");
DEFINE_double(min_z, -1e300,
              "Floor of the cell (mm, base frame z): every joint origin after the first and every "
              "SMR of a planned pose at least this high. Default: no floor.");
DEFINE_string(box, "",
              "xmin,ymin,zmin,xmax,ymax,zmax (mm, base frame): every SMR of a planned pose inside "
              "this box. Default: no box.");
DEFINE_string(keep_out, "",
              "CSV of keep-out boxes, one xmin,ymin,zmin,xmax,ymax,zmax (mm, base frame) per line "
              "('#' comments): no joint origin nor SMR of a planned pose inside any.");
DEFINE_string(joint_ranges, "",
              "Joint ranges narrower than the model's limits, lo:hi per joint separated by commas "
              "(--angle_unit for revolute joints, mm for prismatic; an empty item keeps the "
              "limits), e.g. ':,-1.5:0.5,,,,'. Candidates outside are dropped.");
DEFINE_double(target_accuracy, 0, "--count=auto: predicted held-out RMS to reach (mm).");
DEFINE_double(noise_sigma, 0,
              "Measurement noise per axis (mm): scales the predicted accuracy into mm; required "
              "with --count=auto.");
DEFINE_int32(random_draws, 30, "Random plans of the same size evaluated for comparison.");
DEFINE_string(joint_errors, "none",
              "Joint-space error terms the calibration will identify: none | a comma-separated "
              "list of the registry's terms (compliance, harmonics, ...: docs/joint_errors.md) | "
              "auto, with ',tilt' in a list with compliance for the "
              "gravity tilt. Their identifiable combinations join the parameters the plan must "
              "determine (and the predicted accuracy). 'auto' plans for every term lpoe_calibrate "
              "--joint_errors=auto may choose (all of them; the tilt too when the model carries "
              "compliance values): a plan that identifies the richest model identifies each of its "
              "subsets. The tilt's information is proportional to the compliance values, so "
              "'tilt' needs a --model that carries them (a calibrated model's YAML); with a "
              "nominal model it is refused (docs/planning.md).");
// The options every tool shares (tools/common_flags.cc, lpoe/options.h).
DECLARE_string(model);
DECLARE_string(angle_unit);
DECLARE_string(length_unit);
DECLARE_bool(quiet);
DECLARE_string(output);

namespace lpoe {
namespace {

using tools::kExitInput;
using tools::kExitNotIdentifiable;
using tools::kExitOk;
using tools::kExitOutput;
using tools::kExitUsage;

constexpr char kUsage[] =
    "Chooses the joint configurations that identify the model best (measurement planning).\n\n"
    "  lpoe_plan --model=nominal.yaml --count=40 --output=poses.csv\n"
    "  lpoe_plan --model=robot.urdf --count=60 --candidates=reachable.csv --angle_unit=deg \\\n"
    "      --output=poses.csv --tracker=2500,0,800 --max_range=6000\n"
    "  lpoe_plan --model=nominal.yaml --count=auto --target_accuracy=0.02 --noise_sigma=0.015 \\\n"
    "      --output=poses.csv\n\n"
    "Exit codes: 0 plan written, 1 bad flags or outputs (one names an input or another output,\n"
    "or its directory is missing or not writable: checked before any work), 2 unreadable input,\n"
    "3 no plan possible (too few feasible candidates, the candidates cannot identify the model,\n"
    "no more rows than parameters, or the target accuracy is out of reach), 6 an output could\n"
    "not be written (then none is).";

constexpr double kPi = 3.14159265358979323846;

bool ParseVector3(const std::string& text, Eigen::Vector3d* v) {
  std::stringstream ss(text);
  std::string item;
  int k = 0;
  while (std::getline(ss, item, ',')) {
    if (k >= 3) return false;
    char* end = nullptr;
    (*v)(k) = std::strtod(item.c_str(), &end);
    if (end == item.c_str() || *end != '\0' || !std::isfinite((*v)(k))) return false;
    ++k;
  }
  return k == 3;
}

std::string FormatNumber(double v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof(buf), v);  // shortest exact form
  return std::string(buf, r.ptr);
}

nlohmann::json QualityJson(const PlanQuality& q, double noise_sigma) {
  auto num = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
  nlohmann::json j = {{"poses", q.num_poses},
                      {"rows", q.num_rows},
                      {"rank", q.rank},
                      {"condition_number", num(q.condition_number)},
                      {"predicted_rms_per_unit_noise", num(q.predicted_rms)},
                      {"criteria",
                       {{"D_log_det", num(q.d)},
                        {"A_trace", num(q.a)},
                        {"E_min_eigenvalue", num(q.e)},
                        {"I_mean_variance", num(q.i)},
                        {"O1", num(q.o1)},
                        {"O3", num(q.o3)}}}};
  if (noise_sigma > 0) j["predicted_rms_mm"] = num(noise_sigma * q.predicted_rms);
  return j;
}

// The joint-space terms planned for and their identifiable combinations.
// The gravity tilt, when planned for, is the last entry ("tilt", 2 parameters, linearised at the
// model's compliance values).
nlohmann::json JointErrorsJson(const PlanningModel& pm) {
  nlohmann::json j = nlohmann::json::array();
  for (const JointBlock& block : pm.parameterization().joint_blocks) {
    j.push_back({{"term", block.term->name()},
                 {"parameters", block.term->num_parameters()},
                 {"identifiable_combinations", block.basis.cols()}});
  }
  if (pm.num_tilt_parameters() > 0) {
    j.push_back({{"term", kGravityTiltName},
                 {"parameters", pm.num_tilt_parameters()},
                 {"identifiable_combinations", pm.num_tilt_parameters()}});
  }
  return j;
}

int Run() {
  if (FLAGS_model.empty() || FLAGS_count.empty() || FLAGS_output.empty()) {
    std::cerr << "error: --model, --count and --output are required (see --help)\n";
    return kExitUsage;
  }
  const bool automatic = FLAGS_count == "auto";
  int count = 0;
  if (!automatic) {
    const auto r = std::from_chars(FLAGS_count.data(), FLAGS_count.data() + FLAGS_count.size(), count);
    if (r.ec != std::errc() || r.ptr != FLAGS_count.data() + FLAGS_count.size() || count < 1 ||
        count > 1000000) {
      std::cerr << "error: --count must be a number of poses from 1 to 1000000, or 'auto'\n";
      return kExitUsage;
    }
  } else if (!(FLAGS_target_accuracy > 0) || !(FLAGS_noise_sigma > 0)) {
    std::cerr << "error: --count=auto needs --target_accuracy > 0 and --noise_sigma > 0 (mm)\n";
    return kExitUsage;
  }
  if (!(FLAGS_noise_sigma >= 0) || !(FLAGS_target_accuracy >= 0) || !std::isfinite(FLAGS_noise_sigma)) {
    std::cerr << "error: --noise_sigma and --target_accuracy must be >= 0\n";
    return kExitUsage;
  }
  AngleUnit unit;
  if (!tools::ParseAngleUnit(FLAGS_angle_unit, &unit)) {
    std::cerr << "error: --angle_unit must be rad or deg\n";
    return kExitUsage;
  }
  PlanOptions options;
  if (!ParsePlanCriterion(FLAGS_criterion, &options.criterion)) {
    std::cerr << "error: --criterion must be one of D, A, E, I, O1, O3\n";
    return kExitUsage;
  }
  if (FLAGS_candidate_count < 1 || FLAGS_candidate_count > 1000000 || FLAGS_workspace_count < 1 ||
      FLAGS_workspace_count > 1000000 || FLAGS_random_draws < 1 || FLAGS_random_draws > 10000) {
    std::cerr << "error: --candidate_count and --workspace_count must be in [1, 1000000], "
                 "--random_draws in [1, 10000]\n";
    return kExitUsage;
  }
  // The joint-space terms, compliance first as lpoe_calibrate orders them (docs/joint_errors.md).
  std::vector<std::string> term_names;
  bool tilt = false;  // the gravity tilt, asked for
  std::vector<std::string> kinds;
  std::string error;
  if (FLAGS_joint_errors == "auto") {
    term_names = JointTermNames();
  } else if (ParseJointErrorList(FLAGS_joint_errors, &kinds, &tilt, &error)) {
    term_names = InRegistryOrder(kinds);
  } else {
    std::cerr << "error: --joint_errors=" << FLAGS_joint_errors << ": " << error
              << " (expected none, a comma-separated list of " << JointTermNameList()
              << " or auto, with tilt in a list with compliance)\n";
    return kExitUsage;
  }
  PlanConstraints constraints;
  if (!(FLAGS_min_singularity >= 0) || !(FLAGS_min_singularity < 1)) {
    std::cerr << "error: --min_singularity must be in [0, 1)\n";
    return kExitUsage;
  }
  constraints.min_singularity = FLAGS_min_singularity;
  if (!(FLAGS_acceptance_angle > 0) || !(FLAGS_acceptance_angle <= 90)) {
    std::cerr << "error: --acceptance_angle must be in (0, 90] degrees\n";
    return kExitUsage;
  }
  if (!(FLAGS_max_range >= 0) || !std::isfinite(FLAGS_max_range)) {
    std::cerr << "error: --max_range must be >= 0 (mm; 0 = unlimited)\n";
    return kExitUsage;
  }
  TrackerConstraint& tracker = constraints.tracker;
  if (!FLAGS_tracker.empty()) {
    tracker.enabled = true;
    if (!ParseVector3(FLAGS_tracker, &tracker.position)) {
      std::cerr << "error: --tracker must be x,y,z in mm (three finite numbers)\n";
      return kExitUsage;
    }
    tracker.acceptance_angle = FLAGS_acceptance_angle * kPi / 180.0;
    if (FLAGS_max_range > 0) tracker.max_range = FLAGS_max_range;
  } else if (!FLAGS_smr_facing.empty() || FLAGS_max_range > 0) {
    std::cerr << "error: --smr_facing and --max_range need --tracker\n";
    return kExitUsage;
  }

  // Every output against every input and the other output, and its directory writable, before
  // any work (tools/output_files.h); both are committed together at the end or neither.
  std::string report_path = FLAGS_report;
  if (report_path.empty()) {
    const size_t slash = FLAGS_output.find_last_of('/');
    const size_t dot = FLAGS_output.find_last_of('.');
    report_path = (dot != std::string::npos && (slash == std::string::npos || dot > slash)
                       ? FLAGS_output.substr(0, dot)
                       : FLAGS_output) +
                  ".json";
  }
  tools::OutputSet outputs;
  outputs.AddInput("--model", FLAGS_model);
  outputs.AddInput("--candidates", FLAGS_candidates);
  outputs.AddInput("--workspace", FLAGS_workspace);
  outputs.AddOutput("--output", FLAGS_output);
  outputs.AddOutput(FLAGS_report.empty() ? "--report (default: --output with .json)" : "--report",
                    report_path);
  if (Status s = outputs.Check(); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitUsage;
  }

  RobotModel model;
  if (Status s = tools::CheckUrdfFlagsHaveAUrdf({FLAGS_model}); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return tools::kExitUsage;
  }
  if (Status s = tools::ReadModelWithUrdfFlags(FLAGS_model, &model); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitInput;
  }
  if (!FLAGS_smr_facing.empty()) {
    std::stringstream ss(FLAGS_smr_facing);
    std::string item;
    while (std::getline(ss, item, ';')) {
      Eigen::Vector3d v;
      if (!ParseVector3(item, &v) || v.norm() == 0) {
        std::cerr << "error: --smr_facing: '" << item << "' is not a non-zero x,y,z direction\n";
        return kExitUsage;
      }
      tracker.facing.push_back(v.normalized());
    }
    if (tracker.facing.size() == 1) tracker.facing.resize(model.num_tools(), tracker.facing[0]);
    if (static_cast<int>(tracker.facing.size()) != model.num_tools()) {
      std::cerr << "error: --smr_facing gives " << tracker.facing.size()
                << " directions; the model has " << model.num_tools() << " tools\n";
      return kExitUsage;
    }
  }

  // The cell: floor, box, keep-out boxes, narrower joint ranges.
  if (!std::isfinite(FLAGS_min_z) && FLAGS_min_z != -1e300) {
    std::cerr << "error: --min_z must be a finite height in mm\n";
    return kExitUsage;
  }
  if (FLAGS_min_z != -1e300) constraints.cell.min_z = FLAGS_min_z;
  if (!FLAGS_box.empty()) {
    if (Status s = ParseBox(FLAGS_box, &constraints.cell.box); !s.ok()) {
      std::cerr << "error: --box: " << s.message() << "\n";
      return kExitUsage;
    }
  }
  if (!FLAGS_keep_out.empty()) {
    std::string text;
    if (Status s = ReadFile(FLAGS_keep_out, &text); !s.ok()) {
      std::cerr << "error: " << s.message() << "\n";
      return kExitInput;
    }
    std::stringstream lines(text);
    std::string line;
    for (int number = 1; std::getline(lines, line); ++number) {
      if (!line.empty() && line.back() == '\r') line.pop_back();
      const size_t first = line.find_first_not_of(" \t");
      if (first == std::string::npos || line[first] == '#') continue;
      Eigen::AlignedBox3d b;
      if (Status s = ParseBox(line.substr(first), &b); !s.ok()) {
        std::cerr << "error: " << FLAGS_keep_out << ":" << number << ": " << s.message() << "\n";
        return kExitInput;
      }
      constraints.cell.keep_out.push_back(b);
    }
  }
  if (!FLAGS_joint_ranges.empty()) {
    std::vector<std::string> items;
    std::stringstream ss(FLAGS_joint_ranges);
    for (std::string item; std::getline(ss, item, ',');) items.push_back(item);
    if (!FLAGS_joint_ranges.empty() && FLAGS_joint_ranges.back() == ',') items.push_back("");
    if (static_cast<int>(items.size()) != model.num_joints()) {
      std::cerr << "error: --joint_ranges gives " << items.size() << " items; the model has "
                << model.num_joints() << " joints\n";
      return kExitUsage;
    }
    for (int j = 0; j < model.num_joints(); ++j) {
      const std::string& item = items[j];
      if (item.find_first_not_of(" :") == std::string::npos) continue;  // "" or ":": the limits
      const size_t colon = item.find(':');
      char* end_lo = nullptr;
      char* end_hi = nullptr;
      const std::string lo_text = colon == std::string::npos ? "" : item.substr(0, colon);
      const std::string hi_text = colon == std::string::npos ? "" : item.substr(colon + 1);
      const double lo = std::strtod(lo_text.c_str(), &end_lo);
      const double hi = std::strtod(hi_text.c_str(), &end_hi);
      if (colon == std::string::npos || lo_text.empty() || hi_text.empty() || *end_lo != '\0' ||
          *end_hi != '\0' || !std::isfinite(lo) || !std::isfinite(hi) || !(lo < hi)) {
        std::cerr << "error: --joint_ranges: '" << item << "' for " << model.joints[j].name
                  << " is not lo:hi with lo < hi\n";
        return kExitUsage;
      }
      const double scale =
          unit == AngleUnit::kDegrees && model.joints[j].type == JointType::kRevolute ? kPi / 180.0
                                                                                      : 1.0;
      Joint& joint = model.joints[j];
      joint.lower = std::max(joint.lower, lo * scale);
      joint.upper = std::min(joint.upper, hi * scale);
      if (!(joint.lower < joint.upper)) {
        std::cerr << "error: --joint_ranges: " << item << " for " << joint.name
                  << " does not overlap the joint's limits\n";
        return kExitUsage;
      }
    }
  }

  // Candidates and workspace.
  std::vector<double> candidates, workspace;
  JointTable table;
  if (!FLAGS_candidates.empty()) {
    if (Status s = ReadJointTable(FLAGS_candidates, model, unit, &table); !s.ok()) {
      std::cerr << "error: " << s.message() << "\n";
      return kExitInput;
    }
    for (const std::string& name : table.names) {
      if (name == "candidate_row") {
        std::cerr << "error: " << FLAGS_candidates
                  << ": already has a candidate_row column (remove it to plan from this file)\n";
        return kExitInput;
      }
    }
    candidates = table.q;
  } else if (Status s = SampleConfigurations(model, FLAGS_candidate_count, FLAGS_seed, &candidates);
             !s.ok()) {
    std::cerr << "error: " << FLAGS_model << ": " << s.message() << "\n";
    return kExitInput;
  }
  if (!FLAGS_workspace.empty()) {
    JointTable w;
    if (Status s = ReadJointTable(FLAGS_workspace, model, unit, &w); !s.ok()) {
      std::cerr << "error: " << s.message() << "\n";
      return kExitInput;
    }
    workspace = w.q;
  } else if (Status s = SampleConfigurations(model, FLAGS_workspace_count, FLAGS_seed + 1, &workspace);
             !s.ok()) {
    std::cerr << "error: " << FLAGS_model << ": " << s.message() << "\n";
    return kExitInput;
  }

  std::vector<std::shared_ptr<const JointTerm>> terms;
  for (const std::string& name : term_names) {
    std::shared_ptr<const JointTerm> term;
    if (Status s = MakeJointTerm(name, model, &term); !s.ok()) {
      std::cerr << "error: " << FLAGS_model << ": " << s.message() << "\n";
      return kExitInput;
    }
    terms.push_back(std::move(term));
  }
  // The gravity tilt: planned for when asked (refused with the reason when the model carries no
  // compliance values) and, with auto, whenever the model carries them.
  std::string tilt_note;
  if (const Status s = PlanningGravityTiltStatus(model, terms); tilt && !s.ok()) {
    std::cerr << "error: --joint_errors=" << FLAGS_joint_errors << " with --model=" << FLAGS_model
              << ": " << s.message() << "\n";
    return kExitUsage;
  } else if (FLAGS_joint_errors == "auto") {
    tilt = s.ok();
    if (!tilt) {
      tilt_note = "the model carries no compliance values, so the gravity tilt's information is "
                  "zero (docs/planning.md)";
    }
  }

  // The feasible candidates; with joint-space terms, their identifiable combinations are those the
  // feasible candidates separate from the geometry (the solvers' reduction), and the pool's rows
  // gain their columns.
  CandidatePool pool;
  const std::unique_ptr<PlanningModel> planning =
      BuildPlanningPool(model, terms, candidates, constraints, &pool, tilt);
  const PlanningModel& pm = *planning;
  const int offered = static_cast<int>(candidates.size() / model.num_joints());
  std::cout << "candidates: " << offered << " offered, " << pool.size() << " feasible ("
            << pool.outside_limits << " outside the joint limits, " << pool.outside_cell
            << " outside the cell, " << pool.near_singular << " near a singularity, "
            << pool.nothing_visible << " with no SMR visible)\n";
  std::cout << "parameters: " << pm.num_parameters() << " identifiable (" << model.num_joints()
            << " joints, " << model.num_tools() << " tools";
  for (const JointBlock& block : pm.parameterization().joint_blocks) {
    std::cout << ", " << block.term->name() << " " << block.basis.cols() << " of "
              << block.term->num_parameters();
  }
  if (pm.num_tilt_parameters() > 0) std::cout << ", gravity tilt 2";
  std::cout << ")\n";
  if (!tilt_note.empty()) std::cout << "auto: gravity tilt not planned for: " << tilt_note << "\n";
  const Eigen::MatrixXd L = WorkspaceMoment(pm, workspace);

  // The plan, or for --count=auto the smallest plan predicted to reach the target.
  PlanResult plan;
  PlanQuality quality;
  auto plan_of = [&](int n) -> Status {
    if (Status s = SelectPlan(pm, pool, n, L, options, &plan); !s.ok()) return s;
    quality = EvaluatePlan(pm, pool, plan.selected, L);
    return Status::Ok();
  };
  if (automatic) {
    std::vector<int> all(pool.size());
    for (int c = 0; c < pool.size(); ++c) all[c] = c;
    const double best = FLAGS_noise_sigma * EvaluatePlan(pm, pool, all, L).predicted_rms;
    if (pool.size() == 0 || !(best <= FLAGS_target_accuracy)) {
      std::cerr << "error: even all " << pool.size() << " feasible candidates are predicted to reach "
                << best << " mm, not " << FLAGS_target_accuracy
                << " mm: offer more candidates or accept a larger target\n";
      return kExitNotIdentifiable;
    }
    auto reaches = [&](int n) {
      return plan_of(n).ok() && PlanRefusal(quality, pm.num_parameters(), n).ok() &&
             FLAGS_noise_sigma * quality.predicted_rms <= FLAGS_target_accuracy;
    };
    int max_rows = 3;
    for (int c = 0; c < pool.size(); ++c) max_rows = std::max(max_rows, pool.rows(c));
    int lo = std::max(1, (pm.num_parameters() + max_rows - 1) / max_rows) - 1;  // fails
    int hi = std::min(pool.size(), std::max(lo + 1, 2 * lo));
    while (!reaches(hi)) {
      if (hi >= pool.size()) {  // even every feasible candidate: refused, never a loop
        const Status refusal = plan_of(hi).ok() ? PlanRefusal(quality, pm.num_parameters(), hi)
                                                : Status::Error("no plan of all candidates");
        std::cerr << "error: all " << pool.size() << " feasible candidates: "
                  << (refusal.ok() ? "the target accuracy is out of reach" : refusal.message())
                  << ": offer more candidates\n";
        return kExitNotIdentifiable;
      }
      lo = hi;
      hi = std::min(pool.size(), 2 * hi);
    }
    while (hi - lo > 1) {  // reaches(hi), not reaches(lo)
      const int mid = lo + (hi - lo) / 2;
      (reaches(mid) ? hi : lo) = mid;
    }
    count = hi;
    if (Status s = plan_of(count); !s.ok()) {
      std::cerr << "error: " << s.message() << "\n";
      return kExitNotIdentifiable;
    }
  } else if (Status s = plan_of(count); !s.ok()) {
    std::cerr << "error: " << s.message() << " (" << pool.outside_limits << " outside the limits, "
              << pool.outside_cell << " outside the cell, " << pool.near_singular
              << " near a singularity, " << pool.nothing_visible
              << " with no SMR visible)\n";
    return kExitNotIdentifiable;
  }
  // The refusals lpoe.plan shares (lpoe/refusals.h): full rank, and more rows than parameters.
  if (Status s = PlanRefusal(quality, pm.num_parameters(), count); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitNotIdentifiable;
  }

  // Random plans of the same size, for comparison.
  std::vector<double> random_rms;
  PlanQuality random_quality;
  for (int k = 0; k < FLAGS_random_draws; ++k) {
    const PlanQuality r =
        EvaluatePlan(pm, pool, RandomPlan(pool.size(), count, FLAGS_seed + 1000 + k), L);
    if (k == 0) random_quality = r;
    random_rms.push_back(r.predicted_rms);
  }
  std::sort(random_rms.begin(), random_rms.end());
  double mean_sq = 0;
  int finite = 0;
  for (double v : random_rms) {
    if (std::isfinite(v)) {
      mean_sq += v * v;
      ++finite;
    }
  }
  const double random_rms_mean = finite > 0 ? std::sqrt(mean_sq / finite)
                                            : std::numeric_limits<double>::infinity();

  char line[256];
  std::printf("criterion %s: %d poses (%d rows), %d exchanges in %d passes\n",
              PlanCriterionName(options.criterion), count, quality.num_rows, plan.exchanges,
              plan.passes);
  std::snprintf(line, sizeof(line),
                "predicted held-out RMS per unit noise: plan %.4f, random plan %.4f (RMS of %d "
                "random plans %.4f, best %.4f); scaled condition number %.1f\n",
                quality.predicted_rms, random_quality.predicted_rms, FLAGS_random_draws,
                random_rms_mean, random_rms.front(), quality.condition_number);
  std::cout << line;
  if (FLAGS_noise_sigma > 0) {
    std::snprintf(line, sizeof(line),
                  "with noise sigma %.4g mm: plan %.4f mm, random plan %.4f mm\n",
                  FLAGS_noise_sigma, FLAGS_noise_sigma * quality.predicted_rms,
                  FLAGS_noise_sigma * random_quality.predicted_rms);
    std::cout << line;
  }

  // The gravity tilt's predicted standard deviations with the plan (the last two parameters of
  // M^-1, at the model's compliance values): what the calibration's a-posteriori ones will be at
  // that noise.
  nlohmann::json tilt_json = {{"planned", pm.num_tilt_parameters() > 0}};
  if (!tilt_note.empty()) tilt_json["note"] = tilt_note;
  if (pm.num_tilt_parameters() > 0) {
    const Eigen::MatrixXd M = Information(pool, plan.selected);
    const int P = pm.num_parameters();
    const Eigen::VectorXd d = M.diagonal().cwiseMax(1e-300).cwiseSqrt().cwiseInverse();
    const Eigen::MatrixXd Ms = d.asDiagonal() * M * d.asDiagonal();
    const Eigen::MatrixXd Cs = Ms.ldlt().solve(Eigen::MatrixXd::Identity(P, P));
    nlohmann::json per_unit = nlohmann::json::array();
    nlohmann::json at_noise = nlohmann::json::array();
    std::string text;
    for (int a = 0; a < 2; ++a) {
      const int k = P - 2 + a;
      const double sd_deg = std::sqrt(std::max(0.0, Cs(k, k))) * d(k) * 180.0 / kPi;  // per mm
      per_unit.push_back(std::isfinite(sd_deg) ? nlohmann::json(sd_deg) : nlohmann::json(nullptr));
      if (FLAGS_noise_sigma > 0) at_noise.push_back(FLAGS_noise_sigma * sd_deg);
      char buf[32];
      std::snprintf(buf, sizeof(buf), "%.4g", FLAGS_noise_sigma > 0 ? FLAGS_noise_sigma * sd_deg
                                                                     : sd_deg);
      text += (a ? ", " : "") + std::string(buf);
    }
    tilt_json["predicted_std_dev_deg_per_unit_noise"] = per_unit;
    if (FLAGS_noise_sigma > 0) tilt_json["predicted_std_dev_deg"] = at_noise;
    std::cout << "gravity tilt: predicted standard deviations " << text
              << (FLAGS_noise_sigma > 0 ? " deg" : " deg per mm of noise")
              << " (at the model's compliance values)\n";
  }

  // The plan CSV.
  std::string planned_terms;
  for (const std::string& name : term_names) {
    planned_terms += (planned_terms.empty() ? "" : ",") + name;
  }
  if (tilt) planned_terms += std::string(",") + kGravityTiltName;
  if (planned_terms.empty()) planned_terms = "none";
  std::string csv;
  csv += "# lpoe_plan: model " + tools::CommentText(model.name) + ", criterion " + PlanCriterionName(options.criterion) +
         ", " + std::to_string(count) + " of " + std::to_string(pool.size()) +
         " feasible candidates, joint errors " + planned_terms + ", seed " +
         std::to_string(FLAGS_seed) + "; joint values in " +
         FLAGS_angle_unit + "\n";
  csv += std::string(tracker.enabled ? "# measure the SMRs of the visible column (names separated "
                                       "by ';') at each pose"
                                     : "# measure every SMR at every pose") +
         "; predicted held-out RMS per unit noise " + FormatNumber(quality.predicted_rms) + "\n";
  const int n = model.num_joints();
  // With a tracker: the SMRs it sees at each planned pose.
  auto visible = [&](int c) {
    std::string names;
    for (int t : pool.visible[c]) names += (names.empty() ? "" : ";") + model.tools[t].name;
    return names;
  };
  if (!FLAGS_candidates.empty()) {
    csv += table.header + ",candidate_row" + (tracker.enabled ? ",visible" : "") + "\n";
    for (int c : plan.selected) {
      const int row = pool.source[c];
      csv += table.lines[row] + "," + std::to_string(row) +
             (tracker.enabled ? "," + visible(c) : "") + "\n";
    }
  } else {
    for (int j = 0; j < n; ++j) csv += (j ? ",q" : "q") + std::to_string(j + 1);
    csv += tracker.enabled ? ",visible\n" : "\n";
    for (int c : plan.selected) {
      for (int j = 0; j < n; ++j) {
        double v = pool.q[static_cast<size_t>(c) * n + j];
        if (unit == AngleUnit::kDegrees && model.joints[j].type == JointType::kRevolute) {
          v *= 180.0 / kPi;
        }
        csv += (j ? "," : "") + FormatNumber(v);
      }
      csv += (tracker.enabled ? "," + visible(c) : "") + "\n";
    }
  }

  nlohmann::json report = {
      {"tool", "lpoe_plan"},
      {"model", model.name},
      {"criterion", PlanCriterionName(options.criterion)},
      {"count", count},
      {"count_auto", automatic},
      {"seed", FLAGS_seed},
      {"parameters", pm.num_parameters()},
      {"joint_errors", JointErrorsJson(pm)},
      {"candidates",
       {{"offered", offered},
        {"feasible", pool.size()},
        {"outside_limits", pool.outside_limits},
        {"near_singular", pool.near_singular},
        {"nothing_visible", pool.nothing_visible},
        {"outside_cell", pool.outside_cell},
        {"source", FLAGS_candidates.empty() ? "sampled" : FLAGS_candidates}}},
      {"workspace_configurations", static_cast<int>(workspace.size() / n)},
      {"exchanges", plan.exchanges},
      {"plan", QualityJson(quality, FLAGS_noise_sigma)},
      {"random_plan", QualityJson(random_quality, FLAGS_noise_sigma)},
      {"random_plans",
       {{"draws", FLAGS_random_draws},
        {"rms_of_predicted_rms_per_unit_noise", std::isfinite(random_rms_mean)
                                                    ? nlohmann::json(random_rms_mean)
                                                    : nlohmann::json(nullptr)},
        {"best_predicted_rms_per_unit_noise", std::isfinite(random_rms.front())
                                                  ? nlohmann::json(random_rms.front())
                                                  : nlohmann::json(nullptr)}}}};
  if (FLAGS_noise_sigma > 0) report["noise_sigma_mm"] = FLAGS_noise_sigma;
  if (automatic) report["target_accuracy_mm"] = FLAGS_target_accuracy;
  report["gravity_tilt"] = tilt_json;
  nlohmann::json rows = nlohmann::json::array();
  for (int c : plan.selected) rows.push_back(pool.source[c]);
  report["candidate_rows"] = rows;

  std::cout << std::flush;  // the tool's text comes before an output written to /dev/stdout
  Status staged = outputs.Stage(FLAGS_output, csv);
  if (staged.ok()) staged = outputs.Stage(report_path, tools::JsonText(report));
  std::vector<std::string> written;
  if (Status s = staged.ok() ? outputs.Commit(&written) : staged; !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitOutput;
  }
  for (const std::string& path : written) std::cout << "wrote " << path << "\n";
  return kExitOk;
}

}  // namespace
}  // namespace lpoe

int main(int argc, char** argv) {
  lpoe::tools::InitTool(lpoe::kUsage, &argc, &argv);
  return lpoe::Run();
}
