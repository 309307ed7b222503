// The library workflows the front ends share (lpoe/compensation.h, lpoe/planning_workflow.h), the
// option table (lpoe/options.h) and the one reader of number lists (parse_util.h): the workflow
// equals the building blocks it is made of, does not depend on the thread count, honours the frame
// and the TCP, and refuses what the tools refuse with the same messages.
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "lpoe/compensation.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/options.h"
#include "lpoe/planning.h"
#include "lpoe/planning_workflow.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/model/simulation.h"
#include "io/parse_util.h"

namespace lpoe {
namespace {
namespace workflows_test {

// A calibrated cobot6 registered into a tracker frame 2.4 m away, turned: what lpoe_calibrate
// writes after registration.
RobotModel Calibrated(const RobotModel& nominal) {
  RobotModel m = ApplyErrors(nominal, RandomErrors(nominal, 2e-3, 1.0, 2e-3, 0, 5));
  m.T_measurement_base = SE3d(ExpSO3(Eigen::Vector3d(0.05, -0.1, 0.9)),
                              Eigen::Vector3d(2400, -900, 250));
  m.joints[0].origin = m.T_measurement_base * m.joints[0].origin;
  return m;
}

std::vector<double> Configurations(const RobotModel& model, int count, uint64_t seed) {
  std::vector<double> q;
  EXPECT_TRUE(SampleConfigurations(model, count, seed, &q).ok());
  // Away from the limits: the seeds and targets of a program.
  for (double& v : q) v *= 0.6;
  return q;
}

TEST(ParseNumberList, ReadsEveryItemOrRefuses) {
  std::vector<double> v;
  ASSERT_TRUE(internal::ParseNumberList("2500, 0 ,-8e2", ',', &v));
  EXPECT_EQ(v, (std::vector<double>{2500, 0, -800}));
  ASSERT_TRUE(internal::ParseNumberList("-1.5:0.5", ':', &v));
  EXPECT_EQ(v, (std::vector<double>{-1.5, 0.5}));
  for (const char* bad : {"", "1,,2", "1,2,", "1,x", "1,nan", "1,inf", "1e999", "1 2"}) {
    EXPECT_FALSE(internal::ParseNumberList(bad, ',', &v)) << bad;
  }
}

TEST(Options, TableIsConsistentAndChecksRanges) {
  for (const OptionSpec& s : Options()) {
    ASSERT_NE(s.help, nullptr);
    // The shared options' help is the only one (tools/common/common_flags.cc).
    if (s.scope[0] == '\0') {
      EXPECT_GT(std::string(s.help).size(), 10u) << s.name;
    }
    if (!s.has_range) continue;
    // Every default lies in its range.
    EXPECT_TRUE(CheckOption(s.scope, s.name, OptionDefault(s.scope, s.name)).ok()) << s.name;
    EXPECT_FALSE(CheckOption(s.scope, s.name, NAN).ok()) << s.name;
  }
  EXPECT_EQ(OptionRangeText(*FindOption("lpoe_compensate", "max_iterations")), "[1, 10000]");
  EXPECT_EQ(OptionRangeText(*FindOption("lpoe_plan", "acceptance_angle")), "(0, 90]");
  EXPECT_EQ(OptionRangeText(*FindOption("lpoe_plan", "min_singularity")), "[0, 1)");
  EXPECT_EQ(CheckOption("lpoe_compensate", "restarts", 101).message(),
            "--restarts must be in [0, 100], got 101");
  EXPECT_TRUE(CheckOption("lpoe_plan", "acceptance_angle", 90).ok());
  EXPECT_FALSE(CheckOption("lpoe_plan", "acceptance_angle", 0).ok());
  // A tool's own option before a shared one; a shared one for every tool.
  EXPECT_STREQ(FindOption("lpoe_predict", "length_unit")->scope, "");
  EXPECT_EQ(FindOption("lpoe_predict", "restarts"), nullptr);
}

// lpoe_calibrate's flags and lpoe.calibrate's keywords read their text and flag defaults and their
// help from the table (python/tests/test_options.py compares both with it).
TEST(Options, CalibrateDefaultsAsWrittenWithHelp) {
  EXPECT_STREQ(OptionDefaultText("lpoe_calibrate", "solver"), "linear");
  EXPECT_STREQ(OptionDefaultText("lpoe_calibrate", "fixed_tools"), "");
  EXPECT_STREQ(OptionDefaultText("lpoe_calibrate", "angle_unit"), "rad");  // the shared one
  EXPECT_TRUE(OptionDefaultBool("lpoe_calibrate", "register"));
  EXPECT_FALSE(OptionDefaultBool("lpoe_calibrate", "quiet"));
  EXPECT_EQ(OptionDefault("lpoe_calibrate", "outlier_threshold"), 5.0);
  EXPECT_EQ(OptionDefault("lpoe_calibrate", "split_seed"), 1.0);
  int calibrate_options = 0;
  for (const OptionSpec& s : Options()) {
    if (std::string(s.scope) != "lpoe_calibrate") continue;
    ++calibrate_options;
    EXPECT_GT(std::string(s.help).size(), 10u) << s.name;
  }
  EXPECT_GE(calibrate_options, 27);
}

class CompensationWorkflow : public ::testing::Test {
 protected:
  void SetUp() override {
    nominal_ = MakeCobot6();
    request_.model = Calibrated(nominal_);
    request_.has_nominal = true;
    request_.nominal = nominal_;
    seeds_ = Configurations(nominal_, 600, 11);
  }
  // Targets: the calibrated robot's tool at the seeds slightly moved, in the base frame.
  std::vector<IkTarget> BaseTargets(int tool) const {
    const int n = nominal_.num_joints();
    std::vector<IkTarget> targets(seeds_.size() / n);
    const SE3d base_from_measurement = request_.model.T_measurement_base.Inverse();
    for (size_t k = 0; k < targets.size(); ++k) {
      targets[k].tool = tool;
      targets[k].position = base_from_measurement * ToolPosition(request_.model, &seeds_[k * n], tool) +
                            Eigen::Vector3d(0.3, -0.2, 0.4);
    }
    return targets;
  }
  RobotModel nominal_;
  CompensationRequest request_;
  std::vector<double> seeds_;
};

TEST_F(CompensationWorkflow, BaseFrameTargetsReachedAndEqualToTheMeasurementFrameOnes) {
  std::unique_ptr<Compensator> c;
  ASSERT_TRUE(Compensator::Create(request_, &c).ok());
  std::vector<IkTarget> base = BaseTargets(0);
  const std::vector<IkTarget> given = base;
  CompensatedRows out;
  c->Solve(seeds_.data(), &base, &out);
  const int n = nominal_.num_joints();
  int ok = 0;
  for (int k = 0; k < out.size(); ++k) {
    if (out.results[k].status != IkStatus::kOk) continue;
    ++ok;
    // The calibrated robot reaches the target, carried into its (measurement) frame.
    const Eigen::Vector3d reached = ToolPosition(request_.model, &out.q[size_t(k) * n], 0);
    EXPECT_LT((reached - request_.model.T_measurement_base * given[k].position).norm(), 1e-6);
    // The corrected target: the nominal model's tool at the compensated joints.
    EXPECT_LT((out.corrected[k].t - ToolPosition(nominal_, &out.q[size_t(k) * n], 0)).norm(), 1e-9);
  }
  EXPECT_GT(ok, out.size() * 9 / 10);
  // The same targets given in the measurement frame: the same joints, bit for bit.
  CompensationRequest measurement = request_;
  measurement.frame = TargetFrame::kMeasurement;
  ASSERT_TRUE(Compensator::Create(measurement, &c).ok());
  std::vector<IkTarget> carried = given;
  for (IkTarget& t : carried) t.position = request_.model.T_measurement_base * t.position;
  CompensatedRows same;
  c->Solve(seeds_.data(), &carried, &same);
  EXPECT_EQ(same.q, out.q);
  CompensationSummary summary;
  summary.Add(out);
  EXPECT_TRUE(summary.CheckFrame(request_, "t.csv").ok());
  EXPECT_EQ(summary.rows, out.size());
}

TEST_F(CompensationWorkflow, ResultsDoNotDependOnTheThreadCount) {
  CompensatedRows one, four;
  for (auto [threads, out] : {std::pair<int, CompensatedRows*>{1, &one}, {4, &four}}) {
    CompensationRequest r = request_;
    r.threads = threads;
    std::unique_ptr<Compensator> c;
    ASSERT_TRUE(Compensator::Create(r, &c).ok());
    std::vector<IkTarget> targets = BaseTargets(0);
    c->Solve(seeds_.data(), &targets, out);
  }
  EXPECT_EQ(one.q, four.q);
  ASSERT_EQ(one.size(), four.size());
  for (int k = 0; k < one.size(); ++k) {
    EXPECT_EQ(one.results[k].position_error, four.results[k].position_error);
  }
}

TEST_F(CompensationWorkflow, TargetsInTheOtherFrameAreRefusedNamingIt) {
  std::unique_ptr<Compensator> c;
  CompensationRequest r = request_;
  r.frame = TargetFrame::kMeasurement;  // but the targets are in the base frame, metres away
  ASSERT_TRUE(Compensator::Create(r, &c).ok());
  std::vector<IkTarget> targets = BaseTargets(0);
  CompensatedRows out;
  c->Solve(seeds_.data(), &targets, &out);
  CompensationSummary summary;
  summary.Add(out);
  const Status s = summary.CheckFrame(r, "targets.csv");
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("read in the measurement frame (--frame=measurement)"),
            std::string::npos) << s.message();
  EXPECT_NE(s.message().find("use --frame=base"), std::string::npos);
}

TEST_F(CompensationWorkflow, TcpOffsetIsAToolOfBothModels) {
  CompensationRequest r = request_;
  r.tcp = "10, -20, 150, 0, 0.3, 0";
  std::unique_ptr<Compensator> c;
  ASSERT_TRUE(Compensator::Create(r, &c).ok());
  const int tcp = c->default_tool();
  EXPECT_EQ(tcp, request_.model.num_tools());
  EXPECT_EQ(c->model().tools[tcp].name, "tcp");
  EXPECT_EQ(c->nominal().num_tools(), c->model().num_tools());
  EXPECT_LT((c->model().tools[tcp].origin.t - Eigen::Vector3d(10, -20, 150)).norm(), 1e-12);
  // The numbers given as an array (Python's tcp=[...]): the same tool.
  CompensationRequest numbers = request_;
  numbers.tcp_offset = {10, -20, 150, 0, 0.3, 0};
  std::unique_ptr<Compensator> c2;
  ASSERT_TRUE(Compensator::Create(numbers, &c2).ok());
  EXPECT_TRUE(c2->model().tools[tcp].origin.R.isApprox(c->model().tools[tcp].origin.R, 1e-15));
  // A program's TCP target: the compensated joints put the calibrated TCP there.
  std::vector<IkTarget> targets(1);
  targets[0].tool = tcp;
  const SE3d base_from_measurement = request_.model.T_measurement_base.Inverse();
  targets[0].position = base_from_measurement * ToolPosition(c->model(), seeds_.data(), tcp);
  CompensatedRows out;
  c->Solve(seeds_.data(), &targets, &out);
  ASSERT_EQ(out.results[0].status, IkStatus::kOk);
  EXPECT_LT((ToolPosition(c->model(), out.q.data(), tcp) -
             request_.model.T_measurement_base * base_from_measurement *
                 ToolPosition(c->model(), seeds_.data(), tcp))
                .norm(),
            1e-6);
}

TEST_F(CompensationWorkflow, BadRequestsAreRefusedWithTheToolsMessages) {
  std::unique_ptr<Compensator> c;
  CompensationRequest r = request_;
  r.tcp = "tool0";
  r.tool = "0";
  EXPECT_EQ(Compensator::Create(r, &c).message(), "give --tcp or --tool, not both");
  r = request_;
  r.tcp = "1,2";
  EXPECT_NE(Compensator::Create(r, &c).message().find("expected x,y,z or x,y,z,roll,pitch,yaw"),
            std::string::npos);
  r = request_;
  r.tcp = "no_such_link";
  EXPECT_NE(Compensator::Create(r, &c).message().find("is not a tool of the calibrated model"),
            std::string::npos);
  r = request_;
  r.ik.max_iterations = 0;
  EXPECT_EQ(Compensator::Create(r, &c).message(),
            "--max_iterations must be in [1, 10000], got 0");
  r = request_;
  r.has_nominal = false;
  r.joints_mode = true;
  EXPECT_NE(Compensator::Create(r, &c).message().find("--joints needs --nominal"),
            std::string::npos);
  r = request_;
  r.nominal.joints.pop_back();
  bool input = false;
  EXPECT_FALSE(Compensator::Create(r, &c, &input).ok());
  EXPECT_TRUE(input);
}

PlanRequest SmallPlan() {
  PlanRequest r;
  r.model = MakeCobot6();
  r.model_source = "cobot6.yaml";
  r.count = 14;
  r.candidate_count = 400;
  r.workspace_count = 100;
  r.random_draws = 4;
  r.seed = 3;
  return r;
}

TEST(PlanningWorkflow, EqualsTheBuildingBlocksWithTheSameSeeds) {
  PlanRequest request = SmallPlan();
  // Without an unmodelled error the plan is the criterion's (the exchange on the predicted error
  // with one: next test).
  request.unmodelled_given = true;
  request.unmodelled_error = 0;
  PlanningResult result;
  ASSERT_TRUE(RunPlanning(request, &result).ok());
  EXPECT_EQ(result.count, 14);
  EXPECT_EQ(result.offered, 400);
  EXPECT_EQ(result.PlannedTerms(), "none");
  // The same plan by hand: sampled candidates (seed), workspace (seed + 1), pool, selection.
  std::vector<double> candidates, workspace;
  ASSERT_TRUE(SampleConfigurations(request.model, 400, 3, &candidates).ok());
  ASSERT_TRUE(SampleConfigurations(request.model, 100, 4, &workspace).ok());
  EXPECT_EQ(candidates, result.candidates);
  CandidatePool pool;
  const auto pm = BuildPlanningPool(request.model, {}, candidates, request.constraints, &pool);
  const Eigen::MatrixXd L = WorkspaceMoment(*pm, workspace);
  PlanResult plan;
  ASSERT_TRUE(SelectPlan(*pm, pool, 14, L, request.options, &plan).ok());
  EXPECT_EQ(plan.selected, result.plan.selected);
  EXPECT_EQ(EvaluatePlan(*pm, pool, plan.selected, L).predicted_rms, result.quality.predicted_rms);
  EXPECT_EQ(EvaluatePlan(*pm, pool, RandomPlan(pool.size(), 14, 3 + 1000), L).predicted_rms,
            result.random_quality.predicted_rms);
  ASSERT_EQ(result.random_rms.size(), 4u);
  EXPECT_LT(result.quality.predicted_rms, result.random_rms.front());
}

// With the default unmodelled error: the best of the criterion's plan and the random plans by the
// predicted error, improved by the exchange on it (docs/planning.md, "Unmodelled error"); its
// prediction is below every random plan's.
TEST(PlanningWorkflow, WithAnUnmodelledErrorThePlanIsTheExchangeOnThePredictedError) {
  const PlanRequest request = SmallPlan();
  PlanningResult result;
  ASSERT_TRUE(RunPlanning(request, &result).ok());
  EXPECT_EQ(result.unmodelled_source, "default");
  EXPECT_EQ(result.unmodelled.std, 0.03);
  ASSERT_EQ(result.random_total_rms.size(), 4u);
  EXPECT_LE(result.prediction.total_rms, result.random_total_rms.front());
  // The same by hand.
  std::vector<double> candidates, workspace;
  ASSERT_TRUE(SampleConfigurations(request.model, 400, 3, &candidates).ok());
  ASSERT_TRUE(SampleConfigurations(request.model, 100, 4, &workspace).ok());
  CandidatePool pool;
  const auto pm = BuildPlanningPool(request.model, {}, candidates, request.constraints, &pool);
  const Eigen::MatrixXd L = WorkspaceMoment(*pm, workspace);
  PlanResult plan;
  ASSERT_TRUE(SelectPlan(*pm, pool, 14, L, request.options, &plan).ok());
  UnmodelledErrorModel u;
  u.std = 0.03;
  u.length_scales = Eigen::VectorXd::Constant(6, 1.0);
  const UnmodelledPlanning up(*pm, pool, workspace, L, u, kPlanDefaultNoiseSigma);
  std::vector<int> start = plan.selected;
  double best = up.Predict(start).total_rms;
  for (int k = 0; k < 4; ++k) {
    const std::vector<int> r = RandomPlan(pool.size(), 14, 3 + 1000 + k);
    if (up.Predict(r).total_rms < best) {
      best = up.Predict(r).total_rms;
      start = r;
    }
  }
  up.Exchange(&start, request.options.max_exchange_passes, 32, 3 + 2);
  EXPECT_EQ(start, result.plan.selected);
  EXPECT_EQ(up.Predict(start).total_rms, result.prediction.total_rms);
  EXPECT_LE(result.prediction.total_rms, best);
}

TEST(PlanningWorkflow, CountAutoIsTheSmallestPlanReachingTheTarget) {
  PlanRequest request = SmallPlan();
  request.count_auto = true;
  request.noise_sigma = 0.02;
  request.target_accuracy = 0.03;
  PlanningResult result;
  ASSERT_TRUE(RunPlanning(request, &result).ok());
  EXPECT_LE(request.noise_sigma * result.quality.predicted_rms, request.target_accuracy);
  // One pose fewer of the same criterion (count_auto makes no exchange on the unmodelled error's
  // prediction, so neither does the comparison) does not reach it.
  request.count_auto = false;
  request.count = result.count - 1;
  request.unmodelled_given = true;
  request.unmodelled_error = 0;
  PlanningResult smaller;
  const Status s = RunPlanning(request, &smaller);
  EXPECT_TRUE(!s.ok() || request.noise_sigma * smaller.quality.predicted_rms >
                             request.target_accuracy);
}

TEST(PlanningWorkflow, FailuresSayWhichKind) {
  PlanningResult result;
  PlanFailure failure = PlanFailure::kNone;
  PlanRequest r = SmallPlan();
  r.joint_errors = "compliance,bogus";
  EXPECT_FALSE(RunPlanning(r, &result, &failure).ok());
  EXPECT_EQ(failure, PlanFailure::kUsage);
  r = SmallPlan();
  r.joint_errors = "compliance,tilt";  // a nominal model carries no compliance values
  const Status tilt = RunPlanning(r, &result, &failure);
  EXPECT_EQ(failure, PlanFailure::kUsage);
  EXPECT_NE(tilt.message().find("with --model=cobot6.yaml"), std::string::npos);
  r = SmallPlan();
  r.count = 9;  // 27 rows for 27 parameters
  EXPECT_FALSE(RunPlanning(r, &result, &failure).ok());
  EXPECT_EQ(failure, PlanFailure::kNoPlan);
  r = SmallPlan();
  r.random_draws = 0;
  EXPECT_EQ(RunPlanning(r, &result, &failure).message(),
            "--random_draws must be in [1, 10000], got 0");
  EXPECT_EQ(failure, PlanFailure::kUsage);
  r = SmallPlan();
  r.has_workspace = true;  // and empty
  EXPECT_FALSE(RunPlanning(r, &result, &failure).ok());
  EXPECT_EQ(failure, PlanFailure::kInput);
}

TEST(PlanningWorkflow, NarrowJointRangesKeepsEveryCandidateInside) {
  PlanRequest r = SmallPlan();
  const double nan = std::numeric_limits<double>::quiet_NaN();
  std::vector<std::pair<double, double>> ranges(6, {nan, nan});
  ranges[1] = {-1.5, 0.5};
  ASSERT_TRUE(NarrowJointRanges(ranges, &r.model).ok());
  EXPECT_EQ(r.model.joints[1].lower, std::max(MakeCobot6().joints[1].lower, -1.5));
  EXPECT_EQ(r.model.joints[1].upper, std::min(MakeCobot6().joints[1].upper, 0.5));
  PlanningResult result;
  ASSERT_TRUE(RunPlanning(r, &result).ok());
  for (int c : result.plan.selected) {
    const double q1 = result.pool.q[static_cast<size_t>(c) * 6 + 1];
    EXPECT_GE(q1, -1.5);
    EXPECT_LE(q1, 0.5);
  }
  ranges[1] = {0.5, -1.5};
  EXPECT_NE(NarrowJointRanges(ranges, &r.model).message().find("not lo:hi with lo < hi"),
            std::string::npos);
  ranges[1] = {100, 200};
  EXPECT_NE(NarrowJointRanges(ranges, &r.model).message().find("does not overlap"),
            std::string::npos);
  ranges.pop_back();
  EXPECT_NE(NarrowJointRanges(ranges, &r.model).message().find("gives 5 items"),
            std::string::npos);
}

}  // namespace workflows_test
}  // namespace
}  // namespace lpoe
