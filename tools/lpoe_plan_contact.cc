// lpoe_plan for ballbar distances and probe contacts (lpoe_plan_contact.h, lpoe/contact_planning.h).
#include "lpoe_plan_contact.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include <gflags/gflags.h>
#include <nlohmann/json.hpp>

#include "common/common_flags.h"
#include "report/json_text.h"
#include "lpoe/contact_planning.h"
#include "lpoe/planning.h"
#include "lpoe/planning_workflow.h"
#include "common/output_files.h"
#include "io/parse_util.h"
#include "report/text_safety.h"
#include "common/tool_common.h"

DECLARE_string(measurement);
DECLARE_string(count);
DECLARE_string(report);
DECLARE_uint64(seed);
DECLARE_double(min_singularity);
DECLARE_double(min_z);
DECLARE_string(box);
DECLARE_int32(random_draws);

DEFINE_string(pivots, "",
              "--measurement=ballbar: the pivots' positions in the model's base frame (mm), "
              "'x,y,z' separated by ';' (as set up: a few mm off is fine).");
DEFINE_double(bar_length, 150, "--measurement=ballbar: the bar's length (mm).");
DEFINE_double(stroke, 1, "--measurement=ballbar: the bar's stroke (mm): planned poses put the "
                         "ball within it of the bar's length from its pivot.");
DEFINE_string(planes, "",
              "--measurement=plane: the touched planes, 'nx,ny,nz,d' (outward unit normal, n.x = "
              "d in mm, the model's base frame) separated by ';'.");
DEFINE_string(face_centres, "",
              "--measurement=plane: the centre of each touched face (mm, 'x,y,z' separated by "
              "';', one per plane). Default: each plane's point nearest the base origin.");
DEFINE_double(face_radius, 40, "--measurement=plane: the probed part of each face: within this "
                               "radius (mm) of its centre.");
DEFINE_double(probe_radius, 3, "--measurement=plane: the probe tip's radius (mm).");
DEFINE_int32(samples_per_feature, 400,
             "--measurement=ballbar|plane: random configurations projected onto each pivot's "
             "sphere or each face (the candidates).");
DEFINE_int32(contact_tool, 0, "--measurement=ballbar|plane: the tool that is the ball or the "
                              "probe tip (index in the model's tools).");

