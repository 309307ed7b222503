// The model-YAML keys of the non-geometric terms (docs/joint_errors.md): `gravity`, `payload` and
// `joint_errors`. The model reader and writer (io.cc) call these once each.
#ifndef LPOE_CORE_SRC_JOINT_ERRORS_YAML_H_
#define LPOE_CORE_SRC_JOINT_ERRORS_YAML_H_

#include <yaml-cpp/yaml.h>

#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "lpoe/model/robot_model.h"
#include "lpoe/status.h"

namespace lpoe {
namespace internal {

// Reads the parts of the joint-error YAML against a model (the terms' ReadYaml use it). Every error
// reads "<source>:<line>: <what>; expected <what>", the line of the offending node when it has one,
// else `line`.
class JointErrorsYamlReader {
 public:
  JointErrorsYamlReader(const std::string& source, const RobotModel& model)
      : source_(source), model_(model) {}

  const RobotModel& model() const { return model_; }
  const std::string& source() const { return source_; }

  Status Error(const YAML::Node& node, int line, const std::string& what,
               const std::string& expected) const;
  // A finite number.
  Status Number(const YAML::Node& node, int line, const std::string& what, double* out) const;
  // A list of `count` finite numbers.
  Status Numbers(const YAML::Node& node, int line, const std::string& what, int count,
                 const std::string& expected, double* out) const;
  // The entries of a mapping, each key once and among `allowed`.
  Status Map(const YAML::Node& node, int line, const std::string& what,
             const std::vector<std::string>& allowed,
             std::vector<std::pair<std::string, YAML::Node>>* out) const;
  static const YAML::Node* Find(const std::vector<std::pair<std::string, YAML::Node>>& entries,
                                const char* key);
  // The index of the model's joint named by the scalar `node`.
  Status JointIndex(const YAML::Node& node, int line, const std::string& what, int* index) const;
  // A list of per-joint entries, each joint at most once; `read(item, item_line, &joint)` reads
  // one entry and sets the joint it is for.
  template <typename ReadEntry>
  Status Entries(const YAML::Node& node, int line, const std::string& what,
                 const ReadEntry& read) const {
    if (!node.IsSequence()) {
      return Error(node, line, "'" + what + "' is not a list", "a list of per-joint entries");
    }
    std::vector<int> seen;
    for (const YAML::Node& item : node) {
      int joint = -1;
      const int item_line = LineOf(item, line);
      Status s = read(item, item_line, &joint);
      if (!s.ok()) return s;
      for (int prev : seen) {
        if (prev == joint) return TwiceError(item_line, joint, what);
      }
      seen.push_back(joint);
    }
    return Status::Ok();
  }
  // The 1-based line of `node`, `fallback` when it has none.
  static int LineOf(const YAML::Node& node, int fallback);

 protected:
  Status TwiceError(int line, int joint, const std::string& what) const;

  const std::string& source_;
  const RobotModel& model_;
};

// Takes the keys gravity, payload, joint_errors and residual_layer out of the top-level mapping `root` (left unchanged), reads the
// rest with `read_geometry` (the model reader), then reads those keys against the model and
// validates it. Errors read "<source>:<line>: <what>; expected <what>".
Status ReadModelWithJointErrors(
    const std::string& source, const YAML::Node& root, RobotModel* model,
    const std::function<Status(const YAML::Node&, RobotModel*)>& read_geometry);

// The `residual_layer` block (residual_layer_yaml.cc) against the model `reader` holds.
Status ReadResidualLayerYaml(const JointErrorsYamlReader& reader, const YAML::Node& node, int line,
                             std::shared_ptr<const ResidualLayer>* out);
// The block as YAML text (empty when the model carries no layer).
std::string ResidualLayerToYaml(const RobotModel& model);

// The same keys as YAML text (empty for the defaults: level gravity, no payload, no terms), numbers
// with 17 significant digits.
std::string JointErrorsToYaml(const RobotModel& model);

}  // namespace internal
}  // namespace lpoe

#endif  // LPOE_CORE_SRC_JOINT_ERRORS_YAML_H_
