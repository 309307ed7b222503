// Forward kinematics of the LPoE chain (paper eqs. (6), (7), (26)) and the analytic Jacobians of the
// error model (eqs. (18), (29)).
//
// The chain is written once, as a template on the scalar of the local frames: doubles for the linear
// solver and the tools, ceres::Jet for automatic differentiation (the Ceres residuals pass their
// parameter blocks as frames). Joint values and twists are data, always double.
#ifndef LPOE_KINEMATICS_H_
#define LPOE_KINEMATICS_H_

#include <cmath>
#include <vector>

#include "lpoe/parameterization.h"
#include "lpoe/robot_model.h"
#include "lpoe/se3.h"

namespace lpoe {

// sin(x) and cos(x) in one call: glibc's sincos where available (one argument reduction for both).
inline void SinCos(double x, double* s, double* c) {
#if defined(__GNUC__) && !defined(__clang__) && defined(__GLIBC__)
  __builtin_sincos(x, s, c);
#else
  *s = std::sin(x);
  *c = std::cos(x);
#endif
}

// True for a revolute joint whose twist is exactly (0, 0, 1, 0, 0, 0): its motion is Rz(q) with no
// translation, which the fast paths below apply as a 2-column rotation update.
inline bool IsRevoluteZ(const Joint& joint) {
  const Vector6d& s = joint.twist;
  return joint.type == JointType::kRevolute && s(0) == 0 && s(1) == 0 && s(2) == 1 && s(3) == 0 &&
         s(4) == 0 && s(5) == 0;
}

// exp(s^ q) for a joint of the given twist. Revolute joints about local z (the common case) take a
// closed form with one sin/cos pair.
SE3d JointMotion(const Joint& joint, double q);

namespace internal {

// R <- R Rz(q) given c = cos q, s = sin q: only columns 0 and 1 change (12 multiplications instead
// of a 3x3 product).
template <typename T>
inline void RightMultiplyRotZ(double c, double s, Matrix3<T>* R) {
  for (int r = 0; r < 3; ++r) {
    const T a = (*R)(r, 0);
    const T b = (*R)(r, 1);
    (*R)(r, 0) = c * a + s * b;
    (*R)(r, 1) = c * b - s * a;
  }
}

// X <- X exp(s^ q) for joint i of `model`.
template <typename T>
inline void ApplyJointMotion(const Joint& joint, double q, SE3<T>* X) {
  if (IsRevoluteZ(joint)) {
    double s, c;
    SinCos(q, &s, &c);
    RightMultiplyRotZ(c, s, &X->R);
  } else {
    *X = *X * JointMotion(joint, q).template cast<T>();
  }
}

}  // namespace internal

// T_0,tool(q) = prod_i T_{i-1,i}(0) exp(s_i^ q_i) * T_n,tool with the local frames given by
// `joint_origins[0..n)` and `tool_origin` (paper eq. (7)). `q` holds n joint values.
template <typename T>
SE3<T> ChainPose(const RobotModel& model, const SE3<T>* joint_origins, const SE3<T>& tool_origin,
                 const double* q) {
  SE3<T> X = joint_origins[0];
  for (int i = 0; i < model.num_joints(); ++i) {
    if (i > 0) X = X * joint_origins[i];
    internal::ApplyJointMotion(model.joints[i], q[i], &X);
  }
  return X * tool_origin;
}

// The joint motions exp(s_i^ q_i) of one configuration, computed once: the autodiff residuals
// evaluate the chain many times per Jacobian at a fixed q, and the sin/cos calls would otherwise
// dominate. Revolute-z joints keep (sin, cos); other joints their motion.
class JointMotions {
 public:
  JointMotions(const RobotModel& model, const double* q);

  // p <- exp(s_i^ q_i) p.
  template <typename T>
  void Apply(int i, Vector3<T>* p) const {
    const Motion& m = motions_[i];
    if (m.revolute_z) {
      const T x = (*p)(0);
      (*p)(0) = m.c * x - m.s * (*p)(1);
      (*p)(1) = m.s * x + m.c * (*p)(1);
    } else {
      *p = m.general.R.template cast<T>() * *p + m.general.t.template cast<T>();
    }
  }

