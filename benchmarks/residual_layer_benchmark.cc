// The learned residual layer (docs/residual_layer.md): a calibration of 10^5 rows with the layer
// (the pipeline end to end: registration, solve, analysis, the layer's fit) and the prediction of
// 10^6 points with a layer of 256 inducing inputs (PredictPositions, all hardware threads).
#include <cmath>
#include <memory>
#include <random>
#include <vector>

#include <benchmark/benchmark.h>

#include "lpoe/terms/joint_errors.h"
#include "lpoe/pipeline.h"
#include "lpoe/model/residual_layer.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/model/simulation.h"

namespace lpoe {
namespace {

// Cobot6 with random geometric errors, noise 0.015 mm per axis and a smooth joint-dependent
// deflection no registry term models (0.05 mm).
struct Data {
  RobotModel nominal = MakeCobot6();
  MeasurementSet rows;
  explicit Data(int count) : rows(6) {
    const KinematicErrors errors = RandomErrors(nominal, 2e-3, 0.5, 1e-3, 2e-3, 3);
    const RobotModel actual = ApplyErrors(nominal, errors);
    SimulationOptions o;
    o.count = count;
    o.noise_sigma = 0.015;
    o.lower.assign(6, -1.6);
    o.upper.assign(6, 1.6);
    rows = SimulateMeasurements(actual, errors.joint_zero, o);
    for (int r = 0; r < rows.size(); ++r) {
      const double* q = rows.q(r);
      const double a = 0.05 * std::sin(q[1] + q[2]) * std::cos(q[0]);
      rows.mutable_position(r) += Eigen::Vector3d(a, -0.6 * a, 0.03 * std::cos(q[1]));
    }
  }
};

void BM_CalibrateWithLayer(benchmark::State& state) {
  const Data data(static_cast<int>(state.range(0)));
  PipelineOptions o;
  o.residual_model = ResidualModelKind::kGp;
  for (auto _ : state) {
    const PipelineResult r = RunCalibrationPipeline(data.nominal, data.rows, MeasurementSet(), o);
    benchmark::DoNotOptimize(r.residual_layer.fitted);
    state.counters["rms_mm"] = r.identification_after.norm.rms;
    state.counters["rms_with_layer_mm"] = r.residual_layer.identification_with_layer.norm.rms;
  }
}
BENCHMARK(BM_CalibrateWithLayer)->Arg(100000)->Unit(benchmark::kSecond)->Iterations(1);

void BM_PredictWithLayer(benchmark::State& state) {
  const Data fit(20000);
  PipelineOptions o;
  o.residual_model = ResidualModelKind::kGp;
  const PipelineResult r = RunCalibrationPipeline(fit.nominal, fit.rows, MeasurementSet(), o);
  const RobotModel& model = r.result.model;
  const int count = static_cast<int>(state.range(0));
  std::vector<double> q(static_cast<size_t>(count) * 6);
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> u(-1.6, 1.6);
  for (double& v : q) v = u(rng);
  std::vector<Eigen::Vector3d> out;
  for (auto _ : state) {
    if (!PredictPositions(model, q, {}, 0, &out).ok()) state.SkipWithError("prediction failed");
    benchmark::DoNotOptimize(out.data());
  }
  state.counters["inducing"] = model.residual_layer ? model.residual_layer->num_inducing() : 0;
  state.SetItemsProcessed(state.iterations() * count);
}
BENCHMARK(BM_PredictWithLayer)->Arg(1000000)->Unit(benchmark::kSecond)->Iterations(3);

// One thread: the layer's mean alone, per point (256 inducing inputs, 6 joints).
void BM_LayerMean(benchmark::State& state) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-1.6, 1.6);
  const int rows = 2000;
  std::vector<double> q(rows * 6);
  std::vector<int> tools(rows, 0);
  std::vector<Eigen::Vector3d> e(rows);
  for (int r = 0; r < rows; ++r) {
    for (int j = 0; j < 6; ++j) q[6 * r + j] = u(rng);
    e[r] = Eigen::Vector3d(0.05 * std::sin(q[6 * r + 1] + q[6 * r + 2]), 0.01 * u(rng), 0.0);
  }
  ResidualLayer layer;
  if (!FitResidualLayer(q, tools, e, 6, 1, ResidualLayerOptions(), &layer).ok()) {
    state.SkipWithError("fit failed");
    return;
  }
  int r = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(layer.Mean(&q[6 * r], 0));
    r = (r + 1) % rows;
  }
  state.counters["inducing"] = layer.num_inducing();
}
BENCHMARK(BM_LayerMean);

}  // namespace
}  // namespace lpoe

BENCHMARK_MAIN();
