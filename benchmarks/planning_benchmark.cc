// Measurement planning (lpoe_plan): choosing N poses from C candidates for cobot6 with three SMRs
// (33 identifiable parameters, 9 rows per pose; with the joint-space terms compliance and harmonics
// of lpoe_plan --joint_errors their identifiable combinations too), greedy selection followed by
// the exchange, per criterion. The goal is 50 of 5,000 in at most 1 s. The candidate pool (the rows
// of every candidate) and the workspace moment are built once per size, outside the timed loop;
// building them is timed separately.
#include <map>
#include <string>
#include <memory>
#include <utility>
#include <vector>

#include <benchmark/benchmark.h>
#include <glog/logging.h>

#include "lpoe/terms/joint_term.h"
#include "lpoe/planning.h"

namespace lpoe {
namespace {

RobotModel ThreeSmrCobot() {
  RobotModel model = MakeCobot6(Eigen::Vector3d(40, 0, 60));
  model.tools.push_back({"smr2", SE3d(Eigen::Matrix3d::Identity(), Eigen::Vector3d(-30, 35, 55))});
  model.tools.push_back({"smr3", SE3d(Eigen::Matrix3d::Identity(), Eigen::Vector3d(-25, -45, 50))});
  return model;
}

std::vector<double> Sample(const RobotModel& model, int count, uint64_t seed) {
  std::vector<double> q;
  CHECK(SampleConfigurations(model, count, seed, &q).ok());
  return q;
}

std::vector<std::shared_ptr<const JointTerm>> Terms(const RobotModel& model, bool joint_errors) {
  std::vector<std::shared_ptr<const JointTerm>> terms;
  if (!joint_errors) return terms;
  for (const char* name : {"compliance", "harmonics"}) {
    std::shared_ptr<const JointTerm> term;
    CHECK(MakeJointTerm(name, model, &term).ok());
    terms.push_back(term);
  }
  return terms;
}

struct Setup {
  Setup(int candidates, bool joint_errors)
      : model(ThreeSmrCobot()),
        q(Sample(model, candidates, 1)),
        pm(model, Terms(model, joint_errors), q) {
    pool = BuildCandidatePool(pm, q, PlanConstraints());
    L = WorkspaceMoment(pm, Sample(model, 1000, 2));
  }
  RobotModel model;
  std::vector<double> q;
  PlanningModel pm;
  CandidatePool pool;
  Eigen::MatrixXd L;
};

const Setup& SetupFor(int candidates, bool joint_errors) {
  static std::map<std::pair<int, bool>, std::unique_ptr<Setup>> cache;
  auto& s = cache[{candidates, joint_errors}];
  if (!s) s = std::make_unique<Setup>(candidates, joint_errors);
  return *s;
}

// state.range(0): candidates, range(1): poses chosen, range(2): criterion (PlanCriterion order),
// range(3): 1 with the joint-space terms compliance and harmonics, range(4): threads (0: all).
void BM_SelectPlan(benchmark::State& state) {
  const Setup& s = SetupFor(static_cast<int>(state.range(0)), state.range(3) != 0);
  PlanOptions options;
  options.criterion = static_cast<PlanCriterion>(state.range(2));
  options.num_threads = static_cast<int>(state.range(4));
  PlanResult result;
  for (auto _ : state) {
    CHECK(SelectPlan(s.pm, s.pool, static_cast<int>(state.range(1)), s.L, options, &result).ok());
    benchmark::DoNotOptimize(result.selected.data());
  }
  state.SetLabel(std::string(PlanCriterionName(options.criterion)) + ", " +
                 std::to_string(s.pm.num_parameters()) + " parameters");
  state.counters["exchanges"] = result.exchanges;
  state.counters["passes"] = result.passes;
}
BENCHMARK(BM_SelectPlan)
    ->Args({5000, 50, static_cast<int>(PlanCriterion::kD), 0, 0})
    ->Args({5000, 50, static_cast<int>(PlanCriterion::kD), 0, 1})
    ->Args({5000, 50, static_cast<int>(PlanCriterion::kI), 0, 0})
    ->Args({5000, 50, static_cast<int>(PlanCriterion::kA), 0, 0})
    ->Args({5000, 50, static_cast<int>(PlanCriterion::kE), 0, 0})
    ->Args({1000, 25, static_cast<int>(PlanCriterion::kD), 0, 0})
    ->Args({5000, 50, static_cast<int>(PlanCriterion::kD), 1, 0})
    ->Args({5000, 50, static_cast<int>(PlanCriterion::kI), 1, 0})
    ->Unit(benchmark::kMillisecond)
    ->MeasureProcessCPUTime()  // the candidate loops run on every core
    ->UseRealTime();

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

// The joint-space terms' reduction over 5,000 candidates (the solvers' identifiability analysis).
void BM_PlanningModelWithJointErrors(benchmark::State& state) {
  const RobotModel model = ThreeSmrCobot();
  const std::vector<double> q = Sample(model, static_cast<int>(state.range(0)), 1);
  const auto terms = Terms(model, true);
  for (auto _ : state) {
    const PlanningModel pm(model, terms, q);
    benchmark::DoNotOptimize(pm.num_parameters());
  }
}
BENCHMARK(BM_PlanningModelWithJointErrors)->Arg(5000)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace lpoe

BENCHMARK_MAIN();
