// Forward kinematics of the LPoE chain (paper eqs. (6), (7), (26)) and the analytic Jacobians of the
// error model (eqs. (18), (29)).
//
// The chain is written once (ForwardChain, BackwardChain below), as a template on the scalar of the
// local frames and on the scalar of the joint values: doubles for the linear solver and the tools,
// ceres::Jet for automatic differentiation (the Ceres residuals pass their parameter blocks as frames,
// and Jet joint values when a joint-space term shifts them). Twists are data, always double.
// docs/architecture.md describes the layers; docs/conventions.md the conventions.
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

// sin(x[k]) and cos(x[k]) for k in [0, count), into s[k] and c[k]: for the rows of a block at once
// (the solvers' passes over many measurements). On processors with AVX2 and FMA four values go
// through one call of SLEEF's vectorized sincos (kernels::SinCos4Avx2: within 1.0 ulp of the
// exact values for every double, several times cheaper than a sincos call per value); other
// processors and LPOE_KERNELS=reference take libm's sincos. The result of each value depends on
// that value only (not on count or on its neighbours).
void SinCosMany(const double* x, int count, double* s, double* c);

// The most joints for which the forward passes below take sin and cos given by the caller.
constexpr int kMaxGivenSinCosJoints = 16;

// The same for any other scalar (ceres::Jet joint values: sin and cos found by ADL).
template <typename S>
inline void SinCos(const S& x, S* s, S* c) {
  using std::cos;
  using std::sin;
  *s = sin(x);
  *c = cos(x);
}

// True for a revolute joint whose twist is exactly (0, 0, 1, 0, 0, 0): its motion is Rz(q) with no
// translation, which every chain below applies as a plane rotation of two coordinates.
inline bool IsRevoluteZ(const Joint& joint) {
  const Vector6d& s = joint.twist;
  return joint.type == JointType::kRevolute && s(0) == 0 && s(1) == 0 && s(2) == 1 && s(3) == 0 &&
         s(4) == 0 && s(5) == 0;
}

namespace internal {

// The revolute-about-z update, written once for every chain, scalar and register type:
// (x, y) <- (c x - s y, s x + c y).
//   on a point, p <- Rz(q) p:             PlaneRotation(c, s, &p_x, &p_y);
//   on a frame, R <- R Rz(q) (columns):   PlaneRotation(c, -s, &R_col0, &R_col1) per row.
// `A` is a scalar, a Jet or an SSE2 register (GCC/Clang vector arithmetic), `C` its coefficient.
template <typename A, typename C>
inline void PlaneRotation(const C& c, const C& s, A* x, A* y) {
  const A x0 = *x;
  *x = c * x0 - s * *y;
  *y = s * x0 + c * *y;
}

}  // namespace internal

// ---- Joint models (as Pinocchio's JointModel types): the three kinds of joint the chain knows. Each
// gives its motion exp(s^ q) for any scalar of the joint value (double, Jet); the revolute-z model
// also its updates from (sin q, cos q), the form every chain below applies it in.

// Revolute about the joint frame's z axis, twist exactly (0, 0, 1, 0, 0, 0): Rz(q), no translation.
struct JointModelRevoluteZ {
  template <typename S>
  static SE3<S> Motion(const S& q) {
    S sn, c;
    SinCos(q, &sn, &c);
    SE3<S> X;
    X.R.setIdentity();
    internal::PlaneRotation(c, S(-sn), &X.R(0, 0), &X.R(0, 1));
    internal::PlaneRotation(c, S(-sn), &X.R(1, 0), &X.R(1, 1));
    return X;
  }
  // p <- Rz(q) p.
  template <typename T, typename C>
  static void ApplyLeft(const C& c, const C& s, Vector3<T>* p) {
    internal::PlaneRotation(c, s, &(*p)(0), &(*p)(1));
  }
  // X <- X Rz(q) (the accumulator's two-column update).
  template <typename Accumulator, typename C>
  static void ApplyRight(const C& c, const C& s, Accumulator* X) {
    X->RotZ(c, s);
  }
};

