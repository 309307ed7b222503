// The linear and the Ceres solver on the same problem (lpoe_compare, docs/method.md): both through
// the calibration pipeline (same registration, same start, same data), then their calibrated models
// compared on held-out rows.
#ifndef LPOE_SOLVER_COMPARISON_H_
#define LPOE_SOLVER_COMPARISON_H_

#include <string>

#include "lpoe/measurements/measurements.h"
#include "lpoe/pipeline.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/model/statistics.h"

namespace lpoe {

struct SolverComparison {
  PipelineResult linear;
  PipelineResult ceres;
  // Filled only when both converged (`compared`): on the rows compared (the verification rows, or
  // the identification rows without them).
  bool compared = false;
  ErrorStatistics linear_errors, ceres_errors;
  double position_difference = 0;   // largest distance between the predicted positions, mm
  // Largest difference in the identifiable directions at the linear run's start (rad or mm; with
  // the full parameterization the frames also differ along gauge directions no data see).
  double parameter_difference = 0;
  std::string worst_parameter;       // its name; empty when no parameter is compared
};

// Runs the pipeline with `linear_options` and `ceres_options` (their `solver` fields as given) and,
// when both converged, compares the models on `verification` (or on `identification` when
// `verification` is empty).
SolverComparison CompareSolvers(const RobotModel& nominal, const MeasurementSet& identification,
                                const MeasurementSet& verification,
                                const PipelineOptions& linear_options,
                                const PipelineOptions& ceres_options);

}  // namespace lpoe

#endif  // LPOE_SOLVER_COMPARISON_H_
