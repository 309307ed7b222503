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

#include "lpoe/model/parameterization.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/kinematics/se3.h"

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

// ---- Joint models, as Pinocchio's JointModel types: each kind of joint the chain knows is a type,
// and all of its math is in that type's static functions, for any scalar S of the joint value
// (double, ceres::Jet) and any lane type (the kernels). `s` is the joint's twist (omega, v) in its
// own frame, always double.
//   Data<S>              what one value q leaves for the chain (Pinocchio's JointData);
//   DataAt(s, q)         that data at q;
//   Motion(s, q)         exp(s^ q) as an SE3<S>;
//   ApplyLeft(d, &p)     p <- exp(s^ q) p (BackwardChain);
//   ApplyRight(d, &X)    X <- X exp(s^ q) on a running transform (ForwardChain's accumulators);
//   Derivative(s, d)     d exp(s^ q) / dq = exp(s^ q) s^, 4 x 4;
//   PositionColumn(R, d, s, out), PoseColumn(R, t, s, out): the joint's column of the position and
//                        pose Jacobians at its frame G = (R, t) (Ad_G s, the derivative as the chain
//                        uses it; d = P - t);
//   BaseAxis(R, s)       R omega, the joint's rotation rate in the base frame;
//   kTakesSinCos         true when Data is (sin q, cos q), which callers may compute ahead (SinCosMany).
// JointModelOf classifies a Joint (the one place the kinematics reads its JointType and twist) and
// VisitJointModel is the one switch from that classification to the type. The chains, the Jacobian
// columns and the kernels reach the types only through a dispatcher (JointModelIds, ClassifiedJoints,
// AllJoints below), never by testing a joint's kind. docs/architecture.md: how to add a joint type.

// The classification: one value per joint model type.
enum class JointModelId : unsigned char { kRevoluteZ, kRevolute, kPrismatic };

// (sin q, cos q): the data of a revolute-z joint (S a scalar, a Jet or a lane type).
template <typename S>
struct SinCosData {
  S s, c;
};

// Revolute about the joint frame's z axis, twist exactly (0, 0, 1, 0, 0, 0): Rz(q), no translation,
// applied as a plane rotation of two coordinates (9 + 4 multiplications per joint on a point, 12 on
// a running transform).
struct RevoluteZJoint {
  static constexpr JointModelId kId = JointModelId::kRevoluteZ;
  static constexpr bool kTakesSinCos = true;
  template <typename S>
  using Data = SinCosData<S>;

  template <typename S>
  static Data<S> DataAt(const Vector6d& /*s*/, const S& q) {
    Data<S> d;
    SinCos(q, &d.s, &d.c);
    return d;
  }
  template <typename S>
  static SE3<S> Motion(const Vector6d& s, const S& q) {
    const Data<S> d = DataAt(s, q);
    SE3<S> X;
    X.R.setIdentity();
    internal::PlaneRotation(d.c, S(-d.s), &X.R(0, 0), &X.R(0, 1));
    internal::PlaneRotation(d.c, S(-d.s), &X.R(1, 0), &X.R(1, 1));
    return X;
  }
  // p <- Rz(q) p.
  template <typename T, typename C>
  static void ApplyLeft(const SinCosData<C>& d, Vector3<T>* p) {
    internal::PlaneRotation(d.c, d.s, &(*p)(0), &(*p)(1));
  }
  // X <- X Rz(q) (the accumulator's two-column update).
  template <typename Accumulator, typename C>
  static void ApplyRight(const SinCosData<C>& d, Accumulator* X) {
    X->RotZ(d.c, d.s);
  }
  template <typename S>
  static Matrix4<S> Derivative(const Vector6d& /*s*/, const SinCosData<S>& d) {
    Matrix4<S> D = Matrix4<S>::Zero();
    D(0, 0) = -d.s;
    D(0, 1) = -d.c;
    D(1, 0) = d.c;
    D(1, 1) = -d.s;
    return D;
  }
  // The rotation column about the frame's z (k = 2).
  template <typename V>
  static void PositionColumn(const V* R, const V* d, const Vector6d& /*s*/, V* out) {
    lpoe::PositionColumn(R, d, 2, out);
  }
  static void PoseColumn(const double* R, const double* t, const Vector6d& /*s*/, double* out) {
    AdjointColumn(R, t, 2, out);
  }
  static Eigen::Vector3d BaseAxis(const Eigen::Matrix3d& R, const Vector6d& /*s*/) {
    return R.col(2);
  }
};

