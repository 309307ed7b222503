// lpoe_predict: tool positions predicted by a model (with every error term it carries) at given
// joint values.
//
//   lpoe_predict --model=M.yaml|M.urdf --joints=IN.csv --output=OUT.csv [--angle_unit=deg]
//                [--tool=NAME|INDEX]
//
// IN.csv names q1..qN in its header and may have a `target` column (tool name or 0-based index per
// row, which then overrides --tool); other columns are ignored. OUT.csv has the header x,y,z and one
// row per input row, in mm in the model's frame (the measurement frame of a registered calibration).
// Exit codes: 0 written, 1 bad flags or output (an input's file, or a missing or unwritable
// directory: checked before any work), 2 bad input file, 5 a prediction that is not finite, 6
// output not written.
#include <algorithm>
#include <charconv>
#include <cmath>
#include <iostream>
#include <string>
#include <vector>

#include <gflags/gflags.h>
#include <glog/logging.h>

#include "lpoe/io/csv_rules.h"
#include "lpoe/io/io.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/compensation.h"
#include "lpoe/model/residual_layer.h"
#include "lpoe/io/urdf.h"
#include "common/output_files.h"
#include "common/common_flags.h"
#include "common/tool_common.h"

DEFINE_string(joints, "",
              "CSV of joint values: header with q1..qN, optional target column (required).");
DEFINE_string(frame, "base",
              "Frame of the written positions: base (the model's base frame, the chain's base "
              "link, where the nominal model lives; from the calibrated model's recorded "
              "registration) | measurement (the frame the calibration's measurements were in, "
              "e.g. the tracker's) | link:NAME (a base frame of the model, e.g. link:base, "
              "ur_description's UR controller Base). The same for a model calibrated in the base "
              "frame.");
DEFINE_bool(predict_std, false,
            "Also write the column std: the residual layer's predictive standard deviation (mm, "
            "per axis) at each row (docs/residual_layer.md); the model must carry a layer.");
DEFINE_string(tool, "0",
              "Tool measured by rows without a target column: its name or 0-based index.");

