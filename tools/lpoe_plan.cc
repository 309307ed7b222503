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

#include "lpoe/io/io.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/io/joint_table.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/options.h"
#include "lpoe/planning.h"
#include "lpoe/planning_workflow.h"
#include "lpoe/recalibration.h"
#include "lpoe/model/refusals.h"
#include "report/json_text.h"
#include "common/output_files.h"
#include "io/parse_util.h"
#include "common/common_flags.h"
#include "lpoe_plan_contact.h"
#include "common/tool_common.h"

// Defaults, ranges and help of the numeric options from the option table (lpoe/options.h), shared
// with lpoe.plan.
#define LPOE_DEFAULT(name) lpoe::OptionDefault("lpoe_plan", #name)
#define LPOE_HELP(name) lpoe::OptionHelp("lpoe_plan", #name)
#define LPOE_DEFAULT_TEXT(name) lpoe::OptionDefaultText("lpoe_plan", #name)
DEFINE_string(count, "",
              "Number of poses to plan, or 'auto': the smallest plan predicted to reach "
              "--target_accuracy with --noise_sigma. Required.");
DEFINE_string(report, "", "JSON report (default: --output with its extension replaced by .json).");
DEFINE_string(candidates, "",
              "Candidate configurations, CSV with q1..qN (other columns are kept): choose rows of "
              "this file. Default: sample --candidate_count configurations within the joint limits.");
DEFINE_int32(candidate_count, static_cast<int>(LPOE_DEFAULT(candidate_count)), LPOE_HELP(candidate_count));
DEFINE_string(workspace, "",
              "Configurations where the accuracy matters (CSV with q1..qN), for criterion I and "
              "the predicted accuracy. Default: --workspace_count samples within the joint limits.");
DEFINE_int32(workspace_count, static_cast<int>(LPOE_DEFAULT(workspace_count)), LPOE_HELP(workspace_count));
DEFINE_uint64(seed, static_cast<uint64_t>(LPOE_DEFAULT(seed)), LPOE_HELP(seed));
DEFINE_string(criterion, LPOE_DEFAULT_TEXT(criterion), LPOE_HELP(criterion));
DEFINE_string(tracker, "", "Tracker position x,y,z in the model's base frame (mm). Enables the "
                           "visibility constraints (--max_range, --acceptance_angle, --smr_facing).");
DEFINE_double(max_range, LPOE_DEFAULT(max_range), LPOE_HELP(max_range));
DEFINE_double(acceptance_angle, LPOE_DEFAULT(acceptance_angle), LPOE_HELP(acceptance_angle));
DEFINE_string(smr_facing, "",
              "Facing direction of the SMRs in their tool frames: 'x,y,z' for all, or one 'x,y,z' "
              "per tool separated by ';'. Default: +z of each tool frame.");
DEFINE_double(min_singularity, LPOE_DEFAULT(min_singularity), LPOE_HELP(min_singularity));
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
DEFINE_double(target_accuracy, LPOE_DEFAULT(target_accuracy), LPOE_HELP(target_accuracy));
DEFINE_double(noise_sigma, LPOE_DEFAULT(noise_sigma), LPOE_HELP(noise_sigma));
DEFINE_int32(random_draws, static_cast<int>(LPOE_DEFAULT(random_draws)), LPOE_HELP(random_draws));
DEFINE_double(unmodelled_error, LPOE_DEFAULT(unmodelled_error), LPOE_HELP(unmodelled_error));
DEFINE_string(prior, "",
              "Plan a recalibration (docs/recalibration.md): a calibrated model with its covariance "
              "block (lpoe_calibrate --output) or a fleet prior (lpoe_prior). The plan starts from "
              "its information (posterior = prior + J^T J / sigma^2, sigma --noise_sigma, else the "
              "prior's), so the poses go where it is weak; its model is the model unless --model "
              "is given.");
DEFINE_string(prior_free, "",
              "With --prior: frames whose prior is replaced by the nominal tolerances (what "
              "maintenance changed), comma-separated joint or tool names, e.g. joint5,joint3.");
DEFINE_double(unmodelled_length, LPOE_DEFAULT(unmodelled_length), LPOE_HELP(unmodelled_length));
DEFINE_string(joint_errors, LPOE_DEFAULT_TEXT(joint_errors), LPOE_HELP(joint_errors));
DEFINE_string(measurement, LPOE_DEFAULT_TEXT(measurement), LPOE_HELP(measurement));
#undef LPOE_DEFAULT
#undef LPOE_HELP
#undef LPOE_DEFAULT_TEXT

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


