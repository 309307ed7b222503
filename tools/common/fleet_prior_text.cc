#include "common/fleet_prior_text.h"

#include "lpoe/io/io.h"
#include "lpoe/recalibration.h"

namespace lpoe {
namespace tools {

std::string FleetPriorRefusal(const Status& refused, const std::vector<std::string>& names) {
  // FleetPrior numbers the models from 1 in the order given.
  std::string message = refused.message();
  for (size_t k = names.size(); k-- > 1;) {
    const std::string key = "model " + std::to_string(k + 1);
    const size_t at = message.find(key);
    if (at != std::string::npos) {
      message.replace(at, key.size(), names[k]);
      break;
    }
  }
  return message + " (first model: " + (names.empty() ? std::string("none") : names[0]) + ")";
}

std::vector<std::string> FleetPriorWarnings(int robots, const RobotModel& mean,
                                            const ModelCovariance& covariance) {
  std::vector<std::string> out;
  if (robots < kRobotsForFullCovariance) {
    out.push_back(std::to_string(robots) + " robots: a frame's 6x6 sample covariance has rank at "
                  "most " + std::to_string(robots - 1) + " and needs " +
                  std::to_string(kRobotsForFullCovariance) +
                  " robots for full rank; the directions the fleet does not span get the nominal "
                  "tolerances (--prior_translation, ...) when the file is used as --prior");
  }
  // The covariance of a new robot (the predictive one) needs p + 3 robots for a block of p
  // estimated directions (lpoe/recalibration.h).
  std::string short_blocks;
  const int n = mean.num_joints();
  for (int f = 1; f < static_cast<int>(covariance.frames.size()) && f < mean.num_frames(); ++f) {
    if (covariance.frames[f].rows() != 6) continue;
    const int p = EstimatedDimension(mean, f, covariance.frames[f]);
    if (robots < p + 3) {
      short_blocks += std::string(short_blocks.empty() ? "" : ", ") +
                      (f < n ? mean.joints[f].name : mean.tools[f - n].name) + " (" +
                      std::to_string(p) + " directions: " + std::to_string(p + 3) + ")";
    }
  }
  if (!short_blocks.empty()) {
    out.push_back(std::to_string(robots) + " robots: the covariance of a new robot's deviation "
                  "(the fleet's predictive covariance) needs p + 3 robots for p estimated "
                  "directions: " + short_blocks + "; these blocks are the sample covariance "
                  "times (N + 1) / N only and understate how a new robot varies");
  }
  for (size_t b = 0; b < covariance.terms.size(); ++b) {
    const int P = static_cast<int>(covariance.terms[b].rows());
    if (robots < P + 1) {
      out.push_back("joint term " + covariance.term_names[b] + ": " + std::to_string(P) +
                    " parameters need " + std::to_string(P + 1) +
                    " robots for a full covariance, got " + std::to_string(robots) +
                    "; the directions the fleet does not span get the default tolerance");
    }
  }
  return out;
}

std::string FleetPriorFileText(int robots, const RobotModel& mean,
                               const ModelCovariance& covariance) {
  std::string text = "# lpoe_prior: fleet prior of " + std::to_string(robots) +
                     " calibrated models (their mean; the covariance block: the spread of each "
                     "frame's parameters from robot to robot)\n";
  return text + RobotModelToYaml(mean) + ModelCovarianceYaml(mean, covariance);
}

std::string FleetPriorCountRefusal(int robots) {
  return "a fleet prior needs at least 2 calibrated models (got " + std::to_string(robots) +
         "); a frame's full 6x6 covariance needs " + std::to_string(kRobotsForFullCovariance);
}

Status MakeFleetPriorFile(const std::vector<RobotModel>& models,
                          const std::vector<std::string>& names, FleetPriorFile* out) {
  const int robots = static_cast<int>(models.size());
  if (robots < 2) return Status::Error(FleetPriorCountRefusal(robots));
  if (Status s = FleetPrior(models, &out->mean, &out->covariance); !s.ok()) {
    return Status::Error(FleetPriorRefusal(s, names));
  }
  out->warnings = FleetPriorWarnings(robots, out->mean, out->covariance);
  out->text = FleetPriorFileText(robots, out->mean, out->covariance);
  return Status::Ok();
}

}  // namespace tools
}  // namespace lpoe
