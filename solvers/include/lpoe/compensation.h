// The compensation workflow as a library (docs/compensation.md), shared by lpoe_compensate and
// lpoe.compensate: which frame the targets are in, the TCP they are for, the targets of a joint
// program, the inverse kinematics on the calibrated model on every core, the nominal model's pose
// at the compensated joints, and the refusal of targets that are in another frame. It reads and
// writes no file: the front ends read their rows (CSV or arrays) and write the results.
//
//   CompensationRequest request;             // models, frame, TCP, mode, IK options, threads
//   Compensator compensator;
//   if (Status s = Compensator::Create(request, &compensator); !s.ok()) ...   // a usage error
//   compensator.Solve(seeds, &targets, rows, &out);   // as often as there are chunks of rows
//   summary.Add(out, lines);  ...  summary.CheckFrame(...)
#ifndef LPOE_COMPENSATION_H_
#define LPOE_COMPENSATION_H_

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "lpoe/inverse_kinematics.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/parallel.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/kinematics/se3.h"
#include "lpoe/status.h"

namespace lpoe {

// The frame the targets are given in (docs/conventions.md, "Frames").
enum class TargetFrame {
  kBase,         // the model's base frame (the chain's base): carried into the calibrated model's
                 // frame by its recorded registration T_measurement_base
  kMeasurement,  // the frame the calibration's measurements were in (the tracker's)
  kLink,         // a named base frame of the model (RobotModel::frames, e.g. ur_description's
                 // `base`, the UR controller's base): "link:NAME"
};
const char* TargetFrameName(TargetFrame frame);  // "base" | "measurement" | "link"
// "base", "measurement" or "link:NAME" (`link` receives NAME; may be null when not kLink).
bool ParseTargetFrame(const std::string& text, TargetFrame* frame, std::string* link = nullptr);
// A base frame of `model` by name: its pose in the model's nominal base frame; an error naming
// the frames the model has.
Status FindBaseFrame(const RobotModel& model, const std::string& name, SE3d* pose);
// The controller's flange of `model` (docs/conventions.md): `name` when given (a tool or a
// flange frame), else a tool or flange frame named tool0, else one named flange, else the last
// joint's frame (identity, `*found` false). Its pose in the last joint's frame.
Status FindFlange(const RobotModel& model, const std::string& name, SE3d* pose,
                  std::string* resolved = nullptr);

// Targets this far (mm) from anything the robot reaches are in another frame.
constexpr double kWrongFrameMm = 1000.0;
// A solution farther than this from every inducing configuration of the model's residual layer
// (kernel distance, in length scales) gets less than exp(-3^2 / 2) = 1 % of the kernel's weight
// there: the layer's correction has faded to the parametric model's.
constexpr double kLayerFarDistance = 3.0;

struct CompensationRequest {
  RobotModel model;  // the calibrated model (its frame: the measurement frame)
  // The nominal model: the joint program's model (joints mode) and the corrected targets' model.
  bool has_nominal = false;
  RobotModel nominal;
  // Joints mode: every row's seed is a program's joints and its target the nominal model's tool
  // pose there (carried into the calibrated model's frame); needs the nominal model. Otherwise the
  // rows carry their own targets, in `frame`.
  bool joints_mode = false;
  bool joints_target_pose = true;  // joints mode: the nominal tool pose, or only its position
  TargetFrame frame = TargetFrame::kBase;
  std::string frame_link;  // kLink: the name of the base frame
  // The TCP the targets are for when it was not measured: empty, a tool of the models (at the same
  // index in both), or "x,y,z[,roll,pitch,yaw]" (mm, rad) relative to the flange (as a controller's
  // TCP is: URScript set_tcp, RAPID tframe), added to both models as a tool named "tcp" (each
  // model's own flange times the offset). Rows without a tool of their own use it. `tcp_offset`
  // instead of the text: the same offset given as numbers (3 or 6).
  std::string tcp;
  std::vector<double> tcp_offset;
  // The flange the TCP offset is relative to: a tool or a flange frame of the models; empty: see
  // FindFlange (tool0, flange, else the last joint's frame).
  std::string flange;
  // The tool of rows without their own: a tool name or index (empty: tool 0). Not with a TCP.
  std::string tool;
  IkOptions ik;
  int threads = 0;  // 0: one per hardware thread; the results do not depend on it
};

// What lpoe_compensate refuses before reading a row (a usage error: exit 1), with lpoe.compensate
// sharing the messages: --joints_target, the IK limits (--max_iterations 1..10000, --restarts
// 0..100, --threads 0..256, positive tolerances, --singular_threshold >= 0), --tcp with --tool,
// joints mode without a nominal model.
Status CheckCompensationRequest(const CompensationRequest& request);

// The results of rows: compensated joints (n per row, rad / mm), the IK result of each and, with a
// nominal model, the nominal tool pose at the compensated joints, in the nominal model's base frame.
struct CompensatedRows {
  std::vector<double> q;
  std::vector<IkResult> results;
  std::vector<SE3d> corrected;  // with a nominal model
  // With a residual layer: its kernel distance at each compensated q (ResidualLayer::KernelDistance).
  std::vector<double> layer_distance;
  int size() const { return static_cast<int>(results.size()); }
};

// The last guard before rows are written or returned: every joint value and corrected
// pose of `out` finite, else an error naming the first bad row (`lines[k]`, or the 0-based row
// `first_row + k` when null) of `source`.
Status CheckCompensatedFinite(const CompensatedRows& out, const int* lines, int64_t first_row,
                              const std::string& source);

class Compensator {
 public:
  // Checks the request (CheckCompensationRequest, the models: IK-solvable, the nominal model
  // matching the calibrated one), adds the TCP and resolves the default tool. A bad --tcp / --tool
  // is a usage error, a bad model an input error: `input_error` (optional) says which.
  static Status Create(const CompensationRequest& request, std::unique_ptr<Compensator>* out,
                       bool* input_error = nullptr);