namespace lpoe {
namespace {

constexpr char kUsage[] =
    "Predicts tool positions with every error term of a model (geometry, compliance, "
    "harmonics).\n\n"
    "  lpoe_predict --model=calibrated.yaml --joints=poses.csv --output=predicted.csv\n"
    "  lpoe_predict --model=robot.urdf --tip_link=flange --tool_links=smr1,smr2 \\\n"
    "      --joints=poses.csv --angle_unit=deg --tool=smr2 --output=predicted.csv\n\n"
    "Exit codes: 0 written, 1 bad flags or output (an input's file, or a missing or unwritable "
    "directory), 2 bad input file, 5 a prediction that is not finite (nothing written), 6 "
    "output not written.";

int Run() {
  using tools::kExitInput;
  using tools::kExitOk;
  using tools::kExitOutput;
  using tools::kExitUsage;
  if (FLAGS_model.empty() || FLAGS_joints.empty() || FLAGS_output.empty()) {
    std::cerr << "error: --model, --joints and --output are required (see --help)\n";
    return kExitUsage;
  }
  AngleUnit unit;
  LengthUnit length_unit;
  double mm_per_unit = 1;
  if (!tools::UnitsFromFlags(&unit, &length_unit, &mm_per_unit)) return kExitUsage;
  // The output against the inputs, and its directory writable, before any work
  // (tools/common/output_files.h).
  tools::OutputSet outputs;
  outputs.AddInput("--model", FLAGS_model);
  outputs.AddInput("--joints", FLAGS_joints);
  outputs.AddOutput("--output", FLAGS_output);
  if (Status s = outputs.Check(); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitUsage;
  }
  TargetFrame frame_kind;
  std::string frame_link;
  if (!ParseTargetFrame(FLAGS_frame, &frame_kind, &frame_link)) {
    std::cerr << "error: --frame must be base, measurement or link:NAME, got '" << FLAGS_frame
              << "'\n";
    return kExitUsage;
  }
  RobotModel model;
  if (const int code = tools::ReadModelFlag(&model); code != kExitOk) return code;
  SE3d frame_pose;  // link:NAME in the base frame
  if (frame_kind == TargetFrame::kLink) {
    if (Status s = FindBaseFrame(model, frame_link, &frame_pose); !s.ok()) {
      std::cerr << "error: --frame=" << FLAGS_frame << ": " << FLAGS_model << ": " << s.message()
                << "\n";
      return kExitUsage;
    }
  }
  if (FLAGS_predict_std && !model.residual_layer) {
    std::cerr << "error: --predict_std needs a model with a residual layer (lpoe_calibrate "
                 "--residual_model=gp or auto writes one); "
              << FLAGS_model << " has none\n";
    return kExitUsage;
  }
  int tool = model.FindTool(FLAGS_tool);
  if (tool < 0) {
    char* end = nullptr;
    const long index = std::strtol(FLAGS_tool.c_str(), &end, 10);
    if (!FLAGS_tool.empty() && *end == '\0' && index >= 0 && index < model.num_tools()) {
      tool = static_cast<int>(index);
    }
  }
  if (tool < 0) {
    std::cerr << "error: --tool '" << FLAGS_tool << "' is neither a tool name of the model nor an "
              << "index from 0 to " << model.num_tools() - 1 << "\n";
    return kExitUsage;
  }
  std::string text;
  std::vector<double> q;
  std::vector<int> targets;
  if (Status s = ReadFile(FLAGS_joints, &text); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitInput;
  }
  if (Status s = ParseJointsCsv(text, FLAGS_joints, model, unit == AngleUnit::kDegrees, &q, &targets);
      !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitInput;
  }
  tools::ScalePrismaticJoints(model, length_unit, &q);  // --length_unit: prismatic values to mm
  if (unit == AngleUnit::kRadians) {  // the hint every joint reader gives (lpoe/io/csv_rules.h)
    const int n = model.num_joints();
    std::vector<double> max_abs(n, 0.0);
    for (size_t k = 0; k < q.size(); ++k) max_abs[k % n] = std::max(max_abs[k % n], std::abs(q[k]));
    const std::string hint = JointUnitHint(model, max_abs);
    if (!hint.empty()) std::cerr << "warning: " << FLAGS_joints << ": " << hint << "\n";
  }
  std::vector<Eigen::Vector3d> positions;
  if (Status s = PredictPositions(model, q, targets, tool, &positions); !s.ok()) {
    std::cerr << "error: " << FLAGS_joints << ": " << s.message() << "\n";
    return kExitInput;
  }
  // The model's frame is the measurement frame of its calibration; the base frame is that of the
  // nominal model it was registered from (T_measurement_base).
  if (frame_kind != TargetFrame::kMeasurement) {
    const SE3d frame_from_measurement = (model.T_measurement_base * frame_pose).Inverse();
    for (Eigen::Vector3d& p : positions) p = frame_from_measurement * p;
  }
  for (Eigen::Vector3d& p : positions) p /= mm_per_unit;  // --length_unit
  // The last guard: a prediction that is not finite is an error naming its row, never
  // a row of nan written with exit 0.
  for (size_t r = 0; r < positions.size(); ++r) {
    const int t = targets.empty() ? tool : targets[r];
    const bool finite =
        positions[r].allFinite() &&
        (!FLAGS_predict_std ||
         std::isfinite(model.residual_layer->Std(q.data() + r * model.num_joints(), t)));
    if (!finite) {
      std::cerr << "error: " << FLAGS_joints << ": data row " << r + 1
                << ": the model predicts a non-finite position there; nothing written\n";
      return tools::kExitNumerical;
    }
  }
  std::string csv = PositionsToCsv(positions);
  if (FLAGS_predict_std) {
    // The layer's standard deviation per row, a fourth column (the same in every frame).
    const int n = model.num_joints();
    std::string with_std = "x,y,z,std\n";
    size_t at = csv.find('\n') + 1;
    for (size_t r = 0; r < positions.size(); ++r) {
      const size_t end = csv.find('\n', at);
      with_std.append(csv, at, end - at);
      with_std += ',';
      const int t = targets.empty() ? tool : targets[r];
      char buf[32];
      const auto [end_of_number, ec] = std::to_chars(
          buf, buf + sizeof(buf), model.residual_layer->Std(q.data() + r * n, t) / mm_per_unit);
      with_std.append(buf, end_of_number);
      with_std += '\n';
      at = end + 1;
    }
    csv.swap(with_std);
  }
  const Status staged = outputs.Stage(
      FLAGS_output, "# lpoe_predict: positions in " + FLAGS_length_unit + " in the " +
                        std::string(frame_kind == TargetFrame::kBase          ? "model's base"
                                    : frame_kind == TargetFrame::kMeasurement ? "measurement"
                                                                              : FLAGS_frame) +
                        " frame" + (FLAGS_predict_std ? "; std: the residual layer's predictive "
                                                        "standard deviation per axis, " + FLAGS_length_unit
                                                      : "") +
                        "\n" + csv);
  if (tools::CommitOutputs(staged, &outputs, true) != kExitOk) return kExitOutput;
  if (!FLAGS_quiet) {
    std::cout << "wrote " << FLAGS_output << " (" << positions.size() << " positions)\n";
  }
  return kExitOk;
}

}  // namespace
}  // namespace lpoe

int main(int argc, char** argv) {
  lpoe::tools::InitTool(lpoe::kUsage, &argc, &argv);
  return lpoe::Run();
}
