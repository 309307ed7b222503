// Issue 11: the cost of the joint-space error terms. The same 1000-pose calibration of cobot6 (random
// geometric errors, the simulator's small-arm compliance and harmonics, 0.01 mm noise) with the
// geometry alone and with compliance + harmonics, for both solvers; plus --joint_errors=auto (four
// candidate sets cross-validated on 5 folds, then the final calibration). The target is at most 2x
// the geometric time for the terms.
#include <numeric>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>

#include "identifiability/identifiability.h"
#include "loaded_cobot6.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/pipeline.h"
#include "lpoe/model/simulation.h"
#include "linearization/normal_equations.h"

namespace lpoe {
namespace {

// Position rows, with the given joint-block options.
internal::NormalEquationsOptions PositionRows(const internal::JointColumnsOptions& joint = {}) {
  internal::NormalEquationsOptions o;
  o.joint = joint;
  return o;
}

// The 1000 poses of the loaded cobot6 (tests/loaded_cobot6.h), 0.01 mm noise.
const testing::LoadedCobot6& Poses1000() {
  static const testing::LoadedCobot6* data =
      new testing::LoadedCobot6(testing::MakeLoadedCobot6(1000, 0.01, 7));
  return *data;
}

// range(0): 0 linear, 1 Ceres; range(1): 0 geometry, 1 compliance + harmonics, 2 auto.
void BM_Calibrate(benchmark::State& state) {
  const testing::LoadedCobot6& d = Poses1000();
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
    state.counters["iterations"] = r.iterations;
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

// The passes of a linear-solver calibration with compliance + harmonics (normal_equations.h), at the
// nominal model. range(0): 0 evaluating the rows' regressors (BuildJointSpaceRegressors), 1 the
// reduction's normal equations (every term whole, 141 columns, by structure), 2 the same with
// dense rows, 3 deciding the combinations from them (JointBlockBases), 4 an iteration's normal
// equations of the reduced problem by structure, 5 the same with dense rows, 6 an iteration with
// frozen joint blocks (gradient only), 7 the geometric normal equations alone.
void BM_Pass(benchmark::State& state) {
  const testing::LoadedCobot6& d = Poses1000();
  std::vector<std::shared_ptr<const JointTerm>> terms;
  for (const char* name : {"compliance", "harmonics"}) {
    std::shared_ptr<const JointTerm> t;
    if (!MakeJointTerm(name, d.nominal, &t).ok()) state.SkipWithError("term");
    terms.push_back(t);
  }
  internal::NormalEquations analysed;
  internal::JointSpaceRegressors regs;
  Parameterization whole;
  internal::SolverParameterizationRequest request;
  request.terms = terms;
  request.analysed = &analysed;
  request.regressors = &regs;
  request.analysed_parameterization = &whole;
  const Parameterization reduced = internal::SolverParameterization(d.nominal, d.data, request);
  internal::JointSpaceRegressors reduced_regs = regs;
  internal::SetSlotBasis(reduced, &reduced_regs);
  const Parameterization geometric = MakeParameterization(
      d.nominal, ParameterizationKind::kIdentifiable, DataKind::kPosition);
  internal::JointColumnsOptions structured, dense, gradient;
  dense.dense = true;
  gradient.gradient_only = true;
  gradient.regressors = &reduced_regs;
  const Eigen::VectorXd none;
  const int pass = static_cast<int>(state.range(0));
  for (auto _ : state) {
    switch (pass) {
      case 0:
        benchmark::DoNotOptimize(internal::BuildJointSpaceRegressors(whole, d.data).values.data());
        break;
      case 1:
        structured.regressors = &regs;
        benchmark::DoNotOptimize(
            internal::NormalEquationsOf(d.nominal, d.data, whole, none, PositionRows(structured))
                .H.data());
        break;
      case 2:
        benchmark::DoNotOptimize(
            internal::NormalEquationsOf(d.nominal, d.data, whole, none, PositionRows(dense))
                .H.data());
        break;
      case 3:
        benchmark::DoNotOptimize(internal::JointBlockBases(analysed.H, whole, 1e-4).data());
        break;
      case 4:
        structured.regressors = &reduced_regs;
        benchmark::DoNotOptimize(
            internal::NormalEquationsOf(d.nominal, d.data, reduced, none, PositionRows(structured))
                .H.data());
        break;
      case 5:
        benchmark::DoNotOptimize(
            internal::NormalEquationsOf(d.nominal, d.data, reduced, none, PositionRows(dense))
                .H.data());
        break;
      case 6:
        benchmark::DoNotOptimize(
            internal::NormalEquationsOf(d.nominal, d.data, reduced, none, PositionRows(gradient))
                .H.data());
        break;
      default:
        benchmark::DoNotOptimize(
            internal::NormalEquationsOf(d.nominal, d.data, geometric, none, PositionRows())
                .H.data());
    }
  }
  state.counters["columns"] = pass <= 3 ? whole.num_parameters
                              : pass == 7 ? geometric.num_parameters
                                          : reduced.num_parameters;
}
BENCHMARK(BM_Pass)->ArgName("pass")->DenseRange(0, 7)->Unit(benchmark::kMicrosecond);

}  // namespace
}  // namespace lpoe

BENCHMARK_MAIN();
