// The fleet prior where it matters to a user (docs/recalibration.md, "A new robot of a known
// type"): 8 robots of one type calibrated over their workspace at commissioning, and a ninth
// measured with 20 poses where its cell lets the tracker see them (a narrow region, one joint that
// barely moves), held out over the whole workspace. Realistic magnitudes: a UR5-like 6R arm with 3
// SMRs off the flange axis, a tracker 3 m away, commanded joint values, noise 0.02 mm per axis,
// joint harmonics of a few hundredths of a mrad that no calibration here models (always present),
// and a fleet whose deviation from the drawing is partly the type's (shared) and partly each
// robot's own.
// The linear theory also measures a likelihood with correlated unmodelled error (generalized least
// squares; docs/recalibration.md, "A likelihood with correlated unmodelled error"), which is not in
// the library because it does not pay here.
#include <gtest/gtest.h>

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "lpoe/terms/joint_errors.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/model/model_covariance.h"
#include "lpoe/model/parameterization.h"
#include "lpoe/pipeline.h"
#include "lpoe/planning.h"
#include "lpoe/model/prior.h"
#include "lpoe/recalibration.h"
#include "lpoe/registration.h"
#include "lpoe/model/residual_layer.h"
#include "lpoe/model/simulation.h"
#include "three_smr_cell.h"

