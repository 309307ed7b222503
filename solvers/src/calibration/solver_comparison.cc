// The linear and the Ceres solver on the same problem (lpoe/solver_comparison.h).
#include "lpoe/solver_comparison.h"

#include <algorithm>

#include <Eigen/Core>

#include "lpoe/kinematics/kinematics.h"
#include "lpoe/measurements/measurement_kind_dispatch.h"
#include "lpoe/model/parameterization.h"

namespace lpoe {
namespace {

// The largest distance between the two models' predicted tool positions over `data`'s rows.
double MaxPredictionDifference(const RobotModel& a, const RobotModel& b,
                               const MeasurementSet& data) {
  double worst = 0;
  for (int r = 0; r < data.size(); ++r) {
    worst = std::max(worst, (ToolPosition(a, data.q(r), data.target(r)) -
                             ToolPosition(b, data.q(r), data.target(r)))
                                .norm());
  }
  return worst;
}

}  // namespace

SolverComparison CompareSolvers(const RobotModel& nominal, const MeasurementSet& identification,
                                const MeasurementSet& verification,
                                const PipelineOptions& linear_options,
                                const PipelineOptions& ceres_options) {
  SolverComparison c;
  c.linear = RunCalibrationPipeline(nominal, identification, verification, linear_options);
  c.ceres = RunCalibrationPipeline(nominal, identification, verification, ceres_options);
  const CalibrationResult& lin = c.linear.result;
  const CalibrationResult& cer = c.ceres.result;
  if (!lin.converged() || !cer.converged()) return c;
  c.compared = true;
  const MeasurementSet& check = verification.empty() ? identification : verification;
  c.linear_errors = PositionErrorStatistics(lin.model, check);
  c.ceres_errors = PositionErrorStatistics(cer.model, check);
  c.position_difference = MaxPredictionDifference(lin.model, cer.model, check);
  const Parameterization pi = MakeParameterization(
      c.linear.start, ParameterizationKind::kIdentifiable,
      TrackerDataKind(TrackerKindId(linear_options.use_orientation)));
  const Eigen::VectorXd dx = ParameterDifference(pi, lin.model, cer.model);
  Eigen::Index worst = 0;
  c.parameter_difference = dx.size() ? dx.cwiseAbs().maxCoeff(&worst) : 0.0;
  if (dx.size()) c.worst_parameter = pi.parameters[worst].name;
  return c;
}

}  // namespace lpoe