bool ParseVector3(const std::string& text, Eigen::Vector3d* v) {
  std::vector<double> x;
  if (!internal::ParseNumberList(text, ',', &x) || x.size() != 3) return false;
  *v = Eigen::Vector3d(x[0], x[1], x[2]);
  return true;
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

// The unmodelled error planned for and the predicted error with it (docs/planning.md,
// "Unmodelled error"), as text and as JSON.
std::string UnmodelledText(const PlanningResult& p, int draws) {
  const UnmodelledErrorModel& u = p.unmodelled;
  char line[512];
  std::string text;
  if (p.prior_sigma > 0) {
    text += "unmodelled error: not planned for with --prior (its prediction is that of a "
            "least-squares calibration); the predicted error is the posterior's noise part\n";
  } else if (u.std > 0) {
    std::string lengths;
    for (int j = 0; j < u.length_scales.size(); ++j) {
      char buf[32];
      std::snprintf(buf, sizeof(buf), "%s%.3g", j ? " " : "", u.length_scales(j));
      lengths += buf;
    }
    std::snprintf(line, sizeof(line),
                  "unmodelled error (%s): %.4g mm per axis, length scales %s; the plan is the "
                  "%s improved by %d swaps on the predicted error\n",
                  p.unmodelled_source.c_str(), u.std, lengths.c_str(),
                  p.unmodelled_start == "criterion" ? "criterion's plan"
                                                    : p.unmodelled_start.c_str(),
                  p.unmodelled_swaps);
    text += line;
  } else {
    text += "unmodelled error: none (--unmodelled_error=0)\n";
  }
  std::snprintf(line, sizeof(line),
                "predicted held-out error (calibrated minus true tool positions over the "
                "workspace, noise %.4g mm%s, with the unmodelled error): plan %.4f mm (noise "
                "%.4f, unmodelled %.4f); %d random plans: RMS %.4f mm, best %.4f mm\n",
                p.prediction_sigma, p.prediction_sigma == kPlanDefaultNoiseSigma ? " assumed" : "",
                p.prediction.total_rms, p.prediction.noise_rms, p.prediction.unmodelled_rms, draws,
                p.random_total_rms_mean,
                p.random_total_rms.empty() ? 0.0 : p.random_total_rms.front());
  text += line;
  return text;
}

nlohmann::json UnmodelledJson(const PlanningResult& p) {
  auto number = [](double v) { return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json(nullptr); };
  nlohmann::json lengths = nlohmann::json::array();
  for (int j = 0; j < p.unmodelled.length_scales.size(); ++j) {
    lengths.push_back(number(p.unmodelled.length_scales(j)));
  }
  return {{"source", p.unmodelled_source},
          {"std_mm", p.unmodelled.std},
          {"length_scales", lengths},
          {"tool_correlation", p.unmodelled.tool_correlation},
          {"noise_sigma_mm", p.prediction_sigma},
          {"start", p.unmodelled_start},
          {"swaps", p.unmodelled_swaps},
          {"plan", {{"total_rms_mm", number(p.prediction.total_rms)},
                    {"noise_rms_mm", number(p.prediction.noise_rms)},
                    {"unmodelled_rms_mm", number(p.prediction.unmodelled_rms)}}},
          {"random_plans", {{"rms_of_total_rms_mm", number(p.random_total_rms_mean)},
                            {"best_total_rms_mm", number(p.random_total_rms.empty()
                                                             ? std::numeric_limits<double>::infinity()
                                                             : p.random_total_rms.front())}}}};
}

// What the steps of a plan share: the workflow's request, the units, the files and the result.
struct PlanJob {
  PlanRequest request;
  AngleUnit unit;
  LengthUnit length_unit;
  std::string report_path;
  tools::OutputSet outputs;
  std::string freed;  // --prior_free's frames, as printed
  JointTable table;   // --candidates as read (the plan CSV repeats its lines)
  PlanningResult planned;
};

// The workflow's request (lpoe/planning_workflow.h) from the flags, checked before any file is
// read.
int PlanRequestFromFlags(PlanJob* job) {
  if (!FLAGS_prior.empty() && FLAGS_model.empty()) FLAGS_model = FLAGS_prior;  // the prior's model
  if (!FLAGS_prior_free.empty() && FLAGS_prior.empty()) {
    std::cerr << "error: --prior_free needs --prior\n";
    return kExitUsage;
  }
  if (FLAGS_model.empty() || FLAGS_count.empty() || FLAGS_output.empty()) {
    std::cerr << "error: --model, --count and --output are required (see --help)\n";
    return kExitUsage;
  }
  PlanRequest& request = job->request;
  request.model_source = FLAGS_model;
  request.count_auto = FLAGS_count == "auto";
  if (!request.count_auto) {
    const auto r = std::from_chars(FLAGS_count.data(), FLAGS_count.data() + FLAGS_count.size(),
                                   request.count);
    if (r.ec != std::errc() || r.ptr != FLAGS_count.data() + FLAGS_count.size()) request.count = 0;
  }
  request.target_accuracy = FLAGS_target_accuracy;
  request.noise_sigma = FLAGS_noise_sigma;
  if (!tools::UnitsFromFlags(&job->unit, &job->length_unit, nullptr)) return kExitUsage;
  if (!ParsePlanCriterion(FLAGS_criterion, &request.options.criterion)) {
    std::cerr << "error: --criterion must be one of D, A, E, I, O1, O3\n";
    return kExitUsage;
  }
  request.candidate_count = FLAGS_candidate_count;
  request.workspace_count = FLAGS_workspace_count;
  request.random_draws = FLAGS_random_draws;
  request.unmodelled_error = FLAGS_unmodelled_error;
  request.unmodelled_length = FLAGS_unmodelled_length;
  request.unmodelled_given = !gflags::GetCommandLineFlagInfoOrDie("unmodelled_error").is_default ||
                             !gflags::GetCommandLineFlagInfoOrDie("unmodelled_length").is_default;
  request.seed = FLAGS_seed;
  request.joint_errors = FLAGS_joint_errors;
  PlanConstraints& constraints = request.constraints;
  constraints.min_singularity = FLAGS_min_singularity;
  TrackerConstraint& tracker = constraints.tracker;
  tracker.acceptance_angle = FLAGS_acceptance_angle * kPi / 180.0;
  if (FLAGS_max_range > 0) tracker.max_range = FLAGS_max_range;
  if (!FLAGS_tracker.empty()) {
    tracker.enabled = true;
    if (!ParseVector3(FLAGS_tracker, &tracker.position)) {
      std::cerr << "error: --tracker must be x,y,z in mm (three finite numbers)\n";
      return kExitUsage;
    }
  } else if (!FLAGS_smr_facing.empty()) {
    std::cerr << "error: --smr_facing and --max_range need --tracker\n";
    return kExitUsage;
  }
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
  if (Status s = CheckPlanRequest(request); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitUsage;
  }
  return kExitOk;
}

// Every output against every input and the other output, and its directory writable, before
// any work (tools/common/output_files.h); both are committed together at the end or neither.
int CheckPlanOutputs(PlanJob* job) {
  std::string& report_path = job->report_path;
  report_path = FLAGS_report;
  if (report_path.empty()) report_path = tools::JsonBeside(FLAGS_output);
  tools::OutputSet& outputs = job->outputs;
  outputs.AddInput("--model", FLAGS_model);
  if (!FLAGS_prior.empty()) outputs.AddInput("--prior", FLAGS_prior);
  outputs.AddInput("--candidates", FLAGS_candidates);
  outputs.AddInput("--workspace", FLAGS_workspace);
  outputs.AddInput("--keep_out", FLAGS_keep_out);
  outputs.AddOutput("--output", FLAGS_output);
  outputs.AddOutput(FLAGS_report.empty() ? "--report (default: --output with .json)" : "--report",
                    report_path);
  if (Status s = outputs.Check(); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitUsage;
  }
  return kExitOk;
}

// --prior and --prior_free: the prior's information, the freed frames at the nominal tolerances.
int PriorFromFlags(PlanJob* job) {
  const RobotModel& model = job->request.model;
  RobotModel prior_model;
  auto prior = std::make_shared<ParameterPrior>();
  if (Status s = ReadPrior(FLAGS_prior, PriorScales(), &prior_model, prior.get()); !s.ok()) {
    std::cerr << "error: --prior: " << s.message() << "\n";
    return kExitInput;
  }
  if (prior_model.num_joints() != model.num_joints() ||
      prior_model.num_tools() != model.num_tools()) {
    std::cerr << "error: --prior=" << FLAGS_prior << ": its chain (" << prior_model.num_joints()
              << " joints, " << prior_model.num_tools() << " tools) is not the model's\n";
    return kExitInput;
  }
  std::stringstream names(FLAGS_prior_free);
  for (std::string name; std::getline(names, name, ',');) {
    int frame = -1;
    for (int f = 0; f < prior_model.num_frames(); ++f) {
      const int n = prior_model.num_joints();
      if ((f < n ? prior_model.joints[f].name : prior_model.tools[f - n].name) == name) frame = f;
    }
    if (frame < 0) {
      std::cerr << "error: --prior_free: '" << name << "' is no joint or tool of " << FLAGS_prior
                << "\n";
      return kExitUsage;
    }
    prior->frame_information[frame] =
        DefaultFrameInformation(prior_model, frame, prior->scales, 1.0);
    job->freed += (job->freed.empty() ? "" : ", ") + name;
  }
  job->request.prior = prior;
  return kExitOk;
}

// --smr_facing: one direction for every SMR, or one per tool.
int SmrFacingFromFlags(const RobotModel& model, TrackerConstraint* tracker) {
  std::stringstream ss(FLAGS_smr_facing);
  std::string item;
  while (std::getline(ss, item, ';')) {
    Eigen::Vector3d v;
    if (!ParseVector3(item, &v) || v.norm() == 0) {
      std::cerr << "error: --smr_facing: '" << item << "' is not a non-zero x,y,z direction\n";
      return kExitUsage;
    }
    tracker->facing.push_back(v.normalized());
  }
  if (tracker->facing.size() == 1) tracker->facing.resize(model.num_tools(), tracker->facing[0]);
  if (static_cast<int>(tracker->facing.size()) != model.num_tools()) {
    std::cerr << "error: --smr_facing gives " << tracker->facing.size()
              << " directions; the model has " << model.num_tools() << " tools\n";
    return kExitUsage;
  }
  return kExitOk;
}

// --keep_out: a file of boxes, one a line.
int KeepOutFromFlags(CellConstraint* cell) {
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
    cell->keep_out.push_back(b);
  }
  return kExitOk;
}

