// The residual layer learned from ballbar distances and probe contacts (docs/residual_layer.md,
// "Projected observations"): the projected likelihood's gradient against finite differences, the
// projected posterior against a dense reference written here,
// nothing predicted along directions no row sees, and a simulated 6R arm with an error no model
// term explains, calibrated from ballbar distances at three pivots: the layer lowers the held-out
// distance error and the 3D position error (after rigid alignment) with both solvers, and a layer
// fitted on pure noise does not make the held-out error worse.
#include <cmath>
#include <cstdio>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Dense>
#include <gtest/gtest.h>

#include "lpoe/contact_calibration.h"
#include "lpoe/measurements/contact_measurements.h"
#include "lpoe/contact_pipeline.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/model/residual_layer.h"
#include "lpoe/model/simulation.h"

namespace lpoe {
namespace {
namespace contact_residual_layer_test {

// A smooth joint-dependent deflection (mm) that no frame, joint zero or registry term models:
// tens of micrometres, products of harmonics of the shoulder, elbow and wrist joints.
Eigen::Vector3d Unmodelled(const double* q) {
  return Eigen::Vector3d(0.030 * std::sin(q[1] + q[2]) * std::cos(q[0]),
                         0.025 * std::cos(q[1]) * std::sin(q[2] - q[0]),
                         0.020 * std::sin(q[3] + q[1]) * std::cos(q[4]));
}

// The squared-exponential kernel of `layer` (one tool).
double Kernel(const ResidualLayer& layer, const double* a, const double* b) {
  double d2 = 0;
  for (int j = 0; j < layer.num_joints; ++j) {
    const double d = (a[j] - b[j]) / layer.length_scales(j);
    d2 += d * d;
  }
  return layer.signal_std * layer.signal_std * std::exp(-0.5 * d2);
}

struct Projected {
  std::vector<double> q;
  std::vector<int> tools;
  std::vector<Eigen::Vector3d> u;
  std::vector<double> y;
};

// `rows` random configurations in [-1.2, 1.2] rad, each seeing Unmodelled along a direction of
// its own (random, or `fixed` when not zero) plus noise.
Projected MakeProjected(int rows, double noise, uint64_t seed,
                        const Eigen::Vector3d& fixed = Eigen::Vector3d::Zero()) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> uq(-1.2, 1.2);
  std::normal_distribution<double> g(0.0, 1.0);
  Projected p;
  for (int r = 0; r < rows; ++r) {
    double q[6];
    for (double& v : q) v = uq(rng);
    Eigen::Vector3d u = fixed;
    if (u.norm() == 0) u = Eigen::Vector3d(g(rng), g(rng), g(rng));
    u.normalize();
    p.q.insert(p.q.end(), q, q + 6);
    p.tools.push_back(0);
    p.u.push_back(u);
    p.y.push_back(u.dot(Unmodelled(q)) + noise * g(rng));
  }
  return p;
}

// The textbook DTC posterior (deterministic training conditional) of projected observations with
// the layer's hyperparameters and inducing inputs, dense: the inducing variables f are m's three
// components at each inducing input (f index 3 i + c, prior K_mm (x) I3 with the layer's jitter),
// row r sees Phi_r f with Phi_r(3 i + c) = k(q_r, z_i) u_r(c) (after K_mm^-1), so
//   Sigma = (K3 + Phi^T Phi / s_n^2)^-1 with Phi = Kn3 (the rows' cross-kernel with the
//   projection), a = Sigma Phi^T y / s_n^2, mean(x) = sum_i k(x, z_i) a_i,
//   var_c(x) = s_f^2 - k^T K_mm^-1 k + (k (x) e_c)^T Sigma (k (x) e_c).
struct DtcReference {
  Eigen::MatrixXd Kmm_inv, Sigma;
  Eigen::VectorXd a;
};

DtcReference Reference(const ResidualLayer& layer, const Projected& p) {
  const int m = layer.num_inducing(), N = static_cast<int>(p.y.size());
  Eigen::MatrixXd Kmm(m, m), Phi = Eigen::MatrixXd::Zero(N, 3 * m);
  for (int i = 0; i < m; ++i) {
    for (int k = 0; k < m; ++k) {
      Kmm(i, k) = Kernel(layer, layer.inducing_q.row(i).eval().data(),
                         layer.inducing_q.row(k).eval().data());
    }
  }
  Kmm.diagonal().array() += 1e-6 * layer.signal_std * layer.signal_std;  // kInducingJitter
  for (int r = 0; r < N; ++r) {
    for (int i = 0; i < m; ++i) {
      const double k = Kernel(layer, &p.q[6 * r], layer.inducing_q.row(i).eval().data());
      for (int c = 0; c < 3; ++c) Phi(r, 3 * i + c) = k * p.u[r](c);
    }
  }
  Eigen::MatrixXd K3 = Eigen::MatrixXd::Zero(3 * m, 3 * m);
  for (int i = 0; i < m; ++i) {
    for (int k = 0; k < m; ++k) K3.block<3, 3>(3 * i, 3 * k) = Kmm(i, k) * Eigen::Matrix3d::Identity();
  }
  DtcReference ref;
  ref.Kmm_inv = Kmm.inverse();
  const Eigen::MatrixXd K3_inv = K3.inverse();
  // Phi above holds k(q_r, z_i) u_r; the DTC projection of the rows is Phi K3^-1.
  const Eigen::MatrixXd A = Phi * K3_inv;
  const double sn2 = layer.noise_std * layer.noise_std;
  ref.Sigma = (K3_inv + A.transpose() * A / sn2).inverse();
  ref.a = K3_inv * ref.Sigma * A.transpose() * Eigen::Map<const Eigen::VectorXd>(p.y.data(), N) /
          sn2;
  // In terms of f: mean f = Sigma A^T y / sn2; m(x) = k^T Kmm^-1 f (per component), stored as
  // a = K3^-1 f so that m(x) = sum_i k(x, z_i) a_i.
  return ref;
}

Eigen::Vector3d ReferenceMean(const ResidualLayer& layer, const DtcReference& ref, const double* x) {
  Eigen::Vector3d m = Eigen::Vector3d::Zero();
  for (int i = 0; i < layer.num_inducing(); ++i) {
    m += Kernel(layer, x, layer.inducing_q.row(i).eval().data()) * ref.a.segment<3>(3 * i);
  }
  return m;
}

// The mean over the three components of the posterior variance at x.
double ReferenceVariance(const ResidualLayer& layer, const DtcReference& ref, const double* x) {
  const int m = layer.num_inducing();
  Eigen::VectorXd k(m);
  for (int i = 0; i < m; ++i) k(i) = Kernel(layer, x, layer.inducing_q.row(i).eval().data());
  // Posterior of f (prior K3): the component's variance s_f^2 - k^T Kmm^-1 k + k^T Kmm^-1 S_cc
  // Kmm^-1 k with S the posterior covariance of f.
  const Eigen::VectorXd w = ref.Kmm_inv * k;
  double sum = 0;
  for (int c = 0; c < 3; ++c) {
    Eigen::VectorXd wc = Eigen::VectorXd::Zero(3 * m);
    for (int i = 0; i < m; ++i) wc(3 * i + c) = w(i);
    sum += layer.signal_std * layer.signal_std - k.dot(w) + wc.dot(ref.Sigma * wc);
  }
  return sum / 3;
}

TEST(ContactResidualLayer, ProjectedPosteriorEqualsADenseDtcReference) {
  const Projected train = MakeProjected(150, 0.002, 11);
  ResidualLayerOptions options;
  options.max_inducing = 60;
  ResidualLayer layer;
  ResidualLayerFit fit;
  const Status s = FitResidualLayerProjected(train.q, train.tools, train.u, train.y, 6, 1, options,
                                             &layer, &fit);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_LT(layer.num_inducing(), 100);  // sparse: fewer inducing inputs than rows
  ASSERT_NE(fit.chosen_start, 2) << "the fit found no signal in a 30 um deflection";
  const DtcReference ref = Reference(layer, train);
  const Projected test = MakeProjected(40, 0.0, 12);
  double scale = 0, worst_mean = 0, worst_std = 0;
  for (size_t r = 0; r < test.y.size(); ++r) {
    const double* x = &test.q[6 * r];
    const Eigen::Vector3d got = layer.Mean(x, 0), want = ReferenceMean(layer, ref, x);
    scale = std::max(scale, want.norm());
    worst_mean = std::max(worst_mean, (got - want).norm());
    worst_std = std::max(worst_std,
                         std::abs(layer.Std(x, 0) - std::sqrt(ReferenceVariance(layer, ref, x))));
  }
  std::printf("projected DTC vs dense reference: largest mean %.3g mm, |difference| %.3g mm; "
              "std difference %.3g mm (signal %.3g mm)\n",
              scale, worst_mean, worst_std, layer.signal_std);
  EXPECT_GT(scale, 0.005);  // the layer predicts something
  EXPECT_LT(worst_mean, 1e-8 * scale);
  EXPECT_LT(worst_std, 1e-6 * layer.signal_std);
}

// The projected likelihood's gradient (kernel (u_a . u_b) k, the configuration's term too)
// against central finite differences.
TEST(ContactResidualLayer, ProjectedLikelihoodGradientMatchesFiniteDifferences) {
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<double> uni(-1.0, 1.0);
  const int N = 36, n = 3;
  Eigen::MatrixXd X(N, n), Y(N, 1), U(N, 3);
  std::vector<int> tools(N), configuration(N);
  for (int i = 0; i < N; ++i) {
    for (int j = 0; j < n; ++j) X(i, j) = uni(rng);
    U.row(i) = Eigen::RowVector3d(uni(rng), uni(rng), uni(rng)).normalized();
    Y(i, 0) = 0.04 * std::sin(2 * X(i, 0)) * U(i, 0) + 0.02 * X(i, 1) * U(i, 2) + 0.005 * uni(rng);
    tools[i] = i % 2;
    configuration[i] = i / 2;  // pairs of rows at one stop
  }
  for (bool with_configuration : {false, true}) {
    const std::vector<int>* groups = with_configuration ? &configuration : nullptr;
    Eigen::VectorXd theta(n + 1 + 2 + (with_configuration ? 1 : 0));
    theta.head(n) << std::log(0.6), std::log(1.1), std::log(0.5);
    theta(n) = std::log(0.9);
    theta(n + 1) = std::log(0.03);
    theta(n + 2) = std::log(0.006);
    if (with_configuration) theta(n + 3) = std::log(0.004);
    Eigen::VectorXd gradient;
    internal::GpLogMarginalLikelihood(theta, true, X, tools, Y, &gradient, groups, &U);
    ASSERT_EQ(gradient.size(), theta.size());
    for (int i = 0; i < theta.size(); ++i) {
      const double h = 1e-6;
      Eigen::VectorXd tp = theta, tm = theta;
      tp(i) += h;
      tm(i) -= h;
      const double fd =
          (internal::GpLogMarginalLikelihood(tp, true, X, tools, Y, nullptr, groups, &U) -
           internal::GpLogMarginalLikelihood(tm, true, X, tools, Y, nullptr, groups, &U)) /
          (2 * h);
      EXPECT_NEAR(gradient(i), fd, 1e-5 * (1 + std::abs(fd)))
          << "parameter " << i << " configurations " << with_configuration;
    }
  }
}

// Probe contacts on one plane see only its normal: the layer predicts nothing across it (a GP
// with projected observations gives the other components no data and no coupling).
TEST(ContactResidualLayer, NothingIsPredictedAlongDirectionsNoRowSees) {
  const Eigen::Vector3d normal = Eigen::Vector3d(0.3, -0.5, 0.8).normalized();
  const Projected train = MakeProjected(120, 0.002, 21, normal);
  ResidualLayer layer;
  ResidualLayerOptions options;
  options.max_inducing = 80;
  ASSERT_TRUE(
      FitResidualLayerProjected(train.q, train.tools, train.u, train.y, 6, 1, options, &layer).ok());
  const Projected test = MakeProjected(30, 0.0, 22);
  double along = 0, across = 0;
  for (size_t r = 0; r < test.y.size(); ++r) {
    const Eigen::Vector3d m = layer.Mean(&test.q[6 * r], 0);
    along = std::max(along, std::abs(normal.dot(m)));
    across = std::max(across, (m - normal.dot(m) * normal).norm());
  }
  std::printf("one plane: largest correction along its normal %.3g mm, across it %.3g mm\n",
              along, across);
  EXPECT_GT(along, 0.003);
  EXPECT_LT(across, 1e-12 + 1e-9 * along);
}

// ---------------------------------------------------------------------------------------------
// The stand-in: the contact tests' 6R arm (frame errors of about 1 mm and 3 mrad, joint zeros
// 0.01 rad) plus Unmodelled, a 150 mm bar at three pivots, 0.002 mm noise.

struct Arm {
  RobotModel nominal, truth;
  bool unmodelled = true;
  Eigen::Vector3d True(const double* q, int tool) const {
    Eigen::Vector3d p = ToolPosition(truth, q, tool);
    if (unmodelled) p += Unmodelled(q);
    return p;
  }
};

Arm MakeArm(bool unmodelled) {
  Arm a;
  a.nominal = MakeCobot6();
  const KinematicErrors e = RandomErrors(a.nominal, 0.003, 1.0, 0.0, 0.01, 44);
  a.truth = FoldJointZeros(ApplyErrors(a.nominal, e), e.joint_zero);
  a.unmodelled = unmodelled;
  return a;
}

// `count` ballbar rows (SimulateBallbar's configurations) read on the true arm plus noise.
ContactMeasurementSet Ballbar(const Arm& arm, int count, uint64_t seed) {
  BallbarSimulationOptions o;
  o.count = count;
  o.bar_length = 150;
  o.noise = 0;
  o.num_pivots = 3;
  o.seed = seed;
  ContactMeasurementSet out;
  std::vector<Eigen::Vector3d> pivots;
  EXPECT_TRUE(SimulateBallbar(arm.truth, o, &out, &pivots).ok());
  std::mt19937_64 rng(seed + 1000);
  std::normal_distribution<double> gauss(0.0, 0.002);
  for (int r = 0; r < out.size(); ++r) {
    ContactRow& row = out.rows[r];
    row.value = (arm.True(out.joints(r), row.target) - pivots[row.feature]).norm() + gauss(rng);
    row.sigma = 0.002;
  }
  return out;
}

// RMS (mm) of predicted from true positions after the best rigid alignment (the base is not seen).
double AlignedRms(const std::vector<Eigen::Vector3d>& predicted,
                  const std::vector<Eigen::Vector3d>& truth) {
  const int m = static_cast<int>(predicted.size());
  Eigen::Matrix3Xd A(3, m), B(3, m);
  for (int i = 0; i < m; ++i) {
    A.col(i) = predicted[i];
    B.col(i) = truth[i];
  }
  const Eigen::Matrix4d T = Eigen::umeyama(A, B, false);
  const Eigen::Matrix3Xd moved = (T.topLeftCorner<3, 3>() * A).colwise() + T.topRightCorner<3, 1>();
  return std::sqrt((moved - B).colwise().squaredNorm().mean());
}

struct StandIn {
  Arm arm;
  ContactMeasurementSet identification, held;
  StandIn(bool unmodelled, uint64_t seed) : arm(MakeArm(unmodelled)) {
    const ContactMeasurementSet all = Ballbar(arm, 450, seed);
    std::vector<int> id, ho;
    // The rows cycle through the pivots: every third triple held out (each pivot in both).
    for (int r = 0; r < all.size(); ++r) ((r / 3) % 3 == 2 ? ho : id).push_back(r);
    identification = all.Subset(id);
    held = all.Subset(ho);
  }
  ContactPipelineResult Run(ResidualModelKind kind, const std::string& solver, int kfold = 0) const {
    ContactPipelineOptions o;
    o.solver = solver;
    o.residual_model = kind;
    o.kfold = kfold;
    return RunContactPipeline(arm.nominal, identification, held, o);
  }
  // The 3D position error on the held-out configurations after rigid alignment.
  double HeldOutPositionRms(const RobotModel& model) const {
    std::vector<Eigen::Vector3d> predicted, truth;
    for (int r = 0; r < held.size(); ++r) {
      predicted.push_back(PredictToolPosition(model, held.joints(r), held.rows[r].target));
      truth.push_back(arm.True(held.joints(r), held.rows[r].target));
    }
    return AlignedRms(predicted, truth);
  }
};

double DistanceRms(const ContactPipelineResult& run, bool held) {
  for (const ContactKindSummary& k : run.kinds) {
    if (k.kind->id == MeasurementKindId::kDistance) return held ? k.held.rms : k.fit.rms;
  }
  return -1;
}

TEST(ContactResidualLayerStandIn, BallbarLayerLowersHeldOutDistanceAndPositionErrors) {
  const StandIn s(true, 5);
  const StandIn floor(false, 5);  // the same arm and configurations without the unmodelled error
  const ContactPipelineResult base = floor.Run(ResidualModelKind::kNone, "linear");
  ASSERT_TRUE(base.ok) << base.message;
  const double floor_distance = DistanceRms(base, true);
  const double floor_position = floor.HeldOutPositionRms(base.calibration.model);
  for (const char* solver : {"linear", "ceres"}) {
    const ContactPipelineResult none = s.Run(ResidualModelKind::kNone, solver);
    const ContactPipelineResult gp = s.Run(ResidualModelKind::kGp, solver);
    ASSERT_TRUE(none.ok && gp.ok) << none.message << gp.message;
    ASSERT_TRUE(gp.residual_layer.fitted) << gp.residual_layer.message;
    const ResidualLayer& layer = *gp.calibration.model.residual_layer;
    const double d_none = DistanceRms(none, true), d_gp = DistanceRms(gp, true);
    const double p_none = s.HeldOutPositionRms(none.calibration.model);
    const double p_gp = s.HeldOutPositionRms(gp.calibration.model);
    // The pipeline's held-out figures without the layer are the parametric model's.
    EXPECT_NEAR(gp.kinds[0].held_parametric.rms, d_none, 1e-9);
    std::printf("%s: %d identification / %d held-out rows; held-out distance RMS %.5f mm without "
                "the layer, %.5f mm with it (floor %.5f mm); 3D position RMS after alignment "
                "%.5f mm without, %.5f mm with (floor %.5f mm); %d inducing inputs, signal %.4f mm, "
                "noise %.4f mm, chose start %d; length scales",
                solver, s.identification.size(), s.held.size(), d_none, d_gp, floor_distance,
                p_none, p_gp, floor_position, layer.num_inducing(), layer.signal_std,
                layer.noise_std, gp.residual_layer.fit.chosen_start);
    for (int j = 0; j < 6; ++j) std::printf(" %.3g", layer.length_scales(j));
    std::printf("\n");
    EXPECT_GT(d_none, 2 * floor_distance);  // the unmodelled error shows in the distances
    // At least a third of the unmodelled part of the held-out distance error removed.
    EXPECT_LT(d_gp, d_none - (d_none - floor_distance) / 3) << solver;
    EXPECT_LT(p_gp, p_none) << solver;
  }
  // auto: the cross-validation of the identification rows chooses the layer.
  const ContactPipelineResult automatic = s.Run(ResidualModelKind::kAuto, "linear");
  ASSERT_TRUE(automatic.ok) << automatic.message;
  const ResidualModelSelection& sel = automatic.residual_model_selection;
  ASSERT_TRUE(sel.ran);
  std::printf("auto: CV RMS none %.5f mm, gp %.5f mm; %s\n", sel.candidates[0].cv_rms,
              sel.candidates[1].cv_rms, sel.reason.c_str());
  EXPECT_EQ(sel.candidates[sel.chosen].label, "gp") << sel.reason;
  EXPECT_TRUE(automatic.residual_layer.fitted);
}

// k-fold: each fold's figure with its own layer, beside the figure without it.
TEST(ContactResidualLayerStandIn, KFoldReportsWithAndWithoutTheFoldsLayer) {
  const StandIn s(true, 6);
  const ContactPipelineResult gp = s.Run(ResidualModelKind::kGp, "linear", 4);
  ASSERT_TRUE(gp.ok) << gp.message;
  ASSERT_TRUE(gp.residual_layer.fitted) << gp.residual_layer.message;
  const ContactPipelineResult none = s.Run(ResidualModelKind::kNone, "linear", 4);
  ASSERT_TRUE(none.ok) << none.message;
  const ContactKindSummary& k = gp.kinds[0];
  std::printf("k-fold distance RMS %.5f mm without the layer, %.5f mm with each fold's\n",
              k.kfold_parametric.rms, k.kfold.rms);
  EXPECT_NEAR(k.kfold_parametric.rms, none.kinds[0].kfold.rms, 1e-9);
  EXPECT_LT(k.kfold.rms, k.kfold_parametric.rms);
}

// With no unmodelled error the residual is noise: a forced layer may find no signal or a small
// one, and the held-out error does not get worse (1 % allowed: a fit of ten hyperparameters).
TEST(ContactResidualLayerStandIn, PureNoiseLayerDoesNotMakeHeldOutWorse) {
  const StandIn s(false, 7);
  const ContactPipelineResult none = s.Run(ResidualModelKind::kNone, "linear");
  const ContactPipelineResult gp = s.Run(ResidualModelKind::kGp, "linear");
  ASSERT_TRUE(none.ok && gp.ok) << none.message << gp.message;
  ASSERT_TRUE(gp.residual_layer.fitted) << gp.residual_layer.message;
  const ResidualLayerFit& fit = gp.residual_layer.fit;
  const double p_none = s.HeldOutPositionRms(none.calibration.model);
  const double p_gp = s.HeldOutPositionRms(gp.calibration.model);
  std::printf("pure noise: held-out distance RMS %.5f mm without the layer, %.5f mm with it; 3D "
              "position RMS after alignment %.5f mm without, %.5f mm with; held-out RMS of the "
              "starts %.5f %.5f, of no signal %.5f, chose %d\n",
              DistanceRms(none, true), DistanceRms(gp, true), p_none, p_gp, fit.start_loo_rms[0],
              fit.start_loo_rms[1], fit.start_loo_rms[2], fit.chosen_start);
  EXPECT_LE(DistanceRms(gp, true), 1.01 * DistanceRms(none, true));
  // In 3D a signal learned from noise moves the prediction by a fraction of the rows' noise
  // (0.002 mm) at most.
  EXPECT_LE(p_gp, p_none + 0.25 * 0.002);
  // auto keeps none.
  const ContactPipelineResult automatic = s.Run(ResidualModelKind::kAuto, "linear");
  ASSERT_TRUE(automatic.ok) << automatic.message;
  const ResidualModelSelection& sel = automatic.residual_model_selection;
  ASSERT_TRUE(sel.ran);
  std::printf("pure noise, auto: CV RMS none %.5f mm, gp %.5f mm; %s\n", sel.candidates[0].cv_rms,
              sel.candidates[1].cv_rms, sel.reason.c_str());
  EXPECT_EQ(sel.candidates[sel.chosen].label, "none") << sel.reason;
  EXPECT_FALSE(automatic.calibration.model.residual_layer);
}

}  // namespace contact_residual_layer_test
}  // namespace
}  // namespace lpoe
