// libFuzzer target: ParseRobotModelYaml on arbitrary bytes. Checks that nothing crashes or throws,
// that errors are "<file>:<line>: ..." messages, that an accepted model validates, and that it
// round-trips through RobotModelToYaml with the same structure; and that an accepted model
// predicts finite positions (every number of the file in its plausible range).
#include <cstddef>
#include <cstdint>
#include <cmath>
#include <string>
#include <vector>

#include "fuzz_common.h"
#include "lpoe/io/io.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/model/robot_model.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* bytes, size_t size) {
  const std::string text(reinterpret_cast<const char*>(bytes), size);
  lpoe::RobotModel model;
  const lpoe::Status s = lpoe::ParseRobotModelYaml(text, "fuzz.yaml", &model);
  if (!s.ok()) {
    lpoe::fuzz::CheckErrorMessage(s, "fuzz.yaml");
    return 0;
  }
  if (lpoe::Status v = model.Validate(); !v.ok()) {
    lpoe::fuzz::Fail("accepted a model that does not validate: " + v.message(), text);
  }
  // Every number in its plausible range: an accepted model predicts finite positions,
  // with its joint-space terms and residual layer, at configurations spread over its limits.
  const int n = model.num_joints();
  std::vector<double> q(n);
  for (int k = 0; k < 5; ++k) {
    for (int j = 0; j < n; ++j) {
      const lpoe::Joint& joint = model.joints[j];
      const double open = joint.type == lpoe::JointType::kRevolute ? lpoe::kPi : 1000.0;
      const double lo = std::isfinite(joint.lower) ? joint.lower : -open;
      const double hi = std::isfinite(joint.upper) ? joint.upper : open;
      q[j] = lo + (hi - lo) * (0.25 * k);
    }
    for (int t = 0; t < model.num_tools(); ++t) {
      if (!lpoe::PredictToolPosition(model, q.data(), t).allFinite()) {
        lpoe::fuzz::Fail("accepted a model that predicts a non-finite position", text);
      }
    }
  }
  const std::string yaml = lpoe::RobotModelToYaml(model);
  lpoe::RobotModel again;
  if (lpoe::Status r = lpoe::ParseRobotModelYaml(yaml, "roundtrip.yaml", &again); !r.ok()) {
    lpoe::fuzz::Fail("written model does not read back: " + r.message(), yaml);
  }
  if (again.name != model.name || again.num_joints() != model.num_joints() ||
      again.num_tools() != model.num_tools()) {
    lpoe::fuzz::Fail("round trip changed the model's structure", yaml);
  }
  for (int j = 0; j < model.num_joints(); ++j) {
    if (again.joints[j].name != model.joints[j].name ||
        again.joints[j].type != model.joints[j].type) {
      lpoe::fuzz::Fail("round trip changed a joint", yaml);
    }
  }
  for (int t = 0; t < model.num_tools(); ++t) {
    if (again.tools[t].name != model.tools[t].name) {
      lpoe::fuzz::Fail("round trip changed a tool name", yaml);
    }
  }
  return 0;
}
