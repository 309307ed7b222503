// The learned residual layer (lpoe/model/residual_layer.h, docs/residual_layer.md): its derivatives
// against finite differences, its storage, its prediction far from the data, the pipeline's gp and
// auto on a simulated arm with an error no term models and on one whose residual is noise, and the
// inverse kinematics through it.
#include "lpoe/model/residual_layer.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Dense>
#include <gtest/gtest.h>

#include "lpoe/inverse_kinematics.h"
#include "lpoe/io/io.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/pipeline.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/model/simulation.h"
#include "lpoe/model/statistics.h"
#include "model/level3_workspace.h"
#include "unmodelled_arm.h"

namespace lpoe {
namespace {
namespace residual_layer_test {

// A smooth joint-dependent deflection (mm) no registry term models.
Eigen::Vector3d Deflection(const double* q) {
  const double a = 0.05 * std::sin(q[1] + q[2]) * std::cos(q[0]);
  return Eigen::Vector3d(a, -0.6 * a, 0.03 * std::cos(q[1]) * std::sin(q[2] - q[0]));
}

// A layer fitted on `rows` random configurations of cobot6 (two tools) with residual Deflection +
// noise.
ResidualLayer FitOnDeflection(int rows, double noise, uint64_t seed, int max_inducing = 256) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1.5, 1.5);
  std::normal_distribution<double> g(0.0, noise);
  std::vector<double> q;
  std::vector<int> tools;
  std::vector<Eigen::Vector3d> e;
  for (int r = 0; r < rows; ++r) {
    double qr[6];
    for (double& v : qr) v = u(rng);
    q.insert(q.end(), qr, qr + 6);
    tools.push_back(r % 2);
    e.push_back(Deflection(qr) + Eigen::Vector3d(g(rng), g(rng), g(rng)) +
                Eigen::Vector3d(0, 0, r % 2 ? 0.01 : 0.0));
  }
  ResidualLayerOptions options;
  options.max_inducing = max_inducing;
  ResidualLayer layer;
  const Status s = FitResidualLayer(q, tools, e, 6, 2, options, &layer);
  EXPECT_TRUE(s.ok()) << s.message();
  return layer;
}

RobotModel TwoToolCobot() {
  RobotModel m = MakeCobot6(Eigen::Vector3d(40, 0, 60));
  Tool second = m.tools[0];
  second.name = "smr2";
  second.origin.t = Eigen::Vector3d(-35, 30, 55);
  m.tools.push_back(second);
  return m;
}

TEST(ResidualLayer, MarginalLikelihoodGradientMatchesFiniteDifferences) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const int N = 40, n = 3;
  Eigen::MatrixXd X(N, n), Y(N, 3);
  std::vector<int> tools(N);
  for (int i = 0; i < N; ++i) {
    for (int j = 0; j < n; ++j) X(i, j) = u(rng);
    tools[i] = i % 3 == 0 ? 1 : 0;
    Y.row(i) << 0.05 * std::sin(2 * X(i, 0)) + 0.01 * u(rng), 0.03 * X(i, 1) * X(i, 2),
        0.01 * u(rng);
  }
  // Rows in configurations of up to three (the tools measured at one stop).
  std::vector<int> configuration(N);
  for (int i = 0; i < N; ++i) configuration[i] = i / 3;
  for (bool with_configuration : {false, true}) {
    const std::vector<int>* groups = with_configuration ? &configuration : nullptr;
    for (bool with_tool : {false, true}) {
      Eigen::VectorXd theta(n + (with_tool ? 1 : 0) + 2 + (with_configuration ? 1 : 0));
      theta.head(n) << std::log(0.7), std::log(1.3), std::log(0.4);
      int k = n;
      if (with_tool) theta(k++) = std::log(0.8);
      theta(k++) = std::log(0.04);
      theta(k++) = std::log(0.012);
      if (with_configuration) theta(k) = std::log(0.009);
      Eigen::VectorXd gradient;
      internal::GpLogMarginalLikelihood(theta, with_tool, X, tools, Y, &gradient, groups);
      ASSERT_EQ(gradient.size(), theta.size());
      for (int i = 0; i < theta.size(); ++i) {
        const double h = 1e-6;
        Eigen::VectorXd tp = theta, tm = theta;
        tp(i) += h;
        tm(i) -= h;
        const double fd =
            (internal::GpLogMarginalLikelihood(tp, with_tool, X, tools, Y, nullptr, groups) -
             internal::GpLogMarginalLikelihood(tm, with_tool, X, tools, Y, nullptr, groups)) /
            (2 * h);
        EXPECT_NEAR(gradient(i), fd, 1e-5 * (1 + std::abs(fd)))
            << "parameter " << i << " with_tool " << with_tool << " configurations "
            << with_configuration;
      }
    }
  }
}