// What the joints with a general motion share: their data is the motion itself, applied as a rigid
// transform, and their Jacobian columns are the twist's combination of the frame's columns.
struct GeneralMotionJoint {
  static constexpr bool kTakesSinCos = false;
  template <typename S>
  using Data = SE3<S>;

  template <typename T, typename S>
  static void ApplyLeft(const SE3<S>& M, Vector3<T>* p) {
    *p = M.R.template cast<T>() * *p + M.t.template cast<T>();
  }
  template <typename Accumulator, typename S>
  static void ApplyRight(const SE3<S>& M, Accumulator* X) {
    X->RightMultiply(M);
  }
  template <typename S>
  static Matrix4<S> Derivative(const Vector6d& s, const SE3<S>& M) {
    return M.Matrix() * Hat6(Vector6<S>(s.template cast<S>()));
  }
  // w x d + R v.
  template <typename V>
  static void PositionColumn(const V* R, const V* d, const Vector6d& s, V* out) {
    out[0] = out[1] = out[2] = V();
    V c[3];
    for (int k = 0; k < 6; ++k) {
      if (s(k) == 0.0) continue;
      lpoe::PositionColumn(R, d, k, c);
      for (int r = 0; r < 3; ++r) out[r] += s(k) * c[r];
    }
  }
  // Ad_G s.
  static void PoseColumn(const double* R, const double* t, const Vector6d& s, double* out) {
    for (int r = 0; r < 6; ++r) out[r] = 0.0;
    double c[6];
    for (int k = 0; k < 6; ++k) {
      if (s(k) == 0.0) continue;
      AdjointColumn(R, t, k, c);
      for (int r = 0; r < 6; ++r) out[r] += s(k) * c[r];
    }
  }
  static Eigen::Vector3d BaseAxis(const Eigen::Matrix3d& R, const Vector6d& s) {
    return R * s.head<3>();
  }
};

// Revolute about any axis: exp(s^ q) (any screw; RobotModel::Validate admits zero pitch only).
struct RevoluteJoint : GeneralMotionJoint {
  static constexpr JointModelId kId = JointModelId::kRevolute;
  template <typename S>
  static SE3<S> DataAt(const Vector6d& s, const S& q) {
    return ExpSE3(Vector6<S>(s.template cast<S>() * q));
  }
  template <typename S>
  static SE3<S> Motion(const Vector6d& s, const S& q) {
    return DataAt(s, q);
  }
};

// Prismatic along the twist's v: t = v q, no rotation.
struct PrismaticJoint : GeneralMotionJoint {
  static constexpr JointModelId kId = JointModelId::kPrismatic;
  template <typename S>
  static SE3<S> DataAt(const Vector6d& s, const S& q) {
    SE3<S> X;
    X.t = s.tail<3>().template cast<S>() * q;
    return X;
  }
  template <typename S>
  static SE3<S> Motion(const Vector6d& s, const S& q) {
    return DataAt(s, q);
  }
};

// The model of a joint: prismatic joints are PrismaticJoint, revolute joints of twist exactly
// (0, 0, 1, 0, 0, 0) RevoluteZJoint, other revolute joints RevoluteJoint.
inline JointModelId JointModelOf(const Joint& joint) {
  if (joint.type == JointType::kPrismatic) return JointModelId::kPrismatic;
  const Vector6d& s = joint.twist;
  const bool z = s(0) == 0 && s(1) == 0 && s(2) == 1 && s(3) == 0 && s(4) == 0 && s(5) == 0;
  return z ? JointModelId::kRevoluteZ : JointModelId::kRevolute;
}

// True for a joint of model RevoluteZJoint (the solvers' four-row kernel needs every joint so).
inline bool IsRevoluteZ(const Joint& joint) {
  return JointModelOf(joint) == JointModelId::kRevoluteZ;
}

// The one switch: f(Model()) with the type of `id` (an empty object: its static functions are the
// joint's math). Every case returns the same type.
template <typename F>
inline decltype(auto) VisitJointModel(JointModelId id, F&& f) {
  switch (id) {
    case JointModelId::kRevoluteZ:
      return f(RevoluteZJoint());
    case JointModelId::kRevolute:
      return f(RevoluteJoint());
    case JointModelId::kPrismatic:
      break;
  }
  return f(PrismaticJoint());
}

// Dispatchers: which model each joint of a chain has. `Visit(i, f)` calls f with joint i's model.
//   JointModelIds:    one id per joint, classified once (KinematicChain, JointMotions): a switch per
//                     joint;
//   ClassifiedJoints: classified as the chain reaches each joint (the one-call forms: ToolPose,
//                     ChainPose, ...);
//   AllJoints<M>:     every joint is an M, known at compile time: no switch (the chains of revolute-z
//                     joints, decided once per chain by KinematicChain; the four-row kernel).
struct JointModelIds {
  const JointModelId* ids;
  template <typename F>
  decltype(auto) Visit(int i, F&& f) const {
    return VisitJointModel(ids[i], f);
  }
};

