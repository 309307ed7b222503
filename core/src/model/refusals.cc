#include "lpoe/model/refusals.h"

#include <algorithm>

#include <cmath>

namespace lpoe {
namespace {

bool Finite(const SE3d& T) { return T.R.allFinite() && T.t.allFinite(); }

bool FiniteValues(const std::vector<double>& v) {
  for (double x : v) {
    if (!std::isfinite(x)) return false;
  }
  return true;
}

}  // namespace

Status CheckRedundancy(int rows, int parameters, const std::string& what) {
  if (rows > parameters) return Status::Ok();
  return Status::Error(what + " has " + std::to_string(rows) + " rows (scalar observations) for " +
                       std::to_string(parameters) +
                       " parameters: a plan or data set with no more rows than parameters cannot "
                       "check itself (every residual is zero whatever the errors, no standard "
                       "deviation can be estimated): use more poses, so that the rows outnumber "
                       "the parameters");
}

Status CheckFullRank(int rank, int parameters, const std::string& what) {
  if (rank == parameters) return Status::Ok();
  return Status::Error(what + " identifies only " + std::to_string(rank) + " of " +
                       std::to_string(parameters) +
                       " parameters: plan more poses or offer candidates that move every joint");
}

Status CheckNominalMatches(const RobotModel& calibrated, const RobotModel& nominal) {
  if (nominal.num_joints() != calibrated.num_joints() ||
      nominal.num_tools() < calibrated.num_tools()) {
    return Status::Error("the nominal model has " + std::to_string(nominal.num_joints()) +
                         " joints and " + std::to_string(nominal.num_tools()) +
                         " tools; the calibrated model " + std::to_string(calibrated.num_joints()) +
                         " and " + std::to_string(calibrated.num_tools()));
  }
  for (int j = 0; j < calibrated.num_joints(); ++j) {
    const JointType a = calibrated.joints[j].type, b = nominal.joints[j].type;
    if (a != b) {
      auto name = [](JointType t) { return t == JointType::kPrismatic ? "prismatic" : "revolute"; };
      return Status::Error("joint " + std::to_string(j + 1) + " is " + name(b) +
                           " in the nominal model but " + name(a) +
                           " in the calibrated one: the nominal model describes another robot");
    }
  }
  return Status::Ok();
}

Status CheckModelFinite(const RobotModel& model) {
  for (int j = 0; j < model.num_joints(); ++j) {
    const Joint& joint = model.joints[j];
    if (!Finite(joint.origin) || !joint.twist.allFinite() || std::isnan(joint.lower) ||
        std::isnan(joint.upper)) {
      return Status::Error("joint " + std::to_string(j + 1) +
                           " has a non-finite value: a model with NaN or infinity is not written");
    }
  }
  for (int t = 0; t < model.num_tools(); ++t) {
    if (!Finite(model.tools[t].origin)) {
      return Status::Error("tool " + std::to_string(t + 1) +
                           " has a non-finite value: a model with NaN or infinity is not written");
    }
  }
  if (!Finite(model.T_measurement_base) || !model.gravity.allFinite() ||
      !std::isfinite(model.payload.mass) || !model.payload.com.allFinite() ||
      !std::all_of(model.joint_errors.terms.begin(), model.joint_errors.terms.end(),
                   [](const JointTermEntry& t) { return FiniteValues(t.values); })) {
    return Status::Error(
        "the registration, gravity, payload or joint-error values hold a non-finite value: a "
        "model with NaN or infinity is not written");
  }
  for (const SE3d& T : model.joint_errors.regressor_origins) {
    if (!Finite(T)) {
      return Status::Error("a regressor origin has a non-finite value: a model with NaN or "
                           "infinity is not written");
    }
  }
  return Status::Ok();
}

Status SetFixedTools(const std::vector<std::string>& names, RobotModel* model) {
  for (const std::string& name : names) {
    if (!name.empty() && model->FindTool(name) >= 0) continue;
    std::string tools;
    for (const Tool& t : model->tools) tools += (tools.empty() ? "" : ", ") + t.name;
    return Status::Error(name.empty() ? "an empty tool name among the fixed tools"
                                      : "no tool named '" + name + "' in the model (its tools: " +
                                            tools + ")");
  }
  for (const std::string& name : names) model->tools[model->FindTool(name)].fixed = true;
  return Status::Ok();
}

Status ParseNameList(const std::string& text, std::vector<std::string>* names) {
  names->clear();
  if (text.empty()) return Status::Ok();
  size_t begin = 0;
  while (true) {
    const size_t comma = text.find(',', begin);
    std::string item = text.substr(begin, comma == std::string::npos ? std::string::npos
                                                                      : comma - begin);
    const size_t first = item.find_first_not_of(" \t");
    const size_t last = item.find_last_not_of(" \t");
    item = first == std::string::npos ? "" : item.substr(first, last - first + 1);
    if (item.empty()) {
      names->clear();
      return Status::Error("an empty name in the list '" + text + "'");
    }
    names->push_back(std::move(item));
    if (comma == std::string::npos) break;
    begin = comma + 1;
  }
  return Status::Ok();
}

}  // namespace lpoe
