// Which directions of each local frame's right perturbation are calibrated (DESIGN.md section 3).
//
// For joint i, a perturbation dp of T_{i-1,i}(0) that commutes with the joint's own motion exp(s_i^ q)
// (the centralizer of s_i in se(3): ad_{s_i} dp = 0) can be pushed through the joint into the next
// frame, so no data can tell it apart: 2 directions for a revolute joint (rotation about and
// translation along its axis), 4 for a prismatic one. With position data the rotation of each tool
// frame is never seen (3 directions). The identifiable basis of a frame is the orthogonal complement
// of those directions; the full basis is the identity (the paper's 6 per frame, solved as a
// minimum-norm pseudo-inverse).
#ifndef LPOE_PARAMETERIZATION_H_
#define LPOE_PARAMETERIZATION_H_

#include <string>
#include <vector>

#include <Eigen/Core>

#include "lpoe/robot_model.h"

namespace lpoe {

enum class ParameterizationKind { kIdentifiable, kFull };
enum class DataKind { kPosition, kPose };

const char* ParameterizationName(ParameterizationKind kind);
bool ParseParameterization(const std::string& text, ParameterizationKind* kind);

// A basis direction, with a human-readable name ("joint2.rx", "smr1.vy") and, for the directions
// left out, why.
struct Direction {
  int frame = 0;
  Eigen::Matrix<double, 6, 1> vector;  // unit (omega, v) in the frame's own coordinates
  std::string name;
  std::string reason;  // empty for calibrated directions
};

struct Parameterization {
  ParameterizationKind kind = ParameterizationKind::kIdentifiable;
  DataKind data = DataKind::kPosition;
  // basis[f] is 6 x k_f (orthonormal columns): dp_f = basis[f] * x_f.
  std::vector<Eigen::MatrixXd> basis;
  std::vector<int> offset;  // first parameter of frame f
  int num_parameters = 0;
  std::vector<Direction> parameters;    // one per parameter, in order
  std::vector<Direction> unidentifiable;  // the directions left out (identifiable kind only)
};

// Null space of ad_s (the twists that commute with s), 6 x k, orthonormal columns.
Eigen::MatrixXd TwistCentralizer(const Vector6d& twist);

// The orthogonal complement of the centralizer: the directions of a joint frame that data can see.
Eigen::MatrixXd IdentifiableJointBasis(const Vector6d& twist);

Parameterization MakeParameterization(const RobotModel& model, ParameterizationKind kind,
                                      DataKind data);

// Applies an update x (num_parameters) to the model: T_f <- T_f exp((basis_f x_f)^) (eq. (19)).
void ApplyUpdate(const Parameterization& p, const Eigen::VectorXd& x, RobotModel* model);

// Coordinates of the difference between two models in the calibrated directions:
// x_f = basis_f^T log(a_f^-1 b_f). Used to compare two calibrations.
Eigen::VectorXd ParameterDifference(const Parameterization& p, const RobotModel& a,
                                    const RobotModel& b);

}  // namespace lpoe

#endif  // LPOE_PARAMETERIZATION_H_
