// Calibrates simulated section-4 data through the installed API and checks the result: the two
// solvers, and the problem builder with a prior of the caller's own (another estimator's use).
#include <cmath>
#include <cstdio>

#include <ceres/ceres.h>

#include "lpoe/ceres_solver.h"
#include "lpoe/linear_solver.h"
#include "lpoe/problem_builder.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/model/simulation.h"
#include "lpoe/model/statistics.h"

namespace {

// The caller's prior: the first joint frame's translation stays at its nominal value.
struct HoldTranslation {
  explicit HoldTranslation(const double* nominal) : t{nominal[4], nominal[5], nominal[6]} {}
  template <typename T>
  bool operator()(const T* frame, T* residual) const {
    for (int k = 0; k < 3; ++k) residual[k] = (frame[4 + k] - T(t[k])) / T(1e-6);
    return true;
  }
  double t[3];
};

}  // namespace

int main() {
  const lpoe::RobotModel nominal = lpoe::MakeCobot6();
  const lpoe::KinematicErrors errors = lpoe::PaperTable2Errors();
  lpoe::SimulationOptions options;
  options.count = 70;
  const lpoe::MeasurementSet data = lpoe::SimulateMeasurements(
      lpoe::ApplyErrors(nominal, errors), errors.joint_zero, options);
  const lpoe::CalibrationResult linear = lpoe::CalibrateLinear(nominal, data);
  const lpoe::CalibrationResult ceres = lpoe::CalibrateCeres(nominal, data, {});
  const double e1 = lpoe::PositionErrorStatistics(linear.model, data).norm.max_abs;
  const double e2 = lpoe::PositionErrorStatistics(ceres.model, data).norm.max_abs;

  lpoe::CalibrationProblem builder(nominal, data, lpoe::CalibrationProblemOptions());
  ceres::Problem problem;
  builder.AddTo(&problem);
  const double start[7] = {0, 0, 0, 1, nominal.joints[0].origin.t.x(),
                           nominal.joints[0].origin.t.y(), nominal.joints[0].origin.t.z()};
  problem.AddResidualBlock(new ceres::AutoDiffCostFunction<HoldTranslation, 3, 7>(
                               new HoldTranslation(start)),
                           nullptr, builder.frame_block(0));
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  const lpoe::RobotModel held = builder.Model();
  const double moved = (held.joints[0].origin.t - nominal.joints[0].origin.t).norm();
  // Joint 1's translation is one of the identifiable directions: holding it costs some fit, but
  // the model still explains the data far better than the nominal one.
  const double e3 = lpoe::PositionErrorStatistics(held, data).norm.max_abs;
  const double e0 = lpoe::PositionErrorStatistics(nominal, data).norm.max_abs;
  std::printf("linear %s max %.3g mm, ceres %s max %.3g mm, builder with prior max %.3g mm "
              "(joint1 moved %.2g mm; nominal %.3g mm)\n",
              lpoe::TerminationName(linear.termination), e1,
              lpoe::TerminationName(ceres.termination), e2, e3, moved, e0);
  return linear.converged() && ceres.converged() && e1 < 1e-6 && e2 < 1e-6 && moved < 1e-4 &&
                 e3 < 0.5 * e0
             ? 0
             : 1;
}
