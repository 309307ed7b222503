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

#include <algorithm>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "lpoe/contact_calibration.h"
#include "lpoe/measurements/contact_measurements.h"
#include "lpoe/model/robot_model.h"
#include "test_util.h"

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

// The references' solver: Levenberg-Marquardt damping on the column-scaled normal equations with
// a pseudo-inverse for the null directions (DampedPseudoInverseStep), each step halved while it
// raises the cost and the damping raised after a step that found none. rows(state, &r, &J)
// evaluates a state; step(state, x) returns it moved by x.
template <typename State, typename Rows, typename Step>
State DampedLeastSquares(State state, const Rows& rows, const Step& step) {
  Eigen::VectorXd r;
  Eigen::MatrixXd J;
  rows(state, &r, &J);
  double mu = 1e-6;
  for (int it = 0; it < 100; ++it) {
    Eigen::VectorXd x = DampedPseudoInverseStep(J, r, mu);
    bool lowered = false;
    for (int halving = 0; halving < 30 && !lowered; ++halving, x *= 0.5) {
      State next = step(state, x);
      Eigen::VectorXd r2;
      Eigen::MatrixXd J2;
      rows(next, &r2, &J2);
      if (r2.squaredNorm() <= r.squaredNorm()) {
        mu = std::max(mu / 10, 1e-12);
        state = std::move(next);
        r = std::move(r2);
        J = std::move(J2);
        lowered = true;
      }
    }
    if (!lowered) mu *= 100;
    if (lowered && x.norm() < 1e-11) break;
    if (mu > 1e6) break;
  }
  return state;
}

// Moves every frame of `model` by its six right perturbations in x (frames in the
// parameterization's order) and the pivots by the next 3 each; returns the offset after them.
int StepFramesAndPivots(const Eigen::VectorXd& x, RobotModel* model,
                        std::vector<Eigen::Vector3d>* pivots);

}  // namespace testing
}  // namespace lpoe

#endif  // LPOE_TESTS_MEASUREMENTS_CONTACT_REFERENCE_H_