// The closed form of the leave-one-configuration-out errors equals predicting each configuration's
// rows from the others' (exact GP, the same hyperparameters; a configuration's shared error does
// not reach the others).
TEST(ResidualLayer, LeaveOneConfigurationOutIsThePredictionFromTheOthers) {
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const int N = 30, n = 2;
  Eigen::MatrixXd X(N, n), Y(N, 3);
  std::vector<int> tools(N), configuration(N);
  for (int i = 0; i < N; ++i) {
    configuration[i] = i / 2;
    tools[i] = i % 2;
    if (i % 2 == 0) {
      for (int j = 0; j < n; ++j) X(i, j) = u(rng);
    } else {
      X.row(i) = X.row(i - 1);
    }
    Y.row(i) << std::sin(2 * X(i, 0)) + 0.1 * u(rng), X(i, 1) + 0.1 * u(rng), 0.1 * u(rng);
  }
  Eigen::VectorXd theta(n + 4);
  theta << std::log(0.6), std::log(0.9), std::log(1.5), std::log(0.7), std::log(0.05),
      std::log(0.08);
  const double loo =
      internal::GpLeaveOneConfigurationOut(theta, true, X, tools, Y, &configuration);
  const double sf2 = 0.49, sn2 = 0.0025, rho = std::exp(-1.0 / (1.5 * 1.5));
  auto kse = [&](int a, int b) {
    const double d0 = (X(a, 0) - X(b, 0)) / 0.6, d1 = (X(a, 1) - X(b, 1)) / 0.9;
    return sf2 * std::exp(-0.5 * (d0 * d0 + d1 * d1)) * (tools[a] == tools[b] ? 1.0 : rho);
  };
  double sum = 0;
  for (int g = 0; g < N / 2; ++g) {
    std::vector<int> others;
    for (int i = 0; i < N; ++i) {
      if (configuration[i] != g) others.push_back(i);
    }
    const int m = static_cast<int>(others.size());
    Eigen::MatrixXd K(m, m), Yo(m, 3);
    for (int a = 0; a < m; ++a) {
      for (int b = 0; b < m; ++b) {
        K(a, b) = kse(others[a], others[b]) +
                  (configuration[others[a]] == configuration[others[b]] ? 0.0064 : 0.0) +
                  (a == b ? sn2 + 1e-8 * sf2 : 0.0);
      }
      Yo.row(a) = Y.row(others[a]);
    }
    const Eigen::MatrixXd alpha = K.llt().solve(Yo);
    for (int i = 2 * g; i < 2 * g + 2; ++i) {
      Eigen::RowVectorXd k(m);
      for (int a = 0; a < m; ++a) k(a) = kse(i, others[a]);
      sum += (Y.row(i) - k * alpha).squaredNorm();
    }
  }
  EXPECT_NEAR(loo, sum / N, 1e-7 * sum / N);
}

TEST(ResidualLayer, MeanJacobianMatchesFiniteDifferences) {
  const ResidualLayer layer = FitOnDeflection(300, 0.01, 5);
  ASSERT_GT(layer.num_inducing(), 10);
  std::mt19937_64 rng(9);
  std::uniform_real_distribution<double> u(-1.2, 1.2);
  for (int trial = 0; trial < 5; ++trial) {
    double q[6];
    for (double& v : q) v = u(rng);
    Eigen::Matrix<double, 3, 6> J;
    const Eigen::Vector3d m = layer.Mean(q, trial % 2, J.data());
    EXPECT_GT(m.norm(), 1e-4);  // a real correction there
    for (int j = 0; j < 6; ++j) {
      const double h = 1e-6;
      double qp[6], qm[6];
      std::copy(q, q + 6, qp);
      std::copy(q, q + 6, qm);
      qp[j] += h;
      qm[j] -= h;
      const Eigen::Vector3d fd =
          (layer.Mean(qp, trial % 2) - layer.Mean(qm, trial % 2)) / (2 * h);
      EXPECT_LT((J.col(j) - fd).norm(), 1e-8 + 1e-6 * fd.norm()) << "joint " << j + 1;
    }
  }
}