namespace lpoe {
namespace tools {
namespace {

// "a,b,c;d,e,f" -> vectors of `size` numbers each; false on a malformed item.
bool ParseContactPlanVectors(const std::string& text, int size,
                             std::vector<Eigen::VectorXd>* out) {
  out->clear();
  std::stringstream ss(text);
  for (std::string item; std::getline(ss, item, ';');) {
    std::vector<double> x;
    if (!internal::ParseNumberList(item, ',', &x) || static_cast<int>(x.size()) != size) {
      return false;
    }
    for (double v : x) {
      if (!std::isfinite(v)) return false;
    }
    out->push_back(Eigen::Map<Eigen::VectorXd>(x.data(), size));
  }
  return !out->empty();
}

std::string ContactPlanNumber(double v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof(buf), v);
  return std::string(buf, r.ptr);
}

}  // namespace

namespace {

// The request from the flags (lpoe/contact_planning.h), checked as the library checks it.
int ContactPlanRequestFromFlags(bool ballbar, ContactPlanRequest* request) {
  // The tracker plan's flags that this plan does not use: refused by name rather than ignored.
  for (const char* flag : {"criterion", "tracker", "max_range", "acceptance_angle", "smr_facing",
                           "candidates", "candidate_count", "workspace", "workspace_count",
                           "keep_out", "joint_ranges", "target_accuracy", "noise_sigma",
                           "unmodelled_error", "unmodelled_length", "joint_errors"}) {
    if (!gflags::GetCommandLineFlagInfoOrDie(flag).is_default) {
      std::cerr << "error: --" << flag << " is for tracker plans; with --measurement="
                << FLAGS_measurement
                << " the plan is D-optimal over candidates projected onto the "
                << (ballbar ? "pivots' spheres" : "planes") << " (docs/measurements.md)\n";
      return kExitUsage;
    }
  }
  if (FLAGS_model.empty() || FLAGS_count.empty() || FLAGS_output.empty()) {
    std::cerr << "error: --model, --count and --output are required (see --help)\n";
    return kExitUsage;
  }
  int& count = request->count;
  {
    const auto r = std::from_chars(FLAGS_count.data(), FLAGS_count.data() + FLAGS_count.size(),
                                   count);
    if (r.ec != std::errc() || r.ptr != FLAGS_count.data() + FLAGS_count.size() || count < 1) {
      std::cerr << "error: --count must be a number of poses (1 or more) with --measurement="
                << FLAGS_measurement << " ('auto' plans tracker poses only)\n";
      return kExitUsage;
    }
  }
  ContactPlanOptions& o = request->options;
  std::vector<Eigen::VectorXd> items;
  if (ballbar) {
    if (!FLAGS_planes.empty() || !FLAGS_face_centres.empty()) {
      std::cerr << "error: --planes and --face_centres are for --measurement=plane\n";
      return kExitUsage;
    }
    if (!ParseContactPlanVectors(FLAGS_pivots, 3, &items)) {
      std::cerr << "error: --measurement=ballbar needs --pivots: 'x,y,z' (mm) per pivot "
                   "separated by ';', got '"
                << FLAGS_pivots << "'\n";
      return kExitUsage;
    }
    for (const Eigen::VectorXd& v : items) o.pivots.push_back(v);
  } else {
    if (!FLAGS_pivots.empty()) {
      std::cerr << "error: --pivots is for --measurement=ballbar\n";
      return kExitUsage;
    }
    if (!ParseContactPlanVectors(FLAGS_planes, 4, &items)) {
      std::cerr << "error: --measurement=plane needs --planes: 'nx,ny,nz,d' per plane separated "
                   "by ';', got '"
                << FLAGS_planes << "'\n";
      return kExitUsage;
    }
    for (const Eigen::VectorXd& v : items) o.planes.push_back(v);
    if (!FLAGS_face_centres.empty()) {
      if (!ParseContactPlanVectors(FLAGS_face_centres, 3, &items)) items.clear();
      // An empty list where one was given: refused with the count's message.
      if (items.empty()) items.resize(o.planes.size() + 1, Eigen::VectorXd::Zero(3));
      for (const Eigen::VectorXd& v : items) o.plane_centres.push_back(v);
    }
  }
  o.bar_length = FLAGS_bar_length;
  o.stroke = FLAGS_stroke;
  o.face_radius = FLAGS_face_radius;
  o.probe_radius = FLAGS_probe_radius;
  o.target = FLAGS_contact_tool;
  o.seed = FLAGS_seed;
  o.min_singularity = FLAGS_min_singularity;
  o.samples_per_feature = FLAGS_samples_per_feature;
  if (FLAGS_min_z != -1e300) {
    if (!std::isfinite(FLAGS_min_z)) {
      std::cerr << "error: --min_z must be a finite height in mm\n";
      return kExitUsage;
    }
    o.cell.min_z = FLAGS_min_z;
  }
  if (!FLAGS_box.empty()) {
    if (Status s = ParseBox(FLAGS_box, &o.cell.box); !s.ok()) {
      std::cerr << "error: --box: " << s.message() << "\n";
      return kExitUsage;
    }
  }
  request->random_draws = FLAGS_random_draws;
  if (Status s = CheckContactPlanRequest(*request); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitUsage;
  }
  return kExitOk;
}

// The plan's CSV: joint values (in --angle_unit / --length_unit) and the pivot or plane; the
// distance or contact is what is measured there.
std::string ContactPlanCsv(const RobotModel& model, const ContactPlanRequest& request,
                           const ContactPlanningResult& planned, AngleUnit unit,
                           LengthUnit length_unit) {
  const bool ballbar = !request.options.pivots.empty();
  const ContactPlanOptions& o = request.options;
  const int n = model.num_joints();
  const ContactMeasurementSet& set = planned.candidates.set;
  std::string csv = "# lpoe_plan: model " + CommentText(model.name) + ", " +
                    (ballbar ? "ballbar, bar " + ContactPlanNumber(o.bar_length) + " mm +- " +
                                   ContactPlanNumber(o.stroke) + " mm"
                             : "probe, radius " + ContactPlanNumber(o.probe_radius) + " mm") +
                    ", " + std::to_string(request.count) + " poses of " +
                    std::to_string(set.size()) + " candidates, D-optimal over " +
                    std::to_string(planned.plan.num_parameters) + " parameters; joints in " +
                    FLAGS_angle_unit + (length_unit == LengthUnit::kMetres ? " and m" : "") + "\n";
  csv += ballbar ? "# measure the distance at each pose (add a distance column) and calibrate "
                   "with lpoe_calibrate --measurements\n"
                 : "# touch the plane at each pose (the probe's contact) and calibrate with "
                   "lpoe_calibrate --measurements\n";
  for (int j = 0; j < n; ++j) csv += (j ? ",q" : "q") + std::to_string(j + 1);
  csv += ballbar ? ",pivot\n" : ",plane,offset\n";
  for (int c : planned.plan.selected) {
    const ContactRow& row = set.rows[c];
    for (int j = 0; j < n; ++j) {
      double v = set.joints(c)[j];
      if (model.joints[j].type == JointType::kRevolute) {
        if (unit == AngleUnit::kDegrees) v *= 180.0 / kPi;
      } else {
        v /= MillimetresPer(length_unit);
      }
      csv += (j ? "," : "") + ContactPlanNumber(v);
    }
    const std::string& name = ballbar ? set.pivots[row.feature] : set.planes[row.feature];
    csv += "," + name + (ballbar ? "" : "," + ContactPlanNumber(o.probe_radius)) + "\n";
  }
  return csv;
}

nlohmann::json ContactPlanReport(const ContactPlanRequest& request,
                                 const ContactPlanningResult& planned) {
  const bool ballbar = !request.options.pivots.empty();
  const ContactPlanOptions& o = request.options;
  const ContactCandidates& candidates = planned.candidates;
  const ContactMeasurementSet& set = candidates.set;
  nlohmann::json per_feature = nlohmann::json::object();
  for (int c : planned.plan.selected) {
    const ContactRow& row = set.rows[c];
    const std::string& name = ballbar ? set.pivots[row.feature] : set.planes[row.feature];
    per_feature[name] = per_feature.value(name, 0) + 1;
  }
  return {{"tool", "lpoe_plan"},
          {"measurement", FLAGS_measurement},
          {"poses", request.count},
          {"parameters", planned.plan.num_parameters},
          {"poses_per_feature", per_feature},
          {"candidates",
           {{"sampled",
             o.samples_per_feature * static_cast<int>(o.pivots.size() + o.planes.size())},
            {"feasible", set.size()},
            {"not_reached", candidates.not_converged},
            {"outside_limits", candidates.outside_limits},
            {"outside_cell", candidates.outside_cell},
            {"near_singular", candidates.near_singular},
            {"outside_stroke", candidates.outside_stroke}}},
          {"exchanges", planned.plan.exchanges},
          {"plan", {{"D_log_det", planned.plan.log_det}}},
          {"random_plans",
           {{"draws", request.random_draws},
            {"mean_D_log_det", planned.random_mean_log_det},
            {"best_D_log_det", planned.random_best_log_det}}}};
}

}  // namespace

int RunContactPlan() {
  const bool ballbar = FLAGS_measurement == "ballbar";
  if (!ballbar && FLAGS_measurement != "plane") {
    std::cerr << "error: --measurement must be position, ballbar or plane, got '"
              << FLAGS_measurement << "'\n";
    return kExitUsage;
  }
  ContactPlanRequest request;
  if (int rc = ContactPlanRequestFromFlags(ballbar, &request); rc != kExitOk) return rc;
  std::string report_path = FLAGS_report;
  if (report_path.empty()) report_path = JsonBeside(FLAGS_output);
  OutputSet outputs;
  outputs.AddInput("--model", FLAGS_model);
  outputs.AddOutput("--output", FLAGS_output);
  outputs.AddOutput(FLAGS_report.empty() ? "--report (default: --output with .json)" : "--report",
                    report_path);
  if (Status s = outputs.Check(); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitUsage;
  }
  AngleUnit unit;
  LengthUnit length_unit;
  if (!UnitsFromFlags(&unit, &length_unit, nullptr)) return kExitUsage;
  RobotModel model;
  if (const int code = ReadModelFlag(&model); code != kExitOk) return code;

  ContactPlanningResult planned;
  PlanFailure failure = PlanFailure::kNone;
  if (Status s = RunContactPlanning(model, request, &planned, &failure); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return failure == PlanFailure::kUsage ? kExitUsage : kExitNotIdentifiable;
  }
  if (!FLAGS_quiet) {
    std::cout << "lpoe_plan: " << request.count << " " << FLAGS_measurement << " poses of "
              << planned.candidates.set.size() << " candidates, D-optimal over "
              << planned.plan.num_parameters << " parameters: log det " << planned.plan.log_det
              << " (" << FLAGS_random_draws << " random plans: mean "
              << planned.random_mean_log_det << ", best " << planned.random_best_log_det << ")\n";
  }
  Status staged =
      outputs.Stage(FLAGS_output, ContactPlanCsv(model, request, planned, unit, length_unit));
  if (staged.ok()) staged = outputs.Stage(report_path, JsonText(ContactPlanReport(request, planned)));
  return CommitOutputs(staged, &outputs, FLAGS_quiet);
}

}  // namespace tools
}  // namespace lpoe
