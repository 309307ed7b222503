// The model-YAML keys of the non-geometric terms (docs/joint_errors.md): `gravity`, `payload` and
// `joint_errors`. The model reader and writer (io.cc) call these once each.
#ifndef LPOE_CORE_SRC_JOINT_ERRORS_YAML_H_
#define LPOE_CORE_SRC_JOINT_ERRORS_YAML_H_

#include <yaml-cpp/yaml.h>

#include <functional>
#include <string>

#include "lpoe/robot_model.h"
#include "lpoe/status.h"

namespace lpoe {
namespace internal {

// Takes the keys gravity, payload and joint_errors out of the top-level mapping `root` (left unchanged), reads the
// rest with `read_geometry` (the model reader), then reads those keys against the model and
// validates it. Errors read "<source>:<line>: <what>; expected <what>".
Status ReadModelWithJointErrors(
    const std::string& source, const YAML::Node& root, RobotModel* model,
    const std::function<Status(const YAML::Node&, RobotModel*)>& read_geometry);

// The same keys as YAML text (empty for the defaults: level gravity, no payload, no terms), numbers
// with 17 significant digits.
std::string JointErrorsToYaml(const RobotModel& model);

}  // namespace internal
}  // namespace lpoe

#endif  // LPOE_CORE_SRC_JOINT_ERRORS_YAML_H_
