// CompareSolvers (lpoe/solver_comparison.h), the library call behind lpoe_compare, and
// CalibratedModel / CalibratedModelYaml (lpoe/recalibration.h), the model lpoe_calibrate writes.
#include <string>

#include <gtest/gtest.h>

#include "lpoe/io/io.h"
#include "lpoe/recalibration.h"
#include "lpoe/model/simulation.h"
#include "lpoe/solver_comparison.h"
#include "lpoe/model/statistics.h"

namespace lpoe {
namespace {
namespace solver_comparison_test {

// The paper's robot with its Table 2 errors, measured at 100 configurations with 0.02 mm of
// noise: the first 70 rows identify, the last 30 are held out.
void Section4Like(RobotModel* nominal, MeasurementSet* identification,
                  MeasurementSet* verification) {
  *nominal = MakeCobot6();
  const KinematicErrors errors = PaperTable2Errors();
  SimulationOptions o;
  o.count = 100;
  o.noise_sigma = 0.02;
  o.seed = 5;
  const MeasurementSet all = SimulateMeasurements(ApplyErrors(*nominal, errors),
                                                  errors.joint_zero, o);
  all.SplitAt(70, identification, verification);
}

PipelineOptions TightOptions(SolverKind solver) {
  PipelineOptions o;
  o.solver = solver;
  o.linear.convergence.sd_fraction = 0;
  o.ceres.convergence.sd_fraction = 0;
  return o;
}

TEST(SolverComparison, BothSolversReachTheSameMinimumOnHeldOutRows) {
  RobotModel nominal;
  MeasurementSet identification, verification;
  Section4Like(&nominal, &identification, &verification);
  const SolverComparison c =
      CompareSolvers(nominal, identification, verification, TightOptions(SolverKind::kLinear),
                     TightOptions(SolverKind::kCeres));
  ASSERT_TRUE(c.compared) << c.linear.result.message << " / " << c.ceres.result.message;
  // The same least-squares problem: predictions agree far below the noise.
  EXPECT_LT(c.position_difference, 1e-6);
  EXPECT_LT(c.parameter_difference, 1e-3);
  EXPECT_FALSE(c.worst_parameter.empty());
  // The errors are those of each model on the held-out rows, near the simulated noise.
  const ErrorStatistics lin = PositionErrorStatistics(c.linear.result.model, verification);
  EXPECT_DOUBLE_EQ(c.linear_errors.norm.rms, lin.norm.rms);
  EXPECT_NEAR(c.linear_errors.norm.rms, c.ceres_errors.norm.rms, 1e-6);
  EXPECT_LT(c.linear_errors.norm.rms, 0.1);
  // Without held-out rows, the identification rows are compared.
  const SolverComparison on_identification =
      CompareSolvers(nominal, identification, MeasurementSet(nominal.num_joints()),
                     TightOptions(SolverKind::kLinear), TightOptions(SolverKind::kCeres));
  ASSERT_TRUE(on_identification.compared);
  EXPECT_DOUBLE_EQ(
      on_identification.ceres_errors.norm.max_abs,
      PositionErrorStatistics(on_identification.ceres.result.model, identification).norm.max_abs);
}

TEST(SolverComparison, NothingComparedWhenASolverStopsEarly) {
  RobotModel nominal;
  MeasurementSet identification, verification;
  Section4Like(&nominal, &identification, &verification);
  PipelineOptions linear = TightOptions(SolverKind::kLinear);
  linear.linear.max_iterations = 1;  // far from converged after one step from the nominal model
  const SolverComparison c = CompareSolvers(nominal, identification, verification, linear,
                                            TightOptions(SolverKind::kCeres));
  EXPECT_FALSE(c.linear.result.converged());
  EXPECT_FALSE(c.compared);
  EXPECT_EQ(c.position_difference, 0);
}

TEST(CalibratedModelYaml, CarriesTheCovarianceBlockWhenTheResultHasOne) {
  RobotModel nominal;
  MeasurementSet identification, verification;
  Section4Like(&nominal, &identification, &verification);
  const PipelineResult run =
      RunCalibrationPipeline(nominal, identification, verification, PipelineOptions());
  ASSERT_TRUE(run.result.converged()) << run.result.message;
  const RobotModel calibrated = CalibratedModel(run);
  const std::string yaml = CalibratedModelYaml(calibrated, run.result);
  ASSERT_EQ(yaml.rfind(RobotModelToYaml(calibrated), 0), 0u);  // the model, then its block
  EXPECT_NE(yaml.find("covariance:"), std::string::npos);
  // Without a covariance (none estimated) the model alone.
  CalibrationResult bare = run.result;
  bare.covariance.resize(0, 0);
  EXPECT_EQ(CalibratedModelYaml(calibrated, bare), RobotModelToYaml(calibrated));
}

}  // namespace solver_comparison_test
}  // namespace
}  // namespace lpoe
