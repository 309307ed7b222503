// libFuzzer target: ParseRobotModelUrdf on arbitrary bytes. Checks that nothing crashes or throws,
// that errors are "<file>:<line>: ..." messages, that an accepted model validates, that naming its
// tools explicitly (in reverse order) gives the same tools reversed, and that RobotModelToUrdf
// output reads back with the same joints and tools.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "fuzz_common.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/io/urdf.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* bytes, size_t size) {
  const std::string xml(reinterpret_cast<const char*>(bytes), size);
  lpoe::RobotModel model;
  const lpoe::Status s = lpoe::ParseRobotModelUrdf(xml, "fuzz.urdf", &model);
  if (!s.ok()) {
    lpoe::fuzz::CheckErrorMessage(s, "fuzz.urdf");
    return 0;
  }
  if (lpoe::Status v = model.Validate(); !v.ok()) {
    lpoe::fuzz::Fail("accepted a model that does not validate: " + v.message(), xml);
  }

  lpoe::UrdfOptions options;
  for (const lpoe::Tool& t : model.tools) options.tool_links.push_back(t.name);
  std::reverse(options.tool_links.begin(), options.tool_links.end());
  lpoe::RobotModel reversed;
  if (lpoe::Status r = lpoe::ParseRobotModelUrdf(xml, "fuzz.urdf", &reversed, options); !r.ok()) {
    lpoe::fuzz::Fail("naming the default tools explicitly fails: " + r.message(), xml);
  }
  if (reversed.num_tools() != model.num_tools() || reversed.num_joints() != model.num_joints()) {
    lpoe::fuzz::Fail("explicit tool_links changed the model's structure", xml);
  }
  for (int t = 0; t < model.num_tools(); ++t) {
    if (reversed.tools[t].name != options.tool_links[t]) {
      lpoe::fuzz::Fail("tools not in the order of tool_links", xml);
    }
  }

  // The overlay of the unchanged model writes the same chain back and reads again.
  lpoe::UrdfSource source;
  lpoe::RobotModel kept;
  if (lpoe::Status r = lpoe::ParseRobotModelUrdf(xml, "fuzz.urdf", &kept, {}, &source); !r.ok()) {
    lpoe::fuzz::Fail("keeping the source changed the parse: " + r.message(), xml);
  }
  std::string overlay;
  if (lpoe::Status r = lpoe::CalibratedUrdfOverlay(source, model, {}, &overlay); !r.ok()) {
    // The overlay edits the file's own text in place, so it follows the text's elements itself.
    // Text that tinyxml2 reads leniently but that is not well-formed XML (an end tag with
    // attributes, say) is refused with a reason naming the file ("cannot locate the elements /
    // joints in the text for the overlay"): a refusal, nothing written, which is the contract.
    // Any other failure is a defect.
    if (r.message().find("in the text for the overlay") != std::string::npos) {
      return 0;
    }
    lpoe::fuzz::Fail("the overlay of the model as read fails: " + r.message(), xml);
  }
  lpoe::RobotModel overlaid;
  if (lpoe::Status r = lpoe::ParseRobotModelUrdf(overlay, "overlay.urdf", &overlaid); !r.ok()) {
    lpoe::fuzz::Fail("the overlay does not read back: " + r.message(), overlay);
  }
  if (overlaid.num_joints() != model.num_joints() || overlaid.num_tools() != model.num_tools()) {
    lpoe::fuzz::Fail("the overlay changed the number of joints or tools", overlay);
  }

  const std::string urdf = lpoe::RobotModelToUrdf(model);
  lpoe::RobotModel again;
  if (lpoe::Status r = lpoe::ParseRobotModelUrdf(urdf, "roundtrip.urdf", &again); !r.ok()) {
    lpoe::fuzz::Fail("exported URDF does not read back: " + r.message(), urdf);
  }
  if (again.num_joints() != model.num_joints() || again.num_tools() != model.num_tools()) {
    lpoe::fuzz::Fail("URDF round trip changed the number of joints or tools", urdf);
  }
  for (int j = 0; j < model.num_joints(); ++j) {
    if (again.joints[j].type != model.joints[j].type) {
      lpoe::fuzz::Fail("URDF round trip changed a joint type", urdf);
    }
  }
  return 0;
}
