// The "loaded cobot6" data shared by the joint-space tests and
// benchmarks/joint_errors_benchmark.cc: cobot6 carrying 1 kg 50 mm along the flange's z, random
// geometric errors (seed 11), the simulator's small-arm compliance and harmonics applied to the
// actual robot. Header only, so that a test or benchmark includes it without a library of its own.
#ifndef LPOE_TESTS_LOADED_COBOT6_H_
#define LPOE_TESTS_LOADED_COBOT6_H_

#include <cstdint>

#include <Eigen/Core>

#include "lpoe/measurements/measurements.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/model/simulation.h"

namespace lpoe {
namespace testing {

struct LoadedCobot6 {
  RobotModel nominal;    // cobot6 with the payload: what a calibration starts from
  MeasurementSet data;   // simulated on the actual robot
};

// `count` poses of the actual robot with `noise_sigma` mm of measurement noise, drawn with `seed`.
inline LoadedCobot6 MakeLoadedCobot6(int count, double noise_sigma, uint64_t seed) {
  LoadedCobot6 d;
  d.nominal = MakeCobot6();
  d.nominal.payload.mass = 1.0;
  d.nominal.payload.com = Eigen::Vector3d(0, 0, 50);
  const KinematicErrors errors = RandomErrors(d.nominal, 2e-3, 0.5, 1e-3, 2e-3, 11);
  RobotModel actual = ApplyErrors(d.nominal, errors);
  ApplyJointErrorPhysics(SmallArmJointErrors(d.nominal, SmallArmOptions()), {"compliance", "harmonics"}, &actual);
  SimulationOptions options;
  options.count = count;
  options.noise_sigma = noise_sigma;
  options.seed = seed;
  d.data = SimulateMeasurements(actual, errors.joint_zero, options);
  return d;
}

}  // namespace testing
}  // namespace lpoe

#endif  // LPOE_TESTS_LOADED_COBOT6_H_
