// Whole calibrations and their parts on simulated cobot6 position data (paper section 4: Table 2
// errors, 0.03 mm noise), by number of poses: one linear-solver iteration, the linear solver to
// convergence (70 to 10^6 poses), the Ceres solver (70 to 10^5), registration and CSV parsing (the
// other costs of lpoe_calibrate). The data of each size is generated once and shared.
#include <string>

#include <benchmark/benchmark.h>
#include <glog/logging.h>

#include "benchmark_data.h"
#include "lpoe/ceres_solver.h"
#include "lpoe/io/io.h"
#include "lpoe/linear_solver.h"
#include "lpoe/registration.h"

namespace lpoe {
namespace {

// Builds the model once per run and fetches (generating on first use) the data of state.range(0)
// rows before the timed loop.
class Calibration : public benchmark::Fixture {
 public:
  void SetUp(const benchmark::State& state) override {
    nominal_ = MakeCobot6();
    data_ = &bench::Cobot6Data(static_cast<int>(state.range(0)));
  }

 protected:
  RobotModel nominal_;
  const MeasurementSet* data_ = nullptr;
};

void SetRows(benchmark::State& state, int rows) {
  state.SetItemsProcessed(state.iterations() * rows);
  state.counters["poses"] = rows;
}

// One Gauss-Newton iteration: linearize at the nominal model (normal equations over all poses),
// identifiability check, step, and the linearization of the updated model that accepts it.
BENCHMARK_DEFINE_F(Calibration, BM_LinearIteration)(benchmark::State& state) {
  LinearSolverOptions options;
  options.max_iterations = 1;
  options.compute_covariance = false;
  for (auto _ : state) {
    const CalibrationResult r = CalibrateLinear(nominal_, *data_, options);
    CHECK(r.termination == Termination::kMaxIterations) << r.message;
    benchmark::DoNotOptimize(r.model.joints[0].origin.t.data());
  }
  SetRows(state, data_->size());
}
BENCHMARK_REGISTER_F(Calibration, BM_LinearIteration)
    ->Arg(70)->Arg(1000)->Arg(10000)->Arg(100000)->Arg(1000000)
    ->Unit(benchmark::kMicrosecond);

// The linear solver to convergence, identifiable parameterization, with the covariance.
BENCHMARK_DEFINE_F(Calibration, BM_CalibrateLinear)(benchmark::State& state) {
  int iterations = 0;
  for (auto _ : state) {
    const CalibrationResult r = CalibrateLinear(nominal_, *data_);
    CHECK(r.converged()) << r.message;
    iterations = r.iterations;
    benchmark::DoNotOptimize(r.model.joints[0].origin.t.data());
  }
  SetRows(state, data_->size());
  state.counters["iterations"] = iterations;
}
BENCHMARK_REGISTER_F(Calibration, BM_CalibrateLinear)
    ->Arg(70)->Arg(1000)->Arg(10000)->Arg(100000)->Arg(1000000)
    ->Unit(benchmark::kMicrosecond);

// The paper's 42-parameter pseudo-inverse mode (stacks J: the fidelity mode, not for large N).
BENCHMARK_DEFINE_F(Calibration, BM_CalibrateLinearFull)(benchmark::State& state) {
  LinearSolverOptions options;
  options.parameterization = ParameterizationKind::kFull;
  for (auto _ : state) {
    const CalibrationResult r = CalibrateLinear(nominal_, *data_, options);
    CHECK(r.converged()) << r.message;
    benchmark::DoNotOptimize(r.model.joints[0].origin.t.data());
  }
  SetRows(state, data_->size());
}
BENCHMARK_REGISTER_F(Calibration, BM_CalibrateLinearFull)
    ->Arg(70)->Arg(10000)->Unit(benchmark::kMicrosecond);

// Levenberg-Marquardt with autodiff position residuals, covariance as lpoe_calibrate computes it.
BENCHMARK_DEFINE_F(Calibration, BM_CalibrateCeres)(benchmark::State& state) {
  CeresSolverOptions options;
  options.a_posteriori_covariance = true;
  int iterations = 0;
  for (auto _ : state) {
    const CalibrationResult r = CalibrateCeres(nominal_, *data_, options);
    CHECK(r.converged()) << r.message;
    iterations = r.iterations;
    benchmark::DoNotOptimize(r.model.joints[0].origin.t.data());
  }
  SetRows(state, data_->size());
  state.counters["iterations"] = iterations;
}
BENCHMARK_REGISTER_F(Calibration, BM_CalibrateCeres)
    ->Arg(70)->Arg(1000)->Arg(10000)->Arg(100000)
    ->Unit(benchmark::kMicrosecond);

// The same on one thread (Ceres's default here is every hardware thread): small problems pay
// for the thread pool.
BENCHMARK_DEFINE_F(Calibration, BM_CalibrateCeresOneThread)(benchmark::State& state) {
  CeresSolverOptions options;
  options.a_posteriori_covariance = true;
  options.num_threads = 1;
  for (auto _ : state) {
    const CalibrationResult r = CalibrateCeres(nominal_, *data_, options);
    CHECK(r.converged()) << r.message;
    benchmark::DoNotOptimize(r.model.joints[0].origin.t.data());
  }
  SetRows(state, data_->size());
}
BENCHMARK_REGISTER_F(Calibration, BM_CalibrateCeresOneThread)
    ->Arg(70)->Arg(1000)->Unit(benchmark::kMicrosecond);

// lpoe_calibrate's registration (rigid fit, then base and tool frames) on data in the base frame.
BENCHMARK_DEFINE_F(Calibration, BM_RegisterToMeasurements)(benchmark::State& state) {
  for (auto _ : state) {
    RobotModel registered;
    RegistrationReport report;
    CHECK(RegisterToMeasurements(nominal_, *data_, &registered, &report).ok());
    benchmark::DoNotOptimize(registered.joints[0].origin.t.data());
  }
  SetRows(state, data_->size());
}
BENCHMARK_REGISTER_F(Calibration, BM_RegisterToMeasurements)
    ->Arg(70)->Arg(70000)->Arg(1000000)->Unit(benchmark::kMicrosecond);

// CSV parsing of the same rows (text prepared once, as lpoe_simulate writes it).
BENCHMARK_DEFINE_F(Calibration, BM_ParseMeasurementsCsv)(benchmark::State& state) {
  const std::string text = MeasurementsToCsv(nominal_, *data_);
  for (auto _ : state) {
    MeasurementSet parsed;
    CHECK(ParseMeasurementsCsv(text, "bench.csv", nominal_, AngleUnit::kRadians, &parsed).ok());
    benchmark::DoNotOptimize(parsed.q(0));
  }
  SetRows(state, data_->size());
  state.SetBytesProcessed(state.iterations() * static_cast<int64_t>(text.size()));
}
BENCHMARK_REGISTER_F(Calibration, BM_ParseMeasurementsCsv)
    ->Arg(70000)->Arg(1000000)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace lpoe

BENCHMARK_MAIN();
