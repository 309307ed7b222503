#include "lpoe/compensation.h"

#include "lpoe/model/residual_layer.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <string>
#include <thread>
#include <vector>

#include "lpoe/io/io.h"
#include "lpoe/model/model_limits.h"
#include "lpoe/options.h"
#include "lpoe/model/refusals.h"
#include "io/parse_util.h"

namespace lpoe {

const char* TargetFrameName(TargetFrame frame) {
  switch (frame) {
    case TargetFrame::kBase:
      return "base";
    case TargetFrame::kMeasurement:
      return "measurement";
    case TargetFrame::kLink:
      return "link";
  }
  return "?";
}

bool ParseTargetFrame(const std::string& text, TargetFrame* frame, std::string* link) {
  if (text == "base") {
    *frame = TargetFrame::kBase;
  } else if (text == "measurement") {
    *frame = TargetFrame::kMeasurement;
  } else if (text.rfind("link:", 0) == 0 && text.size() > 5) {
    *frame = TargetFrame::kLink;
    if (link != nullptr) *link = text.substr(5);
  } else {
    return false;
  }
  return true;
}

namespace {

std::string FrameNames(const RobotModel& model, bool on_flange) {
  std::string names;
  for (const NamedFrame& f : model.frames) {
    if (f.on_flange == on_flange) names += (names.empty() ? "" : ", ") + f.name;
  }
  return names.empty() ? std::string("none") : names;
}

}  // namespace

Status FindBaseFrame(const RobotModel& model, const std::string& name, SE3d* pose) {
  const NamedFrame* f = model.FindFrame(name, /*on_flange=*/false);
  if (f == nullptr) {
    return Status::Error("the model " + model.name + " has no base frame '" + name +
                         "' (its base frames: " + FrameNames(model, false) +
                         "; a URDF's links fixed to the base link are)");
  }
  *pose = f->pose;
  return Status::Ok();
}

Status FindFlange(const RobotModel& model, const std::string& name, SE3d* pose,
                  std::string* resolved) {
  const auto lookup = [&](const std::string& n) {
    if (const int t = model.FindTool(n); t >= 0) {
      *pose = model.tools[t].origin;
      return true;
    }
    if (const NamedFrame* f = model.FindFrame(n, /*on_flange=*/true)) {
      *pose = f->pose;
      return true;
    }
    return false;
  };
  if (!name.empty()) {
    if (lookup(name)) {
      if (resolved != nullptr) *resolved = name;
      return Status::Ok();
    }
    return Status::Error("the model " + model.name + " has no tool nor flange frame '" + name +
                         "' (its flange frames: " + FrameNames(model, true) + ")");
  }
  for (const char* n : {"tool0", "flange"}) {
    if (lookup(n)) {
      if (resolved != nullptr) *resolved = n;
      return Status::Ok();
    }
  }
  *pose = SE3d();
  if (resolved != nullptr) *resolved = "";
  return Status::Ok();
}

namespace {

// "x,y,z[,roll,pitch,yaw]" -> 3 or 6 numbers; false when the text is not such a list (then a tool
// name).
bool TcpNumbers(const std::string& text, std::vector<double>* numbers) {
  return !text.empty() && internal::ParseNumberList(text, ',', numbers);
}

}  // namespace

Status CheckCompensationRequest(const CompensationRequest& r) {
  if (r.joints_mode && !r.has_nominal) {
    return Status::Error("--joints needs --nominal (the model the program was planned with)");
  }
  const IkOptions& o = r.ik;
  // The ranges of lpoe/options.h (the tool's flags and lpoe.compensate's keyword arguments).
  const char* kTool = "lpoe_compensate";
  for (const Status& s : {CheckOption(kTool, "threads", r.threads),
                          CheckOption(kTool, "max_iterations", o.max_iterations),
                          CheckOption(kTool, "restarts", o.restarts),
                          CheckOption(kTool, "position_tolerance", o.position_tolerance),
                          CheckOption(kTool, "orientation_tolerance", o.orientation_tolerance),
                          CheckOption(kTool, "singular_threshold", o.singular_threshold)}) {
    if (!s.ok()) return s;
  }
  const bool has_tcp = !r.tcp.empty() || !r.tcp_offset.empty();
  if (has_tcp && !r.tool.empty()) return Status::Error("give --tcp or --tool, not both");
  std::vector<double> numbers = r.tcp_offset;
  if (!r.tcp.empty() && !r.tcp_offset.empty()) {
    return Status::Error("--tcp: a tool name or an offset, not both");
  }
  if (r.tcp.empty() ? !numbers.empty() : TcpNumbers(r.tcp, &numbers)) {
    bool finite = true;
    for (double v : numbers) finite = finite && std::isfinite(v);
    if ((numbers.size() != 3 && numbers.size() != 6) || !finite) {
      return Status::Error("--tcp=" + r.tcp +
                           ": expected x,y,z or x,y,z,roll,pitch,yaw (mm, rad), or a tool name");
    }
    // A TCP is on the tool: lengths and angles in the range of a model file (lpoe/model/model_limits.h).
    for (size_t k = 0; k < numbers.size(); ++k) {
      const double limit = k < 3 ? kMaxModelLengthMm : kMaxModelAngleRad;
      if (!(std::abs(numbers[k]) <= limit)) {
        return Status::Error("--tcp=" + (r.tcp.empty() ? std::string("(offset)") : r.tcp) +
                             ": " + (k < 3 ? "an offset" : "an angle") + " beyond " +
                             internal::ShortNumber(limit) + (k < 3 ? " mm" : " rad") +
                             " is not a tool centre point (mm, rad)");
      }
    }
  }
  return Status::Ok();
}

int Compensator::ResolveTool(const std::string& field) const {
  const int by_name = model_.FindTool(field);
  if (by_name >= 0) return by_name;
  int index = -1;
  const auto [p, ec] = std::from_chars(field.data(), field.data() + field.size(), index);
  if (ec != std::errc() || p != field.data() + field.size()) return -1;
  return index >= 0 && index < model_.num_tools() ? index : -1;
}

Status Compensator::Create(const CompensationRequest& request, std::unique_ptr<Compensator>* out,
                           bool* input_error) {
  bool scratch = false;
  bool& input = input_error != nullptr ? *input_error : scratch;
  input = false;
  if (Status s = CheckCompensationRequest(request); !s.ok()) return s;
  std::unique_ptr<Compensator> c(new Compensator());
  c->request_ = request;
  c->model_ = request.model;
  if (Status s = InverseKinematics::CheckModel(c->model_); !s.ok()) {
    input = true;
    return s;
  }
  if (request.has_nominal) {
    c->nominal_ = request.nominal;
    if (Status s = c->nominal_.Validate(); !s.ok()) {
      input = true;
      return s;
    }
    if (Status s = CheckNominalMatches(c->model_, c->nominal_); !s.ok()) {
      input = true;
      return Status::Error("nominal: " + s.message());
    }
  }
  if (request.frame == TargetFrame::kLink) {
    // The named base frame, from the nominal model (the calibrated one carries the same).
    if (Status s = FindBaseFrame(c->nominal(), request.frame_link, &c->frame_pose_); !s.ok()) {
      return Status::Error("--frame=link:" + request.frame_link + ": " + s.message());
    }
  }
  std::vector<double> numbers = request.tcp_offset;
  if (!request.tcp_offset.empty() || TcpNumbers(request.tcp, &numbers)) {
    // The residual layer corrects the positions of the tools it was fitted on (the measured
    // SMRs): a TCP elsewhere on the flange has no correction of its own.
    if (c->model_.residual_layer) {
      std::string names;
      for (const Tool& t : c->model_.tools) names += (names.empty() ? "" : ", ") + t.name;
      return Status::Error(
          "--tcp=" + (request.tcp.empty() ? std::string("x,y,z") : request.tcp) +
          ": the model's residual layer corrects only the tools it was measured with (" + names +
          "); a TCP given by its offset has no correction of its own: give --tcp=<one of those "
          "tools>, or compensate with a model calibrated with --residual_model=none");
    }
    // A TCP given by its offset on the flange: one more tool of both models, each model's flange
    // times the offset (a calibrated flange tool moves the TCP with it).
    const bool rpy = numbers.size() == 6;
    const Eigen::Matrix3d R = RotationFromRpy(rpy ? numbers[3] : 0.0, rpy ? numbers[4] : 0.0,
                                              rpy ? numbers[5] : 0.0);
    const SE3d offset(R, Eigen::Vector3d(numbers[0], numbers[1], numbers[2]));
    SE3d flange_cal, flange_nom;
    if (Status s = FindFlange(c->model_, request.flange, &flange_cal, &c->flange_name_);
        !s.ok()) {
      return Status::Error("--flange: " + s.message());
    }
    if (request.has_nominal) {
      if (Status s = FindFlange(c->nominal_, c->flange_name_, &flange_nom); !s.ok()) {
        return Status::Error("--flange: nominal: " + s.message());
      }
      c->nominal_.tools.push_back(Tool{"tcp", flange_nom * offset});
    }
    c->model_.tools.push_back(Tool{"tcp", flange_cal * offset});
    c->default_tool_ = c->model_.num_tools() - 1;
  } else if (!request.tcp.empty()) {
    c->default_tool_ = c->model_.FindTool(request.tcp);
    if (c->default_tool_ < 0 ||
        (request.has_nominal && c->nominal_.FindTool(request.tcp) != c->default_tool_)) {
      return Status::Error("--tcp=" + request.tcp + " is not a tool of the " +
                           (c->default_tool_ < 0 ? "calibrated" : "nominal") +
                           " model (at the same index in both models) nor x,y,z[,roll,pitch,yaw]; "
                           "with a URDF, name its link in --tool_links");
    }
  }
  if (!request.tool.empty()) {
    c->default_tool_ = c->ResolveTool(request.tool);
    if (c->default_tool_ < 0) {
      return Status::Error("--tool=" + request.tool + " is neither a tool name of the model nor " +
                           "an index below " + std::to_string(c->model_.num_tools()));
    }
  }
  // The model with the TCP added, checked as the inverse kinematics requires (never an abort).
  if (Status s = InverseKinematics::CheckModel(c->model_); !s.ok()) return s;
  c->ik_ = std::make_unique<InverseKinematics>(c->model_, request.ik);  // with its joint terms
  c->nominal_chain_ = std::make_unique<KinematicChain>(c->nominal());
  *out = std::move(c);
  return Status::Ok();
}

int Compensator::Blocks(int rows) const {
  const int threads = request_.threads > 0
                          ? request_.threads
                          : std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  return std::max(1, std::min(threads, rows / 256));
}

void Compensator::Solve(const double* seeds, std::vector<IkTarget>* targets,
                        CompensatedRows* out) const {
  const int rows = static_cast<int>(targets->size());
  const int n = model_.num_joints();
  out->q.resize(static_cast<size_t>(rows) * n);
  out->results.resize(rows);
  out->corrected.resize(request_.has_nominal ? rows : 0);
  out->layer_distance.resize(model_.residual_layer ? rows : 0);
  ForEachBlock(rows, [&](int, int begin, int end) {
    for (int k = begin; k < end; ++k) {
      IkTarget& t = (*targets)[k];
      const double* seed = seeds + static_cast<size_t>(k) * n;
      double* q = &out->q[static_cast<size_t>(k) * n];
      out->results[k] = SolveRow(&t, seed, q);
      if (request_.has_nominal) out->corrected[k] = nominal_chain_->Pose(q, t.tool);
      if (model_.residual_layer) out->layer_distance[k] = model_.residual_layer->KernelDistance(q);
    }
  });
}

Status CheckCompensatedFinite(const CompensatedRows& out, const int* lines, int64_t first_row,
                              const std::string& source) {
  const size_t n = out.size() > 0 ? out.q.size() / out.size() : 0;
  for (int k = 0; k < out.size(); ++k) {
    bool finite = true;
    for (size_t j = 0; j < n; ++j) finite = finite && std::isfinite(out.q[k * n + j]);
    if (!out.corrected.empty()) {
      finite = finite && out.corrected[k].t.allFinite() && out.corrected[k].R.allFinite();
    }
    if (!finite) {
      const int64_t line = lines != nullptr ? lines[k] : first_row + k;
      return Status::Error(source + ": " + (lines != nullptr ? "line " : "row ") +
                           std::to_string(line) +
                           ": the compensation is not finite (the model predicts NaN or infinity "
                           "there); nothing written");
    }
  }
  return Status::Ok();
}

IkResult Compensator::SolveRow(IkTarget* target, const double* seed, double* q) const {
  IkTarget& t = *target;
  const SE3d& T_mb = model_.T_measurement_base;
  if (request_.joints_mode) {
    // The nominal tool pose at the program's joints, in the calibrated model's frame.
    const SE3d T = T_mb * nominal_chain_->Pose(seed, t.tool);
    t.position = T.t;
    t.rotation = T.R;
    t.has_orientation = request_.joints_target_pose;
  } else if (request_.frame != TargetFrame::kMeasurement) {
    // base: T_measurement_base; link:NAME: that frame's pose in the base frame first.
    const SE3d T = T_mb * frame_pose_;
    t.position = T * t.position;
    t.rotation = T.R * t.rotation;
  }
  return ik_->Solve(t, seed, q);
}

void CompensationSummary::Add(const CompensatedRows& out, const int* lines) {
  for (int k = 0; k < out.size(); ++k) {
    const IkResult& r = out.results[k];
    const int64_t line = lines != nullptr ? lines[k] : rows + k;
    ++per_status[static_cast<int>(r.status)];
    if (r.correction > max_correction) {
      max_correction = r.correction;
      max_correction_line = line;
    }
    if (r.position_error > kWrongFrameMm) ++far_rows;
    if (!out.layer_distance.empty() && out.layer_distance[k] > kLayerFarDistance) {
      if (layer_far_rows++ == 0) layer_far_line = line;
    }
    if (r.position_error > max_residual) {
      max_residual = r.position_error;
      max_residual_line = line;
    }
    max_orientation_residual = std::max(max_orientation_residual, r.orientation_error);
  }
  rows += out.size();
}

Status CompensationSummary::CheckFrame(const CompensationRequest& request,
                                       const std::string& source) const {
  if (request.joints_mode || rows == 0 || 2 * far_rows <= rows) return Status::Ok();
  const bool base = request.frame != TargetFrame::kMeasurement;
  const std::string frame_flag =
      request.frame == TargetFrame::kLink ? "link:" + request.frame_link
                                          : std::string(TargetFrameName(request.frame));
  char residual[32];
  std::snprintf(residual, sizeof(residual), "%g", max_residual);
  // Another frame moves targets by the distance between the frames (metres at most); a length
  // unit a thousand times off moves them by hundreds of reaches: blame the unit, not the frame.
  const double reach = ModelReach(request.model);
  if (reach > 0 && max_residual > 50 * reach) {
    char times[32];
    std::snprintf(times, sizeof(times), "%.3g", max_residual / reach);
    return Status::Error(
        source + ": " + std::to_string(far_rows) + " of " + std::to_string(rows) +
        " targets are far from any pose the calibrated robot reaches (line " +
        std::to_string(max_residual_line) + ": " + residual + " mm, " + times +
        " times its reach): their lengths are in another unit than the one they were read in "
        "(--length_unit: mm or m); no output written");
  }
  char limit[32];
  std::snprintf(limit, sizeof(limit), "%g", kWrongFrameMm);
  return Status::Error(
      source + ": " + std::to_string(far_rows) + " of " + std::to_string(rows) +
      " targets are more than " + limit + " mm from any pose the calibrated robot reaches (line " +
      std::to_string(max_residual_line) + ": " + residual + " mm): the targets were read in the " +
      (base ? "robot's base" : "measurement") + " frame (--frame=" + frame_flag +
      "); if they are in the " + (base ? "measurement (tracker)" : "robot's base") +
      " frame, use --frame=" + (base ? "measurement" : "base") + "; no output written");
}

}  // namespace lpoe
