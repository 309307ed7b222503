// The fleet prior where it matters to a user (docs/recalibration.md, "A new robot of a known
// type"): 8 robots of one type calibrated over their workspace at commissioning, and a ninth
// measured with 20 poses where its cell lets the tracker see them (a narrow region, one joint that
// barely moves), held out over the whole workspace. Realistic magnitudes: a UR5-like 6R arm with 3
// SMRs off the flange axis, a tracker 3 m away, commanded joint values, noise 0.02 mm per axis,
// joint harmonics of a few hundredths of a mrad that no calibration here models (always present),
// and a fleet whose deviation from the drawing is partly the type's (shared) and partly each
// robot's own.
#include <gtest/gtest.h>

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "lpoe/joint_errors.h"
#include "lpoe/kinematics.h"
#include "lpoe/model_covariance.h"
#include "lpoe/parameterization.h"
#include "lpoe/pipeline.h"
#include "lpoe/planning.h"
#include "lpoe/prior.h"
#include "lpoe/recalibration.h"
#include "lpoe/registration.h"
#include "lpoe/simulation.h"
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
Robot Member(const RobotModel& type, uint64_t seed) {
  const KinematicErrors e = OwnDeviation(type, seed);
  Robot r{ApplyErrors(type, e), e.joint_zero};
  JointErrorPhysics physics;
  physics.stiffness.assign(r.actual.num_joints(), 0.0);  // rigid: the harmonics only
  std::mt19937_64 rng(seed + 7);
  std::normal_distribution<double> h(0.0, 3e-5);
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
                            const Eigen::MatrixXd* C, double s) {
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
  for (int k = 0; k < data.size(); ++k) {
    pm.Rows(data.q(k), {data.target(k)}, &J);
    const Eigen::Vector3d y = registration * at[k] - nominal[k];
    H += J.transpose() * J / (s * s);
    g += J.transpose() * y / (s * s);
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
  for (int k = 0; k < 8; ++k) {
    const PipelineResult r = RunCalibrationPipeline(
        drawing,
        Measure(Member(type, 100 + k), 60, 200 + k, Tracker(300 + k), kNoise, kWorkspaceLower,
                kWorkspaceUpper),
        MeasurementSet(6), PipelineOptions());
    ASSERT_TRUE(r.result.converged()) << r.result.message;
    calibrated.push_back(r.result.model);
  }
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
  double lin_ls2 = 0, lin_block2 = 0, lin_full2 = 0;
  int lin_better = 0;
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
      std::cout << "  linearized: least squares " << a << ", per-frame fleet " << b
                << ", cross-frame fleet " << c << " mm\n";
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
              << " mm, the fleet mean alone " << e_mean << " mm; " << from_prior << " of "
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