// Revolute about any axis (a general screw of zero pitch, or with pitch): exp(s^ q).
struct JointModelRevolute {
  template <typename S>
  static SE3<S> Motion(const Vector6d& twist, const S& q) {
    return ExpSE3(Vector6<S>(twist.template cast<S>() * q));
  }
};

// Prismatic along the twist's v: t = v q, no rotation.
struct JointModelPrismatic {
  template <typename S>
  static SE3<S> Motion(const Vector6d& twist, const S& q) {
    SE3<S> X;
    X.t = twist.tail<3>().template cast<S>() * q;
    return X;
  }
};

// exp(s^ q) for a joint of the given twist, for any scalar of the joint value (double, Jet): the
// joint's model's motion.
template <typename S>
SE3<S> JointMotion(const Joint& joint, const S& q) {
  if (joint.type == JointType::kPrismatic) return JointModelPrismatic::Motion(joint.twist, q);
  if (IsRevoluteZ(joint)) return JointModelRevoluteZ::Motion(q);
  return JointModelRevolute::Motion(joint.twist, q);
}

// ---- One forward-kinematics template.
//
// Every evaluation of the chain T_0,tool(q) = prod_i T_{i-1,i}(0) exp(s_i^ q_i) * T_n,tool (paper
// eq. (7)) goes through one of two passes, written once:
//   ForwardChain:  from the base to the tool on a running transform (poses, perturbation frames);
//   BackwardChain: from the tool back to the base on a point (positions, eq. (26)): 9 + 4
//                  multiplications per revolute-z joint and no rotation products.
// What differs between the fast double paths, the Jet paths of Ceres and the analytic Jacobians is
// a policy:
//   * the running transform (`Accumulator`): SE3Accumulator<T> for any scalar (Jets);
//     LaneAccumulator<V> on twelve values of a lane type (the four-row kernel's four configurations
//     at once); for the double fast paths the register-pair form of kinematics.cc (rows 0 and 1 of
//     a column in one SSE2 register: 1.1-1.2x faster IK than LaneAccumulator<double>, measured);
//   * the local frames (`origin(i)`): the model's own frames, or parameter blocks (SE3<T>, or
//     QuaternionTransform<T> acting on a point straight from the quaternion);
//   * the joint motions (`Motions`): precomputed once per configuration (JointMotions, the
//     "Data" of one q: sin/cos up front), or computed on the fly (OnTheFlyMotions);
//   * which joints are revolute about z: checked per call, or once (KinematicChain).
// Joint values are of any scalar S (double, or Jet when a joint-space term shifts them).

// The motions exp(s_i^ q_i) of one configuration, computed once (the per-call Data of the chain):
// revolute-z joints keep (sin, cos), other joints their motion. The autodiff residuals evaluate the
// chain many times per Jacobian at a fixed q, and the sin/cos calls would otherwise dominate.
template <typename S = double>
class JointMotions {
 public:
  JointMotions(const RobotModel& model, const S* q) : motions_(model.num_joints()) {
    for (int i = 0; i < model.num_joints(); ++i) {
      Motion& m = motions_[i];
      m.revolute_z = IsRevoluteZ(model.joints[i]);
      if (m.revolute_z) {
        SinCos(q[i], &m.s, &m.c);
      } else {
        m.general = JointMotion(model.joints[i], q[i]);
      }
    }
  }

  // p <- exp(s_i^ q_i) p.
  template <typename T>
  void ApplyLeft(int i, Vector3<T>* p) const {
    const Motion& m = motions_[i];
    if (m.revolute_z) {
      JointModelRevoluteZ::ApplyLeft(m.c, m.s, p);
    } else {
      *p = m.general.R.template cast<T>() * *p + m.general.t.template cast<T>();
    }
  }
  // X <- X exp(s_i^ q_i).
  template <typename Accumulator>
  void ApplyRight(int i, Accumulator* X) const {
    const Motion& m = motions_[i];
    if (m.revolute_z) {
      JointModelRevoluteZ::ApplyRight(m.c, m.s, X);
    } else {
      X->RightMultiply(m.general);
    }
  }

