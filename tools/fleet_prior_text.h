// The fleet prior's messages and file text, shared by lpoe_prior and Python's lpoe.fleet_prior (one
// wording for both front ends; docs/recalibration.md).
#ifndef LPOE_TOOLS_FLEET_PRIOR_TEXT_H_
#define LPOE_TOOLS_FLEET_PRIOR_TEXT_H_

#include <string>
#include <vector>

#include "lpoe/model_covariance.h"
#include "lpoe/robot_model.h"
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

}  // namespace tools
}  // namespace lpoe

#endif  // LPOE_TOOLS_FLEET_PRIOR_TEXT_H_
