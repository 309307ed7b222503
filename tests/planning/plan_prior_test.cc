// lpoe_plan --prior (docs/recalibration.md): a plan that starts from a prior's information puts its
// few poses where the prior is weak. Simulated with realistic magnitudes: a UR5-like 6R arm with 3
// SMRs off the flange axis, a previous calibration of 60 poses as the prior with joint 5's frame
// freed (maintenance), the maintained robot measured from a tracker 3 m away, noise 0.02 mm.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <memory>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "lpoe/terms/joint_errors.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/model/model_covariance.h"
#include "lpoe/pipeline.h"
#include "lpoe/planning.h"
#include "lpoe/planning_workflow.h"
#include "lpoe/recalibration.h"
#include "lpoe/registration.h"
#include "lpoe/model/simulation.h"
#include "three_smr_cell.h"

namespace lpoe {
namespace {
namespace plan_prior_test {

constexpr double kNoise = 0.02;

RobotModel Nominal() { return testing::ThreeSmrUr5(); }

SE3d Tracker(uint64_t seed) { return testing::TrackerThreeMetresAway(seed, 0.3); }

struct Robot {
  RobotModel with_errors;
  std::vector<double> zero;
};

// Every SMR at the configurations `q` (row-major), in tracker frame T, with noise.
MeasurementSet MeasureAt(const Robot& r, const std::vector<double>& q, uint64_t seed,
                         const SE3d& T, double noise) {
  SimulationOptions o;
  o.all_tools = true;
  o.configurations = q;
  o.noise_sigma = noise;
  o.seed = seed;
  const MeasurementSet d = SimulateMeasurements(r.with_errors, r.zero, o);
  MeasurementSet out(d.num_joints());
  for (int k = 0; k < d.size(); ++k) out.Add(d.q(k), T * d.position(k), d.target(k));
  return out;
}

std::vector<double> RandomConfigurations(int poses, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> angle(-kPi, kPi);
  std::vector<double> q;
  for (int c = 0; c < poses * 6; ++c) q.push_back(angle(rng));
  return q;
}

// RMS distance of a model's SMRs from the robot's over fresh configurations, after a rigid fit.
double HeldOut(const Robot& r, const RobotModel& model) {
  const MeasurementSet fresh = MeasureAt(r, RandomConfigurations(200, 4242), 1, SE3d(), 0.0);
  std::vector<Eigen::Vector3d> predicted, measured;
  for (int k = 0; k < fresh.size(); ++k) {
    predicted.push_back(PredictToolPosition(model, fresh.q(k), fresh.target(k)));
    measured.push_back(fresh.position(k));
  }
  SE3d fit;
  EXPECT_TRUE(FitRigidTransform(predicted, measured, &fit).ok());
  double sum = 0;
  for (size_t k = 0; k < predicted.size(); ++k) sum += (fit * predicted[k] - measured[k]).squaredNorm();
  return std::sqrt(sum / predicted.size());
}

std::vector<double> ConfigurationsOf(const CandidatePool& pool, const std::vector<int>& plan) {
  std::vector<double> q;
  for (int c : plan) q.insert(q.end(), pool.q.begin() + 6 * c, pool.q.begin() + 6 * (c + 1));
  return q;
}

TEST(PlanWithPrior, PosesGoWhereThePriorIsWeak) {
  const RobotModel type = Nominal();
  const KinematicErrors e = RandomErrors(type, 0.002, 1.0, 0.001, 0.002, 31);
  Robot robot{ApplyErrors(type, e), e.joint_zero};
  // The previous calibration (60 poses) and its covariance: the prior.
  const PipelineResult previous = RunCalibrationPipeline(
      type, MeasureAt(robot, RandomConfigurations(60, 32), 33, Tracker(34), kNoise),
      MeasurementSet(6), PipelineOptions());
  ASSERT_TRUE(previous.result.converged()) << previous.result.message;
  const RobotModel& model = previous.result.model;
  auto prior = std::make_shared<ParameterPrior>(
      PriorFromCovariance(model, CovarianceOf(previous.result), PriorScales()));
  // Maintenance on joint 5: its frame's prior is freed (the nominal tolerances), and the robot's
  // frame moves 0.3 mm and 1 mrad across its axis.
  prior->frame_information[4] = DefaultFrameInformation(model, 4, prior->scales, 1.0);
  Robot after = robot;
  Vector6d d;
  d << 0.001, 0, 0, 0, 0.3, 0;
  after.with_errors.joints[4].origin = after.with_errors.joints[4].origin * ExpSE3(d);

  // 3 poses (27 rows): fewer than what the prior leaves open and the registration need alone
  // (joint 5's frame 4, the base 6 + 2); from 6 poses on, random poses do as well.
  constexpr int kPoses = 3;
  PlanRequest request;
  request.model = model;
  request.count = kPoses;
  request.candidate_count = 400;
  request.workspace_count = 200;
  request.random_draws = 8;
  request.noise_sigma = kNoise;
  request.seed = 5;
  request.prior = prior;
  // Criterion I: the predicted error over the workspace, registration left out as the held-out
  // check below leaves it out (a rigid fit).
  request.options.criterion = PlanCriterion::kI;
  PlanningResult with;
  ASSERT_TRUE(RunPlanning(request, &with).ok());
  // The same criterion on the same pool without the prior (4 poses alone cannot identify the model:
  // lpoe_plan would refuse them, the selection itself is still made).
  PlanResult without;
  ASSERT_TRUE(
      SelectPlan(*with.planning, with.pool, kPoses, with.workspace_moment, [&] {
        PlanOptions o;
        o.criterion = request.options.criterion;
        return o;
      }(), &without)
          .ok());

  // The posterior's predicted error: the plan against random plans with the same prior.
  std::cout << "predicted held-out RMS per unit noise with the prior: plan "
            << with.quality.predicted_rms << ", random plans " << with.random_rms_mean
            << " (RMS of " << with.random_rms.size() << "; the first "
            << with.random_quality.predicted_rms << ")\n";
  EXPECT_LT(with.quality.predicted_rms, with.random_rms_mean);
  EXPECT_LT(with.quality.predicted_rms, with.random_quality.predicted_rms);
  // The plan differs from the plan without the prior.
  const std::set<int> a(with.plan.selected.begin(), with.plan.selected.end());
  const std::set<int> b(without.selected.begin(), without.selected.end());
  EXPECT_NE(a, b);

  // Held out on the simulated truth: the planned poses, and random poses of the same pool, each
  // measured from another tracker stand and calibrated with the prior.
  PipelineOptions o;
  o.prior = prior;
  auto held_out_of = [&](const std::vector<int>& plan, uint64_t seed) {
    const MeasurementSet data =
        MeasureAt(after, ConfigurationsOf(with.pool, plan), seed, Tracker(seed), kNoise);
    const PipelineResult r = RunCalibrationPipeline(model, data, MeasurementSet(6), o);
    EXPECT_TRUE(r.result.converged()) << r.result.message;
    return HeldOut(after, r.result.model);
  };
  double planned = 0, random = 0;
  constexpr int kDraws = 12;
  for (int k = 0; k < kDraws; ++k) {
    planned += std::pow(held_out_of(with.plan.selected, 100 + k), 2) / kDraws;
    random += std::pow(held_out_of(RandomPlan(with.pool.size(), kPoses, 200 + k), 100 + k), 2) /
              kDraws;
  }
  planned = std::sqrt(planned);
  random = std::sqrt(random);
  const double previous_as_is = HeldOut(after, model);
  std::cout << "held out (RMS over " << kDraws << " noise draws): planned " << planned
            << " mm, random " << random << " mm; the previous model as is " << previous_as_is
            << " mm\n";
  EXPECT_LT(planned, random);
  EXPECT_LT(planned, 0.5 * previous_as_is);
}

// Joint-space terms in a plan with a prior (lpoe_plan --prior --joint_errors=harmonics): a previous
// calibration with the harmonics (150 poses, 0.1 mrad per coefficient) whose covariance block
// lists them is the prior, then joint 3's gearbox is swapped: its harmonics are freed in the prior
// (their variance the 1 mrad tolerance, their correlations with the others dropped) and redrawn
// on the robot. The plan now knows what the prior says about the other joints' harmonics: it
// differs from the plan that gave them no prior information (as before), that plan is predicted
// worse under the prior actually used, and the planned poses recalibrate better held out than
// random poses of the same pool.
TEST(PlanWithPrior, JointTermsOfThePriorGuideThePlan) {
  const RobotModel type = Nominal();
  const KinematicErrors e = RandomErrors(type, 0.002, 1.0, 0.001, 0.002, 41);
  Robot robot{ApplyErrors(type, e), e.joint_zero};
  JointErrorPhysics physics;
  physics.stiffness.assign(6, 0.0);  // rigid: the harmonics only
  std::mt19937_64 rng(42);
  std::normal_distribution<double> h(0.0, 1e-4);  // 0.1 mrad per coefficient
  for (int j = 0; j < 6; ++j) physics.harmonics.push_back(Eigen::Vector4d(h(rng), h(rng), h(rng), h(rng)));
  ApplyJointErrorPhysics(physics, {"harmonics"}, &robot.with_errors);
  PipelineOptions with_terms;
  with_terms.joint_errors = {"harmonics"};
  const PipelineResult previous = RunCalibrationPipeline(
      type, MeasureAt(robot, RandomConfigurations(150, 43), 44, Tracker(45), kNoise),
      MeasurementSet(6), with_terms);
  ASSERT_TRUE(previous.result.converged()) << previous.result.message;
  const RobotModel& model = previous.result.model;
  ModelCovariance covariance = CovarianceOf(previous.result);
  ASSERT_EQ(covariance.term_names.size(), 1u);
  ASSERT_EQ(covariance.term_names[0], "harmonics");
  // Joint 3's gearbox swapped: its four coefficients (parameters 8..11 of the term: four per
  // joint) freed, and redrawn on the robot.
  Eigen::MatrixXd& C = covariance.terms[0];
  ASSERT_EQ(C.rows(), 24);
  for (int i = 8; i < 12; ++i) {
    C.row(i).setZero();
    C.col(i).setZero();
    C(i, i) = 1e-6;  // 1 mrad
  }
  auto prior = std::make_shared<ParameterPrior>(PriorFromCovariance(model, covariance, PriorScales()));
  ASSERT_EQ(prior->joint_terms.size(), 1u);
  Robot after = robot;
  JointErrorPhysics swapped = physics;
  swapped.harmonics[2] = Eigen::Vector4d(h(rng), h(rng), h(rng), h(rng));
  RobotModel redrawn = robot.with_errors;
  ApplyJointErrorPhysics(swapped, {"harmonics"}, &redrawn);
  *after.with_errors.joint_errors.MutableValues("harmonics") =
      redrawn.joint_errors.Values("harmonics");

  // 10 poses: with 3 or 6 the freed coefficients stay open and any recalibration is worse than the
  // previous model (docs/recalibration.md gives the figures).
  constexpr int kPoses = 10;
  PlanRequest request;
  request.model = model;
  request.count = kPoses;
  request.candidate_count = 400;
  request.workspace_count = 200;
  request.random_draws = 8;
  request.noise_sigma = kNoise;
  request.seed = 6;
  request.joint_errors = "harmonics";
  request.prior = prior;
  request.options.criterion = PlanCriterion::kI;
  PlanningResult with;
  ASSERT_TRUE(RunPlanning(request, &with).ok());
  ASSERT_EQ(with.term_names, std::vector<std::string>{"harmonics"});
  const PlanningModel& pm = *with.planning;
  const Parameterization& par = pm.parameterization();
  ASSERT_EQ(par.joint_blocks.size(), 1u);
  const int k = static_cast<int>(par.joint_blocks[0].basis.cols());
  ASSERT_GT(k, 0);
  // The prior's information now covers the term's combinations; without the term's prior (the
  // planner before) it is zero there, and the frames' part is the same.
  const Eigen::MatrixXd M0 = PlanningPriorInformation(pm, *prior, kNoise);
  ParameterPrior frames_only = *prior;
  frames_only.joint_terms.clear();
  const Eigen::MatrixXd M0_frames = PlanningPriorInformation(pm, frames_only, kNoise);
  const int j0 = par.joint_blocks[0].offset;
  EXPECT_GT(M0.block(j0, j0, k, k).trace(), 0.0);
  EXPECT_EQ(M0_frames.block(j0, j0, k, k).norm(), 0.0);
  EXPECT_LT((M0 - M0_frames).topLeftCorner(j0, j0).norm(), 1e-12 * M0.norm());

  // The plan the planner made before (no information on the term) on the same pool and workspace.
  PlanResult before;
  PlanOptions o;
  o.criterion = request.options.criterion;
  o.prior_information = M0_frames;
  ASSERT_TRUE(SelectPlan(pm, with.pool, kPoses, with.workspace_moment, o, &before).ok());
  const PlanQuality before_quality =
      EvaluatePlan(pm, with.pool, before.selected, with.workspace_moment, M0);
  std::cout << "predicted held-out RMS per unit noise with the prior (its harmonics included): "
               "plan "
            << with.quality.predicted_rms << ", the plan without the term's prior "
            << before_quality.predicted_rms << ", random plans " << with.random_rms_mean << "\n";
  const std::set<int> a(with.plan.selected.begin(), with.plan.selected.end());
  const std::set<int> b(before.selected.begin(), before.selected.end());
  EXPECT_NE(a, b);
  EXPECT_LT(with.quality.predicted_rms, before_quality.predicted_rms);
  EXPECT_LT(with.quality.predicted_rms, with.random_rms_mean);

  // Held out on the simulated truth: planned and random poses, each from another tracker stand,
  // calibrated with the prior and the harmonics.
  PipelineOptions cal = with_terms;
  cal.prior = prior;
  auto held_out_of = [&](const std::vector<int>& plan, uint64_t seed) {
    const MeasurementSet data =
        MeasureAt(after, ConfigurationsOf(with.pool, plan), seed, Tracker(seed), kNoise);
    const PipelineResult r = RunCalibrationPipeline(model, data, MeasurementSet(6), cal);
    EXPECT_TRUE(r.result.converged()) << r.result.message;
    return HeldOut(after, r.result.model);
  };
  double planned = 0, random = 0, planned_before = 0;
  constexpr int kDraws = 8;
  for (int d = 0; d < kDraws; ++d) {
    planned += std::pow(held_out_of(with.plan.selected, 300 + d), 2) / kDraws;
    planned_before += std::pow(held_out_of(before.selected, 300 + d), 2) / kDraws;
    random += std::pow(held_out_of(RandomPlan(with.pool.size(), kPoses, 400 + d), 300 + d), 2) /
              kDraws;
  }
  planned = std::sqrt(planned);
  planned_before = std::sqrt(planned_before);
  random = std::sqrt(random);
  const double previous_as_is = HeldOut(after, model);
  std::cout << "held out (RMS over " << kDraws << " noise draws): planned " << planned
            << " mm, the plan without the term's prior " << planned_before << " mm, random "
            << random << " mm; the previous model as is " << previous_as_is << " mm\n";
  EXPECT_LT(planned, random);
  EXPECT_LT(planned, previous_as_is);
}

}  // namespace plan_prior_test
}  // namespace
}  // namespace lpoe
