// Measurement planning (lpoe_plan): choosing N poses from C candidates for cobot6 with three SMRs
// (33 identifiable parameters, 9 rows per pose), greedy selection followed by the exchange, per
// criterion. The goal is 50 of 5,000 in at most 1 s. The candidate pool (the rows of every
// candidate) and the workspace moment are built once per size, outside the timed loop; building
// them is timed separately.
#include <map>
#include <memory>
#include <utility>
#include <vector>

#include <benchmark/benchmark.h>
#include <glog/logging.h>

#include "lpoe/planning.h"

namespace lpoe {
namespace {

RobotModel ThreeSmrCobot() {
  RobotModel model = MakeCobot6(Eigen::Vector3d(40, 0, 60));
  model.tools.push_back({"smr2", SE3d(Eigen::Matrix3d::Identity(), Eigen::Vector3d(-30, 35, 55))});
  model.tools.push_back({"smr3", SE3d(Eigen::Matrix3d::Identity(), Eigen::Vector3d(-25, -45, 50))});
  return model;
}

struct Setup {
  explicit Setup(int candidates) : model(ThreeSmrCobot()), pm(model) {
    std::vector<double> q, w;
    CHECK(SampleConfigurations(model, candidates, 1, &q).ok());
    CHECK(SampleConfigurations(model, 1000, 2, &w).ok());
    pool = BuildCandidatePool(pm, q, PlanConstraints());
    L = WorkspaceMoment(pm, w);
  }
  RobotModel model;
  PlanningModel pm;
  CandidatePool pool;
  Eigen::MatrixXd L;
};

const Setup& SetupFor(int candidates) {
  static std::map<int, std::unique_ptr<Setup>> cache;
  auto& s = cache[candidates];
  if (!s) s = std::make_unique<Setup>(candidates);
  return *s;
}

// state.range(0): candidates, range(1): poses chosen, range(2): criterion (PlanCriterion order).
void BM_SelectPlan(benchmark::State& state) {
  const Setup& s = SetupFor(static_cast<int>(state.range(0)));
  PlanOptions options;
  options.criterion = static_cast<PlanCriterion>(state.range(2));
  PlanResult result;
  for (auto _ : state) {
    CHECK(SelectPlan(s.pm, s.pool, static_cast<int>(state.range(1)), s.L, options, &result).ok());
    benchmark::DoNotOptimize(result.selected.data());
  }
  state.SetLabel(PlanCriterionName(options.criterion));
  state.counters["exchanges"] = result.exchanges;
  state.counters["passes"] = result.passes;
}
BENCHMARK(BM_SelectPlan)
    ->Args({5000, 50, static_cast<int>(PlanCriterion::kD)})
    ->Args({5000, 50, static_cast<int>(PlanCriterion::kI)})
    ->Args({5000, 50, static_cast<int>(PlanCriterion::kA)})
    ->Args({5000, 50, static_cast<int>(PlanCriterion::kE)})
    ->Args({1000, 25, static_cast<int>(PlanCriterion::kD)})
    ->Unit(benchmark::kMillisecond);

// The rows of 5,000 candidates (forward kinematics and Jacobians of three tools each).
void BM_BuildCandidatePool(benchmark::State& state) {
  const RobotModel model = ThreeSmrCobot();
  const PlanningModel pm(model);
  std::vector<double> q;
  CHECK(SampleConfigurations(model, static_cast<int>(state.range(0)), 1, &q).ok());
  for (auto _ : state) {
    const CandidatePool pool = BuildCandidatePool(pm, q, PlanConstraints());
    benchmark::DoNotOptimize(pool.J.data());
  }
}
BENCHMARK(BM_BuildCandidatePool)->Arg(5000)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace lpoe

BENCHMARK_MAIN();