  // The models with the TCP added.
  const RobotModel& model() const { return model_; }
  const RobotModel& nominal() const { return request_.has_nominal ? nominal_ : model_; }
  const CompensationRequest& request() const { return request_; }
  int default_tool() const { return default_tool_; }
  // A tool of model() by name or index; -1 when neither.
  int ResolveTool(const std::string& text) const;

  // Solves `rows` rows: seeds[k * n ...] (rad / mm, n = model().num_joints()) and targets[k] (its
  // tool; in targets mode its position and orientation in the request's frame). Each target is
  // carried into the calibrated model's frame in place (joints mode: replaced by the nominal pose
  // at the seed). Runs on request().threads threads in fixed contiguous blocks: the output does not
  // depend on the thread count.
  void Solve(const double* seeds, std::vector<IkTarget>* targets, CompensatedRows* out) const;
  // One row of Solve: `target` (in the request's frame; carried into the calibrated model's frame
  // in place) solved from `seed` into `q`. Program targets are compensated by this same call.
  IkResult SolveRow(IkTarget* target, const double* seed, double* q) const;
  // The pose of the request's frame in the nominal base frame (identity for base and measurement).
  const SE3d& frame_pose() const { return frame_pose_; }
  // The flange's name and its pose in the last joint's frame of the calibrated / nominal model.
  const std::string& flange_name() const { return flange_name_; }

  // The blocks Solve cuts `rows` rows into (one per thread, at least 256 rows each), and
  // fn(block, begin, end) run for each on as many threads (lpoe/parallel.h), for a front end's
  // formatting of the results in the same blocks: block b's rows precede block b + 1's.
  int Blocks(int rows) const;
  template <typename Fn>
  void ForEachBlock(int rows, Fn&& fn) const {
    const int blocks = Blocks(rows);
    ForEachTask(blocks, blocks, [&](int b, int) {
      fn(b, static_cast<int>(int64_t{rows} * b / blocks),
         static_cast<int>(int64_t{rows} * (b + 1) / blocks));
    });
  }

 private:
  Compensator() = default;
  CompensationRequest request_;
  RobotModel model_, nominal_;
  int default_tool_ = 0;
  SE3d frame_pose_;
  std::string flange_name_;
  std::unique_ptr<InverseKinematics> ik_;
  std::unique_ptr<KinematicChain> nominal_chain_;
};

// Counts and extremes over all rows solved; `Add` once per chunk in row order.
struct CompensationSummary {
  int rows = 0;
  int per_status[5] = {};  // by IkStatus
  double max_correction = 0, max_residual = 0, max_orientation_residual = 0;
  int64_t max_correction_line = 0, max_residual_line = 0;  // the caller's line (or row) numbers
  int far_rows = 0;  // rows kWrongFrameMm or more from anything the robot reaches
  // Rows whose solution is kLayerFarDistance or more from every identification configuration of
  // the model's residual layer, and the first of them.
  int layer_far_rows = 0;
  int64_t layer_far_line = 0;

  // `lines` (may be null: the 0-based row over all chunks) names each row of `out`.
  void Add(const CompensatedRows& out, const int* lines = nullptr);
  // Most targets metres from anything the robot reaches are in another frame, not beyond its reach:
  // an error that says which frame was assumed and what to give instead (targets mode only; one far
  // row is an unreachable target, kept with its status). `source` names the input.
  Status CheckFrame(const CompensationRequest& request, const std::string& source) const;
};

}  // namespace lpoe

#endif  // LPOE_COMPENSATION_H_
