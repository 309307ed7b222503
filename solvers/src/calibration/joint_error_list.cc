#include "lpoe/joint_error_list.h"

#include <algorithm>
#include <sstream>

#include "calibration/block_kind.h"
#include "lpoe/terms/joint_term.h"

namespace lpoe {

const std::vector<BilinearEffectName>& BilinearEffectNames() {
  static const std::vector<BilinearEffectName> names = [] {
    std::vector<BilinearEffectName> out;
    for (const internal::BlockKind* kind : internal::BlockKinds()) {
      const internal::BilinearBlockKind* bilinear = kind->bilinear();
      if (bilinear == nullptr) continue;
      out.push_back({bilinear->name(), bilinear->description(), bilinear->partner_term(),
                     bilinear->needs_partner_message()});
    }
    return out;
  }();
  return names;
}

const BilinearEffectName* FindBilinearEffectName(const std::string& name) {
  for (const BilinearEffectName& e : BilinearEffectNames()) {
    if (e.name == name) return &e;
  }
  return nullptr;
}

std::string BilinearEffectsHelp(bool example) {
  std::string out;
  for (const BilinearEffectName& e : BilinearEffectNames()) {
    if (!out.empty()) out += ", ";
    out += "with " + e.name + " in a list with " + e.partner;
    if (example) out += " (" + e.partner + "," + e.name + ")";
  }
  return out;
}

bool ParseJointErrorList(const std::string& text, std::vector<std::string>* terms,
                         std::vector<std::string>* effects, std::string* error) {
  std::string expected = "not a comma-separated list of " + JointTermNameList();
  for (const BilinearEffectName& e : BilinearEffectNames()) expected += ", " + e.name;
  // The effects (in the order given) and the rest, which must be a list of terms.
  std::vector<std::string> named;
  std::stringstream ss(text);
  std::string item, rest;
  while (std::getline(ss, item, ',')) {
    if (FindBilinearEffectName(item) != nullptr) {
      if (std::find(named.begin(), named.end(), item) != named.end()) {
        *error = "'" + item + "' is listed more than once";
        return false;
      }
      named.push_back(item);
      continue;
    }
    rest += (rest.empty() ? "" : ",") + item;
  }
  if (!text.empty() && (text.back() == ',' || text.front() == ',')) {
    *error = expected;
    return false;
  }
  if (!named.empty() && (rest.empty() || rest == "none")) {
    *error = FindBilinearEffectName(named.front())->needs_partner;
    return false;
  }
  std::vector<std::string> out;
  std::string why;
  if ((named.empty() || !rest.empty()) && !ParseJointTermList(rest, &out, &why)) {
    *error = expected + ": " + why;
    return false;
  }
  for (const std::string& name : named) {
    const BilinearEffectName* e = FindBilinearEffectName(name);
    if (std::find(out.begin(), out.end(), e->partner) == out.end()) {
      *error = e->needs_partner;
      return false;
    }
  }
  *terms = out;
  *effects = named;
  return true;
}

std::shared_ptr<const BilinearJointEffect> MakeBilinearEffect(const std::string& name,
                                                              const RobotModel& start) {
  const internal::BilinearBlockKind* kind = internal::FindBilinearBlockKind(name);
  return kind != nullptr ? kind->MakeEffect(start) : nullptr;
}

}  // namespace lpoe