 private:
  struct Motion {
    bool revolute_z = false;
    S s = S(0), c = S(1);
    SE3<S> general;
  };
  std::vector<Motion> motions_;
};

// The joint motions computed as the chain reaches each joint (no set-up, nothing stored): sin/cos
// interleaved with the chain. `is_z(i)` tells which joints are revolute about z.
template <typename IsZ, typename S = double>
class OnTheFlyMotions {
 public:
  OnTheFlyMotions(const Joint* joints, const S* q, IsZ is_z) : joints_(joints), q_(q), is_z_(is_z) {}

  template <typename T>
  void ApplyLeft(int i, Vector3<T>* p) const {
    if (is_z_(i)) {
      S s, c;
      SinCos(q_[i], &s, &c);
      JointModelRevoluteZ::ApplyLeft(c, s, p);
    } else {
      const SE3<S> M = JointMotion(joints_[i], q_[i]);
      *p = M.R.template cast<T>() * *p + M.t.template cast<T>();
    }
  }
  template <typename Accumulator>
  void ApplyRight(int i, Accumulator* X) const {
    if (is_z_(i)) {
      S s, c;
      SinCos(q_[i], &s, &c);
      JointModelRevoluteZ::ApplyRight(c, s, X);
    } else {
      X->RightMultiply(JointMotion(joints_[i], q_[i]));
    }
  }

 private:
  const Joint* joints_;
  const S* q_;
  IsZ is_z_;
};

template <typename S, typename IsZ>
OnTheFlyMotions<IsZ, S> MakeOnTheFlyMotions(const Joint* joints, const S* q, IsZ is_z) {
  return OnTheFlyMotions<IsZ, S>(joints, q, is_z);
}

// The joint motions with sin(q_i) and cos(q_i) of the revolute-z joints given (computed for many
// values at once by SinCosMany, or kept up to date by the caller); other joints as OnTheFlyMotions.
template <typename IsZ>
class GivenSinCosMotions {
 public:
  GivenSinCosMotions(const Joint* joints, const double* q, IsZ is_z, const double* sin_q,
                     const double* cos_q)
      : other_(joints, q, is_z), is_z_(is_z), s_(sin_q), c_(cos_q) {}

  template <typename T>
  void ApplyLeft(int i, Vector3<T>* p) const {
    if (is_z_(i)) {
      JointModelRevoluteZ::ApplyLeft(c_[i], s_[i], p);
    } else {
      other_.ApplyLeft(i, p);
    }
  }
  template <typename Accumulator>
  void ApplyRight(int i, Accumulator* X) const {
    if (is_z_(i)) {
      JointModelRevoluteZ::ApplyRight(c_[i], s_[i], X);
    } else {
      other_.ApplyRight(i, X);
    }
  }

 private:
  OnTheFlyMotions<IsZ, double> other_;
  IsZ is_z_;
  const double* s_;
  const double* c_;
};

template <typename IsZ>
GivenSinCosMotions<IsZ> MakeGivenSinCosMotions(const Joint* joints, const double* q, IsZ is_z,
                                               const double* sin_q, const double* cos_q) {
  return GivenSinCosMotions<IsZ>(joints, q, is_z, sin_q, cos_q);
}

// The joint motions of a chain whose joints are all revolute about z, with sin(q_i) and cos(q_i) given
// as values of C (double, or a vector of lanes: one configuration per lane).
template <typename C>
class RevoluteZMotions {
 public:
  RevoluteZMotions(const C* sin_q, const C* cos_q) : s_(sin_q), c_(cos_q) {}
  template <typename T>
  void ApplyLeft(int i, Vector3<T>* p) const {
    JointModelRevoluteZ::ApplyLeft(c_[i], s_[i], p);
  }
  template <typename Accumulator>
  void ApplyRight(int i, Accumulator* X) const {
    JointModelRevoluteZ::ApplyRight(c_[i], s_[i], X);
  }