 private:
  struct Motion {
    bool revolute_z = false;
    double s = 0, c = 1;
    SE3d general;
  };
  std::vector<Motion> motions_;
};

namespace internal {

// The position chain from the tool back to the base; `apply_motion(i, &p)` applies joint i's motion.
template <typename T, typename Frame, typename ApplyMotion>
Vector3<T> ChainPositionBackward(int num_joints, const Frame* joint_origins,
                                 const Vector3<T>& tool_point, const ApplyMotion& apply_motion) {
  Vector3<T> p = tool_point;
  for (int i = num_joints - 1; i >= 0; --i) {
    apply_motion(i, &p);
    p = joint_origins[i] * p;
  }
  return p;
}

}  // namespace internal

// Position-only variant (eq. (26)): P = T_0,n(q) * p_tool, evaluated from the tool back to the base
// with vectors only, p <- T_{i-1,i}(0) (exp(s_i^ q_i) p): 9 + 4 multiplications per revolute-z joint
// and no rotation products.
// `Frame` is SE3<T> or any transform acting on a Vector3<T> with operator* (e.g.
// QuaternionTransform<T>, used by the autodiff residual).
template <typename T, typename Frame = SE3<T>>
Vector3<T> ChainPosition(const RobotModel& model, const Frame* joint_origins,
                         const Vector3<T>& tool_point, const double* q) {
  return internal::ChainPositionBackward<T>(
      model.num_joints(), joint_origins, tool_point, [&](int i, Vector3<T>* p) {
        const Joint& joint = model.joints[i];
        if (IsRevoluteZ(joint)) {
          double s, c;
          SinCos(q[i], &s, &c);
          const T x = (*p)(0);
          (*p)(0) = c * x - s * (*p)(1);
          (*p)(1) = s * x + c * (*p)(1);
        } else {
          const SE3d M = JointMotion(joint, q[i]);
          *p = M.R.template cast<T>() * *p + M.t.template cast<T>();
        }
      });
}

// The same chain with the joint motions precomputed.
template <typename T, typename Frame = SE3<T>>
Vector3<T> ChainPosition(const JointMotions& motions, int num_joints, const Frame* joint_origins,
                         const Vector3<T>& tool_point) {
  return internal::ChainPositionBackward<T>(
      num_joints, joint_origins, tool_point,
      [&](int i, Vector3<T>* p) { motions.Apply(i, p); });
}

// Convenience forms on the model's own frames (double).
SE3d ToolPose(const RobotModel& model, const double* q, int tool = 0);
Eigen::Vector3d ToolPosition(const RobotModel& model, const double* q, int tool = 0);

// Frame of every joint at configuration q: G_i = T_0,i-1(q) T_{i-1,i}(0) (before joint i moves),
// i = 0..n-1, followed by the tool frame T_0,n(q) T_n,tool. This is where a right perturbation of
// local frame i acts: T_0,tool(perturbed) = exp((Ad_{G_i} dp_i)^) T_0,tool.
void PerturbationFrames(const RobotModel& model, const double* q, int tool,
                        std::vector<SE3d>* frames);

// Jacobian of the tool position with respect to the right perturbations dp_i (omega, v) of every
// local frame (paper eq. (29)): J = [-P^ I3] [Ad_G_0 ... Ad_G_n-1, Ad_G_tool]. Written without the
// 6x6 adjoints: for frame G = (R, t), dP/d omega = -(P - t)^ R, dP/d v = R.
// `J_p_frames` is resized to 3 x 6 * model.num_frames(); the columns of tools other than `tool` are
// zero. Returns P.
Eigen::Vector3d ToolPositionJacobian(const RobotModel& model, const double* q, int tool,
                                     Eigen::MatrixXd* J_p_frames);

// Jacobian of the pose error log(T_measured T_model^-1)^vee with respect to the same perturbations
// (paper eq. (18)): J = [Ad_G_0 ... Ad_G_tool], 6 x 6 * num_frames. Returns T_0,tool(q).
SE3d ToolPoseJacobian(const RobotModel& model, const double* q, int tool,
                      Eigen::MatrixXd* J_pose_frames);

// ---- Fast double paths for repeated evaluation (the solvers' inner loops, the benchmarks).

// A frame as rotation and translation, left uninitialized (scratch space: no per-call set-up).
struct FrameRt {
  Eigen::Matrix3d R;
  Eigen::Vector3d t;
};

// A robot model prepared for many evaluations: which joints are revolute about local z is decided
// once (the model-independent checks leave the loop). Like Pinocchio's Model/Data split, it refers to
// `model` without owning it: the model must outlive the chain; its frames may change between calls,
// its joint types and twists may not. Evaluation allocates nothing and gives the values of ToolPose,
// ToolPosition and PerturbationFrames to round-off.
class KinematicChain {
 public:
  explicit KinematicChain(const RobotModel& model);

  const RobotModel& model() const { return *model_; }
  int num_joints() const { return static_cast<int>(z_revolute_.size()); }

  SE3d Pose(const double* q, int tool = 0) const;
  Eigen::Vector3d Position(const double* q, int tool = 0) const;
  // The perturbation frames G_0..G_n-1 and G_tool (as PerturbationFrames) into frames[0..n]; the
  // tool position is frames[n].t.
  void Frames(const double* q, int tool, FrameRt* frames) const;

 private:
  const RobotModel* model_;
  std::vector<unsigned char> z_revolute_;
  bool all_z_ = false;  // every joint revolute about z: the loops take no per-joint branch
};

// The error-model Jacobians restricted to a parameterization's bases, dP/dx = J_p_frames
// blockdiag(B_f) (eq. (29)) and d log(..)/dx = [Ad_G_f] blockdiag(B_f) (eq. (18)), in one pass with
// the forward kinematics, without forming the 3 x 6F (or 6 x 6F) frame Jacobian. Bases whose columns
// are canonical directions (the revolute-z joints' rx, ry, tx, ty and the tools' tx, ty, tz of the
// identifiable parameterization, the identity of the full one) select columns instead of multiplying.
// Refers to `model` and `p` without owning them (see KinematicChain). Evaluation allocates nothing.
class BasisJacobian {
 public:
  BasisJacobian(const RobotModel& model, const Parameterization& p);

  int num_parameters() const { return num_parameters_; }

  // Writes the 3 x num_parameters position Jacobian column-major with leading dimension `ld` >= 3
  // (J[c * ld + r]); returns P. `frames` is scratch for num_joints() + 1 frames.
  Eigen::Vector3d Position(const double* q, int tool, double* J, int ld, FrameRt* frames) const;
  // Writes the 6 x num_parameters pose Jacobian (rows (omega, v)) the same way; returns T_0,tool(q).
  SE3d Pose(const double* q, int tool, double* J, int ld, FrameRt* frames) const;

 private:
  struct FramePlan {
    int offset = 0;
    int cols = 0;
    std::vector<int> select;  // canonical column of each basis direction, or empty: general basis
    Eigen::Matrix<double, 6, Eigen::Dynamic> basis;
  };
  KinematicChain chain_;
  int num_parameters_ = 0;
  int num_joints_ = 0;
  std::vector<FramePlan> plan_;  // one per frame of the model
};

}  // namespace lpoe

#endif  // LPOE_KINEMATICS_H_