struct ClassifiedJoints {
  const Joint* joints;
  template <typename F>
  decltype(auto) Visit(int i, F&& f) const {
    return VisitJointModel(JointModelOf(joints[i]), f);
  }
};

template <typename Model>
struct AllJoints {
  template <typename F>
  decltype(auto) Visit(int, F&& f) const {
    return f(Model());
  }
};

// Whether joint i's data is (sin q_i, cos q_i).
template <typename Models>
inline bool TakesSinCos(const Models& models, int i) {
  return models.Visit(i, [](auto model) { return decltype(model)::kTakesSinCos; });
}

// exp(s^ q) for a joint, for any scalar of the joint value (double, Jet): its model's motion.
template <typename S>
SE3<S> JointMotion(const Joint& joint, const S& q) {
  return VisitJointModel(JointModelOf(joint),
                         [&](auto model) { return decltype(model)::Motion(joint.twist, q); });
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
//   * the joint motions (`Motions`): where each joint's Data comes from: precomputed once per
//     configuration (JointMotions, sin/cos up front), computed on the fly (OnTheFlyMotions), or
//     sin/cos given by the caller (GivenSinCosMotions, RevoluteZMotions);
//   * the dispatcher of the joint models (above): per joint, or once per chain (AllJoints).
// Joint values are of any scalar S (double, or Jet when a joint-space term shifts them).

// The two operations every joint-motions policy gives the chain, written once: joint i's model
// (from the policy's dispatcher, models()) applied to joint i's data (the policy's DataOf(model, i)).
template <typename Policy>
class JointMotionsBase {
 public:
  // p <- exp(s_i^ q_i) p.
  template <typename T>
  void ApplyLeft(int i, Vector3<T>* p) const {
    const Policy& self = static_cast<const Policy&>(*this);
    self.models().Visit(i, [&](auto model) {
      decltype(model)::ApplyLeft(self.DataOf(model, i), p);
    });
  }
  // X <- X exp(s_i^ q_i).
  template <typename Accumulator>
  void ApplyRight(int i, Accumulator* X) const {
    const Policy& self = static_cast<const Policy&>(*this);
    self.models().Visit(i, [&](auto model) {
      decltype(model)::ApplyRight(self.DataOf(model, i), X);
    });
  }
};

// The motions exp(s_i^ q_i) of one configuration, computed once (the per-call Data of the chain):
// revolute-z joints keep (sin, cos), other joints their motion. The autodiff residuals evaluate the
// chain many times per Jacobian at a fixed q, and the sin/cos calls would otherwise dominate.
template <typename S = double>
class JointMotions : public JointMotionsBase<JointMotions<S>> {
 public:
  JointMotions() = default;
  JointMotions(const RobotModel& model, const S* q) { Set(model, q); }

  void Set(const RobotModel& model, const S* q) {
    motions_.resize(model.num_joints());
    for (int i = 0; i < model.num_joints(); ++i) {
      const Joint& joint = model.joints[i];
      Motion& m = motions_[i];
      m.id = JointModelOf(joint);
      VisitJointModel(m.id,
                      [&](auto type) { Store(decltype(type)::DataAt(joint.twist, q[i]), &m); });
    }
  }

  // The dispatcher and the data (JointMotionsBase).
  struct Models {
    const JointMotions* motions;
    template <typename F>
    decltype(auto) Visit(int i, F&& f) const {
      return VisitJointModel(motions->motions_[i].id, f);
    }
  };
  Models models() const { return Models{this}; }
  const SinCosData<S>& DataOf(RevoluteZJoint, int i) const { return motions_[i].sin_cos; }
  template <typename Model>
  const SE3<S>& DataOf(Model, int i) const {
    return motions_[i].general;
  }

 private:
  struct Motion {
    JointModelId id = JointModelId::kRevoluteZ;
    SinCosData<S> sin_cos = {S(0), S(1)};
    SE3<S> general;
  };
  static void Store(const SinCosData<S>& d, Motion* m) { m->sin_cos = d; }
  static void Store(const SE3<S>& M, Motion* m) { m->general = M; }
  std::vector<Motion> motions_;
};

// The joint motions computed as the chain reaches each joint (no set-up, nothing stored): sin/cos
// interleaved with the chain. `models` is the chain's dispatcher.
template <typename Models, typename S = double>
class OnTheFlyMotions : public JointMotionsBase<OnTheFlyMotions<Models, S>> {
 public:
  OnTheFlyMotions(const Joint* joints, const S* q, Models models)
      : joints_(joints), q_(q), models_(models) {}

  const Models& models() const { return models_; }
  template <typename Model>
  auto DataOf(Model, int i) const {
    return Model::DataAt(joints_[i].twist, q_[i]);
  }

 private:
  const Joint* joints_;
  const S* q_;
  Models models_;
};

template <typename S, typename Models>
OnTheFlyMotions<Models, S> MakeOnTheFlyMotions(const Joint* joints, const S* q, Models models) {
  return OnTheFlyMotions<Models, S>(joints, q, models);
}

// The joint motions with sin(q_i) and cos(q_i) of the revolute-z joints given as values of C
// (computed for many values at once by SinCosMany, kept up to date by the caller, or a vector of
// lanes: one configuration per lane); other joints as OnTheFlyMotions (joints and q may be null when
// the dispatcher has revolute-z joints only).
template <typename Models, typename C = double>
class GivenSinCosMotions : public JointMotionsBase<GivenSinCosMotions<Models, C>> {
 public:
  GivenSinCosMotions(const Joint* joints, const double* q, Models models, const C* sin_q,
                     const C* cos_q)
      : joints_(joints), q_(q), models_(models), s_(sin_q), c_(cos_q) {}

  const Models& models() const { return models_; }
  SinCosData<C> DataOf(RevoluteZJoint, int i) const { return SinCosData<C>{s_[i], c_[i]}; }
  template <typename Model>
  auto DataOf(Model, int i) const {
    return Model::DataAt(joints_[i].twist, q_[i]);
  }

 private:
  const Joint* joints_;
  const double* q_;
  Models models_;
  const C* s_;
  const C* c_;
};

template <typename Models>
GivenSinCosMotions<Models> MakeGivenSinCosMotions(const Joint* joints, const double* q,
                                                  Models models, const double* sin_q,
                                                  const double* cos_q) {
  return GivenSinCosMotions<Models>(joints, q, models, sin_q, cos_q);
}

// The joint motions of a chain whose joints are all revolute about z, with sin(q_i) and cos(q_i)
// given as values of C (double, or a vector of lanes: one configuration per lane).
template <typename C>
GivenSinCosMotions<AllJoints<RevoluteZJoint>, C> RevoluteZMotions(const C* sin_q, const C* cos_q) {
  return GivenSinCosMotions<AllJoints<RevoluteZJoint>, C>(nullptr, nullptr,
                                                          AllJoints<RevoluteZJoint>(), sin_q, cos_q);
}

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
               MakeOnTheFlyMotions(model.joints.data(), q, ClassifiedJoints{model.joints.data()}),
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
      MakeOnTheFlyMotions(model.joints.data(), q, ClassifiedJoints{model.joints.data()}),
      tool_point);
}

