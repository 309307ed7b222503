// Calibrates simulated section-4 data through the installed API and checks the result.
#include <cstdio>

#include "lpoe/ceres_solver.h"
#include "lpoe/linear_solver.h"
#include "lpoe/robot_model.h"
#include "lpoe/simulation.h"
#include "lpoe/statistics.h"

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
  std::printf("linear %s max %.3g mm, ceres %s max %.3g mm\n",
              lpoe::TerminationName(linear.termination), e1,
              lpoe::TerminationName(ceres.termination), e2);
  return linear.converged() && ceres.converged() && e1 < 1e-6 && e2 < 1e-6 ? 0 : 1;
}
