// The contact tests' arm (contact_measurements_test, measurement_kind_dispatch_test,
// contact_planning_test): cobot6 and its actual robot with the errors, and its ballbar and
// probe rows as the simulator draws them. Header only.
#ifndef LPOE_TESTS_CONTACT_ARM_H_
#define LPOE_TESTS_CONTACT_ARM_H_

#include <cstdint>

#include <gtest/gtest.h>

#include "lpoe/contact_calibration.h"
#include "lpoe/measurements/contact_measurements.h"
#include "lpoe/model/parameterization.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/model/simulation.h"

namespace lpoe {
namespace testing {

struct ContactArm {
  RobotModel nominal;  // cobot6
  RobotModel truth;    // the actual robot with its joint zeros folded in
};

// Frame errors of about 1 mm and 3 mrad, joint zeros 0.01 rad, drawn with `seed`.
inline ContactArm MakeContactArm(uint64_t seed) {
  ContactArm a;
  a.nominal = MakeCobot6();
  const KinematicErrors e = RandomErrors(a.nominal, 0.003, 1.0, 0.0, 0.01, seed);
  a.truth = FoldJointZeros(ApplyErrors(a.nominal, e), e.joint_zero);
  return a;
}

// `count` ballbar rows of a 150 mm bar around `num_pivots` pivots, noise 0.002 mm.
inline ContactMeasurementSet BallbarRows(const RobotModel& truth, int count, int num_pivots,
                                         uint64_t seed) {
  BallbarSimulationOptions o;
  o.count = count;
  o.bar_length = 150;
  o.noise = 0.002;
  o.num_pivots = num_pivots;
  o.seed = seed;
  ContactMeasurementSet out;
  EXPECT_TRUE(SimulateBallbar(truth, o, &out, nullptr).ok());
  return out;
}

// `count` probe contacts of a 3 mm tip on the cube's faces, noise 0.003 mm.
inline ContactMeasurementSet CubeRows(const RobotModel& truth, int count, uint64_t seed) {
  PlaneSimulationOptions o;
  o.count = count;
  o.probe_radius = 3;
  o.noise = 0.003;
  o.seed = seed;
  ContactMeasurementSet out;
  EXPECT_TRUE(SimulatePlaneContacts(truth, o, &out, nullptr).ok());
  return out;
}

// The model and features moved by `step` along column c of the contact parameterization (the
// solvers' update: ApplyUpdate on the robot's columns, ApplyFeatureStep on the features'), for
// central differences.
struct MovedContactState {
  RobotModel model;
  ContactFeatures features;
};
inline MovedContactState MoveAlongContactColumn(const RobotModel& model, const ContactFeatures& f,
                                                const ContactParameterization& p, int c,
                                                double step) {
  Eigen::VectorXd x = Eigen::VectorXd::Zero(p.num_parameters);
  x(c) = step;
  MovedContactState s{model, f};
  ApplyUpdate(p.frames, x.head(p.frames.num_parameters), &s.model);
  ApplyFeatureStep(p, x, &s.features);
  return s;
}

}  // namespace testing
}  // namespace lpoe

#endif  // LPOE_TESTS_CONTACT_ARM_H_