// The same chain with the joint motions precomputed.
template <typename T, typename Frame = SE3<T>, typename S = double>
Vector3<T> ChainPosition(const JointMotions<S>& motions, int num_joints, const Frame* joint_origins,
                         const Vector3<T>& tool_point) {
  return BackwardChain<T>(
      num_joints, [&](int i) -> const Frame& { return joint_origins[i]; }, motions, tool_point);
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

// A robot model prepared for many evaluations: each joint's model (JointModelOf) is decided once,
// and whether one model serves the whole chain (the model-independent checks leave the loop). Like Pinocchio's Model/Data split, it refers to
// `model` without owning it: the model must outlive the chain; its frames may change between calls,
// its joint types and twists may not. Evaluation allocates nothing and gives the values of ToolPose,
// ToolPosition and PerturbationFrames to round-off.
class KinematicChain {
 public:
  explicit KinematicChain(const RobotModel& model);

  const RobotModel& model() const { return *model_; }
  int num_joints() const { return static_cast<int>(models_.size()); }
  // Joint i's model (JointModelOf, decided once).
  JointModelId joint_model(int i) const { return models_[i]; }

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

  // Calls f with the chain's dispatcher of the joint models, chosen once per call:
  // AllJoints<RevoluteZJoint> when every joint is revolute about z (the loops inline the plane
  // rotations with no per-joint switch), else the joints' ids (JointModelIds).
  template <typename F>
  decltype(auto) WithModels(F&& f) const {
    if (all_z_) return f(AllJoints<RevoluteZJoint>());
    return f(JointModelIds{models_.data()});
  }

 private:
  const RobotModel* model_;
  std::vector<JointModelId> models_;
  bool all_z_ = false;  // every joint revolute about z
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