TEST(ResidualLayer, LearnsTheDeflectionAndReturnsToZeroFarAway) {
  const ResidualLayer layer = FitOnDeflection(400, 0.005, 7);
  // Inside the data: the deflection within a few noise levels.
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> u(-1.2, 1.2);
  double sum = 0, sum_truth = 0;
  for (int trial = 0; trial < 200; ++trial) {
    double q[6];
    for (double& v : q) v = u(rng);
    const Eigen::Vector3d truth = Deflection(q) + Eigen::Vector3d(0, 0, trial % 2 ? 0.01 : 0.0);
    sum += (layer.Mean(q, trial % 2) - truth).squaredNorm();
    sum_truth += truth.squaredNorm();
    EXPECT_LT(layer.Std(q, trial % 2), layer.signal_std);
  }
  EXPECT_LT(std::sqrt(sum / 200), 0.25 * std::sqrt(sum_truth / 200));
  // Far from every identification configuration (joints 2 and 3 far outside [-1.5, 1.5]): no
  // correction, the parametric model's prediction, and the prior's standard deviation.
  RobotModel model = TwoToolCobot();
  const RobotModel parametric = model;
  model.residual_layer = std::make_shared<const ResidualLayer>(layer);
  ASSERT_TRUE(model.Validate().ok()) << model.Validate().message();
  const double far[6] = {0.3, 2.9 + 12 * layer.length_scales(1), -2.9 - 12 * layer.length_scales(2),
                         0.2, 0.1, 0.0};
  EXPECT_GT(layer.KernelDistance(far), 10.0);
  for (int tool = 0; tool < 2; ++tool) {
    EXPECT_LT((PredictToolPosition(model, far, tool) - PredictToolPosition(parametric, far, tool))
                  .norm(),
              1e-9);
    EXPECT_NEAR(layer.Std(far, tool), layer.signal_std, 1e-12);
  }
}

TEST(ResidualLayer, YamlRoundTripReproducesPredictions) {
  RobotModel model = TwoToolCobot();
  model.residual_layer = std::make_shared<const ResidualLayer>(FitOnDeflection(200, 0.01, 13, 64));
  const std::string text = RobotModelToYaml(model);
  RobotModel back;
  const Status s = ParseRobotModelYaml(text, "calibrated.yaml", &back);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_TRUE(back.residual_layer);
  EXPECT_EQ(RobotModelToYaml(back), text);  // written byte for byte the same again
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> u(-1.5, 1.5);
  std::vector<double> q;
  std::vector<int> targets;
  for (int r = 0; r < 100; ++r) {
    for (int j = 0; j < 6; ++j) q.push_back(u(rng));
    targets.push_back(r % 2);
  }
  std::vector<Eigen::Vector3d> a, b;
  ASSERT_TRUE(PredictPositions(model, q, targets, 0, &a).ok());
  ASSERT_TRUE(PredictPositions(back, q, targets, 0, &b).ok());
  double largest_correction = 0;
  for (int r = 0; r < 100; ++r) {
    EXPECT_LT((a[r] - b[r]).norm(), 1e-9);
    EXPECT_NEAR(model.residual_layer->Std(&q[6 * r], r % 2),
                back.residual_layer->Std(&q[6 * r], r % 2), 1e-12);
    largest_correction =
        std::max(largest_correction, model.residual_layer->Mean(&q[6 * r], r % 2).norm());
  }
  EXPECT_GT(largest_correction, 0.01);  // the layer is there and matters
}

// Replaces the first occurrence of `from` (after `after`) in `text`; returns its 1-based line.
int Replace(std::string* text, const std::string& after, const std::string& from,
            const std::string& to) {
  const size_t start = text->find(after);
  EXPECT_NE(start, std::string::npos) << after;
  const size_t at = text->find(from, start);
  EXPECT_NE(at, std::string::npos) << from;
  text->replace(at, from.size(), to);
  return 1 + static_cast<int>(std::count(text->begin(), text->begin() + at, '\n'));
}

TEST(ResidualLayer, BadYamlBlocksAreRejectedWithFileAndLine) {
  RobotModel model = TwoToolCobot();
  model.residual_layer = std::make_shared<const ResidualLayer>(FitOnDeflection(60, 0.01, 19, 8));
  const std::string good = RobotModelToYaml(model);
  struct Case {
    std::string after, from, to, expect;
  } cases[] = {
      {"residual_layer:", "  kernel: se_ard", "  kernel: matern", "kernel is not se_ard"},
      {"residual_layer:", "  frame: base", "  frame: tracker", "frame is not base"},
      {"residual_layer:", "  signal_std: ", "  signal_std: -", "out of range"},
      {"residual_layer:", "  tool_correlation: ", "  tool_correlation: 1", "out of range"},
      {"residual_layer:", "  length_scales: [", "  length_scales: [0, ", "length_scales"},
      {"residual_layer:", "  inducing_tools: [", "  inducing_tools: [7, ", "inducing_tools"},
      {"  weights:", "    - [", "    - [1, ", "'weights' row 1"},
      {"  variance:", "    - [", "    - [oops, ", "'variance' row 1"},
      {"residual_layer:", "  noise_std:", "  noise_sd:", "unknown key"},
  };
  for (const Case& c : cases) {
    std::string bad = good;
    const int line = Replace(&bad, c.after, c.from, c.to);
    RobotModel back;
    const Status s = ParseRobotModelYaml(bad, "m.yaml", &back);
    ASSERT_FALSE(s.ok()) << c.to;
    EXPECT_NE(s.message().find("m.yaml:" + std::to_string(line) + ":"), std::string::npos)
        << c.to << ": " << s.message();
    EXPECT_NE(s.message().find(c.expect), std::string::npos) << c.to << ": " << s.message();
  }
  // A missing block key names the block's line.
  std::string bad = good;
  const size_t at = bad.find("  weights:");
  const size_t end = bad.find("  variance:");
  bad.erase(at, end - at);
  RobotModel back;
  const Status s = ParseRobotModelYaml(bad, "m.yaml", &back);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("has no 'weights'"), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("m.yaml:"), std::string::npos) << s.message();
}

