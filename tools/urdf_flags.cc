// The URDF chain-selection flags, shared by every tool that reads a model. They are linked into a
// tool only when it calls UrdfOptionsFromFlags (this object file of the static library).
#include <sstream>
#include <string>
#include <vector>

#include <gflags/gflags.h>

#include "lpoe/io.h"
#include "lpoe/urdf.h"
#include "tool_common.h"

DEFINE_string(base_link, "",
              "URDF --model: the link whose frame is the model's base frame. Default: the root link.");
DEFINE_string(tip_link, "",
              "URDF --model: the link that ends the chain (e.g. tool0). Needed when moving joints "
              "lead to several leaf links (the error lists them). Default: the one candidate tip.");
DEFINE_string(tool_links, "",
              "URDF --model: comma-separated links fixed to the last moving link that are the "
              "measured tools (CSV target names). Default: the tip link.");

namespace lpoe {
namespace tools {

bool UrdfOptionsFromFlags(const std::string& model_path, UrdfOptions* options) {
  *options = UrdfOptions();
  options->base_link = FLAGS_base_link;
  options->tip_link = FLAGS_tip_link;
  std::stringstream tools(FLAGS_tool_links);
  for (std::string name; std::getline(tools, name, ',');) {
    if (!name.empty()) options->tool_links.push_back(name);
  }
  return IsUrdfPath(model_path) ||
         (FLAGS_base_link.empty() && FLAGS_tip_link.empty() && FLAGS_tool_links.empty());
}

Status CheckUrdfFlagsHaveAUrdf(const std::vector<std::string>& paths) {
  if (FLAGS_base_link.empty() && FLAGS_tip_link.empty() && FLAGS_tool_links.empty()) {
    return Status::Ok();
  }
  for (const std::string& p : paths) {
    if (IsUrdfPath(p)) return Status::Ok();
  }
  return Status::Error("--base_link, --tip_link and --tool_links select a URDF chain; " +
                       (paths.size() == 1 ? paths[0] : std::string("no model given")) +
                       " is not a URDF (a name ending in .urdf)");
}

Status ReadModelWithUrdfFlags(const std::string& path, RobotModel* model, bool other_urdf) {
  UrdfOptions options;
  if (!UrdfOptionsFromFlags(path, &options) && !other_urdf) {
    return Status::Error("--base_link, --tip_link and --tool_links select a URDF chain; " + path +
                         " is not a URDF (a name ending in .urdf)");
  }
  return IsUrdfPath(path) ? ReadRobotModelUrdf(path, model, options)
                          : ReadRobotModelFile(path, model);
}

}  // namespace tools
}  // namespace lpoe