// --joint_ranges: lo:hi per joint (--angle_unit for revolute joints, --length_unit for
// prismatic ones); an empty item (or ':') keeps the joint's limits.
int JointRangesFromFlags(const PlanJob& job, RobotModel* model) {
  std::vector<std::string> items;
  std::stringstream ss(FLAGS_joint_ranges);
  for (std::string item; std::getline(ss, item, ',');) items.push_back(item);
  if (FLAGS_joint_ranges.back() == ',') items.push_back("");
  std::vector<std::pair<double, double>> ranges(items.size(), {NAN, NAN});
  for (size_t j = 0; static_cast<int>(items.size()) == model->num_joints() && j < items.size();
       ++j) {
    const std::string& item = items[j];
    if (item.find_first_not_of(" :") == std::string::npos) continue;  // "" or ":": the limits
    std::vector<double> v;
    if (!internal::ParseNumberList(item, ':', &v) || v.size() != 2 || !(v[0] < v[1])) {
      std::cerr << "error: --joint_ranges: '" << item << "' for " << model->joints[j].name
                << " is not lo:hi with lo < hi\n";
      return kExitUsage;
    }
    const double scale = model->joints[j].type == JointType::kRevolute
                             ? (job.unit == AngleUnit::kDegrees ? kPi / 180.0 : 1.0)
                             : tools::MillimetresPer(job.length_unit);
    ranges[j] = {v[0] * scale, v[1] * scale};
  }
  if (Status s = NarrowJointRanges(ranges, model); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitUsage;
  }
  return kExitOk;
}