 private:
  const C* s_;
  const C* c_;
};

// Scratch for one value per joint: on the stack for up to N joints, else on the heap (the autodiff
// residuals build their frames in it on every evaluation).
template <typename V, int N = 16>
class JointScratch {
 public:
  explicit JointScratch(int count) {
    if (count > N) heap_.resize(count);
    data_ = count > N ? heap_.data() : stack_;
  }
  V* data() { return data_; }
  V& operator[](int i) { return data_[i]; }

 private:
  V stack_[N];
  std::vector<V> heap_;
  V* data_;
};

// The running transform of ForwardChain for any scalar.
template <typename T>
struct SE3Accumulator {
  SE3<T> X;

  template <typename Frame>
  void Set(const Frame& F) {
    X = F.template cast<T>();
  }
  template <typename Frame>
  void RightMultiply(const Frame& F) {
    X = X * F.template cast<T>();
  }
  // R <- R Rz(q): columns 0 and 1 only (12 multiplications instead of a 3x3 product).
  template <typename C>
  void RotZ(const C& c, const C& s) {
    for (int r = 0; r < 3; ++r) internal::PlaneRotation(c, C(-s), &X.R(r, 0), &X.R(r, 1));
  }
};

// The running transform of ForwardChain as twelve values of an arithmetic type V (R column-major in
// R[0..8], t in t[0..2]): V is a vector of lanes (GCC/Clang vector arithmetic: several
// configurations at once, one per lane, as the four-row kernel of core/src/kernels/ instantiates
// it), or double.
// Coefficients are doubles (the same frame in every lane) or V (a frame per lane). The products in a
// fixed order: new column c = (R_0 a + R_1 b) + R_2 d, t <- (R_0 a + t) + (R_1 b + R_2 d).
template <typename V>
struct LaneAccumulator {
  V R[9];
  V t[3];

  // X <- F (the same frame in every lane).
  void Set(const SE3d& F) {
    for (int k = 0; k < 9; ++k) R[k] = Splat(F.R.data()[k]);
    for (int k = 0; k < 3; ++k) t[k] = Splat(F.t(k));
  }
  // X <- X F (the same frame in every lane).
  void RightMultiply(const SE3d& F) { RightMultiplyBy(F.R.data(), F.t.data()); }
  // X <- X (M, m): M column-major; C is double (one frame) or V (a frame per lane).
  template <typename C>
  void RightMultiplyBy(const C* M, const C* m) {
    V N[9];
    for (int c = 0; c < 3; ++c) {
      for (int r = 0; r < 3; ++r) {
        N[3 * c + r] = (R[r] * M[3 * c] + R[3 + r] * M[3 * c + 1]) + R[6 + r] * M[3 * c + 2];
      }
    }
    for (int r = 0; r < 3; ++r) t[r] = (R[r] * m[0] + t[r]) + (R[3 + r] * m[1] + R[6 + r] * m[2]);
    for (int k = 0; k < 9; ++k) R[k] = N[k];
  }
  // R <- R Rz(q): columns 0 and 1 only (12 multiplications instead of a 3x3 product).
  template <typename C>
  void RotZ(const C& c, const C& s) {
    for (int r = 0; r < 3; ++r) internal::PlaneRotation(c, C(-s), &R[r], &R[3 + r]);
  }

 private:
  static V Splat(double x) {
    V v = {};
    return v + x;  // a scalar converts to every lane
  }
};