// Cobot6 with two SMRs tens of mm off the nominal tool point, random geometric errors and joint
// zeros, measured by a tracker metres away (noise 0.015 mm per axis), plus `deflection` times the
// smooth joint-dependent error no term models.
struct Arm {
  RobotModel nominal = TwoToolCobot();
  MeasurementSet identification, verification;
  double noise = 0.015;
  Arm(double deflection, uint64_t seed) {
    const KinematicErrors errors = RandomErrors(nominal, 2e-3, 0.5, 1e-3, 2e-3, seed);
    RobotModel actual = ApplyErrors(nominal, errors);
    actual.tools[0].origin.t += Eigen::Vector3d(12, -20, 15);
    actual.tools[1].origin.t += Eigen::Vector3d(-18, 10, 22);
    SimulationOptions options;
    options.count = 360;
    options.noise_sigma = noise;
    options.seed = seed + 1;
    options.all_tools = true;
    options.lower.assign(6, -1.6);
    options.upper.assign(6, 1.6);
    MeasurementSet data = SimulateMeasurements(actual, errors.joint_zero, options);
    const SE3d tracker(RotationFromRpy(0.02, -0.01, 2.1), Eigen::Vector3d(2400, -1300, 350));
    for (int r = 0; r < data.size(); ++r) {
      data.mutable_position(r) =
          tracker * (data.position(r) + deflection * Deflection(data.q(r)));
    }
    // Sequential 70/30 split by configuration (rows pose by pose, both SMRs at each pose).
    std::vector<int> id, ver;
    for (int r = 0; r < data.size(); ++r) (r < 0.7 * data.size() ? id : ver).push_back(r);
    identification = data.Subset(id);
    verification = data.Subset(ver);
  }
};

PipelineResult Calibrate(const Arm& arm, ResidualModelKind kind, SolverKind solver) {
  PipelineOptions o;
  o.solver = solver;
  o.residual_model = kind;
  return RunCalibrationPipeline(arm.nominal, arm.identification, arm.verification, o);
}

TEST(ResidualLayerPipeline, GpReachesTheNoiseFloorHeldOutAndAutoChoosesIt) {
  const Arm arm(1.0, 23);
  // The noise floor of the held-out error norm: sqrt(3) sigma.
  const double floor = std::sqrt(3.0) * arm.noise;
  const PipelineResult none = Calibrate(arm, ResidualModelKind::kNone, SolverKind::kLinear);
  ASSERT_TRUE(none.result.converged()) << none.result.message;
  EXPECT_FALSE(none.result.model.residual_layer);
  EXPECT_GT(none.verification_after.norm.rms, 1.3 * floor);
  for (SolverKind solver : {SolverKind::kLinear, SolverKind::kCeres}) {
    const PipelineResult gp = Calibrate(arm, ResidualModelKind::kGp, solver);
    ASSERT_TRUE(gp.result.converged()) << gp.result.message;
    ASSERT_TRUE(gp.residual_layer.fitted) << gp.residual_layer.message;
    ASSERT_TRUE(gp.result.model.residual_layer);
    EXPECT_LT(gp.verification_after.norm.rms, 1.15 * floor)
        << "without the layer " << gp.residual_layer.verification_parametric.norm.rms;
    EXPECT_NEAR(gp.residual_layer.verification_parametric.norm.rms, none.verification_after.norm.rms,
                1e-3 * none.verification_after.norm.rms);
    // The calibrated model predicts the held-out points with its layer (PredictToolPosition).
    double sum = 0;
    for (int r = 0; r < arm.verification.size(); ++r) {
      sum += (arm.verification.position(r) -
              PredictToolPosition(gp.result.model, arm.verification.q(r),
                                  arm.verification.target(r)))
                 .squaredNorm();
    }
    EXPECT_NEAR(std::sqrt(sum / arm.verification.size()), gp.verification_after.norm.rms, 1e-9);
    std::printf("deflection, %s: held-out %.6f mm with the layer, %.6f without (floor %.6f)\n",
                solver == SolverKind::kLinear ? "linear" : "ceres", gp.verification_after.norm.rms,
                gp.residual_layer.verification_parametric.norm.rms, floor);
  }
  const PipelineResult automatic = Calibrate(arm, ResidualModelKind::kAuto, SolverKind::kLinear);
  const ResidualModelSelection& sel = automatic.residual_model_selection;
  ASSERT_TRUE(sel.ran);
  ASSERT_EQ(sel.candidates.size(), 2u);
  std::printf("deflection, auto: cv RMS none %.6f gp %.6f mm, chose %d; held-out %.6f mm\n",
              sel.candidates[0].cv_rms, sel.candidates[1].cv_rms, sel.chosen,
              automatic.verification_after.norm.rms);
  EXPECT_EQ(sel.candidates[sel.chosen].label, "gp") << sel.reason;
  EXPECT_LT(sel.candidates[1].cv_rms, 0.8 * sel.candidates[0].cv_rms);
  EXPECT_TRUE(automatic.residual_layer.fitted);
  EXPECT_LT(automatic.verification_after.norm.rms, 1.15 * floor);
}

