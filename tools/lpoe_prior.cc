// lpoe_prior: the fleet prior of calibrated robots of one type (docs/recalibration.md):
// the mean of their models and the per-frame covariance of their parameters, written as a model
// with a covariance block that `lpoe_calibrate --prior=` reads.
//
//   lpoe_prior --models=a.yaml,b.yaml,... --output=fleet.yaml
//
// Exit codes: 0 written, 1 bad flags (fewer than two models, an output that collides with an
// input), 2 an input model missing or malformed, or models of different chains or tools, 6 output
// not written.
#include <algorithm>
#include <iostream>
#include <string>
#include <vector>

#include <gflags/gflags.h>
#include <glog/logging.h>

#include "lpoe/io/io.h"
#include "lpoe/model/model_covariance.h"
#include "lpoe/recalibration.h"
#include "common/common_flags.h"
#include "common/fleet_prior_text.h"
#include "common/output_files.h"
#include "common/tool_common.h"

DEFINE_string(models, "",
              "Comma-separated calibrated models (YAML, as lpoe_calibrate --output writes) of "
              "robots of one type: same chain, same tools; at least 2 (a full 6x6 covariance of "
              "a frame needs 7) (required).");

namespace lpoe {
namespace {

constexpr char kUsage[] =
    "Fleet prior: the mean and per-frame covariance of calibrated robots of one type, written as "
    "a model with a covariance block for lpoe_calibrate --prior.\n\n"
    "  lpoe_prior --models=r1.yaml,r2.yaml,r3.yaml,r4.yaml,r5.yaml,r6.yaml,r7.yaml,r8.yaml \\\n"
    "      --output=fleet.yaml\n\n"
    "Exit codes: 0 written, 1 bad flags (fewer than two models, an output that is an input), 2 an "
    "input model missing or malformed, or models of different chains or tools (the first "
    "difference named), 6 output not written.";

std::vector<std::string> SplitModelList(const std::string& text) {
  std::vector<std::string> out;
  size_t at = 0;
  while (at <= text.size()) {
    const size_t comma = std::min(text.find(',', at), text.size());
    out.push_back(text.substr(at, comma - at));
    at = comma + 1;
  }
  return out;
}

int Run() {
  using tools::kExitInput;
  using tools::kExitOk;
  using tools::kExitOutput;
  using tools::kExitUsage;
  if (FLAGS_models.empty() || FLAGS_output.empty()) {
    std::cerr << "error: --models and --output are required (see --help)\n";
    return kExitUsage;
  }
  if (!FLAGS_model.empty() || !FLAGS_base_link.empty() || !FLAGS_tip_link.empty() ||
      !FLAGS_tool_links.empty()) {
    std::cerr << "error: lpoe_prior reads calibrated YAML models from --models, not --model or the "
                 "URDF chain flags\n";
    return kExitUsage;
  }
  const std::vector<std::string> paths = SplitModelList(FLAGS_models);
  for (size_t k = 0; k < paths.size(); ++k) {
    if (paths[k].empty()) {
      std::cerr << "error: --models: item " << k + 1 << " is empty\n";
      return kExitUsage;
    }
  }
  if (paths.size() < 2) {
    std::cerr << "error: --models: "
              << tools::FleetPriorCountRefusal(static_cast<int>(paths.size())) << "\n";
    return kExitUsage;
  }
  for (size_t a = 0; a < paths.size(); ++a) {
    for (size_t b = a + 1; b < paths.size(); ++b) {
      if (tools::SameFile(paths[a], paths[b])) {
        std::cerr << "error: --models: " << paths[b] << " is listed twice (item " << a + 1
                  << " and " << b + 1 << "): one robot would count twice\n";
        return kExitUsage;
      }
    }
  }
  tools::OutputSet outputs;
  for (const std::string& p : paths) outputs.AddInput("--models", p);
  outputs.AddOutput("--output", FLAGS_output);
  if (Status s = outputs.Check(); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitUsage;
  }
  std::vector<RobotModel> models(paths.size());
  for (size_t k = 0; k < paths.size(); ++k) {
    if (Status s = ReadRobotModel(paths[k], &models[k]); !s.ok()) {
      std::cerr << "error: " << s.message() << "\n";
      return kExitInput;
    }
  }
  tools::FleetPriorFile prior;
  if (Status s = tools::MakeFleetPriorFile(models, paths, &prior); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitInput;
  }
  for (const std::string& w : prior.warnings) std::cerr << "warning: " << w << "\n";
  const Status staged = outputs.Stage(FLAGS_output, prior.text);
  if (tools::CommitOutputs(staged, &outputs, true) != kExitOk) return kExitOutput;
  if (!FLAGS_quiet) {
    std::cout << "fleet prior of " << models.size() << " robots (" << prior.mean.num_joints()
              << " joints, " << prior.mean.num_tools() << " tools)\n";
    std::cout << "wrote " << FLAGS_output << "\n";
  }
  return kExitOk;
}

}  // namespace
}  // namespace lpoe

int main(int argc, char** argv) {
  lpoe::tools::InitTool(lpoe::kUsage, &argc, &argv);
  return lpoe::Run();
}
