// The `gear_ratio` joint-space term: a registry entry used end to end without any other
// source file naming it. Registry and regressor, YAML, simulation, and recovery of simulated ratios
// by both solvers, alone and with compliance, and as a candidate of --joint_errors=auto.
#include <algorithm>
#include <cmath>
#include <iostream>
#include <memory>
#include <numeric>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "lpoe/io/io.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/model/parameterization.h"
#include "lpoe/pipeline.h"
#include "lpoe/model/simulation.h"
#include "lpoe/model/statistics.h"

namespace lpoe {
namespace {
namespace gear_ratio_test {

constexpr char kGearRatio[] = "gear_ratio";

TEST(GearRatio, IsARegistryTermWithRegressorDiagQ) {
  const std::vector<std::string> names = JointTermNames();
  ASSERT_NE(std::find(names.begin(), names.end(), kGearRatio), names.end());
  const RobotModel m = MakeCobot6();
  std::shared_ptr<const JointTerm> term;
  ASSERT_TRUE(MakeJointTerm(kGearRatio, m, &term).ok());
  ASSERT_EQ(term->num_parameters(), m.num_joints());
  EXPECT_EQ(term->ParameterName(1), m.joints[1].name + ".s");
  const std::vector<double> q = {0.3, -2.9, 1.7, 0.0, -0.4, 3.1};
  Eigen::MatrixXd Y(6, 6);
  term->Regressor(q.data(), Y.data());
  for (int i = 0; i < 6; ++i) {
    for (int k = 0; k < 6; ++k) EXPECT_EQ(Y(i, k), i == k ? q[i] : 0.0) << i << "," << k;
    EXPECT_EQ(term->ParameterJoint(i), i);
  }
  // A model that carries it predicts at q + s q.
  RobotModel carrying = m;
  const std::vector<double> s = {1e-4, -2e-4, 3e-4, -4e-4, 5e-4, -6e-4};
  *carrying.joint_errors.MutableValues(kGearRatio) = s;
  ASSERT_TRUE(carrying.Validate().ok());
  std::vector<double> q_eff(6), scaled(6);
  EffectiveJoints(carrying, q.data(), q_eff.data());
  for (int j = 0; j < 6; ++j) {
    EXPECT_DOUBLE_EQ(q_eff[j], q[j] + s[j] * q[j]);
    scaled[j] = q[j] * (1 + s[j]);
  }
  EXPECT_LT((PredictToolPosition(carrying, q.data(), 0) - ToolPosition(m, scaled.data(), 0)).norm(),
            1e-9);
  // The wrong number of values is refused by Validate.
  carrying.joint_errors.MutableValues(kGearRatio)->pop_back();
  EXPECT_FALSE(carrying.Validate().ok());
}

TEST(GearRatio, YamlRoundTripAndUnknownTermNamesTheLine) {
  RobotModel model = MakeCobot6();
  *model.joint_errors.MutableValues(kGearRatio) = {2.5e-4, 0, -7.5e-4, 1e-3, 0, 3.3e-4};
  const std::string text = RobotModelToYaml(model);
  EXPECT_NE(text.find("  gear_ratio:\n    - joint: "), std::string::npos) << text;
  RobotModel back;
  Status s = ParseRobotModelYaml(text, "model.yaml", &back);
  ASSERT_TRUE(s.ok()) << s.message() << "\n" << text;
  EXPECT_EQ(back.joint_errors.Values(kGearRatio), model.joint_errors.Values(kGearRatio));
  EXPECT_EQ(RobotModelToYaml(back), text);  // written byte for byte the same again

  // A term the registry does not know: an error naming its line.
  std::string bad = text;
  const size_t at = bad.find("  gear_ratio:");
  ASSERT_NE(at, std::string::npos);
  bad.replace(at, 13, "  gear_ration:");
  const int line = 1 + static_cast<int>(std::count(bad.begin(), bad.begin() + at, '\n'));
  s = ParseRobotModelYaml(bad, "model.yaml", &back);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("model.yaml:" + std::to_string(line) + ":"), std::string::npos)
      << s.message();
  EXPECT_NE(s.message().find("gear_ration"), std::string::npos) << s.message();
}

// Cobot6 with random geometric errors and joint zeros; the actual robot carries the simulator's
// gear ratios (|s| in [1e-4, 1e-3]) and, with `compliance`, the small-arm compliance.
struct GearFixture {
  RobotModel nominal = MakeCobot6();
  RobotModel actual, truth;  // truth: joint zeros folded in
  MeasurementSet identification, verification;
  double noise = 0.005;
  explicit GearFixture(bool compliance) {
    nominal.payload.mass = 1.0;
    nominal.payload.com = Eigen::Vector3d(0, 0, 50);
    const KinematicErrors errors = RandomErrors(nominal, 2e-3, 0.5, 1e-3, 2e-3, 17);
    actual = ApplyErrors(nominal, errors);
    std::vector<std::string> terms = {kGearRatio};
    if (compliance) terms.insert(terms.begin(), "compliance");
    ApplyJointErrorPhysics(SmallArmJointErrors(nominal, SmallArmOptions()), terms, &actual);
    truth = FoldJointZeros(actual, errors.joint_zero);
    SimulationOptions options;
    options.count = 300;
    options.noise_sigma = noise;
    options.seed = 5;
    const MeasurementSet data = SimulateMeasurements(actual, errors.joint_zero, options);
    std::vector<int> id(200), ver(100);
    std::iota(id.begin(), id.end(), 0);
    std::iota(ver.begin(), ver.end(), 200);
    identification = data.Subset(id);
    verification = data.Subset(ver);
  }
};

PipelineResult Calibrate(const GearFixture& f, SolverKind solver, const std::vector<std::string>& terms,
                         bool automatic = false) {
  PipelineOptions o;
  o.solver = solver;
  o.register_frames = false;
  o.joint_errors = terms;
  o.joint_errors_auto = automatic;
  return RunCalibrationPipeline(f.nominal, f.identification, f.verification, o);
}

TEST(GearRatio, SimulationDrawsRatiosAndFoldsTheJointZeros) {
  const GearFixture f(false);
  const std::vector<double>& s = f.actual.joint_errors.Values(kGearRatio);
  ASSERT_EQ(s.size(), 6u);
  for (double v : s) {
    EXPECT_GE(std::abs(v), 1e-4);
    EXPECT_LE(std::abs(v), 1e-3);
  }
  EXPECT_EQ(f.truth.joint_errors.Values(kGearRatio), s);
  // The folded truth predicts the simulated measurements at the commanded joints (up to noise).
  std::vector<Eigen::Vector3d> residuals;
  for (int r = 0; r < f.verification.size(); ++r) {
    residuals.push_back(f.verification.position(r) -
                        PredictToolPosition(f.truth, f.verification.q(r),
                                            f.verification.target(r)));
  }
  EXPECT_LT(ComputeStatistics(residuals).norm.rms, 1.5 * std::sqrt(3.0) * f.noise);
}

// Each identified ratio against the truth.
void ExpectRatiosRecovered(const GearFixture& f, const PipelineResult& p, const char* what) {
  ASSERT_TRUE(p.result.converged()) << what << ": " << p.result.message;
  const std::vector<double>& truth = f.actual.joint_errors.Values(kGearRatio);
  const std::vector<double>& found = p.result.model.joint_errors.Values(kGearRatio);
  ASSERT_EQ(found.size(), truth.size()) << what << ": the ratios are not in the calibrated model";
  double sum2 = 0;
  for (size_t j = 0; j < truth.size(); ++j) {
    std::cout << what << " joint " << j + 1 << ": true " << truth[j] << ", identified " << found[j]
              << "\n";
    // Each within 10% of the smallest ratio simulated (1e-4); 0.005 mm of noise over 200 poses
    // leaves ~1e-6 on the shoulder and elbow, a few 1e-6 on the wrist joints (shorter lever).
    EXPECT_NEAR(found[j], truth[j], 1e-5) << what << " joint " << j + 1;
    sum2 += (found[j] - truth[j]) * (found[j] - truth[j]);
  }
  // And 3% of it as an RMS over the joints.
  EXPECT_LT(std::sqrt(sum2 / truth.size()), 3e-6) << what;
  // The calibrated model's YAML carries them.
  EXPECT_NE(RobotModelToYaml(p.result.model).find("gear_ratio:"), std::string::npos);
  const double noise_only = std::sqrt(3.0) * f.noise;
  EXPECT_LT(p.verification_after.norm.rms, 1.5 * noise_only) << what;
}

TEST(GearRatio, BothSolversRecoverSimulatedRatios) {
  const GearFixture f(false);
  const PipelineResult geometric = Calibrate(f, SolverKind::kLinear, {});
  const PipelineResult linear = Calibrate(f, SolverKind::kLinear, {kGearRatio});
  const PipelineResult ceres = Calibrate(f, SolverKind::kCeres, {kGearRatio});
  ASSERT_TRUE(geometric.result.converged()) << geometric.result.message;
  std::cout << "held-out RMS: geometry only " << geometric.verification_after.norm.rms
            << " mm, with gear_ratio " << linear.verification_after.norm.rms << " mm\n";
  // The ratios are not absorbed by the geometry (the joint offsets): leaving them out costs.
  EXPECT_GT(geometric.verification_after.norm.rms, 3 * linear.verification_after.norm.rms);
  ExpectRatiosRecovered(f, linear, "linear");
  ExpectRatiosRecovered(f, ceres, "ceres");
}

TEST(GearRatio, CombinesWithCompliance) {
  const GearFixture f(true);
  for (SolverKind solver : {SolverKind::kLinear, SolverKind::kCeres}) {
    const PipelineResult p = Calibrate(f, solver, {"compliance", kGearRatio});
    const char* what = solver == SolverKind::kLinear ? "linear compliance,gear_ratio"
                                                     : "ceres compliance,gear_ratio";
    ExpectRatiosRecovered(f, p, what);
    EXPECT_FALSE(p.result.model.joint_errors.Values("compliance").empty());
  }
}

// The rank logic (ReduceJointErrorTerms, the solvers' joint blocks) needs nothing term-specific:
// where a joint does not move over the data, its ratio error is a constant joint offset that the
// geometry already has, and that combination is left out; with the joint spanning +-pi it is kept.
TEST(GearRatio, AJointHeldStillLosesItsRatioToTheJointOffset) {
  const RobotModel model = MakeCobot6();
  SimulationOptions options;
  options.count = 150;
  options.seed = 9;
  options.lower.assign(6, -3.14159265358979);
  options.upper.assign(6, 3.14159265358979);
  const Parameterization p =
      MakeParameterization(model, ParameterizationKind::kIdentifiable, DataKind::kPosition);
  std::vector<JointErrorReduction> reductions;
  ASSERT_TRUE(ReduceJointErrorTerms(model, p, SimulateMeasurements(model, {}, options),
                                    {"harmonics", kGearRatio}, &reductions)
                  .ok());
  ASSERT_EQ(reductions.size(), 2u);
  EXPECT_EQ(reductions[1].term, kGearRatio);
  EXPECT_EQ(reductions[1].basis.cols(), 6);  // every joint's ratio, after the harmonics too
  constexpr int kStill = 3;                  // joint 4
  options.lower[kStill] = options.upper[kStill] = 0.7;
  ASSERT_TRUE(ReduceJointErrorTerms(model, p, SimulateMeasurements(model, {}, options),
                                    {kGearRatio}, &reductions)
                  .ok());
  EXPECT_EQ(reductions[0].rank_alone, 6);  // seen at the tool ...
  EXPECT_EQ(reductions[0].basis.cols(), 5);  // ... but as joint 4's offset: left out
  EXPECT_EQ(reductions[0].per_joint[kStill], 0);
  for (int c = 0; c < reductions[0].basis.cols(); ++c) {
    EXPECT_LT(std::abs(reductions[0].basis(kStill, c)), 1e-6) << c;
  }
}

// A joint whose motion does not move the tool (joint 6 with the tool on its axis) loses its ratio
// in the calibration as it loses its harmonics; both solvers still recover the others.
TEST(GearRatio, InvisibleJointIsLeftOutByBothSolvers) {
  const RobotModel nominal = MakeCobot6(Eigen::Vector3d(0, 0, 60));
  KinematicErrors errors = RandomErrors(nominal, 2e-3, 0.5, 1e-3, 2e-3, 17);
  // The actual tool on the actual joint 6 axis: no tilt of that axis (a tilt of 1e-3 rad puts a
  // point 60 mm up 0.06 mm off it, which these data (0.005 mm noise) see: the identifiability is
  // decided from the data, docs/identifiability.md).
  errors.twist[nominal.num_joints() - 1].setZero();
  RobotModel actual = ApplyErrors(nominal, errors);
  actual.tools[0].origin = nominal.tools[0].origin;  // keep the tool on joint 6's axis
  ApplyJointErrorPhysics(SmallArmJointErrors(nominal, SmallArmOptions()), {kGearRatio}, &actual);
  SimulationOptions options;
  options.count = 250;
  options.noise_sigma = 0.005;
  options.seed = 9;
  const MeasurementSet data = SimulateMeasurements(actual, errors.joint_zero, options);
  std::vector<int> id(200), ver(50);
  std::iota(id.begin(), id.end(), 0);
  std::iota(ver.begin(), ver.end(), 200);
  for (SolverKind solver : {SolverKind::kLinear, SolverKind::kCeres}) {
    PipelineOptions o;
    o.solver = solver;
    o.register_frames = false;
    o.joint_errors = {kGearRatio};
    const PipelineResult p = RunCalibrationPipeline(nominal, data.Subset(id), data.Subset(ver), o);
    ASSERT_TRUE(p.result.converged()) << p.result.message;
    ASSERT_EQ(p.result.parameterization.joint_blocks.size(), 1u);
    EXPECT_EQ(p.result.parameterization.joint_blocks[0].basis.cols(), 5);
    const std::vector<double>& truth = actual.joint_errors.Values(kGearRatio);
    const std::vector<double>& found = p.result.model.joint_errors.Values(kGearRatio);
    ASSERT_EQ(found.size(), 6u);
    EXPECT_LT(std::abs(found[5]), 1e-9);  // left out, not fitted to noise
    for (int j = 0; j < 5; ++j) EXPECT_NEAR(found[j], truth[j], 1e-5) << "joint " << j + 1;
    EXPECT_LT(p.verification_after.norm.rms, 1.5 * std::sqrt(3.0) * options.noise_sigma);
  }
}

TEST(GearRatio, AutoConsidersAndChoosesIt) {
  const GearFixture f(false);
  const PipelineResult p = Calibrate(f, SolverKind::kLinear, {}, /*automatic=*/true);
  ASSERT_TRUE(p.result.converged()) << p.result.message;
  const JointErrorSelection& s = p.joint_error_selection;
  ASSERT_GE(s.chosen, 0);
  bool listed = false;
  for (const JointErrorCandidate& c : s.candidates) {
    std::cout << "  " << c.label << ": " << c.parameters << " combinations, CV rms " << c.cv_rms
              << " mm" << (c.ok ? "" : " FAILED") << "\n";
    listed = listed || c.label == kGearRatio;
  }
  EXPECT_TRUE(listed);
  EXPECT_EQ(s.candidates[s.chosen].label, kGearRatio) << s.reason;
  const std::vector<double>& truth = f.actual.joint_errors.Values(kGearRatio);
  const std::vector<double>& found = p.result.model.joint_errors.Values(kGearRatio);
  ASSERT_EQ(found.size(), truth.size());
  for (size_t j = 0; j < truth.size(); ++j) EXPECT_NEAR(found[j], truth[j], 1e-5) << j + 1;
}

}  // namespace gear_ratio_test
}  // namespace
}  // namespace lpoe
