// The options every tool shares, defined once (their help and defaults from lpoe/options.h, the
// table the Python module uses too): the model and its URDF chain, the units of the CSV files,
// --quiet and the main --output. Each tool reads them with the same meaning.
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include <gflags/gflags.h>

#include "common/common_flags.h"
#include "lpoe/io/io.h"
#include "lpoe/options.h"
#include "lpoe/io/urdf.h"
#include "common/tool_common.h"

DEFINE_string(model, "", lpoe::OptionHelp("", "model"));
DEFINE_string(base_link, "", lpoe::OptionHelp("", "base_link"));
DEFINE_string(tip_link, "", lpoe::OptionHelp("", "tip_link"));
DEFINE_string(tool_links, "", lpoe::OptionHelp("", "tool_links"));
DEFINE_string(angle_unit, "rad", lpoe::OptionHelp("", "angle_unit"));
DEFINE_string(length_unit, "mm", lpoe::OptionHelp("", "length_unit"));
DEFINE_bool(quiet, false, lpoe::OptionHelp("", "quiet"));
DEFINE_string(output, "", lpoe::OptionHelp("", "output"));

namespace lpoe {
namespace tools {

Status ParseUnitFlags(AngleUnit* angle, LengthUnit* length) {
  if (!ParseAngleUnit(FLAGS_angle_unit, angle)) {
    return Status::Error("--angle_unit must be rad or deg, got '" + FLAGS_angle_unit + "'");
  }
  if (!ParseLengthUnit(FLAGS_length_unit, length)) {
    return Status::Error("--length_unit must be mm or m, got '" + FLAGS_length_unit + "'");
  }
  return Status::Ok();
}

bool UnitsFromFlags(AngleUnit* angle, LengthUnit* length, double* mm_per_unit) {
  if (Status s = ParseUnitFlags(angle, length); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return false;
  }
  if (mm_per_unit != nullptr) *mm_per_unit = MillimetresPer(*length);
  return true;
}

int ReadModelFlag(RobotModel* model) {
  if (Status s = CheckUrdfFlagsHaveAUrdf({FLAGS_model}); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitUsage;
  }
  if (Status s = ReadModelWithUrdfFlags(FLAGS_model, model); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitInput;
  }
  return kExitOk;
}

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