// X = O_0 M_0 O_1 M_1 ... O_n-1 M_n-1 (the chain up to the last joint); `frame(i, X)` sees X just
// before joint i moves, G_i = T_0,i-1(q) T_{i-1,i}(0), and `moved(i, X)` just after, the link frame
// T_0,i(q). The accumulator is set from origin(0).
template <typename Accumulator, typename Origins, typename Motions, typename FrameSink,
          typename MovedSink>
inline void ForwardChain(int num_joints, const Origins& origin, const Motions& motions,
                         Accumulator* X, const FrameSink& frame, const MovedSink& moved) {
  X->Set(origin(0));
  for (int i = 0; i < num_joints; ++i) {
    if (i > 0) X->RightMultiply(origin(i));
    frame(i, *X);
    motions.ApplyRight(i, X);
    moved(i, *X);
  }
}

template <typename Accumulator, typename Origins, typename Motions, typename FrameSink>
inline void ForwardChain(int num_joints, const Origins& origin, const Motions& motions,
                         Accumulator* X, const FrameSink& frame) {
  ForwardChain(num_joints, origin, motions, X, frame, [](int, const Accumulator&) {});
}

// P = O_0 M_0 ... O_n-1 M_n-1 p, from the tool back to the base: p <- O_i (M_i p).
template <typename T, typename Origins, typename Motions>
inline Vector3<T> BackwardChain(int num_joints, const Origins& origin, const Motions& motions,
                                Vector3<T> p) {
  for (int i = num_joints - 1; i >= 0; --i) {
    motions.ApplyLeft(i, &p);
    p = origin(i) * p;
  }
  return p;
}

// T_0,tool(q) with the local frames given by `joint_origins[0..n)` and `tool_origin` (paper eq. (7)).
// `q` holds n joint values (double, or a Jet when joint-space terms shift them).
template <typename T, typename Q = double>
SE3<T> ChainPose(const RobotModel& model, const SE3<T>* joint_origins, const SE3<T>& tool_origin,
                 const Q* q) {
  SE3Accumulator<T> X;
  ForwardChain(model.num_joints(), [&](int i) -> const SE3<T>& { return joint_origins[i]; },
               MakeOnTheFlyMotions(model.joints.data(), q,
                                   [&](int i) { return IsRevoluteZ(model.joints[i]); }),
               &X, [](int, const SE3Accumulator<T>&) {});
  return X.X * tool_origin;
}

// The same chain with the joint motions precomputed.
template <typename T, typename S = double>
SE3<T> ChainPose(const JointMotions<S>& motions, int num_joints, const SE3<T>* joint_origins,
                 const SE3<T>& tool_origin) {
  SE3Accumulator<T> X;
  ForwardChain(num_joints, [&](int i) -> const SE3<T>& { return joint_origins[i]; }, motions, &X,
               [](int, const SE3Accumulator<T>&) {});
  return X.X * tool_origin;
}

// Position-only variant (eq. (26)): P = T_0,n(q) * p_tool, evaluated backward on a point.
// `Frame` is SE3<T> or any transform acting on a Vector3<T> with operator* (e.g.
// QuaternionTransform<T>, used by the autodiff residual).
template <typename T, typename Frame = SE3<T>, typename Q = double>
Vector3<T> ChainPosition(const RobotModel& model, const Frame* joint_origins,
                         const Vector3<T>& tool_point, const Q* q) {
  return BackwardChain<T>(
      model.num_joints(), [&](int i) -> const Frame& { return joint_origins[i]; },
      MakeOnTheFlyMotions(model.joints.data(), q,
                          [&](int i) { return IsRevoluteZ(model.joints[i]); }),
      tool_point);
}

// The same chain with the joint motions precomputed.
template <typename T, typename Frame = SE3<T>, typename S = double>
Vector3<T> ChainPosition(const JointMotions<S>& motions, int num_joints, const Frame* joint_origins,
                         const Vector3<T>& tool_point) {
  return BackwardChain<T>(
      num_joints, [&](int i) -> const Frame& { return joint_origins[i]; }, motions, tool_point);
}

