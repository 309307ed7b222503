// A calibration's list of joint errors ("compliance,harmonics,tilt", docs/joint_errors.md): the
// joint-space terms of the term registry (lpoe/terms/joint_term.h) and the effects bilinear with
// one of them (lpoe/terms/bilinear_term.h; the gravity tilt), each effect a block kind of the
// solvers' registry. Every front end (lpoe_calibrate, lpoe_plan, the Python module, the contact
// pipeline) reads the list here, so a new kind of either registry is known to all of them.
#ifndef LPOE_JOINT_ERROR_LIST_H_
#define LPOE_JOINT_ERROR_LIST_H_

#include <memory>
#include <string>
#include <vector>

#include "lpoe/model/robot_model.h"
#include "lpoe/status.h"
#include "lpoe/terms/bilinear_term.h"

namespace lpoe {

// A bilinear effect a list may name: its name ("tilt"), what messages call it ("gravity tilt"),
// its partner term ("compliance") and the message when the list lacks the partner.
struct BilinearEffectName {
  std::string name;
  std::string description;
  std::string partner;
  std::string needs_partner;
};
// Every such effect, in the registry's order.
const std::vector<BilinearEffectName>& BilinearEffectNames();
// The effect named `name`, nullptr when there is none.
const BilinearEffectName* FindBilinearEffectName(const std::string& name);
// For messages: "with tilt in a list with compliance" (and " (compliance,tilt)" with `example`),
// one clause per effect joined by ", "; empty without effects.
std::string BilinearEffectsHelp(bool example);

// Parses a comma-separated list of the term registry's names (ParseJointTermList: "none" or empty
// is no term) and bilinear effects, each at most once, each effect with its partner term in the
// list. `terms` in the order given, `effects` in the order given. Returns false (and `error`) on
// anything else.
bool ParseJointErrorList(const std::string& text, std::vector<std::string>* terms,
                         std::vector<std::string>* effects, std::string* error);

// The effect `name` on a calibration's start model (its block kind's MakeEffect), nullptr when
// `name` is no bilinear effect.
std::shared_ptr<const BilinearJointEffect> MakeBilinearEffect(const std::string& name,
                                                              const RobotModel& start);

}  // namespace lpoe

#endif  // LPOE_JOINT_ERROR_LIST_H_