TEST(ResidualLayerPipeline, PureNoiseResidualMakesAutoChooseNone) {
  const Arm arm(0.0, 29);
  const PipelineResult none = Calibrate(arm, ResidualModelKind::kNone, SolverKind::kLinear);
  const PipelineResult automatic = Calibrate(arm, ResidualModelKind::kAuto, SolverKind::kLinear);
  ASSERT_TRUE(automatic.result.converged());
  const ResidualModelSelection& sel = automatic.residual_model_selection;
  ASSERT_TRUE(sel.ran);
  EXPECT_EQ(sel.candidates[sel.chosen].label, "none") << sel.reason;
  EXPECT_FALSE(automatic.result.model.residual_layer);
  EXPECT_LE(automatic.verification_after.norm.rms, 1.01 * none.verification_after.norm.rms);
  // gp on noise: no worse than 1% either (its signal shrinks to nothing).
  const PipelineResult gp = Calibrate(arm, ResidualModelKind::kGp, SolverKind::kLinear);
  ASSERT_TRUE(gp.residual_layer.fitted);
  std::printf("noise: cv RMS none %.6f gp %.6f mm, chose %d; held-out none %.6f auto %.6f gp %.6f mm\n",
              sel.candidates[0].cv_rms, sel.candidates[1].cv_rms, sel.chosen,
              none.verification_after.norm.rms, automatic.verification_after.norm.rms,
              gp.verification_after.norm.rms);
  EXPECT_LE(gp.verification_after.norm.rms, 1.01 * none.verification_after.norm.rms);
}

TEST(ResidualLayerPipeline, WithJointSpaceTermsThePredictionIsTheTermsPlusTheLayer) {
  const Arm arm(1.0, 43);
  PipelineOptions o;
  o.joint_errors = {"compliance"};
  o.residual_model = ResidualModelKind::kGp;
  const PipelineResult gp =
      RunCalibrationPipeline(arm.nominal, arm.identification, arm.verification, o);
  ASSERT_TRUE(gp.residual_layer.fitted) << gp.residual_layer.message;
  ASSERT_FALSE(gp.result.model.joint_errors.empty());
  // The held-out figure is the calibrated model's own prediction: terms and layer together.
  double sum = 0;
  for (int r = 0; r < arm.verification.size(); ++r) {
    sum += (arm.verification.position(r) -
            PredictToolPosition(gp.result.model, arm.verification.q(r), arm.verification.target(r)))
               .squaredNorm();
  }
  EXPECT_NEAR(std::sqrt(sum / arm.verification.size()), gp.verification_after.norm.rms, 1e-9);
  std::printf("terms and layer: held-out %.6f mm, without the layer %.6f mm\n",
              gp.verification_after.norm.rms, gp.residual_layer.verification_parametric.norm.rms);
  EXPECT_LT(gp.verification_after.norm.rms, 0.8 * gp.residual_layer.verification_parametric.norm.rms);
}

TEST(ResidualLayerPipeline, KFoldIncludesTheFoldsOwnLayer) {
  const Arm arm(1.0, 31);
  PipelineOptions o;
  o.kfold = 3;
  const PipelineResult none = RunCalibrationPipeline(arm.nominal, arm.identification,
                                                     arm.verification, o);
  o.residual_model = ResidualModelKind::kGp;
  const PipelineResult gp = RunCalibrationPipeline(arm.nominal, arm.identification,
                                                   arm.verification, o);
  ASSERT_EQ(gp.folds.size(), 3u);
  std::printf("k-fold pooled: %.6f mm with the layer, %.6f mm without\n", gp.folds_pooled.norm.rms,
              none.folds_pooled.norm.rms);
  EXPECT_LT(gp.folds_pooled.norm.rms, 0.8 * none.folds_pooled.norm.rms);
}