// ---- Jacobian columns, written once for every scalar and lane type V (double, or the lanes of the
// four-row kernel). A frame G = (R, t) is given by R column-major (R[3 k + r]) and t; d = P - t is the
// tool point P seen from the frame's origin.

// Column k of the 3 x 6 position Jacobian of a right perturbation (omega, v) of G (eq. (29) without
// the adjoint): k < 3: d/d omega_k = R_k x d (= -(P - t)^ R e_k); k >= 3: d/d v_k = R_{k-3}. The
// position column of a joint revolute about its frame's z is k = 2.
template <typename V>
inline void PositionColumn(const V* R, const V* d, int k, V* out) {
  if (k < 3) {
    const V* Rk = R + 3 * k;
    out[0] = Rk[1] * d[2] - Rk[2] * d[1];
    out[1] = Rk[2] * d[0] - Rk[0] * d[2];
    out[2] = Rk[0] * d[1] - Rk[1] * d[0];
  } else {
    const V* Rk = R + 3 * (k - 3);
    out[0] = Rk[0];
    out[1] = Rk[1];
    out[2] = Rk[2];
  }
}

// Column k of Ad_G = [[R, 0], [t^ R, R]] (eq. (18)): k < 3: (R_k, t x R_k); k >= 3: (0, R_{k-3}).
template <typename V>
inline void AdjointColumn(const V* R, const V* t, int k, V* out) {
  if (k < 3) {
    const V* Rk = R + 3 * k;
    out[0] = Rk[0];
    out[1] = Rk[1];
    out[2] = Rk[2];
    out[3] = t[1] * Rk[2] - t[2] * Rk[1];
    out[4] = t[2] * Rk[0] - t[0] * Rk[2];
    out[5] = t[0] * Rk[1] - t[1] * Rk[0];
  } else {
    const V* Rk = R + 3 * (k - 3);
    out[0] = out[1] = out[2] = V();
    out[3] = Rk[0];
    out[4] = Rk[1];
    out[5] = Rk[2];
  }
}

// The column of a joint whose twist in its own frame is s (revolute about z when `z`) at its frame
// G = (R, t): Ad_G s (6 rows; the pose Jacobian, and the joint's twist in the base frame), the
// twist's combination of the frame's AdjointColumns.
inline void JointPoseColumn(const double* R, const double* t, const Vector6d& s, bool z,
                            double* out) {
  if (z) return AdjointColumn(R, t, 2, out);
  for (int r = 0; r < 6; ++r) out[r] = 0.0;
  double c[6];
  for (int k = 0; k < 6; ++k) {
    if (s(k) == 0.0) continue;
    AdjointColumn(R, t, k, c);
    for (int r = 0; r < 6; ++r) out[r] += s(k) * c[r];
  }
}

