// The plain least-squares reference of a ballbar and touch-probe calibration, used by the contact
// tests: every frame's six right perturbations, the pivots and the planes (n unnormalized, d),
// Gauss-Newton with a pseudo-inverse (no decisions: the null directions are simply not moved).
// Without a scale row it fails on planes alone (it shrinks the robot:
// ContactCalibration.ReferenceWithoutScaleShrinksOnPlanes).
//
// It lives in the test-support library (tests/CMakeLists.txt, lpoe_test_support), compiled like the
// library: in the sanitizer build the test files themselves are compiled without optimization, and
// this reference does the heavy numeric work of its tests.
#ifndef LPOE_TESTS_MEASUREMENTS_CONTACT_REFERENCE_H_
#define LPOE_TESTS_MEASUREMENTS_CONTACT_REFERENCE_H_

#include <vector>

#include <Eigen/Core>

#include "lpoe/contact_calibration.h"
#include "lpoe/measurements/contact_measurements.h"
#include "lpoe/model/robot_model.h"

namespace lpoe {
namespace testing {

struct Reference {
  RobotModel model;
  std::vector<Eigen::Vector3d> pivots;
  std::vector<Eigen::Vector4d> planes;
};

// The reference's rows at `ref`: residuals r (one per row, in sigmas) and their Jacobian J.
void ReferenceRows(const Reference& ref, const ContactMeasurementSet& data, Eigen::VectorXd* r,
                   Eigen::MatrixXd* J);

// The reference solved from `nominal` and the features `start`; with `hold_scale`, one more row
// holds the size of the predicted points. J_start receives the rows' Jacobian at the start.
Reference PlainLeastSquares(const RobotModel& nominal, const ContactFeatures& start,
                            const ContactMeasurementSet& data, bool hold_scale,
                            Eigen::MatrixXd* J_start);

}  // namespace testing
}  // namespace lpoe

#endif  // LPOE_TESTS_MEASUREMENTS_CONTACT_REFERENCE_H_
