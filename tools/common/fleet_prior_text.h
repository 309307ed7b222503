// The fleet prior's messages and file text, shared by lpoe_prior and Python's lpoe.fleet_prior (one
// wording for both front ends; docs/recalibration.md).
#ifndef LPOE_TOOLS_FLEET_PRIOR_TEXT_H_
#define LPOE_TOOLS_FLEET_PRIOR_TEXT_H_

#include <string>
#include <vector>

#include "lpoe/model/model_covariance.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/status.h"

namespace lpoe {
namespace tools {

// FleetPrior's refusal with its "model k" replaced by names[k-1] (the file of that robot), and the
// first model named: "<message> (first model: <names[0]>)".
std::string FleetPriorRefusal(const Status& refused, const std::vector<std::string>& names);

// The warnings for a fleet of `robots` robots: a frame's sample covariance below
// kRobotsForFullCovariance robots (rank), a block of p estimated directions below p + 3 robots
// (its predictive covariance, lpoe/recalibration.h), a joint term of P values below P + 1.
std::vector<std::string> FleetPriorWarnings(int robots, const RobotModel& mean,
                                            const ModelCovariance& covariance);

// The file lpoe_prior writes: a comment line, the mean model and its covariance block.
std::string FleetPriorFileText(int robots, const RobotModel& mean,
                               const ModelCovariance& covariance);

// "a fleet prior needs at least 2 calibrated models (got N); a frame's full 6x6 covariance needs
// K" (each front end names its list first).
std::string FleetPriorCountRefusal(int robots);

// What lpoe_prior and lpoe.fleet_prior make of the models (named by `names`, files or "model k"):
// the mean and covariance (FleetPrior), its warnings and the file text. An error: fewer than 2
// models (FleetPriorCountRefusal), or FleetPrior's refusal (FleetPriorRefusal).
struct FleetPriorFile {
  RobotModel mean;
  ModelCovariance covariance;
  std::vector<std::string> warnings;
  std::string text;
};
Status MakeFleetPriorFile(const std::vector<RobotModel>& models,
                          const std::vector<std::string>& names, FleetPriorFile* out);

}  // namespace tools
}  // namespace lpoe

#endif  // LPOE_TOOLS_FLEET_PRIOR_TEXT_H_