// The same joint's column in the position Jacobian at the tool point (d = P - t): w x d + R v, the
// twist's combination of the frame's PositionColumns.
inline void JointPositionColumn(const double* R, const double* d, const Vector6d& s, bool z,
                                double* out) {
  if (z) return PositionColumn(R, d, 2, out);
  out[0] = out[1] = out[2] = 0.0;
  double c[3];
  for (int k = 0; k < 6; ++k) {
    if (s(k) == 0.0) continue;
    PositionColumn(R, d, k, c);
    for (int r = 0; r < 3; ++r) out[r] += s(k) * c[r];
  }
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

// Jacobian of the tool position with respect to the joint values at q (3 x n): column i is
// w_i x P + v_i, where (w_i, v_i) = Ad_{G_i} s_i is joint i's twist in the base frame
// (T(q + dq e_i) = exp((Ad_{G_i} s_i dq)^) T(q)). `J_p_q` is resized to 3 x n. Returns P.
Eigen::Vector3d ToolPositionJointJacobian(const RobotModel& model, const double* q, int tool,
                                          Eigen::MatrixXd* J_p_q);
Eigen::Vector3d ToolPositionJointJacobian(const RobotModel& model, const double* q, int tool,
                                          Eigen::Matrix<double, 3, Eigen::Dynamic>* J_p_q);

// The same for the pose, in the convention of ToolPoseJacobian (6 x n, column i = Ad_{G_i} s_i).
// Returns T_0,tool(q).
SE3d ToolPoseJointJacobian(const RobotModel& model, const double* q, int tool,
                           Eigen::MatrixXd* J_pose_q);

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
  // The same with sin(q_i) and cos(q_i) of the revolute-z joints given (as Frames below; other
  // joints read q[i]); the same value as Position(q, tool) when they are libm's.
  Eigen::Vector3d Position(const double* q, const double* sin_q, const double* cos_q,
                           int tool) const;
  // The perturbation frames G_0..G_n-1 and G_tool (as PerturbationFrames) into frames[0..n]; the
  // tool position is frames[n].t.
  void Frames(const double* q, int tool, FrameRt* frames) const;
  // The same with sin(q_i) and cos(q_i) of the revolute-z joints given (sin_q[i], cos_q[i]; other
  // joints read q[i]): for a caller that updates them incrementally instead of calling sincos.
  void Frames(const double* q, const double* sin_q, const double* cos_q, int tool,
              FrameRt* frames) const;
  // Joint Jacobian at the tool point from the frames of Frames() (geometric Jacobian, one forward
  // sweep): 6 x n, column-major with leading dimension ld >= 6. Column i is joint i's spatial twist
  // Ad_{G_i} s_i moved to the tool position P = frames[n].t: rows dP/dq_i = w_i x (P - t_i) + R_i v_i
  // (mm per rad or mm per mm), then w_i = R_i omega_i (the base-frame rotation rate), with
  // G_i = (R_i, t_i) and s_i = (omega_i, v_i).
  // With rows = 3 only the position rows (ld >= 3).
  void ToolJointJacobian(const FrameRt* frames, double* J, int ld, int rows = 6) const;

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
  int num_joints() const { return num_joints_; }

  // Writes the 3 x num_parameters position Jacobian column-major with leading dimension `ld` >= 3
  // (J[c * ld + r]); returns P. `frames` is scratch for num_joints() + 1 frames.
  Eigen::Vector3d Position(const double* q, int tool, double* J, int ld, FrameRt* frames) const;
  // Writes the 6 x num_parameters pose Jacobian (rows (omega, v)) the same way; returns T_0,tool(q).
  SE3d Pose(const double* q, int tool, double* J, int ld, FrameRt* frames) const;
  // The same two with sin(q_i) and cos(q_i) of the revolute-z joints given (SinCosMany over a block
  // of rows; KinematicChain::Frames): at most kMaxGivenSinCosJoints joints.
  Eigen::Vector3d Position(const double* q, const double* sin_q, const double* cos_q, int tool,
                           double* J, int ld, FrameRt* frames) const;
  SE3d Pose(const double* q, const double* sin_q, const double* cos_q, int tool, double* J, int ld,
            FrameRt* frames) const;

  // After Position (or Pose) at q with the same `frames`: the 3 x n (or 6 x n) Jacobian of that
  // output with respect to the joint values, column-major with leading dimension `ld`.
  void PositionJointJacobian(const FrameRt* frames, double* J, int ld) const;
  void PoseJointJacobian(const FrameRt* frames, double* J, int ld) const;

 private:
  struct FramePlan {
    int offset = 0;
    int cols = 0;
    std::vector<int> select;  // canonical column of each basis direction, or empty: general basis
    Eigen::Matrix<double, 6, Eigen::Dynamic> basis;
  };
  KinematicChain chain_;
  const RobotModel* model_;
  int num_parameters_ = 0;
  int num_joints_ = 0;
  std::vector<FramePlan> plan_;  // one per frame of the model
};

}  // namespace lpoe

#endif  // LPOE_KINEMATICS_H_
