// The calibration parameters as a list of blocks (docs/architecture.md): one block per local frame
// (right perturbations on SE(3), restricted to the identifiable directions) and one block per
// joint-space term (joint_term.h), each carrying its own identifiability analysis and names. Both
// solvers assemble their problem from this one list: the linear solver's columns, Ceres's parameter
// blocks and manifolds, the covariance's order.
//
// Frames (docs/conventions.md, "Parameters that cannot be identified"):
// For joint i, a perturbation dp of T_{i-1,i}(0) that commutes with the joint's own motion exp(s_i^ q)
// (the centralizer of s_i in se(3): ad_{s_i} dp = 0) can be pushed through the joint into the next
// frame, so no data can tell it apart: 2 directions for a revolute joint (rotation about and
// translation along its axis), 4 for a prismatic one. With position data the rotation of each tool
// frame is never seen (3 directions). The identifiable basis of a frame is the orthogonal complement
// of those directions; the full basis is the identity (the paper's 6 per frame, solved as a
// minimum-norm pseudo-inverse).
#ifndef LPOE_PARAMETERIZATION_H_
#define LPOE_PARAMETERIZATION_H_

#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "lpoe/terms/bilinear_term.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/model/robot_model.h"

namespace lpoe {


enum class ParameterizationKind { kIdentifiable, kFull };
enum class DataKind { kPosition, kPose };

const char* ParameterizationName(ParameterizationKind kind);
bool ParseParameterization(const std::string& text, ParameterizationKind* kind);

// A basis direction, with a human-readable name ("joint2.rx", "smr1.vy") and, for the directions
// left out, why.
// For a joint-space block, `frame` is -1, `joint_block` its index and `combination` the unit
// combination of the term's parameters theta.
struct Direction {
  int frame = 0;
  // Unit (omega, v) in the frame's own coordinates; zero for a joint block's combination.
  Eigen::Matrix<double, 6, 1> vector = Eigen::Matrix<double, 6, 1>::Zero();
  std::string name;
  std::string reason;  // empty for calibrated directions
  int joint_block = -1;
  Eigen::VectorXd combination;
};

// A joint-space term's parameter block: theta = basis * x_block, where basis (P x k, orthonormal
// columns) spans the combinations of the term's parameters the data separate from the geometry and
// from the earlier blocks (found by the solvers from the stacked Jacobian, see
// solvers/src/identifiability/identifiability.h). Until that analysis ran, basis = I.
struct JointBlock {
  std::shared_ptr<const JointTerm> term;
  Eigen::MatrixXd basis;
  int offset = 0;  // first parameter of the block in x
};

// A block of an effect bilinear with joint block `partner` (lpoe/terms/bilinear_term.h).
struct BilinearBlock {
  std::shared_ptr<const BilinearJointEffect> effect;
  int partner = -1;  // index in joint_blocks
  int offset = 0;    // first parameter of the block in x
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
  // Joint-space blocks, after all frame parameters.
  std::vector<JointBlock> joint_blocks;
  // Blocks of effects bilinear with a joint block (lpoe/terms/bilinear_term.h; the gravity tilt),
  // after the joint blocks.
  std::vector<BilinearBlock> bilinear_blocks;

  int num_bilinear_parameters() const {
    int k = 0;
    for (const BilinearBlock& b : bilinear_blocks) k += b.effect->num_parameters();
    return k;
  }
  // The joint-space columns: every joint block's, then the bilinear blocks'.
  int num_joint_parameters() const {
    int k = num_bilinear_parameters();
    for (const JointBlock& b : joint_blocks) k += static_cast<int>(b.basis.cols());
    return k;
  }
  int num_frame_parameters() const { return num_parameters - num_joint_parameters(); }
};

// Null space of ad_s (the twists that commute with s), 6 x k, orthonormal columns.
Eigen::MatrixXd TwistCentralizer(const Vector6d& twist);

// The orthogonal complement of the centralizer: the directions of a joint frame that data can see.
Eigen::MatrixXd IdentifiableJointBasis(const Vector6d& twist);

// A fixed tool (Tool::fixed) has no columns: its directions are listed in `unidentifiable` with
// kFixedToolReason (with position data its rotations with the usual reason), and the last joint's
// frame keeps every direction, its zero and its translation along the axis included (nothing after
// it can absorb them: docs/identifiability.md, "Known SMR nests").
Parameterization MakeParameterization(const RobotModel& model, ParameterizationKind kind,
                                      DataKind data);

// The reason given for the directions of a fixed tool.
extern const char* const kFixedToolReason;

// Appends a joint-space block for `term` with the identity basis (every parameter) and its names.
void AddJointBlock(std::shared_ptr<const JointTerm> term, Parameterization* p);

// Replaces the basis of joint block b (P x k, orthonormal columns), renumbering the later offsets and
// the names; the combinations left out go to p->unidentifiable with `reason`.
void SetJointBlockBasis(int b, const Eigen::MatrixXd& basis, const std::string& reason,
                        Parameterization* p);

// Appends a block of `effect`'s parameters (named by the effect) after the joint blocks, bilinear
// with joint block `partner` (a block of the effect's partner term).
void AddBilinearBlock(std::shared_ptr<const BilinearJointEffect> effect, int partner,
                      Parameterization* p);

// Replaces to's joint blocks (and their left-out combinations, and the bilinear blocks) by from's.
void CopyJointBlocks(const Parameterization& from, Parameterization* to);

// Applies an update x (num_parameters) to the model: T_f <- T_f exp((basis_f x_f)^) (eq. (19)).
// The joint-space part of x is not used (see JointValuesOf).
void ApplyUpdate(const Parameterization& p, const Eigen::VectorXd& x, RobotModel* model);

// The terms' values theta_b = basis_b x_b from the joint-space part of x (num_parameters). A joint
// block with a bilinear block has its term rebuilt at the bilinear block's values
// (BilinearJointEffect::PartnerAt: its regressor then gives the bilinear offsets exactly).
std::vector<JointTermValues> JointValuesOf(const Parameterization& p, const Eigen::VectorXd& x);

// Bilinear block b's values in x (num_parameters).
Eigen::VectorXd BilinearValuesOf(const Parameterization& p, int b, const Eigen::VectorXd& x);

// Coordinates of the difference between two models in the calibrated directions:
// x_f = basis_f^T log(a_f^-1 b_f). Used to compare two calibrations.
Eigen::VectorXd ParameterDifference(const Parameterization& p, const RobotModel& a,
                                    const RobotModel& b);

}  // namespace lpoe

#endif  // LPOE_PARAMETERIZATION_H_
