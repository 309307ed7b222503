#include "lpoe/kinematics/kinematics.h"

#include "lpoe/kinematics/kernels.h"

#include <algorithm>
#include <cmath>

#include <glog/logging.h>


namespace lpoe {
namespace {

// The running product of the double forward pass on a lane type: each column of R (and t) as a
// pair of rows 0 and 1 (GCC/Clang vector arithmetic, two doubles: SSE2 on x86-64, NEON elsewhere,
// plain code where there is none) plus row 2 as a scalar, so that a 3x3 product takes 18 multiplications
// on pairs or scalars instead of 27. The products in a fixed order: new column c =
// (R_0 a + R_1 b) + R_2 d, t <- (R_0 a + t) + (R_1 b + R_2 d).
struct Accumulator {
  typedef double Pair __attribute__((vector_size(16)));
  Pair lo[4];     // rows 0 and 1 of columns 0..2 of R, then of t
  double hi[4];   // row 2

  static Pair Splat(double v) { return Pair{v, v}; }
  void Set(const SE3d& X) {
    for (int k = 0; k < 3; ++k) {
      lo[k] = Pair{X.R(0, k), X.R(1, k)};
      hi[k] = X.R(2, k);
    }
    lo[3] = Pair{X.t(0), X.t(1)};
    hi[3] = X.t(2);
  }
  // (R, t) <- (R, t) * (M, m).
  void RightMultiply(const SE3d& X) {
    const double* M = X.R.data();  // column-major
    Pair nlo[3];
    double nhi[3];
    for (int c = 0; c < 3; ++c) {
      const double a = M[3 * c], b = M[3 * c + 1], d = M[3 * c + 2];
      nlo[c] = (lo[0] * Splat(a) + lo[1] * Splat(b)) + lo[2] * Splat(d);
      nhi[c] = (hi[0] * a + hi[1] * b) + hi[2] * d;
    }
    const double a = X.t(0), b = X.t(1), d = X.t(2);
    lo[3] = (lo[0] * Splat(a) + lo[3]) + (lo[1] * Splat(b) + lo[2] * Splat(d));
    hi[3] = (hi[0] * a + hi[3]) + (hi[1] * b + hi[2] * d);
    for (int c = 0; c < 3; ++c) {
      lo[c] = nlo[c];
      hi[c] = nhi[c];
    }
  }
  // R <- R Rz(q): columns 0 and 1 only.
  void RotZ(double cq, double sq) {
    internal::PlaneRotation(Splat(cq), Splat(-sq), &lo[0], &lo[1]);
    internal::PlaneRotation(cq, -sq, &hi[0], &hi[1]);
  }
  void Store(Eigen::Matrix3d* R, Eigen::Vector3d* t) const {
    for (int k = 0; k < 3; ++k) {
      (*R)(0, k) = lo[k][0];
      (*R)(1, k) = lo[k][1];
      (*R)(2, k) = hi[k];
    }
    (*t)(0) = lo[3][0];
    (*t)(1) = lo[3][1];
    (*t)(2) = hi[3];
  }
};

// Joints whose sin/cos are computed ahead of the chain (longer chains compute them on the fly).
// Every XMM register is caller-saved on x86-64, so a sincos call inside the chain would spill and
// reload the running product; computed first, the calls have nothing live around them.
constexpr int kSinCosUpFront = kMaxGivenSinCosJoints;

// The forward pass shared by every double path (ForwardChain with the accumulator above):
// X = prod_i T_{i-1,i}(0) exp(s_i^ q_i) * tail, `models` the dispatcher of the joint models. When
// `frames` is given, frames[i] receives G_i = T_0,i-1(q) T_{i-1,i}(0) (before joint i moves).
template <typename Models>
inline void ForwardPass(const RobotModel& model, const double* q, Models models, const SE3d* tail,
                        Eigen::Matrix3d* R, Eigen::Vector3d* t, FrameRt* frames,
                        const double* sin_q = nullptr, const double* cos_q = nullptr) {
  const int n = model.num_joints();
  const Joint* joints = model.joints.data();
  Accumulator X;
  auto origin = [joints](int i) -> const SE3d& { return joints[i].origin; };
  auto sink = [frames](int i, const Accumulator& A) {
    if (frames != nullptr) A.Store(&frames[i].R, &frames[i].t);
  };
  if (n <= kSinCosUpFront) {
    // The sin/cos of every revolute-z joint before the chain (unless given), on the stack.
    double own_s[kSinCosUpFront], own_c[kSinCosUpFront];
    if (sin_q == nullptr) {
      for (int i = 0; i < n; ++i) {
        if (TakesSinCos(models, i)) SinCos(q[i], &own_s[i], &own_c[i]);
      }
      sin_q = own_s;
      cos_q = own_c;
    }
    ForwardChain(n, origin, MakeGivenSinCosMotions(joints, q, models, sin_q, cos_q), &X, sink);
  } else {
    CHECK(sin_q == nullptr) << "given sin/cos: at most " << kSinCosUpFront << " joints";
    ForwardChain(n, origin, MakeOnTheFlyMotions(joints, q, models), &X, sink);
  }
  if (tail != nullptr) X.RightMultiply(*tail);
  X.Store(R, t);
}

// P = T_0,n(q) p, from the tool back to the base with vectors only (BackwardChain). Here the
// sin/cos calls stay interleaved with the chain (measured faster than computing them first: only
// three values are live across each call, and the chain of one joint overlaps the next call).
template <typename Models>
inline Eigen::Vector3d BackwardPosition(const RobotModel& model, const double* q, Models models,
                                        const Eigen::Vector3d& tool_point) {
  const Joint* joints = model.joints.data();
  return BackwardChain<double>(
      model.num_joints(), [joints](int i) -> const SE3d& { return joints[i].origin; },
      MakeOnTheFlyMotions(joints, q, models), tool_point);
}

template <typename Models>
inline Eigen::Vector3d BackwardPosition(const RobotModel& model, const double* q, Models models,
                                        const double* sin_q, const double* cos_q,
                                        const Eigen::Vector3d& tool_point) {
  const Joint* joints = model.joints.data();
  return BackwardChain<double>(
      model.num_joints(), [joints](int i) -> const SE3d& { return joints[i].origin; },
      MakeGivenSinCosMotions(joints, q, models, sin_q, cos_q), tool_point);
}

template <typename Models>
inline SE3d PoseOf(const RobotModel& model, const double* q, int tool, Models models) {
  Eigen::Matrix3d R;  // uninitialized, unlike SE3d's members
  Eigen::Vector3d t;
  ForwardPass(model, q, models, &model.tools[tool].origin, &R, &t, nullptr);
  return SE3d(R, t);
}

template <typename Models>
inline void FramesOf(const RobotModel& model, const double* q, int tool, Models models,
                     FrameRt* frames, const double* sin_q = nullptr,
                     const double* cos_q = nullptr) {
  const int n = model.num_joints();
  ForwardPass(model, q, models, &model.tools[tool].origin, &frames[n].R, &frames[n].t, frames, sin_q,
              cos_q);
}

// The frames G_0..G_n of configuration q (as PerturbationFrames) in scratch space, handed to `use`.
template <typename Use>
inline auto WithFrames(const RobotModel& model, const double* q, int tool, const Use& use) {
  JointScratch<FrameRt> frames(model.num_joints() + 1);
  FramesOf(model, q, tool, ClassifiedJoints{model.joints.data()}, frames.data());
  return use(frames.data());
}

// The columns of kinematics.h on a FrameRt.
inline void PositionColumn(const FrameRt& G, const Eigen::Vector3d& d, int k, double* out) {
  lpoe::PositionColumn(G.R.data(), d.data(), k, out);
}
inline void AdjointColumn(const FrameRt& G, int k, double* out) {
  lpoe::AdjointColumn(G.R.data(), G.t.data(), k, out);
}

// The 3 x n (6 x n) joint Jacobian at the frames G_0..G_n of one configuration, column-major with
// leading dimension ld: column i is joint i's model's column of its twist at G_i.
template <typename Models>
void PositionJointColumns(const RobotModel& model, Models models, const FrameRt* G, double* J,
                          int ld) {
  const int n = model.num_joints();
  for (int i = 0; i < n; ++i) {
    const Vector6d& s = model.joints[i].twist;
    const Eigen::Vector3d d = G[n].t - G[i].t;
    models.Visit(i, [&](auto m) {
      decltype(m)::PositionColumn(G[i].R.data(), d.data(), s, J + i * ld);
    });
  }
}
template <typename Models>
void PoseJointColumns(const RobotModel& model, Models models, const FrameRt* G, double* J, int ld) {
  for (int i = 0; i < model.num_joints(); ++i) {
    const Vector6d& s = model.joints[i].twist;
    models.Visit(i, [&](auto m) {
      decltype(m)::PoseColumn(G[i].R.data(), G[i].t.data(), s, J + i * ld);
    });
  }
}

}  // namespace

// f(dispatcher) for the one-call forms: AllJoints<RevoluteZJoint> when every joint is revolute
// about z (most arms: no switch per joint in the pass), else classified per joint.
template <typename F>
decltype(auto) WithJointModelsOf(const RobotModel& model, F&& f) {
  for (const Joint& joint : model.joints) {
    if (!IsRevoluteZ(joint)) return f(ClassifiedJoints{model.joints.data()});
  }
  return f(AllJoints<RevoluteZJoint>());
}

SE3d ToolPose(const RobotModel& model, const double* q, int tool) {
  DCHECK(tool >= 0 && tool < model.num_tools());
  return WithJointModelsOf(model, [&](auto models) { return PoseOf(model, q, tool, models); });
}

Eigen::Vector3d ToolPosition(const RobotModel& model, const double* q, int tool) {
  DCHECK(tool >= 0 && tool < model.num_tools());
  return WithJointModelsOf(model, [&](auto models) {
    return BackwardPosition(model, q, models, model.tools[tool].origin.t);
  });
}

void PerturbationFrames(const RobotModel& model, const double* q, int tool,
                        std::vector<SE3d>* frames) {
  const int n = model.num_joints();
  WithFrames(model, q, tool, [&](const FrameRt* G) {
    frames->resize(n + 1);
    for (int i = 0; i <= n; ++i) (*frames)[i] = SE3d(G[i].R, G[i].t);
  });
}

Eigen::Vector3d ToolPositionJacobian(const RobotModel& model, const double* q, int tool,
                                     Eigen::MatrixXd* J_p_frames) {
  const int n = model.num_joints();
  return WithFrames(model, q, tool, [&](const FrameRt* G) {
    const Eigen::Vector3d P = G[n].t;
    J_p_frames->setZero(3, 6 * model.num_frames());
    for (int f = 0; f <= n; ++f) {
      const int col = 6 * (f < n ? f : n + tool);
      // dP = (R w) x (P - t) + R v  =>  d/dw = -(P - t)^ R, d/dv = R   (eq. (29) without Ad).
      const Eigen::Vector3d d = P - G[f].t;
      for (int k = 0; k < 6; ++k) PositionColumn(G[f], d, k, J_p_frames->col(col + k).data());
    }
    return P;
  });
}

SE3d ToolPoseJacobian(const RobotModel& model, const double* q, int tool,
                      Eigen::MatrixXd* J_pose_frames) {
  const int n = model.num_joints();
  return WithFrames(model, q, tool, [&](const FrameRt* G) {
    J_pose_frames->setZero(6, 6 * model.num_frames());
    for (int f = 0; f <= n; ++f) {
      const int col = 6 * (f < n ? f : n + tool);
      for (int k = 0; k < 6; ++k) AdjointColumn(G[f], k, J_pose_frames->col(col + k).data());  // (18)
    }
    return SE3d(G[n].R, G[n].t);
  });
}

// The joint columns are the position (pose) Jacobian's columns of the twist s_i at G_i.
template <typename Matrix>
Eigen::Vector3d PositionJointJacobianInto(const RobotModel& model, const double* q, int tool,
                                          Matrix* J_p_q) {
  const int n = model.num_joints();
  return WithFrames(model, q, tool, [&](const FrameRt* G) {
    J_p_q->resize(3, n);
    PositionJointColumns(model, ClassifiedJoints{model.joints.data()}, G, J_p_q->data(), 3);
    return Eigen::Vector3d(G[n].t);
  });
}

Eigen::Vector3d ToolPositionJointJacobian(const RobotModel& model, const double* q, int tool,
                                          Eigen::MatrixXd* J_p_q) {
  return PositionJointJacobianInto(model, q, tool, J_p_q);
}

Eigen::Vector3d ToolPositionJointJacobian(const RobotModel& model, const double* q, int tool,
                                          Eigen::Matrix<double, 3, Eigen::Dynamic>* J_p_q) {
  return PositionJointJacobianInto(model, q, tool, J_p_q);
}

SE3d ToolPoseJointJacobian(const RobotModel& model, const double* q, int tool,
                           Eigen::MatrixXd* J_pose_q) {
  const int n = model.num_joints();
  return WithFrames(model, q, tool, [&](const FrameRt* G) {
    J_pose_q->resize(6, n);
    PoseJointColumns(model, ClassifiedJoints{model.joints.data()}, G, J_pose_q->data(), 6);
    return SE3d(G[n].R, G[n].t);
  });
}

// ---- SinCosMany.

void SinCosMany(const double* x, int count, double* s, double* c) {
  if (kernels::Avx2Fma()) {
    int k = 0;
    for (; k + 4 <= count; k += 4) kernels::SinCos4Avx2(x + k, s + k, c + k);
    if (k < count) {  // the last 1-3 values through the same path (padded)
      double xs[4] = {0, 0, 0, 0}, ss[4], cs[4];
      for (int l = 0; k + l < count; ++l) xs[l] = x[k + l];
      kernels::SinCos4Avx2(xs, ss, cs);
      for (int l = 0; k + l < count; ++l) {
        s[k + l] = ss[l];
        c[k + l] = cs[l];
      }
    }
    return;
  }
  for (int k = 0; k < count; ++k) SinCos(x[k], &s[k], &c[k]);
}

// ---- KinematicChain.

KinematicChain::KinematicChain(const RobotModel& model) : model_(&model) {
  CHECK_GT(model.num_joints(), 0);
  models_.resize(model.num_joints());
  all_z_ = true;
  for (int i = 0; i < model.num_joints(); ++i) {
    models_[i] = JointModelOf(model.joints[i]);
    all_z_ = all_z_ && models_[i] == JointModelId::kRevoluteZ;
  }
}

SE3d KinematicChain::Pose(const double* q, int tool) const {
  DCHECK(tool >= 0 && tool < model_->num_tools());
  return WithModels([&](auto models) { return PoseOf(*model_, q, tool, models); });
}

Eigen::Vector3d KinematicChain::Position(const double* q, int tool) const {
  DCHECK(tool >= 0 && tool < model_->num_tools());
  return WithModels([&](auto models) {
    return BackwardPosition(*model_, q, models, model_->tools[tool].origin.t);
  });
}

Eigen::Vector3d KinematicChain::Position(const double* q, const double* sin_q,
                                         const double* cos_q, int tool) const {
  DCHECK(tool >= 0 && tool < model_->num_tools());
  return WithModels([&](auto models) {
    return BackwardPosition(*model_, q, models, sin_q, cos_q, model_->tools[tool].origin.t);
  });
}

void KinematicChain::Frames(const double* q, int tool, FrameRt* frames) const {
  DCHECK(tool >= 0 && tool < model_->num_tools());
  WithModels([&](auto models) { FramesOf(*model_, q, tool, models, frames); });
}

void KinematicChain::Frames(const double* q, const double* sin_q, const double* cos_q, int tool,
                            FrameRt* frames) const {
  DCHECK(tool >= 0 && tool < model_->num_tools());
  WithModels([&](auto models) { FramesOf(*model_, q, tool, models, frames, sin_q, cos_q); });
}

void KinematicChain::ToolJointJacobian(const FrameRt* frames, double* J, int ld, int rows) const {
  DCHECK(rows == 3 || rows == 6);
  const int n = num_joints();
  const Eigen::Vector3d& P = frames[n].t;
  WithModels([&](auto models) {
    for (int i = 0; i < n; ++i) {
      const Vector6d& s = model_->joints[i].twist;
      const FrameRt& G = frames[i];
      double* col = J + static_cast<std::ptrdiff_t>(i) * ld;
      const Eigen::Vector3d d = P - G.t;
      models.Visit(i, [&](auto m) {
        using Model = decltype(m);
        Model::PositionColumn(G.R.data(), d.data(), s, col);
        if (rows == 3) return;
        const Eigen::Vector3d w = Model::BaseAxis(G.R, s);
        col[3] = w(0);
        col[4] = w(1);
        col[5] = w(2);
      });
    }
  });
}

// ---- BasisJacobian.

BasisJacobian::BasisJacobian(const RobotModel& model, const Parameterization& p)
    : chain_(model), model_(&model), num_parameters_(p.num_parameters), num_joints_(model.num_joints()) {
  CHECK_EQ(static_cast<int>(p.basis.size()), model.num_frames());
  plan_.resize(model.num_frames());
  for (int f = 0; f < model.num_frames(); ++f) {
    FramePlan& fp = plan_[f];
    const Eigen::MatrixXd& B = p.basis[f];
    CHECK_EQ(B.rows(), 6);
    fp.offset = p.offset[f];
    fp.cols = static_cast<int>(B.cols());
    fp.basis = B;
    // A column that is exactly a canonical unit vector selects that column of the frame block.
    for (int c = 0; c < fp.cols; ++c) {
      int one = -1;
      bool canonical = true;
      for (int r = 0; r < 6 && canonical; ++r) {
        if (B(r, c) == 1.0 && one < 0) {
          one = r;
        } else if (B(r, c) != 0.0) {
          canonical = false;
        }
      }
      if (!canonical || one < 0) {
        fp.select.clear();
        break;
      }
      fp.select.push_back(one);
    }
  }
}

Eigen::Vector3d BasisJacobian::Position(const double* q, int tool, double* J, int ld,
                                        FrameRt* frames) const {
  return Position(q, nullptr, nullptr, tool, J, ld, frames);
}

SE3d BasisJacobian::Pose(const double* q, int tool, double* J, int ld, FrameRt* frames) const {
  return Pose(q, nullptr, nullptr, tool, J, ld, frames);
}

// (Null sin_q and cos_q: computed by the chain.)
Eigen::Vector3d BasisJacobian::Position(const double* q, const double* sin_q, const double* cos_q,
                                        int tool, double* J, int ld, FrameRt* frames) const {
  const int n = num_joints_;
  chain_.Frames(q, sin_q, cos_q, tool, frames);
  const Eigen::Vector3d P = frames[n].t;
  const int F = static_cast<int>(plan_.size());
  for (int f = 0; f < F; ++f) {
    const FramePlan& fp = plan_[f];
    if (fp.cols == 0) continue;
    double* out = J + static_cast<std::ptrdiff_t>(fp.offset) * ld;
    const bool measured = f < n || f == n + tool;
    if (!measured) {  // another tool: zero columns
      for (int c = 0; c < fp.cols; ++c) out[c * ld] = out[c * ld + 1] = out[c * ld + 2] = 0.0;
      continue;
    }
    const FrameRt& G = frames[f < n ? f : n];
    const Eigen::Vector3d d = P - G.t;
    if (!fp.select.empty()) {
      for (int c = 0; c < fp.cols; ++c) PositionColumn(G, d, fp.select[c], out + c * ld);
    } else {
      Eigen::Matrix<double, 3, 6> block;
      for (int k = 0; k < 6; ++k) PositionColumn(G, d, k, block.col(k).data());
      for (int c = 0; c < fp.cols; ++c) {
        const Eigen::Vector3d v = block * fp.basis.col(c);
        out[c * ld] = v(0);
        out[c * ld + 1] = v(1);
        out[c * ld + 2] = v(2);
      }
    }
  }
  return P;
}

SE3d BasisJacobian::Pose(const double* q, const double* sin_q, const double* cos_q, int tool,
                         double* J, int ld, FrameRt* frames) const {
  const int n = num_joints_;
  chain_.Frames(q, sin_q, cos_q, tool, frames);
  const int F = static_cast<int>(plan_.size());
  for (int f = 0; f < F; ++f) {
    const FramePlan& fp = plan_[f];
    if (fp.cols == 0) continue;
    double* out = J + static_cast<std::ptrdiff_t>(fp.offset) * ld;
    const bool measured = f < n || f == n + tool;
    if (!measured) {
      for (int c = 0; c < fp.cols; ++c) {
        for (int r = 0; r < 6; ++r) out[c * ld + r] = 0.0;
      }
      continue;
    }
    const FrameRt& G = frames[f < n ? f : n];
    if (!fp.select.empty()) {
      for (int c = 0; c < fp.cols; ++c) AdjointColumn(G, fp.select[c], out + c * ld);
    } else {
      Eigen::Matrix<double, 6, 6> block;
      for (int k = 0; k < 6; ++k) AdjointColumn(G, k, block.col(k).data());
      for (int c = 0; c < fp.cols; ++c) {
        const Vector6d v = block * fp.basis.col(c);
        for (int r = 0; r < 6; ++r) out[c * ld + r] = v(r);
      }
    }
  }
  return SE3d(frames[n].R, frames[n].t);
}

void BasisJacobian::PositionJointJacobian(const FrameRt* frames, double* J, int ld) const {
  chain_.WithModels([&](auto models) { PositionJointColumns(*model_, models, frames, J, ld); });
}

void BasisJacobian::PoseJointJacobian(const FrameRt* frames, double* J, int ld) const {
  chain_.WithModels([&](auto models) { PoseJointColumns(*model_, models, frames, J, ld); });
}

// The forward-kinematics templates, instantiated for double here (the tests instantiate them for
// ceres::Jet; the residuals library for its own Jets).
template SE3d ChainPose<double>(const RobotModel&, const SE3d*, const SE3d&, const double*);
template Eigen::Vector3d ChainPosition<double, SE3d, double>(const RobotModel&, const SE3d*,
                                                             const Eigen::Vector3d&,
                                                             const double*);
template SE3d JointMotion<double>(const Joint&, const double&);

}  // namespace lpoe