TEST(ResidualLayerIk, CompensationReachesTheTargetsTheLayeredModelPredicts) {
  RobotModel model = TwoToolCobot();
  // A layer with corrections of about 0.05 mm over the working range.
  model.residual_layer = std::make_shared<const ResidualLayer>(FitOnDeflection(300, 0.005, 37, 128));
  const InverseKinematics ik(model);
  std::mt19937_64 rng(41);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (int trial = 0; trial < 10; ++trial) {
    double q_true[6], seed[6], q[6];
    for (int j = 0; j < 6; ++j) {
      q_true[j] = u(rng);
      seed[j] = q_true[j] + 0.05 * u(rng);
    }
    const int tool = trial % 2;
    IkTarget target;
    target.tool = tool;
    target.position = PredictToolPosition(model, q_true, tool);
    const IkResult r = ik.Solve(target, seed, q);
    ASSERT_NE(r.status, IkStatus::kUnreachable) << trial;
    EXPECT_LT((PredictToolPosition(model, q, tool) - target.position).norm(), 1e-6) << trial;
    EXPECT_LT(r.position_error, 1e-6);
    // The layer mattered: the parametric model alone is off at these joints by its correction.
    RobotModel parametric = model;
    parametric.residual_layer = nullptr;
    EXPECT_GT((PredictToolPosition(parametric, q, tool) - target.position).norm(), 1e-4) << trial;
  }
}

// ---- The stand-in for a real arm (tests/unmodelled_arm.h): cobot6 with three SMRs,
// frame errors, tracker noise 0.01 mm and repeatability 0.01 mm per axis, and an unmodelled error of
// 0.08 mm per axis (0.14 mm RMS norm) drawn from a GP with length scales 0.6, 0.8 and 1.0 rad on
// joints 4-6, every joint within [-1.6, 1.6] rad. Identification and verification by configuration
// (70 / 30, both at random configurations).
struct StandIn {
  testing::UnmodelledArm arm;
  MeasurementSet identification, verification;
  StandIn(double unmodelled_std, int configurations, uint64_t seed)
      : arm(testing::MakeUnmodelledArm(unmodelled_std, Eigen::Vector3d(0.6, 0.8, 1.0), 0.01, 0.01,
                                       seed)) {
    std::mt19937_64 rng(seed + 3);
    std::uniform_real_distribution<double> u(-1.6, 1.6);
    std::vector<double> q(6 * configurations);
    for (double& v : q) v = u(rng);
    const MeasurementSet data = arm.Measure(q, seed + 4);
    std::vector<int> id, ver;
    for (int r = 0; r < data.size(); ++r) (r < 0.7 * data.size() ? id : ver).push_back(r);
    identification = data.Subset(id);
    verification = data.Subset(ver);
  }
};

// The number of configurations of the stand-in tests: 1000 as the arm with
// LPOE_RESIDUAL_STUDY=1, else 600 (the tests' run time: two calibrations and a cross-validated
// layer take about ten seconds in the dev build, more under ASan).
int StandInConfigurations() {
  const char* study = std::getenv("LPOE_RESIDUAL_STUDY");
  return study != nullptr && std::string(study) == "1" ? 1000 : 600;
}

PipelineResult CalibrateStandIn(const StandIn& s, ResidualModelKind kind) {
  PipelineOptions o;
  o.solver = SolverKind::kLinear;
  o.residual_model = kind;
  return RunCalibrationPipeline(s.arm.nominal, s.identification, s.verification, o);
}

