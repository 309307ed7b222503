// libFuzzer target: ParseRobotModelYaml on arbitrary bytes. Checks that nothing crashes or throws,
// that errors are "<file>:<line>: ..." messages, that an accepted model validates, and that it
// round-trips through RobotModelToYaml with the same structure.
#include <cstddef>
#include <cstdint>
#include <string>

#include "fuzz_common.h"
#include "lpoe/io.h"
#include "lpoe/robot_model.h"

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
