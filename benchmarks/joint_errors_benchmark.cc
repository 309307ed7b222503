// Issue 11: the cost of the joint-space error terms. The same 1000-pose calibration of cobot6 (random
// geometric errors, the simulator's small-arm compliance and harmonics, 0.01 mm noise) with the
// geometry alone and with compliance + harmonics, for both solvers; plus --joint_errors=auto (four
// candidate sets cross-validated on 5 folds, then the final calibration). The target is at most 2x
// the geometric time for the terms.
#include <numeric>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>

#include "lpoe/joint_errors.h"
#include "lpoe/pipeline.h"
#include "lpoe/simulation.h"

namespace lpoe {
namespace {

struct Data {
  RobotModel nominal = MakeCobot6();
  MeasurementSet data;
  explicit Data(int rows) {
    nominal.payload.mass = 1.0;
    nominal.payload.com = Eigen::Vector3d(0, 0, 50);
    const KinematicErrors errors = RandomErrors(nominal, 2e-3, 0.5, 1e-3, 2e-3, 11);
    RobotModel actual = ApplyErrors(nominal, errors);
    ApplyJointErrorPhysics(SmallArmJointErrors(nominal, SmallArmOptions()), true, true, &actual);
    SimulationOptions options;
    options.count = rows;
    options.noise_sigma = 0.01;
    options.seed = 7;
    data = SimulateMeasurements(actual, errors.joint_zero, options);
  }
};

const Data& Poses1000() {
  static const Data* data = new Data(1000);
  return *data;
}

// range(0): 0 linear, 1 Ceres; range(1): 0 geometry, 1 compliance + harmonics, 2 auto.
void BM_Calibrate(benchmark::State& state) {
  const Data& d = Poses1000();
  PipelineOptions o;
  o.solver = state.range(0) == 0 ? SolverKind::kLinear : SolverKind::kCeres;
  o.register_frames = false;
  if (state.range(1) == 1) o.joint_errors = {"compliance", "harmonics"};
  o.joint_errors_auto = state.range(1) == 2;
  for (auto _ : state) {
    const CalibrationResult r =
        o.joint_errors_auto
            ? RunCalibrationPipeline(d.nominal, d.data, MeasurementSet(6), o).result
            : SolveCalibration(d.nominal, d.data, o, "benchmark", nullptr, nullptr, nullptr);
    if (!r.converged()) state.SkipWithError(r.message.c_str());
    benchmark::DoNotOptimize(r.model.joints[0].origin.t.data());
  }
  state.counters["poses"] = d.data.size();
}
BENCHMARK(BM_Calibrate)
    ->ArgNames({"ceres", "terms"})
    ->Args({0, 0})
    ->Args({0, 1})
    ->Args({0, 2})
    ->Args({1, 0})
    ->Args({1, 1})
    ->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace lpoe

BENCHMARK_MAIN();