// Done when: the layer's length scales within a factor 2 of the truth's, the held-out
// error reduced by at least half the unmodelled part, and auto choosing the layer.
TEST(ResidualLayerStandIn, AutoChoosesALayerWithTheTruthsLengthScalesThatHalvesTheUnmodelledError) {
  const int configurations = StandInConfigurations();
  const StandIn with(0.08, configurations, 101);
  const StandIn without(0.0, configurations, 101);  // the same arm, noise and configurations
  const PipelineResult floor = CalibrateStandIn(without, ResidualModelKind::kNone);
  const PipelineResult none = CalibrateStandIn(with, ResidualModelKind::kNone);
  const PipelineResult automatic = CalibrateStandIn(with, ResidualModelKind::kAuto);
  ASSERT_TRUE(automatic.result.converged()) << automatic.result.message;
  const ResidualModelSelection& sel = automatic.residual_model_selection;
  ASSERT_TRUE(sel.ran);
  EXPECT_EQ(sel.candidates[sel.chosen].label, "gp") << sel.reason;
  ASSERT_TRUE(automatic.residual_layer.fitted) << automatic.residual_layer.message;
  const ResidualLayer& layer = *automatic.result.model.residual_layer;
  const ResidualLayerFit& fit = automatic.residual_layer.fit;
  const double held_out_floor = floor.verification_after.norm.rms;
  const double held_out_none = none.verification_after.norm.rms;
  const double held_out_layer = automatic.verification_after.norm.rms;
  std::printf("stand-in, %d configurations x 3 SMRs: held-out RMS without the unmodelled error "
              "%.5f mm, with it %.5f mm, with the layer %.5f mm; length scales",
              configurations, held_out_floor, held_out_none, held_out_layer);
  for (int j = 0; j < 6; ++j) std::printf(" %.3g", layer.length_scales(j));
  std::printf(" (spacing");
  for (int j = 0; j < 6; ++j) std::printf(" %.3g", fit.spacing(j));
  std::printf("); configuration error %.4f mm; %d inducing inputs; LOO RMS of the starts %.5f "
              "%.5f, of no signal %.5f, chose %d\n",
              fit.configuration_std, layer.num_inducing(), fit.start_loo_rms[0],
              fit.start_loo_rms[1], fit.start_loo_rms[2], fit.chosen_start);
  EXPECT_NE(fit.chosen_start, 2);
  const double truth[3] = {0.6, 0.8, 1.0};
  for (int j = 3; j < 6; ++j) {
    EXPECT_GT(layer.length_scales(j), 0.5 * truth[j - 3]) << "joint " << j + 1;
    EXPECT_LT(layer.length_scales(j), 2.0 * truth[j - 3]) << "joint " << j + 1;
  }
  // Joints 1-3 do not matter: longer than the data's range of 3.2 rad.
  for (int j = 0; j < 3; ++j) EXPECT_GT(layer.length_scales(j), 3.2) << "joint " << j + 1;
  EXPECT_TRUE(JointsBelowSpacing(layer.length_scales, fit.spacing).empty());
  EXPECT_GT(held_out_none, 2 * held_out_floor);  // the unmodelled error dominates
  EXPECT_LT(held_out_layer, held_out_none - 0.5 * (held_out_none - held_out_floor));
}

// The arm's repeatability is shared by the SMRs of a configuration: without the configuration's
// own error term the likelihood explains it by length scales so short that the kernel matrix is
// that of the configurations alone. With pure noise (no unmodelled error) auto keeps none.
TEST(ResidualLayerStandIn, PureNoiseAndRepeatabilityMakeAutoChooseNone) {
  const StandIn noise(0.0, 300, 103);
  const PipelineResult automatic = CalibrateStandIn(noise, ResidualModelKind::kAuto);
  ASSERT_TRUE(automatic.result.converged()) << automatic.result.message;
  const ResidualModelSelection& sel = automatic.residual_model_selection;
  ASSERT_TRUE(sel.ran);
  EXPECT_EQ(sel.candidates[sel.chosen].label, "none") << sel.reason;
  EXPECT_FALSE(automatic.result.model.residual_layer);
  // A forced layer finds nothing its fit's own cross-validation trusts: no signal, and the held-out
  // error of the parametric model.
  const PipelineResult gp = CalibrateStandIn(noise, ResidualModelKind::kGp);
  ASSERT_TRUE(gp.residual_layer.fitted) << gp.residual_layer.message;
  std::printf("pure noise, forced layer: LOO RMS of the starts %.5f %.5f, of no signal %.5f, "
              "chose %d; held-out %.5f mm, without the layer %.5f mm\n",
              gp.residual_layer.fit.start_loo_rms[0], gp.residual_layer.fit.start_loo_rms[1],
              gp.residual_layer.fit.start_loo_rms[2], gp.residual_layer.fit.chosen_start,
              gp.verification_after.norm.rms, automatic.verification_after.norm.rms);
  EXPECT_LE(gp.verification_after.norm.rms, 1.01 * automatic.verification_after.norm.rms);
}

