// Helpers shared by the unit tests: deterministic random draws, the four test robots, models whose
// joint axes are tilted and offset, and Jets seeded on a right perturbation of every local frame.
#ifndef LPOE_TESTS_TEST_UTIL_H_
#define LPOE_TESTS_TEST_UTIL_H_

#include <cmath>
#include <cstdint>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <Eigen/SVD>

#include "lpoe/model/robot_model.h"
#include "lpoe/kinematics/se3.h"
#include "lpoe/model/simulation.h"

namespace lpoe {
namespace testing {


// A seeded source of test values. Uses only the raw engine output so that the draws are the same
// on every standard library.
class TestRandom {
 public:
  explicit TestRandom(uint64_t seed) : engine_(seed) {}
  double Uniform(double lo, double hi) {
    return lo + (hi - lo) * static_cast<double>(engine_() >> 11) * 0x1.0p-53;
  }
  Eigen::Vector3d Vector3(double bound) {
    // One by one, in gcc's (right-to-left) order: argument evaluation order is unspecified.
    const double z = Uniform(-bound, bound);
    const double y = Uniform(-bound, bound);
    const double x = Uniform(-bound, bound);
    return Eigen::Vector3d(x, y, z);
  }
  Eigen::Vector3d UnitVector() {
    Eigen::Vector3d v;
    do {
      v = Vector3(1.0);
    } while (v.norm() < 0.1 || v.norm() > 1.0);
    return v.normalized();
  }
  // A twist whose rotation has the given angle about a random axis, translation in [-trans, trans].
  Vector6d Twist(double angle, double trans) {
    Vector6d xi;
    xi << angle * UnitVector(), Vector3(trans);
    return xi;
  }
  SE3d Pose(double trans) { return ExpSE3(Twist(Uniform(0, kPi), trans)); }
  // Joint values uniform in [-pi, pi] (revolute) or [-100, 100] mm (prismatic).
  std::vector<double> Configuration(const RobotModel& model) {
    std::vector<double> q;
    for (const Joint& j : model.joints) {
      q.push_back(j.type == JointType::kRevolute ? Uniform(-kPi, kPi) : Uniform(-100, 100));
    }
    return q;
  }

 private:
  std::mt19937_64 engine_;
};

struct NamedRobot {
  std::string name;
  RobotModel model;
};

// The nominal robots of the acceptance criteria.
inline std::vector<NamedRobot> TestRobots() {
  return {{"cobot6", MakeCobot6()},
          {"ur5_like", MakeUr5Like()},
          {"arm7", MakeSevenJointArm()},
          {"arm_prismatic", MakeArmWithPrismatic()}};
}

// The nominal robots followed by versions whose twists are tilted (ApplyErrors(RandomErrors)) and
// whose revolute axes are moved off the local origin (v = -omega x r, r random), so that no twist is
// the default (0, 0, 1, 0, 0, 0) and the general exp branch of JointMotion is exercised.
inline std::vector<NamedRobot> TestRobotsWithTiltedVariants(uint64_t seed) {
  std::vector<NamedRobot> out = TestRobots();
  TestRandom rng(seed);
  const size_t nominal_count = out.size();
  for (size_t k = 0; k < nominal_count; ++k) {
    RobotModel m = ApplyErrors(out[k].model, RandomErrors(out[k].model, 0.01, 3.0, 0.2, 0.0,
                                                          seed + 17 * k));
    for (Joint& j : m.joints) {
      if (j.type != JointType::kRevolute) continue;
      const Eigen::Vector3d w = j.twist.head<3>();
      j.twist.tail<3>() = -w.cross(rng.Vector3(50.0));
    }
    out.push_back({out[k].name + "_tilted", std::move(m)});
  }
  return out;
}

// Local frame f of a model: joint origins first, then the tools.
inline SE3d& FrameOf(RobotModel* model, int f) {
  const int n = model->num_joints();
  return f < n ? model->joints[f].origin : model->tools[f - n].origin;
}
inline const SE3d& FrameOf(const RobotModel& model, int f) {
  const int n = model.num_joints();
  return f < n ? model.joints[f].origin : model.tools[f - n].origin;
}

// The model with local frame f perturbed on the right: T_f <- T_f exp(dp^) (eq. (19)).
inline RobotModel PerturbFrame(const RobotModel& model, int f, const Vector6d& dp) {
  RobotModel out = model;
  SE3d& T = FrameOf(&out, f);
  T = T * ExpSE3(dp);
  return out;
}

// Largest absolute entry of a - b relative to max(1, largest entry of b).
inline double RelativeMaxDifference(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  const double scale = std::max(1.0, b.cwiseAbs().maxCoeff());
  return (a - b).cwiseAbs().maxCoeff() / scale;
}

// The step of the tests' plain least-squares references: Levenberg-Marquardt damping `mu` on the
// column-scaled Jacobian, a pseudo-inverse (relative threshold 1e-9) for its null directions;
// x minimises |r + J x| to first order.
inline Eigen::VectorXd DampedPseudoInverseStep(const Eigen::MatrixXd& J, const Eigen::VectorXd& r,
                                               double mu) {
  Eigen::VectorXd D(J.cols());
  for (int c = 0; c < J.cols(); ++c) D(c) = J.col(c).norm() > 0 ? 1.0 / J.col(c).norm() : 1.0;
  const Eigen::MatrixXd Js = J * D.asDiagonal();
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(Js, Eigen::ComputeThinU | Eigen::ComputeThinV);
  const Eigen::VectorXd& sv = svd.singularValues();
  Eigen::VectorXd z = Eigen::VectorXd::Zero(Js.cols());
  const Eigen::VectorXd ur = svd.matrixU().transpose() * r;
  for (int k = 0; k < sv.size(); ++k) {
    if (sv(k) > 1e-9 * sv(0)) z -= svd.matrixV().col(k) * (sv(k) * ur(k) / (sv(k) * sv(k) + mu));
  }
  return D.asDiagonal() * z;
}

}  // namespace testing
}  // namespace lpoe

#endif  // LPOE_TESTS_TEST_UTIL_H_
