// The recalibration tests' cell (recalibration_test, fleet_prior_test, plan_prior_test): a UR5-like
// arm with three SMRs off the flange axis, measured by a tracker 3 m away.
#ifndef LPOE_TESTS_THREE_SMR_CELL_H_
#define LPOE_TESTS_THREE_SMR_CELL_H_

#include <cmath>
#include <cstdint>
#include <random>
#include <string>

#include "lpoe/model/robot_model.h"
#include "lpoe/kinematics/se3.h"
#include "lpoe/model/simulation.h"

namespace lpoe {
namespace testing {

// MakeUr5Like with three SMRs 90 mm out from the flange, 55 to 60 mm off its axis.
inline RobotModel ThreeSmrUr5() {
  RobotModel m = MakeUr5Like();
  m.tools.resize(3);
  const Eigen::Vector3d points[3] = {{60, 0, 90}, {-30, 55, 90}, {-30, -55, 90}};
  for (int t = 0; t < 3; ++t) {
    m.tools[t].name = "smr" + std::to_string(t + 1);
    m.tools[t].origin = SE3d(Eigen::Matrix3d::Identity(), points[t]);
  }
  return m;
}

// A tracker 3 m from the base in a random direction, within 200 mm of its height, turned by a
// random angle about the vertical and tilted by up to `tilt` rad about x and y.
inline SE3d TrackerThreeMetresAway(uint64_t seed, double tilt) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  Vector6d xi;
  xi << tilt * u(rng), tilt * u(rng), kPi * u(rng), 0, 0, 0;
  SE3d T = ExpSE3(xi);
  const double a = kPi * u(rng);
  T.t = Eigen::Vector3d(3000 * std::cos(a), 3000 * std::sin(a), 200 * u(rng));
  return T;
}

}  // namespace testing
}  // namespace lpoe

#endif  // LPOE_TESTS_THREE_SMR_CELL_H_