// The likelihood's triangular solves and products and the planning selector's general products
// with packing buffers kept between calls (core/src/model/level3_workspace.h) give bit for bit what
// Eigen's expressions give, at sizes
// below and above Eigen's stack limit for those buffers (128 KB), on blocks with an outer stride
// as the likelihood uses them, and with one workspace reused over growing and shrinking sizes.
TEST(Level3Workspace, BitIdenticalToEigensExpressions) {
  std::mt19937_64 rng(23);
  std::normal_distribution<double> g(0.0, 1.0);
  auto random = [&](Eigen::Index rows, Eigen::Index cols) {
    Eigen::MatrixXd m(rows, cols);
    for (Eigen::Index i = 0; i < m.size(); ++i) m.data()[i] = g(rng);
    return m;
  };
  auto same_bits = [](const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
    if (a.rows() != b.rows() || a.cols() != b.cols()) return false;
    for (Eigen::Index i = 0; i < a.size(); ++i) {
      if (std::memcmp(&a.data()[i], &b.data()[i], sizeof(double)) != 0) return false;
    }
    return true;
  };
  internal::Level3Workspace w;
  int compared = 0;
  for (const int N : {7, 300, 40, 613, 130}) {
    const Eigen::MatrixXd R = random(N, N);
    Eigen::MatrixXd K = R * R.transpose() / N;
    K.diagonal().array() += 0.5;
    const Eigen::LLT<Eigen::MatrixXd> llt(K);
    ASSERT_EQ(llt.info(), Eigen::Success);
    const Eigen::MatrixXd& L = llt.matrixLLT();  // its strict upper triangle holds K's
    for (const int cols : {1, 3, 48}) {
      for (const int j0 : {0, N / 3}) {
        const Eigen::Index size = N - j0;
        const Eigen::MatrixXd start = random(N, cols);
        // Lower solve on a block of L with the outer stride of L, in place in a block of a larger
        // matrix.
        Eigen::MatrixXd expected = start, got = start;
        L.block(j0, j0, size, size)
            .triangularView<Eigen::Lower>()
            .solveInPlace(expected.bottomRows(size));
        w.LowerSolveInPlace(L.block(j0, j0, size, size), got.bottomRows(size));
        EXPECT_TRUE(same_bits(expected, got)) << "lower solve N " << N << " cols " << cols;
        // Transposed lower solve (the second half of LLT::solve).
        expected = start;
        got = start;
        L.block(j0, j0, size, size)
            .transpose()
            .triangularView<Eigen::Upper>()
            .solveInPlace(expected.bottomRows(size));
        w.LowerTransposeSolveInPlace(L.block(j0, j0, size, size), got.bottomRows(size));
        EXPECT_TRUE(same_bits(expected, got)) << "transposed solve N " << N << " cols " << cols;
        // The whole solve equals LLT::solve.
        if (j0 == 0) {
          got = start;
          w.LowerSolveInPlace(L, got);
          w.LowerTransposeSolveInPlace(L, got);
          EXPECT_TRUE(same_bits(llt.solve(start), got)) << "LLT solve N " << N << " cols " << cols;
        }
        // Transposed lower triangle times a block, into a block of a larger matrix (the strict
        // upper triangle of L is not read: it holds K's entries).
        if (cols <= size) {
          Eigen::MatrixXd expected_dst = random(N, N), got_dst = expected_dst;
          expected_dst.block(j0, j0, size, cols).noalias() =
              L.block(j0, j0, size, size).transpose().triangularView<Eigen::Upper>() *
              start.block(j0, 0, size, cols);
          w.LowerTransposeTimes(L.block(j0, j0, size, size), start.block(j0, 0, size, cols),
                                got_dst.block(j0, j0, size, cols));
          EXPECT_TRUE(same_bits(expected_dst, got_dst)) << "product N " << N << " cols " << cols;
        }
        ++compared;
      }
    }
  }
  EXPECT_EQ(compared, 30);
  // The general product (the planning selector's chunk updates): a row-major block of rows times a
  // column-major matrix, and column-major times column-major, at sizes Eigen evaluates
  // coefficient by coefficient, as matrix-vector products and by its blocked kernel.
  using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
  int products = 0;
  for (const int rows : {3, 1, 4000, 700, 1500}) {
    for (const int depth : {1, 6, 40}) {
      for (const int cols : {1, 2, 6}) {
        const RowMatrix J = random(rows + 5, depth);
        const Eigen::MatrixXd U = random(depth, cols);
        const Eigen::MatrixXd expected = J.middleRows(2, rows) * U;
        Eigen::MatrixXd got = random(3, 3);  // resized
        w.Product(J.middleRows(2, rows), U, &got);
        EXPECT_TRUE(same_bits(expected, got))
            << "product " << rows << " x " << depth << " x " << cols;
        const Eigen::MatrixXd K = random(cols, cols);
        const Eigen::MatrixXd expected_k = expected * K;
        Eigen::MatrixXd got_k;
        w.Product(got, K, &got_k);
        EXPECT_TRUE(same_bits(expected_k, got_k)) << "product by " << cols << " x " << cols;
        ++products;
      }
    }
  }
  EXPECT_EQ(products, 45);
}

}  // namespace residual_layer_test
}  // namespace
}  // namespace lpoe
