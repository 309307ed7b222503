// The stand-in for a real arm whose error the model cannot fully explain, shared by
// tests/model/residual_layer_test.cc and tests/planning/planning_test.cc: cobot6 with three SMRs on the flange,
// random frame errors and joint zeros, tracker noise per row, the arm's repeatability (an error
// shared by the SMRs of one configuration, independent between configurations) and an unmodelled
// error U(q): a smooth configuration-dependent position error (mm, base frame) that no registry
// term models, added to the simulated positions (a test-side truth, not a model term).
//
// U is a draw from a Gaussian process with the layer's kernel (squared exponential, per-joint
// length scales; joints without one do not matter), made of random Fourier features:
//   U_a(q) = s sqrt(2 / F) sum_f c_fa cos(w_f . q + b_fa),  w_fj ~ N(0, 1 / l_j^2), c ~ N(0, 1),
// b ~ U(0, 2 pi), whose covariance is s^2 exp(-1/2 sum_j ((q_j - q'_j) / l_j)^2): the truth's length
// scales are the l_j, known exactly. Header only.
#ifndef LPOE_TESTS_UNMODELLED_ARM_H_
#define LPOE_TESTS_UNMODELLED_ARM_H_

#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <vector>

#include <Eigen/Core>

#include "lpoe/kinematics/kinematics.h"
#include "lpoe/measurements/measurements.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/model/simulation.h"

namespace lpoe {
namespace testing {

struct UnmodelledError {
  double std = 0;                 // s, mm per axis
  Eigen::VectorXd length_scales;  // per joint (rad); infinity: the joint does not matter
  Eigen::MatrixXd w;              // F x n frequencies
  Eigen::MatrixXd b, c;           // F x 3 phases and weights

  Eigen::Vector3d operator()(const double* q) const {
    Eigen::Vector3d u = Eigen::Vector3d::Zero();
    if (std == 0) return u;
    const int F = static_cast<int>(w.rows());
    for (int f = 0; f < F; ++f) {
      double phase = 0;
      for (int j = 0; j < w.cols(); ++j) phase += w(f, j) * q[j];
      for (int a = 0; a < 3; ++a) u(a) += c(f, a) * std::cos(phase + b(f, a));
    }
    return std * std::sqrt(2.0 / F) * u;
  }
};

inline UnmodelledError MakeUnmodelledError(double std, const Eigen::VectorXd& length_scales,
                                           uint64_t seed, int features = 400) {
  UnmodelledError u;
  u.std = std;
  u.length_scales = length_scales;
  const int n = static_cast<int>(length_scales.size());
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  std::uniform_real_distribution<double> phase(0.0, 2 * 3.14159265358979323846);
  u.w.resize(features, n);
  u.b.resize(features, 3);
  u.c.resize(features, 3);
  for (int f = 0; f < features; ++f) {
    for (int j = 0; j < n; ++j) {
      const double z = normal(rng);
      u.w(f, j) = std::isfinite(length_scales(j)) ? z / length_scales(j) : 0.0;
    }
    for (int a = 0; a < 3; ++a) {
      u.b(f, a) = phase(rng);
      u.c(f, a) = normal(rng);
    }
  }
  return u;
}

struct UnmodelledArm {
  RobotModel nominal;  // cobot6 with three SMRs: what a calibration starts from
  RobotModel actual;
  std::vector<double> joint_zero;
  UnmodelledError unmodelled;
  double noise = 0.01;          // mm per axis and row (tracker)
  double repeatability = 0.0;   // mm per axis, shared by the SMRs of a configuration

  // Every SMR measured at each configuration (row-major), rows pose by pose.
  MeasurementSet Measure(const std::vector<double>& configurations, uint64_t seed) const {
    SimulationOptions so;
    so.noise_sigma = noise;
    so.all_tools = true;
    so.configurations = configurations;
    so.seed = seed;
    MeasurementSet data = SimulateMeasurements(actual, joint_zero, so);
    std::mt19937_64 rng(seed + 77);
    std::normal_distribution<double> normal(0.0, repeatability);
    const int n = data.num_joints();
    Eigen::Vector3d shared = Eigen::Vector3d::Zero();
    for (int r = 0; r < data.size(); ++r) {
      const bool new_configuration =
          r == 0 || !std::equal(data.q(r), data.q(r) + n, data.q(r - 1));
      if (new_configuration && repeatability > 0) {
        shared = Eigen::Vector3d(normal(rng), normal(rng), normal(rng));
      }
      data.mutable_position(r) += unmodelled(data.q(r)) + shared;
    }
    return data;
  }

  // The true position of tool `tool` at q (with the unmodelled error, without noise).
  Eigen::Vector3d Truth(const double* q, int tool) const {
    std::vector<double> qe(q, q + nominal.num_joints());
    for (size_t j = 0; j < qe.size(); ++j) qe[j] += joint_zero[j];
    return PredictToolPosition(actual, qe.data(), tool) + unmodelled(q);
  }
};

// cobot6 with three SMRs, every joint within [-1.6, 1.6] rad, frame errors of 2 mrad / 0.5 mm, joint zeros of 2 mrad (seed), the
// unmodelled error of `unmodelled_std` mm per axis varying with joints 4-6 over `wrist_lengths`
// (rad), noise and repeatability in mm per axis.
inline UnmodelledArm MakeUnmodelledArm(double unmodelled_std, const Eigen::Vector3d& wrist_lengths,
                                       double noise, double repeatability, uint64_t seed) {
  UnmodelledArm arm;
  RobotModel model = MakeCobot6(Eigen::Vector3d(40, 0, 60));
  model.tools[0].name = "smr1";
  model.tools.push_back(
      Tool{"smr2", SE3d(Eigen::Matrix3d::Identity(), Eigen::Vector3d(-30, 35, 55))});
  model.tools.push_back(
      Tool{"smr3", SE3d(Eigen::Matrix3d::Identity(), Eigen::Vector3d(-25, -45, 50))});
  for (Joint& joint : model.joints) {  // the measured range of every joint
    joint.lower = -1.6;
    joint.upper = 1.6;
  }
  arm.nominal = model;
  const KinematicErrors errors = RandomErrors(model, 2e-3, 0.5, 1e-3, 2e-3, seed);
  arm.actual = ApplyErrors(model, errors);
  arm.joint_zero = errors.joint_zero;
  Eigen::VectorXd lengths = Eigen::VectorXd::Constant(6, std::numeric_limits<double>::infinity());
  lengths.tail(3) = wrist_lengths;
  arm.unmodelled = MakeUnmodelledError(unmodelled_std, lengths, seed + 5);
  arm.noise = noise;
  arm.repeatability = repeatability;
  return arm;
}

}  // namespace testing
}  // namespace lpoe

#endif  // LPOE_TESTS_UNMODELLED_ARM_H_