// Candidates and workspace: files in the tool's units, else sampled by the workflow.
int ReadCandidatesAndWorkspace(PlanJob* job) {
  PlanRequest& request = job->request;
  const RobotModel& model = request.model;
  if (!FLAGS_candidates.empty()) {
    JointTable& table = job->table;
    if (Status s = ReadJointTable(FLAGS_candidates, model, job->unit, &table); !s.ok()) {
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
    request.has_candidates = true;
    request.candidates = table.q;
    tools::ScalePrismaticJoints(model, job->length_unit, &request.candidates);
  }
  if (!FLAGS_workspace.empty()) {
    JointTable w;
    if (Status s = ReadJointTable(FLAGS_workspace, model, job->unit, &w); !s.ok()) {
      std::cerr << "error: " << s.message() << "\n";
      return kExitInput;
    }
    request.has_workspace = true;
    request.workspace = w.q;
    tools::ScalePrismaticJoints(model, job->length_unit, &request.workspace);
  }
  return kExitOk;
}

// The model read and the request completed from the files and flags that need it.
int ReadPlanInputs(PlanJob* job) {
  PlanRequest& request = job->request;
  RobotModel& model = request.model;
  if (const int code = tools::ReadModelFlag(&model); code != kExitOk) return code;
  if (!FLAGS_prior.empty()) {
    if (int rc = PriorFromFlags(job); rc != kExitOk) return rc;
  }
  if (!FLAGS_smr_facing.empty()) {
    if (int rc = SmrFacingFromFlags(model, &request.constraints.tracker); rc != kExitOk) return rc;
  }
  // The cell: keep-out boxes, narrower joint ranges.
  if (!FLAGS_keep_out.empty()) {
    if (int rc = KeepOutFromFlags(&request.constraints.cell); rc != kExitOk) return rc;
  }
  if (!FLAGS_joint_ranges.empty()) {
    if (int rc = JointRangesFromFlags(*job, &model); rc != kExitOk) return rc;
  }
  return ReadCandidatesAndWorkspace(job);
}

// The candidates, the parameters and the prior, printed (unless --quiet).
void PrintPlanInputs(const PlanJob& job) {
  const PlanningResult& planned = job.planned;
  const PlanningModel& pm = *planned.planning;
  const CandidatePool& pool = planned.pool;
  const RobotModel& model = job.request.model;
  std::cout << "candidates: " << planned.offered << " offered, " << pool.size() << " feasible ("
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
  if (!planned.tilt_note.empty()) {
    std::cout << "auto: gravity tilt not planned for: " << planned.tilt_note << "\n";
  }
  if (job.request.prior) {
    std::cout << "prior: " << FLAGS_prior << " (weighed against " << planned.prior_sigma
              << " mm noise per axis" << (job.freed.empty() ? "" : "; freed: " + job.freed)
              << "): the plan resolves what it leaves open; every figure below is the "
                 "posterior's\n";
  }
}

// The plan's quality against random plans, printed (unless --quiet).
void PrintPlanQuality(const PlanJob& job) {
  const PlanningResult& planned = job.planned;
  const PlanQuality& quality = planned.quality;
  const PlanQuality& random_quality = planned.random_quality;
  char line[256];
  std::printf("criterion %s: %d poses (%d rows), %d exchanges in %d passes\n",
              PlanCriterionName(job.request.options.criterion), planned.count, quality.num_rows,
              planned.plan.exchanges, planned.plan.passes);
  std::snprintf(line, sizeof(line),
                "predicted held-out RMS per unit noise: plan %.4f, random plan %.4f (RMS of %d "
                "random plans %.4f, best %.4f); scaled condition number %.1f\n",
                quality.predicted_rms, random_quality.predicted_rms, FLAGS_random_draws,
                planned.random_rms_mean, planned.random_rms.front(), quality.condition_number);
  std::cout << line;
  if (FLAGS_noise_sigma > 0) {
    std::snprintf(line, sizeof(line),
                  "with noise sigma %.4g mm: plan %.4f mm, random plan %.4f mm\n", FLAGS_noise_sigma, FLAGS_noise_sigma * quality.predicted_rms,
                  FLAGS_noise_sigma * random_quality.predicted_rms);
    std::cout << line;
  }
  std::cout << UnmodelledText(planned, FLAGS_random_draws);
}

// The gravity tilt's predicted standard deviations with the plan (at the model's compliance
// values): what the calibration's a-posteriori ones will be at that noise. Printed (unless
// --quiet) and returned for the report.
nlohmann::json PlannedTiltJson(const PlanningResult& planned) {
  const PlanningModel& pm = *planned.planning;
  nlohmann::json tilt_json = {{"planned", pm.num_tilt_parameters() > 0}};
  if (!planned.tilt_note.empty()) tilt_json["note"] = planned.tilt_note;
  if (pm.num_tilt_parameters() > 0) {
    nlohmann::json per_unit = nlohmann::json::array();
    nlohmann::json at_noise = nlohmann::json::array();
    std::string text;
    for (int a = 0; a < 2; ++a) {
      const double sd_deg = planned.tilt_sd_deg_per_unit[a];
      per_unit.push_back(std::isfinite(sd_deg) ? nlohmann::json(sd_deg) : nlohmann::json(nullptr));
      if (FLAGS_noise_sigma > 0) at_noise.push_back(FLAGS_noise_sigma * sd_deg);
      char buf[32];
      std::snprintf(buf, sizeof(buf), "%.4g", FLAGS_noise_sigma > 0 ? FLAGS_noise_sigma * sd_deg
                                                                     : sd_deg);
      text += (a ? ", " : "") + std::string(buf);
    }
    tilt_json["predicted_std_dev_deg_per_unit_noise"] = per_unit;
    if (FLAGS_noise_sigma > 0) tilt_json["predicted_std_dev_deg"] = at_noise;
    if (!FLAGS_quiet) {
      std::cout << "gravity tilt: predicted standard deviations " << text
                << (FLAGS_noise_sigma > 0 ? " deg" : " deg per mm of noise")
                << " (at the model's compliance values)\n";
    }
  }
  return tilt_json;
}

// The plan CSV: the candidates file's lines with their rows, else the sampled configurations in
// the tool's units; with a tracker, the SMRs it sees at each pose.
std::string PlanCsv(const PlanJob& job) {
  const PlanningResult& planned = job.planned;
  const CandidatePool& pool = planned.pool;
  const RobotModel& model = job.request.model;
  const bool tracked = job.request.constraints.tracker.enabled;
  std::string csv;
  csv += "# lpoe_plan: model " + tools::CommentText(model.name) + ", criterion " +
         PlanCriterionName(job.request.options.criterion) + ", " + std::to_string(planned.count) +
         " of " + std::to_string(pool.size()) + " feasible candidates, joint errors " +
         planned.PlannedTerms() + ", seed " + std::to_string(FLAGS_seed) +
         "; joint values in " + FLAGS_angle_unit +
         (job.length_unit == LengthUnit::kMetres ? " and m" : "") + "\n";
  csv += std::string(tracked ? "# measure the SMRs of the visible column (names separated "
                               "by ';') at each pose"
                             : "# measure every SMR at every pose") +
         "; predicted held-out RMS per unit noise " + FormatNumber(planned.quality.predicted_rms) +
         "\n";
  const int n = model.num_joints();
  auto visible = [&](int c) {
    std::string names;
    for (int t : pool.visible[c]) names += (names.empty() ? "" : ";") + model.tools[t].name;
    return names;
  };
  if (!FLAGS_candidates.empty()) {
    csv += job.table.header + ",candidate_row" + (tracked ? ",visible" : "") + "\n";
    for (int c : planned.plan.selected) {
      const int row = pool.source[c];
      csv += job.table.lines[row] + "," + std::to_string(row) +
             (tracked ? "," + visible(c) : "") + "\n";
    }
  } else {
    for (int j = 0; j < n; ++j) csv += (j ? ",q" : "q") + std::to_string(j + 1);
    csv += tracked ? ",visible\n" : "\n";
    for (int c : planned.plan.selected) {
      for (int j = 0; j < n; ++j) {
        double v = pool.q[static_cast<size_t>(c) * n + j];
        if (model.joints[j].type == JointType::kRevolute) {
          if (job.unit == AngleUnit::kDegrees) v *= 180.0 / kPi;
        } else {
          v /= tools::MillimetresPer(job.length_unit);
        }
        csv += (j ? "," : "") + FormatNumber(v);
      }
      csv += (tracked ? "," + visible(c) : "") + "\n";
    }
  }
  return csv;
}

// The JSON report (docs/planning.md).
nlohmann::json PlanReport(const PlanJob& job, const nlohmann::json& tilt_json) {
  const PlanningResult& planned = job.planned;
  const CandidatePool& pool = planned.pool;
  const std::vector<double>& random_rms = planned.random_rms;
  const double random_rms_mean = planned.random_rms_mean;
  nlohmann::json report = {
      {"tool", "lpoe_plan"},
      {"model", job.request.model.name},
      {"criterion", PlanCriterionName(job.request.options.criterion)},
      {"count", planned.count},
      {"count_auto", job.request.count_auto},
      {"seed", FLAGS_seed},
      {"parameters", planned.planning->num_parameters()},
      {"joint_errors", JointErrorsJson(*planned.planning)},
      {"candidates",
       {{"offered", planned.offered},
        {"feasible", pool.size()},
        {"outside_limits", pool.outside_limits},
        {"near_singular", pool.near_singular},
        {"nothing_visible", pool.nothing_visible},
        {"outside_cell", pool.outside_cell},
        {"source", FLAGS_candidates.empty() ? "sampled" : FLAGS_candidates}}},
      {"workspace_configurations", planned.workspace_configurations},
      {"exchanges", planned.plan.exchanges},
      {"plan", QualityJson(planned.quality, FLAGS_noise_sigma)},
      {"random_plan", QualityJson(planned.random_quality, FLAGS_noise_sigma)},
      {"random_plans",
       {{"draws", FLAGS_random_draws},
        {"rms_of_predicted_rms_per_unit_noise", std::isfinite(random_rms_mean)
                                                    ? nlohmann::json(random_rms_mean)
                                                    : nlohmann::json(nullptr)},
        {"best_predicted_rms_per_unit_noise", std::isfinite(random_rms.front())
                                                  ? nlohmann::json(random_rms.front())
                                                  : nlohmann::json(nullptr)}}}};
  if (FLAGS_noise_sigma > 0) report["noise_sigma_mm"] = FLAGS_noise_sigma;
  report["unmodelled_error"] = UnmodelledJson(planned);
  if (job.request.prior) {
    std::vector<std::string> freed_list;
    std::stringstream names(FLAGS_prior_free);
    for (std::string name; std::getline(names, name, ',');) freed_list.push_back(name);
    report["prior"] = {{"file", FLAGS_prior}, {"noise_sigma_mm", planned.prior_sigma},
                       {"freed", freed_list}};
  }
  if (job.request.count_auto) report["target_accuracy_mm"] = FLAGS_target_accuracy;
  report["gravity_tilt"] = tilt_json;
  nlohmann::json rows = nlohmann::json::array();
  for (int c : planned.plan.selected) rows.push_back(pool.source[c]);
  report["candidate_rows"] = rows;
  return report;
}

int Run() {
  // Ballbar and probe poses (tools/lpoe_plan_contact.cc).
  if (FLAGS_measurement != "position") {
    if (!FLAGS_prior.empty() || !FLAGS_prior_free.empty()) {
      std::cerr << "error: --prior and --prior_free plan a recalibration from tracker (position) "
                   "measurements; a --measurement="
                << FLAGS_measurement << " plan takes no prior\n";
      return kExitUsage;
    }
    return tools::RunContactPlan();
  }
  PlanJob job;
  if (int rc = PlanRequestFromFlags(&job); rc != kExitOk) return rc;
  if (int rc = CheckPlanOutputs(&job); rc != kExitOk) return rc;
  if (int rc = ReadPlanInputs(&job); rc != kExitOk) return rc;
  PlanFailure failure = PlanFailure::kNone;
  if (Status s = RunPlanning(job.request, &job.planned, &failure); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return failure == PlanFailure::kUsage   ? kExitUsage
           : failure == PlanFailure::kInput ? kExitInput
                                            : kExitNotIdentifiable;
  }
  if (!FLAGS_quiet) {
    PrintPlanInputs(job);
    PrintPlanQuality(job);
  }
  const nlohmann::json tilt_json = PlannedTiltJson(job.planned);
  Status staged = job.outputs.Stage(FLAGS_output, PlanCsv(job));
  if (staged.ok()) {
    staged = job.outputs.Stage(job.report_path, tools::JsonText(PlanReport(job, tilt_json)));
  }
  return tools::CommitOutputs(staged, &job.outputs, FLAGS_quiet);
}

}  // namespace
}  // namespace lpoe

int main(int argc, char** argv) {
  lpoe::tools::InitTool(lpoe::kUsage, &argc, &argv);
  return lpoe::Run();
}