namespace lpoe {
namespace {
namespace fleet_prior_test {

constexpr double kNoise = 0.02;

RobotModel Drawing() { return testing::ThreeSmrUr5(); }

SE3d Tracker(uint64_t seed) { return testing::TrackerThreeMetresAway(seed, 0.05); }

struct Robot {
  RobotModel actual;  // its geometry and its (unmodelled) joint harmonics
  std::vector<double> zero;
};

// a * x + b * y, per entry.
KinematicErrors Combined(double a, const KinematicErrors& x, double b, const KinematicErrors& y) {
  KinematicErrors out = x;
  for (size_t f = 0; f < x.frame.size(); ++f) out.frame[f] = a * x.frame[f] + b * y.frame[f];
  for (size_t j = 0; j < x.twist.size(); ++j) out.twist[j] = a * x.twist[j] + b * y.twist[j];
  for (size_t j = 0; j < x.joint_zero.size(); ++j) {
    out.joint_zero[j] = a * x.joint_zero[j] + b * y.joint_zero[j];
  }
  return out;
}

// A robot's own deviation from the type (0.2 mm, 0.3 mrad, zeros 0.5 mrad per parameter at most,
// the same spread as before) is half its own and half shared manufacturing (in variance): a
// robot of a series is made by the same processes (a casting batch, the machining of the links,
// the jig the wrist is assembled in, the fixture the zeros are set with), and each process's
// variation moves many parameters of every frame together in a pattern of its own. The model:
//     own = sqrt(1/2) independent + sqrt(1/2) sum_k z_k pattern_k / sqrt(3),
// three processes, each pattern a fixed deviation of the whole chain at the same tolerances (the
// type's: drawn once, seed 77), z_k ~ N(0, 1) per robot; the independent part drawn per robot. So
// every parameter has the variance it had with everything independent, and the robots' deviations
// are correlated across frames as a series' are. The joint harmonics (each gearbox's) are
// independent.
constexpr int kProcesses = 3;
KinematicErrors OwnDeviation(const RobotModel& type, uint64_t seed) {
  const KinematicErrors independent = RandomErrors(type, 0.0003, 0.2, 0.0002, 0.0005, seed);
  KinematicErrors own = Combined(std::sqrt(0.5), independent, 0.0, independent);
  std::mt19937_64 rng(seed + 11);
  std::normal_distribution<double> z(0.0, 1.0);
  for (int k = 0; k < kProcesses; ++k) {
    const KinematicErrors pattern = RandomErrors(type, 0.0003, 0.2, 0.0002, 0.0005, 77 + k);
    own = Combined(1.0, own, std::sqrt(0.5 / kProcesses) * z(rng), pattern);
  }
  return own;
}

// A robot of the type: its own deviation (above) and harmonics of about 0.03 mrad per joint.
constexpr double kHarmonicStd = 3e-5;  // rad, each harmonic coefficient
Robot Member(const RobotModel& type, uint64_t seed) {
  const KinematicErrors e = OwnDeviation(type, seed);
  Robot r{ApplyErrors(type, e), e.joint_zero};
  JointErrorPhysics physics;
  physics.stiffness.assign(r.actual.num_joints(), 0.0);  // rigid: the harmonics only
  std::mt19937_64 rng(seed + 7);
  std::normal_distribution<double> h(0.0, kHarmonicStd);
  for (int j = 0; j < r.actual.num_joints(); ++j) {
    physics.harmonics.push_back(Eigen::Vector4d(h(rng), h(rng), h(rng), h(rng)));
  }
  ApplyJointErrorPhysics(physics, {"harmonics"}, &r.actual);
  return r;
}

// `poses` configurations uniform in [lower, upper] per joint, every SMR at each, in tracker frame T.
MeasurementSet Measure(const Robot& r, int poses, uint64_t seed, const SE3d& T, double noise,
                       const std::vector<double>& lower, const std::vector<double>& upper) {
  std::mt19937_64 rng(seed);
  SimulationOptions o;
  o.all_tools = true;
  for (int c = 0; c < poses; ++c) {
    for (int j = 0; j < 6; ++j) {
      o.configurations.push_back(std::uniform_real_distribution<double>(lower[j], upper[j])(rng));
    }
  }
  o.noise_sigma = noise;
  o.seed = seed + 1;
  const MeasurementSet d = SimulateMeasurements(r.actual, r.zero, o);
  MeasurementSet out(d.num_joints());
  for (int k = 0; k < d.size(); ++k) out.Add(d.q(k), T * d.position(k), d.target(k));
  return out;
}

const std::vector<double> kWorkspaceLower(6, -kPi), kWorkspaceUpper(6, kPi);
// The ninth robot's cell: what the tracker sees of it there (joint 6 barely moves).
const std::vector<double> kCellLower = {-0.5, -2.0, 0.6, -2.2, 1.0, -0.1};
const std::vector<double> kCellUpper = {0.5, -1.0, 1.8, -0.8, 2.0, 0.1};

// RMS distance of a model's SMRs from the robot's over the whole workspace (noise-free, with its
// harmonics), after a rigid fit of the model into that frame.
double HeldOut(const Robot& r, const RobotModel& model) {
  const MeasurementSet fresh = Measure(r, 300, 4242, SE3d(), 0.0, kWorkspaceLower, kWorkspaceUpper);
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

// ---- What a covariance across frames would give (a linearized comparison, not the library's
// estimator: docs/recalibration.md, Limitations). The frame parameters of `pm` (its identifiable
// directions, x_f = B_f^T xi_f) of `m` against `mean`.
Eigen::VectorXd FrameCoordinates(const PlanningModel& pm, const RobotModel& mean,
                                 const RobotModel& m) {
  const Parameterization& p = pm.parameterization();
  Eigen::VectorXd x = Eigen::VectorXd::Zero(p.num_frame_parameters());
  for (size_t f = 0; f < p.basis.size(); ++f) {
    if (p.basis[f].cols() == 0) continue;
    x.segment(p.offset[f], p.basis[f].cols()) =
        p.basis[f].transpose() * FrameDeviation(mean, m, static_cast<int>(f));
  }
  return x;
}

// Orthonormal basis of the registration's directions in x (the base frame's, and those of joint
// 2's frame that commute with joint 1), as the planner leaves them out.
Eigen::MatrixXd RegistrationDirections(const PlanningModel& pm) {
  const Parameterization& par = pm.parameterization();
  const RobotModel& m = pm.model();
  const int P = par.num_frame_parameters();
  std::vector<Eigen::VectorXd> rigid;
  for (int c = 0; c < par.basis[0].cols(); ++c) {
    rigid.push_back(Eigen::VectorXd::Unit(P, par.offset[0] + c));
  }
  const Eigen::MatrixXd U =
      Adjoint(m.joints[1].origin.Inverse()) * TwistCentralizer(m.joints[0].twist);
  for (int c = 0; c < U.cols(); ++c) {
    Eigen::VectorXd v = Eigen::VectorXd::Zero(P);
    v.segment(par.offset[1], par.basis[1].cols()) = par.basis[1].transpose() * U.col(c);
    rigid.push_back(v);
  }
  Eigen::MatrixXd R(P, static_cast<Eigen::Index>(rigid.size()));
  for (size_t k = 0; k < rigid.size(); ++k) R.col(static_cast<Eigen::Index>(k)) = rigid[k];
  const Eigen::HouseholderQR<Eigen::MatrixXd> qr(R);
  return (qr.householderQ() * Eigen::MatrixXd::Identity(P, P)).leftCols(R.cols());
}

// The square root of a PSD matrix and its pseudo-inverse (on its range).
void SqrtAndInverseSqrt(const Eigen::MatrixXd& S, Eigen::MatrixXd* root, Eigen::MatrixXd* inv_root) {
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(0.5 * (S + S.transpose()));
  const Eigen::VectorXd l = eig.eigenvalues();
  const double top = l.cwiseAbs().maxCoeff();
  Eigen::VectorXd r(l.size()), ir(l.size());
  for (int k = 0; k < l.size(); ++k) {
    r(k) = l(k) > 1e-12 * top ? std::sqrt(l(k)) : 0.0;
    ir(k) = r(k) > 0 ? 1.0 / r(k) : 0.0;
  }
  *root = eig.eigenvectors() * r.asDiagonal() * eig.eigenvectors().transpose();
  *inv_root = eig.eigenvectors() * ir.asDiagonal() * eig.eigenvectors().transpose();
}

// Fleet covariances of x (the registration's directions `Q` projected out): per frame the
// predictive covariance (what FleetPrior writes), and the same blocks with their cross-frame
// correlations, shrunk toward none (Ledoit-Wolf in the block-whitened coordinates, the intensity
// `lambda` from the robots' own scatter).
void FleetCovariances(const PlanningModel& pm, const std::vector<Eigen::VectorXd>& xs,
                      const Eigen::MatrixXd& Q, Eigen::MatrixXd* block, Eigen::MatrixXd* full,
                      double* lambda) {
  const Parameterization& par = pm.parameterization();
  const int P = par.num_frame_parameters();
  const int N = static_cast<int>(xs.size());
  const Eigen::MatrixXd Np = Eigen::MatrixXd::Identity(P, P) - Q * Q.transpose();
  Eigen::VectorXd mu = Eigen::VectorXd::Zero(P);
  for (const auto& x : xs) mu += Np * x / N;
  Eigen::MatrixXd X(P, N);
  for (int k = 0; k < N; ++k) X.col(k) = Np * xs[k] - mu;
  const Eigen::MatrixXd S = X * X.transpose() / (N - 1);
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(P, P), W_inv = Eigen::MatrixXd::Zero(P, P);
  *block = Eigen::MatrixXd::Zero(P, P);
  for (size_t f = 0; f < par.basis.size(); ++f) {
    const int k = static_cast<int>(par.basis[f].cols()), o = par.offset[f];
    if (k == 0) continue;
    const Eigen::MatrixXd Sf = S.block(o, o, k, k);
    const double c = FleetPredictiveFactor(N, k);
    Eigen::MatrixXd root, inv_root;
    SqrtAndInverseSqrt(Sf, &root, &inv_root);
    A.block(o, o, k, k) = std::sqrt(c) * root;
    W_inv.block(o, o, k, k) = inv_root;
    block->block(o, o, k, k) = c * Sf;
  }
  // Block-whitened deviations: their sample covariance has (projector) diagonal blocks and the
  // cross-frame correlations off them.
  const Eigen::MatrixXd Z = W_inv * X;
  const Eigen::MatrixXd Wz = Z * Z.transpose() / (N - 1);
  // Ledoit-Wolf: the off-block entries' estimated variance over their squares.
  double num = 0, den = 0;
  for (size_t f = 0; f < par.basis.size(); ++f) {
    for (size_t g = 0; g < par.basis.size(); ++g) {
      if (f == g) continue;
      for (int i = 0; i < par.basis[f].cols(); ++i) {
        for (int j = 0; j < par.basis[g].cols(); ++j) {
          const int a = par.offset[f] + i, b = par.offset[g] + j;
          double v = 0;
          for (int k = 0; k < N; ++k) v += std::pow(Z(a, k) * Z(b, k) - Wz(a, b), 2);
          num += v / (static_cast<double>(N) * N);
          den += Wz(a, b) * Wz(a, b);
        }
      }
    }
  }
  *lambda = den > 0 ? std::clamp(num / den, 0.0, 1.0) : 1.0;
  Eigen::MatrixXd R = Wz;
  for (size_t f = 0; f < par.basis.size(); ++f) {
    for (size_t g = 0; g < par.basis.size(); ++g) {
      if (f == g) continue;
      R.block(par.offset[f], par.offset[g], par.basis[f].cols(), par.basis[g].cols()) *=
          1 - *lambda;
    }
  }
  *full = A * R * A.transpose();
}

// The linearized MAP about the mean of the data (positions in the mean model's base frame), with
// prior covariance `C` off the registration's directions (null: least squares), the data weighed
// with s; its held-out RMS over the workspace after a rigid fit.
double LinearizedMapHeldOut(const PlanningModel& pm, const RobotModel& mean, const Robot& r,
                            const MeasurementSet& data, const Eigen::MatrixXd& Q,
                            const Eigen::MatrixXd* C, double s,
                            const Eigen::MatrixXd* row_kernel = nullptr) {
  const int P = pm.parameterization().num_frame_parameters();
  Eigen::MatrixXd H = Eigen::MatrixXd::Zero(P, P);
  Eigen::VectorXd g = Eigen::VectorXd::Zero(P);
  Eigen::MatrixXd J;
  // The data registered into the mean model's base frame first (a rigid fit, as the pipeline's
  // registration: the mean's base frame is an average of the robots' registrations).
  std::vector<Eigen::Vector3d> at, nominal;
  for (int k = 0; k < data.size(); ++k) {
    at.push_back(data.position(k));
    nominal.push_back(PredictToolPosition(mean, data.q(k), data.target(k)));
  }
  SE3d registration;
  EXPECT_TRUE(FitRigidTransform(at, nominal, &registration).ok());
  Eigen::MatrixXd J_all(3 * data.size(), P);
  Eigen::VectorXd y_all(3 * data.size());
  for (int k = 0; k < data.size(); ++k) {
    pm.Rows(data.q(k), {data.target(k)}, &J);
    J_all.middleRows(3 * k, 3) = J;
    y_all.segment<3>(3 * k) = registration * at[k] - nominal[k];
  }
  if (row_kernel == nullptr) {
    H = J_all.transpose() * J_all / (s * s);
    g = J_all.transpose() * y_all / (s * s);
  } else {
    // Generalized least squares: rows with covariance K + s^2 I, whitened by its Cholesky factor.
    Eigen::MatrixXd Crow = *row_kernel;
    Crow.diagonal().array() += s * s;
    const Eigen::LLT<Eigen::MatrixXd> llt(Crow);
    const Eigen::MatrixXd Jw = llt.matrixL().solve(J_all);
    const Eigen::VectorXd yw = llt.matrixL().solve(y_all);
    H = Jw.transpose() * Jw;
    g = Jw.transpose() * yw;
  }
  const Eigen::MatrixXd Np = Eigen::MatrixXd::Identity(P, P) - Q * Q.transpose();
  // The default tolerances (a calibration without --prior) where the fleet says nothing.
  const Parameterization& par = pm.parameterization();
  Eigen::MatrixXd tolerances = Eigen::MatrixXd::Zero(P, P);
  for (size_t f = 0; f < par.basis.size(); ++f) {
    const Eigen::MatrixXd& B = par.basis[f];
    if (B.cols() == 0) continue;
    tolerances.block(par.offset[f], par.offset[f], B.cols(), B.cols()) =
        B.transpose() * DefaultFrameInformation(mean, static_cast<int>(f), PriorScales(), 1.0) * B;
  }
  Eigen::MatrixXd info = tolerances;
  if (C != nullptr) {
    Eigen::MatrixXd root, inv_root;
    SqrtAndInverseSqrt(Np * *C * Np, &root, &inv_root);
    const Eigen::MatrixXd open = Eigen::MatrixXd::Identity(P, P) - root * inv_root;
    info = inv_root * inv_root + open * tolerances * open;
  }
  const Eigen::MatrixXd M = H + info;
  const Eigen::VectorXd d = M.diagonal().cwiseSqrt().cwiseInverse();
  const Eigen::VectorXd x =
      d.asDiagonal() * (d.asDiagonal() * M * d.asDiagonal()).ldlt().solve(d.asDiagonal() * g);
  const MeasurementSet fresh =
      Measure(r, 300, 4242, SE3d(), 0.0, kWorkspaceLower, kWorkspaceUpper);
  std::vector<Eigen::Vector3d> predicted, measured;
  for (int k = 0; k < fresh.size(); ++k) {
    pm.Rows(fresh.q(k), {fresh.target(k)}, &J);
    predicted.push_back(PredictToolPosition(mean, fresh.q(k), fresh.target(k)) + J * x);
    measured.push_back(fresh.position(k));
  }
  SE3d fit;
  EXPECT_TRUE(FitRigidTransform(predicted, measured, &fit).ok());
  double sum = 0;
  for (size_t k = 0; k < predicted.size(); ++k) {
    sum += (fit * predicted[k] - measured[k]).squaredNorm();
  }
  return std::sqrt(sum / predicted.size());
}

// ---- The unmodelled error's covariance between rows (3N x 3N, row 3k + axis of measurement k).
// The oracle: the stand-in's harmonics dq_j = h_j . (sin q, cos q, sin 2q, cos 2q), h_j ~ N(0,
// s_h^2 I), moved to the SMR by the joint's column of d position / d q (of `model`):
//   Cov(e_a, e_b) = s_h^2 sum_j Jq_j(a) Jq_j(b)^T (cos(q_aj - q_bj) + cos 2(q_aj - q_bj)).
Eigen::MatrixXd OracleRowKernel(const RobotModel& model, const MeasurementSet& d, double s_h) {
  const int N = d.size(), n = d.num_joints();
  std::vector<Eigen::MatrixXd> Jq(N, Eigen::MatrixXd(3, n));
  for (int k = 0; k < N; ++k) {
    std::vector<double> q(d.q(k), d.q(k) + n);
    for (int j = 0; j < n; ++j) {
      const double h = 1e-6, q0 = q[j];
      q[j] = q0 + h;
      const Eigen::Vector3d p = PredictToolPosition(model, q.data(), d.target(k));
      q[j] = q0 - h;
      const Eigen::Vector3d m = PredictToolPosition(model, q.data(), d.target(k));
      q[j] = q0;
      Jq[k].col(j) = (p - m) / (2 * h);
    }
  }
  Eigen::MatrixXd K = Eigen::MatrixXd::Zero(3 * N, 3 * N);
  for (int a = 0; a < N; ++a) {
    for (int b = 0; b < N; ++b) {
      Eigen::Matrix3d block = Eigen::Matrix3d::Zero();
      for (int j = 0; j < n; ++j) {
        const double t = d.q(a)[j] - d.q(b)[j];
        block += (std::cos(t) + std::cos(2 * t)) * Jq[a].col(j) * Jq[b].col(j).transpose();
      }
      K.block<3, 3>(3 * a, 3 * b) = s_h * s_h * block;
    }
  }
  return K;
}

// The residual layer's kernel form (docs/residual_layer.md): per axis, independent axes,
//   k = s_f^2 exp(-|q_a - q_b|^2_l / 2) rho^[tools differ] + s_c^2 [same configuration].
struct RowKernelHyper {
  Eigen::VectorXd l;
  double rho = 1, sf = 0, sn = 0, sc = 0;
};
Eigen::MatrixXd LayerRowKernel(const RowKernelHyper& h, const MeasurementSet& d) {
  const int N = d.size(), n = d.num_joints();
  Eigen::MatrixXd K = Eigen::MatrixXd::Zero(3 * N, 3 * N);
  for (int a = 0; a < N; ++a) {
    for (int b = 0; b < N; ++b) {
      double d2 = 0;
      bool same = true;
      for (int j = 0; j < n; ++j) {
        const double t = (d.q(a)[j] - d.q(b)[j]) / h.l(j);
        d2 += t * t;
        same = same && d.q(a)[j] == d.q(b)[j];
      }
      double k = h.sf * h.sf * std::exp(-0.5 * d2) * (d.target(a) == d.target(b) ? 1.0 : h.rho);
      if (same) k += h.sc * h.sc;
      K.block<3, 3>(3 * a, 3 * b) = k * Eigen::Matrix3d::Identity();
    }
  }
  return K;
}

// A residual layer fitted to a calibration's residuals (what a user of the fleet has: its robots'
// commissioning data and models), its hyperparameters as a row kernel.
RowKernelHyper FittedRowKernel(const MeasurementSet& d, const RobotModel& calibrated) {
  std::vector<double> q;
  std::vector<int> tools;
  std::vector<Eigen::Vector3d> residuals;
  for (int i = 0; i < d.size(); ++i) {
    q.insert(q.end(), d.q(i), d.q(i) + d.num_joints());
    tools.push_back(d.target(i));
    residuals.push_back(d.position(i) - PredictToolPosition(calibrated, d.q(i), d.target(i)));
  }
  ResidualLayer layer;
  ResidualLayerFit fit;
  EXPECT_TRUE(FitResidualLayer(q, tools, residuals, d.num_joints(),
                               static_cast<int>(calibrated.tools.size()), ResidualLayerOptions(),
                               &layer, &fit)
                  .ok());
  return {layer.length_scales, layer.tool_correlation, layer.signal_std, layer.noise_std,
          fit.configuration_std};
}

// The fleet's pooled hyperparameters: geometric mean of the length scales, mean variances, mean rho.
RowKernelHyper PooledRowKernel(const std::vector<RowKernelHyper>& hs) {
  const double n = static_cast<double>(hs.size());
  RowKernelHyper out{Eigen::VectorXd::Zero(hs[0].l.size()), 0, 0, 0, 0};
  double sf2 = 0, sn2 = 0, sc2 = 0;
  for (const RowKernelHyper& h : hs) {
    out.l += h.l.array().log().matrix() / n;
    out.rho += h.rho / n;
    sf2 += h.sf * h.sf / n;
    sn2 += h.sn * h.sn / n;
    sc2 += h.sc * h.sc / n;
  }
  out.l = out.l.array().exp().matrix();
  out.sf = std::sqrt(sf2);
  out.sn = std::sqrt(sn2);
  out.sc = std::sqrt(sc2);
  return out;
}

PipelineOptions LeastSquares() {
  PipelineOptions o;
  o.prior = nullptr;
  return o;
}

TEST(FleetPrior, NewRobotOfAKnownTypeFromTwentyPosesInItsCell) {
  const RobotModel drawing = Drawing();
  // The type's own deviation from the drawing (every robot of it shares it).
  const RobotModel type = ApplyErrors(drawing, RandomErrors(drawing, 0.003, 2.0, 0.002, 0.0, 99));
  std::vector<RobotModel> calibrated;
  std::vector<RowKernelHyper> layers;
  for (int k = 0; k < 8; ++k) {
    const MeasurementSet sixty = Measure(Member(type, 100 + k), 60, 200 + k, Tracker(300 + k),
                                         kNoise, kWorkspaceLower, kWorkspaceUpper);
    const PipelineResult r =
        RunCalibrationPipeline(drawing, sixty, MeasurementSet(6), PipelineOptions());
    ASSERT_TRUE(r.result.converged()) << r.result.message;
    calibrated.push_back(r.result.model);
    layers.push_back(FittedRowKernel(sixty, r.result.model));
  }
  const RowKernelHyper pooled = PooledRowKernel(layers);
  std::cout << "the fleet's residual layers, pooled: length scales " << pooled.l.transpose()
            << " rad, rho " << pooled.rho << ", s_f " << pooled.sf << ", s_n " << pooled.sn
            << ", s_c " << pooled.sc << " mm\n";
  RobotModel mean;
  ModelCovariance covariance;
  ASSERT_TRUE(FleetPrior(calibrated, &mean, &covariance).ok());
  const ParameterPrior prior = PriorFromCovariance(mean, covariance, PriorScales());
  const PlanningModel pm(mean);
  const Eigen::MatrixXd Q = RegistrationDirections(pm);
  std::vector<Eigen::VectorXd> xs;
  for (const RobotModel& m : calibrated) xs.push_back(FrameCoordinates(pm, mean, m));
  Eigen::MatrixXd block_cov, full_cov;
  double lambda = 0;
  FleetCovariances(pm, xs, Q, &block_cov, &full_cov, &lambda);
  std::cout << "shrinkage intensity of the cross-frame correlations " << lambda << "\n";
  double lin_ls2 = 0, lin_block2 = 0, lin_full2 = 0, lin_oracle2 = 0, lin_layer2 = 0,
         lin_inflated2 = 0;
  int lin_better = 0, oracle_better = 0;
  // Six ninth robots, each measured in its cell (20 poses, every SMR) from another tracker stand.
  double fleet2 = 0, ls2 = 0;
  int better = 0;
  constexpr int kRobots = 6;
  for (int k = 0; k < kRobots; ++k) {
    const Robot ninth = Member(type, 108 + k);
    const MeasurementSet twenty =
        Measure(ninth, 20, 408 + k, Tracker(400 + k), kNoise, kCellLower, kCellUpper);
    PipelineOptions o;
    o.prior = std::make_shared<const ParameterPrior>(prior);
    const RecalibrationResult fleet = Recalibrate(mean, twenty, MeasurementSet(6), o);
    ASSERT_TRUE(fleet.run.result.converged()) << fleet.run.result.message;
    const PipelineResult ls =
        RunCalibrationPipeline(drawing, twenty, MeasurementSet(6), LeastSquares());
    ASSERT_TRUE(ls.result.converged()) << ls.result.message;
    const double e_fleet = HeldOut(ninth, fleet.run.result.model);
    const double e_ls = HeldOut(ninth, ls.result.model);
    const double e_mean = HeldOut(ninth, mean);
    {
      const MeasurementSet local =
          Measure(ninth, 20, 408 + k, SE3d(), kNoise, kCellLower, kCellUpper);
      const double sd = covariance.data_sigma > 0 ? covariance.data_sigma : kNoise;
      const double a = LinearizedMapHeldOut(pm, mean, ninth, local, Q, nullptr, sd);
      const double b = LinearizedMapHeldOut(pm, mean, ninth, local, Q, &block_cov, sd);
      const double c = LinearizedMapHeldOut(pm, mean, ninth, local, Q, &full_cov, sd);
      // The per-frame fleet prior with a likelihood of correlated unmodelled error (generalized
      // least squares): the stand-in's own covariance of it (the oracle), and the residual layer's
      // kernel with the fleet's pooled hyperparameters.
      const Eigen::MatrixXd oracle = OracleRowKernel(mean, local, kHarmonicStd);
      const Eigen::MatrixXd layer = LayerRowKernel(pooled, local);
      const double d = LinearizedMapHeldOut(pm, mean, ninth, local, Q, &block_cov, kNoise, &oracle);
      const double e = LinearizedMapHeldOut(pm, mean, ninth, local, Q, &block_cov, pooled.sn, &layer);
      // The independent likelihood weighed with the data's whole variance (noise and the
      // unmodelled error's, the oracle's mean): a smaller data weight instead of correlation.
      const double f = LinearizedMapHeldOut(pm, mean, ninth, local, Q, &block_cov,
                                            std::sqrt(kNoise * kNoise + oracle.diagonal().mean()));
      std::cout << "  linearized: least squares " << a << ", per-frame fleet " << b
                << ", cross-frame fleet " << c << ", per-frame fleet with the correlated "
                << "likelihood: oracle " << d << ", the fleet's layer kernel " << e
                << "; independent, weighed with the whole variance " << f << " mm\n";
      lin_inflated2 += f * f / kRobots;
      if (k == 0) {
        // The whitened path with no kernel is the independent likelihood.
        const Eigen::MatrixXd none = Eigen::MatrixXd::Zero(oracle.rows(), oracle.cols());
        EXPECT_NEAR(LinearizedMapHeldOut(pm, mean, ninth, local, Q, &block_cov, sd, &none), b,
                    1e-9);
      }
      lin_oracle2 += d * d / kRobots;
      lin_layer2 += e * e / kRobots;
      oracle_better += d < a ? 1 : 0;
      // The linear theory reproduces the calibrations it stands for (to within the difference of
      // the residuals' s and kNoise the fleet prior is weighed with).
      lin_ls2 += a * a / kRobots;
      lin_block2 += b * b / kRobots;
      lin_full2 += c * c / kRobots;
      lin_better += c < a ? 1 : 0;
    }
    // What the fleet contributed: the parameters whose information is mostly the prior's.
    const Eigen::VectorXd& share = fleet.run.result.data_share;
    int from_prior = 0;
    std::string names;
    for (int c = 0; c < share.size(); ++c) {
      if (!(share(c) < 0.5)) continue;
      ++from_prior;
      names += " " + fleet.run.identifiability.parameter_names[c];
    }
    std::cout << "robot " << k + 9 << ": held out over the workspace: fleet prior + 20 poses "
              << e_fleet << " mm, least squares of the 20 poses " << e_ls
              << " mm, the fleet mean alone " << e_mean << " mm (the data weighed with s = "
              << fleet.run.result.prior_data_sigma << " mm); " << from_prior << " of "
              << share.size() << " parameters mostly from the fleet:" << names << "\n";
    EXPECT_LT(e_fleet, e_mean);
    EXPECT_GT(from_prior, 0);
    fleet2 += e_fleet * e_fleet / kRobots;
    ls2 += e_ls * e_ls / kRobots;
    better += e_fleet < e_ls ? 1 : 0;
  }
  const double floor_rms = HeldOut(
      Member(type, 108),
      RunCalibrationPipeline(drawing,
                             Measure(Member(type, 108), 300, 77, Tracker(78), kNoise,
                                     kWorkspaceLower, kWorkspaceUpper),
                             MeasurementSet(6), LeastSquares())
          .result.model);
  std::cout << "linearized RMS: least squares " << std::sqrt(lin_ls2) << ", per-frame fleet "
            << std::sqrt(lin_block2) << ", cross-frame fleet " << std::sqrt(lin_full2)
            << " mm; cross-frame better than least squares for " << lin_better << "\n";
  std::cout << "linearized RMS with the correlated likelihood: oracle " << std::sqrt(lin_oracle2)
            << " (better than least squares for " << oracle_better << "), the fleet's layer kernel "
            << std::sqrt(lin_layer2) << " mm; independent, weighed with the whole variance "
            << std::sqrt(lin_inflated2) << " mm\n";
  // The correlated likelihood (docs/recalibration.md, "A likelihood with correlated unmodelled
  // error"): the unmodelled error's own covariance helps (the diagnosis: the cell's misfit is
  // correlated; by 6 % on gcc's draw of this stand-in and 11 % on clang's, whose random streams
  // differ), but the kernel a user can estimate, the residual layer's from the fleet, does not
  // help. The feature is not in the library for that reason: if a kernel or a stand-in changes
  // this, revisit the docs' decision.
  EXPECT_LT(std::sqrt(lin_oracle2), std::sqrt(lin_block2));
  EXPECT_GT(std::sqrt(lin_layer2), 0.95 * std::sqrt(lin_block2));
  EXPECT_GE(oracle_better, kRobots - 1);
  // 20 poses over the whole workspace: the fleet changes nothing, nor does either likelihood.
  {
    double ls = 0, fleet = 0, oracle = 0, layer = 0;
    for (int k = 0; k < kRobots; ++k) {
      const Robot ninth = Member(type, 108 + k);
      const MeasurementSet spread =
          Measure(ninth, 20, 408 + k, SE3d(), kNoise, kWorkspaceLower, kWorkspaceUpper);
      const double sd = covariance.data_sigma > 0 ? covariance.data_sigma : kNoise;
      const Eigen::MatrixXd Ko = OracleRowKernel(mean, spread, kHarmonicStd);
      const Eigen::MatrixXd Kl = LayerRowKernel(pooled, spread);
      const double a = LinearizedMapHeldOut(pm, mean, ninth, spread, Q, nullptr, sd);
      const double b = LinearizedMapHeldOut(pm, mean, ninth, spread, Q, &block_cov, sd);
      const double c = LinearizedMapHeldOut(pm, mean, ninth, spread, Q, &block_cov, kNoise, &Ko);
      const double d = LinearizedMapHeldOut(pm, mean, ninth, spread, Q, &block_cov, pooled.sn, &Kl);
      ls += a * a / kRobots;
      fleet += b * b / kRobots;
      oracle += c * c / kRobots;
      layer += d * d / kRobots;
    }
    std::cout << "20 poses over the workspace, linearized RMS: least squares " << std::sqrt(ls)
              << ", per-frame fleet " << std::sqrt(fleet) << ", with the correlated likelihood: "
              << "oracle " << std::sqrt(oracle) << ", the fleet's layer kernel " << std::sqrt(layer)
              << " mm\n";
    EXPECT_NEAR(std::sqrt(fleet), std::sqrt(ls), 0.05 * std::sqrt(ls));
    EXPECT_NEAR(std::sqrt(oracle), std::sqrt(fleet), 0.1 * std::sqrt(fleet));
    EXPECT_NEAR(std::sqrt(layer), std::sqrt(fleet), 0.1 * std::sqrt(fleet));
  }
  EXPECT_NEAR(std::sqrt(lin_ls2), std::sqrt(ls2), 0.1 * std::sqrt(ls2));
  EXPECT_NEAR(std::sqrt(lin_block2), std::sqrt(fleet2), 0.1 * std::sqrt(fleet2));
  std::cout << "RMS over the " << kRobots << " robots: fleet prior + 20 poses " << std::sqrt(fleet2)
            << " mm, least squares " << std::sqrt(ls2) << " mm (ratio "
            << std::sqrt(fleet2 / ls2) << "); the fleet better for " << better
            << "; 300 poses over the workspace (robot 9) " << floor_rms << " mm\n";
  // Better on average, not by a large factor (docs/recalibration.md, "A new robot of a known type").
  EXPECT_LT(std::sqrt(fleet2), 0.9 * std::sqrt(ls2));
  EXPECT_GE(better, kRobots / 2 + 1);
}

}  // namespace fleet_prior_test
}  // namespace
}  // namespace lpoe
