#include "lpoe/kinematics.h"

#include <algorithm>
#include <cmath>

#include <glog/logging.h>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace lpoe {
namespace {

// Frames kept on the stack by the convenience functions (longer chains use the heap).
constexpr int kStackFrames = 16;

// Scratch frames: on the stack for up to kStackFrames, else on the heap.
class FrameScratch {
 public:
  explicit FrameScratch(int count) {
    if (count > kStackFrames) heap_.resize(count);
    data_ = count > kStackFrames ? heap_.data() : stack_;
  }
  FrameRt* data() { return data_; }

 private:
  FrameRt stack_[kStackFrames];
  std::vector<FrameRt> heap_;
  FrameRt* data_;
};

#if defined(__SSE2__)
// The running product of the forward pass in SSE2 registers: each column of R (and t) as a pair
// (rows 0, 1) plus a scalar (row 2), so that a 3x3 product takes 18 packed-or-scalar multiplications
// instead of 27. SSE2 is part of x86-64; other targets use the scalar form below.
struct Accumulator {
  __m128d lo[4];  // rows 0 and 1 of columns 0..2 of R, then of t
  __m128d hi[4];  // row 2 (low lane)

  void Set(const SE3d& X) {
    for (int k = 0; k < 3; ++k) {
      lo[k] = _mm_loadu_pd(X.R.data() + 3 * k);
      hi[k] = _mm_load_sd(X.R.data() + 3 * k + 2);
    }
    lo[3] = _mm_loadu_pd(X.t.data());
    hi[3] = _mm_load_sd(X.t.data() + 2);
  }
  // (R, t) <- (R, t) * (M, m).
  void RightMultiply(const SE3d& X) {
    const double* M = X.R.data();  // column-major
    __m128d nlo[3], nhi[3];
    for (int c = 0; c < 3; ++c) {
      const __m128d a = _mm_set1_pd(M[3 * c]);
      const __m128d b = _mm_set1_pd(M[3 * c + 1]);
      const __m128d d = _mm_set1_pd(M[3 * c + 2]);
      nlo[c] = _mm_add_pd(_mm_add_pd(_mm_mul_pd(lo[0], a), _mm_mul_pd(lo[1], b)),
                          _mm_mul_pd(lo[2], d));
      nhi[c] = _mm_add_sd(_mm_add_sd(_mm_mul_sd(hi[0], a), _mm_mul_sd(hi[1], b)),
                          _mm_mul_sd(hi[2], d));
    }
    const __m128d a = _mm_set1_pd(X.t(0));
    const __m128d b = _mm_set1_pd(X.t(1));
    const __m128d d = _mm_set1_pd(X.t(2));
    lo[3] = _mm_add_pd(_mm_add_pd(_mm_mul_pd(lo[0], a), lo[3]),
                       _mm_add_pd(_mm_mul_pd(lo[1], b), _mm_mul_pd(lo[2], d)));
    hi[3] = _mm_add_sd(_mm_add_sd(_mm_mul_sd(hi[0], a), hi[3]),
                       _mm_add_sd(_mm_mul_sd(hi[1], b), _mm_mul_sd(hi[2], d)));
    for (int c = 0; c < 3; ++c) {
      lo[c] = nlo[c];
      hi[c] = nhi[c];
    }
  }
  // R <- R Rz(q): columns 0 and 1 only.
  void RotZ(double cq, double sq) {
    const __m128d c = _mm_set1_pd(cq), s = _mm_set1_pd(sq);
    const __m128d l0 = lo[0], l1 = lo[1], h0 = hi[0], h1 = hi[1];
    lo[0] = _mm_add_pd(_mm_mul_pd(c, l0), _mm_mul_pd(s, l1));
    lo[1] = _mm_sub_pd(_mm_mul_pd(c, l1), _mm_mul_pd(s, l0));
    hi[0] = _mm_add_sd(_mm_mul_sd(c, h0), _mm_mul_sd(s, h1));
    hi[1] = _mm_sub_sd(_mm_mul_sd(c, h1), _mm_mul_sd(s, h0));
  }
  void Store(Eigen::Matrix3d* R, Eigen::Vector3d* t) const {
    for (int k = 0; k < 3; ++k) {
      _mm_storeu_pd(R->data() + 3 * k, lo[k]);
      _mm_store_sd(R->data() + 3 * k + 2, hi[k]);
    }
    _mm_storeu_pd(t->data(), lo[3]);
    _mm_store_sd(t->data() + 2, hi[3]);
  }
};
#else
// The running product of the forward pass as 12 scalars (column-major R, then t).
struct Accumulator {
  double r[9];
  double t[3];

  void Set(const SE3d& X) {
    for (int k = 0; k < 9; ++k) r[k] = X.R.data()[k];
    for (int k = 0; k < 3; ++k) t[k] = X.t(k);
  }
  // (r, t) <- (r, t) * (M, m).
  void RightMultiply(const SE3d& X) {
    const double* M = X.R.data();  // column-major
    double n[9];
    for (int c = 0; c < 3; ++c) {
      const double a = M[3 * c], b = M[3 * c + 1], d = M[3 * c + 2];
      for (int row = 0; row < 3; ++row) n[3 * c + row] = r[row] * a + r[3 + row] * b + r[6 + row] * d;
    }
    for (int row = 0; row < 3; ++row) {
      t[row] += r[row] * X.t(0) + r[3 + row] * X.t(1) + r[6 + row] * X.t(2);
    }
    for (int k = 0; k < 9; ++k) r[k] = n[k];
  }
  // r <- r Rz(q): columns 0 and 1 only.
  void RotZ(double c, double s) {
    for (int row = 0; row < 3; ++row) {
      const double a = r[row], b = r[3 + row];
      r[row] = c * a + s * b;
      r[3 + row] = c * b - s * a;
    }
  }
  void Store(Eigen::Matrix3d* R, Eigen::Vector3d* tt) const {
    for (int k = 0; k < 9; ++k) R->data()[k] = r[k];
    for (int k = 0; k < 3; ++k) (*tt)(k) = t[k];
  }
};
#endif

// Joints whose sin/cos are computed ahead of the chain in one batch. Every XMM register is
// caller-saved on x86-64, so a sincos call inside the chain would spill and reload the running
// product; computed first, the calls have nothing live around them.
constexpr int kSinCosBatch = 16;

// The forward pass shared by every double path: X = prod_i T_{i-1,i}(0) exp(s_i^ q_i) * tail, with
// `is_z(i)` telling which joints take the 2-column update. When `frames` is given, frames[i] receives
// G_i = T_0,i-1(q) T_{i-1,i}(0) (before joint i moves).
template <typename IsZ>
inline void ForwardPass(const RobotModel& model, const double* q, IsZ is_z, const SE3d* tail,
                        Eigen::Matrix3d* R, Eigen::Vector3d* t, FrameRt* frames) {
  const int n = model.num_joints();
  const Joint* joints = model.joints.data();
  Accumulator X;
  X.Set(joints[0].origin);
  double sn[kSinCosBatch], cs[kSinCosBatch];
  bool z[kSinCosBatch];
  for (int i0 = 0; i0 < n; i0 += kSinCosBatch) {
    const int i1 = std::min(n, i0 + kSinCosBatch);
    for (int i = i0; i < i1; ++i) {
      z[i - i0] = is_z(i);
      if (z[i - i0]) SinCos(q[i], &sn[i - i0], &cs[i - i0]);
    }
    for (int i = i0; i < i1; ++i) {
      const Joint& joint = joints[i];
      if (i > 0) X.RightMultiply(joint.origin);
      if (frames != nullptr) X.Store(&frames[i].R, &frames[i].t);
      if (z[i - i0]) {
        X.RotZ(cs[i - i0], sn[i - i0]);
      } else {
        X.RightMultiply(JointMotion(joint, q[i]));
      }
    }
  }
  if (tail != nullptr) X.RightMultiply(*tail);
  X.Store(R, t);
}

// P = T_0,n(q) p, from the tool back to the base with vectors only (as ChainPosition). Here the
// sin/cos calls stay interleaved with the chain (measured faster than batching them: only three
// values are live across each call, and the chain of one joint overlaps the next call).
template <typename IsZ>
inline Eigen::Vector3d BackwardPosition(const RobotModel& model, const double* q, IsZ is_z,
                                        const Eigen::Vector3d& tool_point) {
  const Joint* joints = model.joints.data();
  double p0 = tool_point(0), p1 = tool_point(1), p2 = tool_point(2);
  for (int i = model.num_joints() - 1; i >= 0; --i) {
    const Joint& joint = joints[i];
    if (is_z(i)) {
      double s, c;
      SinCos(q[i], &s, &c);
      const double x = p0;
      p0 = c * x - s * p1;
      p1 = s * x + c * p1;
    } else {
      const SE3d M = JointMotion(joint, q[i]);
      const Eigen::Vector3d p = M.R * Eigen::Vector3d(p0, p1, p2) + M.t;
      p0 = p(0);
      p1 = p(1);
      p2 = p(2);
    }
    const double* O = joint.origin.R.data();  // column-major
    const Eigen::Vector3d& o = joint.origin.t;
    const double x = O[0] * p0 + O[3] * p1 + O[6] * p2 + o(0);
    const double y = O[1] * p0 + O[4] * p1 + O[7] * p2 + o(1);
    const double z = O[2] * p0 + O[5] * p1 + O[8] * p2 + o(2);
    p0 = x;
    p1 = y;
    p2 = z;
  }
  return Eigen::Vector3d(p0, p1, p2);
}

template <typename IsZ>
inline SE3d PoseOf(const RobotModel& model, const double* q, int tool, IsZ is_z) {
  Eigen::Matrix3d R;  // uninitialized, unlike SE3d's members
  Eigen::Vector3d t;
  ForwardPass(model, q, is_z, &model.tools[tool].origin, &R, &t, nullptr);
  return SE3d(R, t);
}

template <typename IsZ>
inline void FramesOf(const RobotModel& model, const double* q, int tool, IsZ is_z,
                     FrameRt* frames) {
  const int n = model.num_joints();
  ForwardPass(model, q, is_z, &model.tools[tool].origin, &frames[n].R, &frames[n].t, frames);
}

// Column k of the 3 x 6 position block of frame (R, t) at tool position P (eq. (29) without Ad):
// d/d omega_k = R_k x (P - t) (= -(P - t)^ R e_k), d/d v_k = R_k.
inline void PositionColumn(const FrameRt& G, const Eigen::Vector3d& d, int k, double* out) {
  if (k < 3) {
    const auto Rk = G.R.col(k);
    out[0] = Rk(1) * d(2) - Rk(2) * d(1);
    out[1] = Rk(2) * d(0) - Rk(0) * d(2);
    out[2] = Rk(0) * d(1) - Rk(1) * d(0);
  } else {
    const auto Rk = G.R.col(k - 3);
    out[0] = Rk(0);
    out[1] = Rk(1);
    out[2] = Rk(2);
  }
}

// Column k of Ad_G = [[R, 0], [t^ R, R]] (eq. (18)).
inline void AdjointColumn(const FrameRt& G, int k, double* out) {
  if (k < 3) {
    const auto Rk = G.R.col(k);
    const Eigen::Vector3d tr = G.t.cross(Eigen::Vector3d(Rk));
    out[0] = Rk(0);
    out[1] = Rk(1);
    out[2] = Rk(2);
    out[3] = tr(0);
    out[4] = tr(1);
    out[5] = tr(2);
  } else {
    const auto Rk = G.R.col(k - 3);
    out[0] = out[1] = out[2] = 0.0;
    out[3] = Rk(0);
    out[4] = Rk(1);
    out[5] = Rk(2);
  }
}

}  // namespace

SE3d JointMotion(const Joint& joint, double q) {
  SE3d X;
  if (joint.type == JointType::kPrismatic) {
    X.t = joint.twist.tail<3>() * q;
    return X;
  }
  if (IsRevoluteZ(joint)) {
    double sn, c;
    SinCos(q, &sn, &c);
    X.R << c, -sn, 0, sn, c, 0, 0, 0, 1;
    return X;
  }
  return ExpSE3(Vector6d(joint.twist * q));
}

SE3d ToolPose(const RobotModel& model, const double* q, int tool) {
  DCHECK(tool >= 0 && tool < model.num_tools());
  return PoseOf(model, q, tool, [&](int i) { return IsRevoluteZ(model.joints[i]); });
}

Eigen::Vector3d ToolPosition(const RobotModel& model, const double* q, int tool) {
  DCHECK(tool >= 0 && tool < model.num_tools());
  return BackwardPosition(model, q, [&](int i) { return IsRevoluteZ(model.joints[i]); },
                          model.tools[tool].origin.t);
}

void PerturbationFrames(const RobotModel& model, const double* q, int tool,
                        std::vector<SE3d>* frames) {
  const int n = model.num_joints();
  FrameScratch scratch(n + 1);
  FramesOf(model, q, tool, [&](int i) { return IsRevoluteZ(model.joints[i]); }, scratch.data());
  frames->resize(n + 1);
  for (int i = 0; i <= n; ++i) (*frames)[i] = SE3d(scratch.data()[i].R, scratch.data()[i].t);
}

Eigen::Vector3d ToolPositionJacobian(const RobotModel& model, const double* q, int tool,
                                     Eigen::MatrixXd* J_p_frames) {
  const int n = model.num_joints();
  FrameScratch scratch(n + 1);
  FrameRt* G = scratch.data();
  FramesOf(model, q, tool, [&](int i) { return IsRevoluteZ(model.joints[i]); }, G);
  const Eigen::Vector3d P = G[n].t;
  J_p_frames->setZero(3, 6 * model.num_frames());
  for (int f = 0; f <= n; ++f) {
    const int col = 6 * (f < n ? f : n + tool);
    // dP = (R w) x (P - t) + R v  =>  d/dw = -(P - t)^ R, d/dv = R   (eq. (29) without Ad).
    const Eigen::Vector3d d = P - G[f].t;
    for (int k = 0; k < 6; ++k) PositionColumn(G[f], d, k, J_p_frames->col(col + k).data());
  }
  return P;
}

SE3d ToolPoseJacobian(const RobotModel& model, const double* q, int tool,
                      Eigen::MatrixXd* J_pose_frames) {
  const int n = model.num_joints();
  FrameScratch scratch(n + 1);
  FrameRt* G = scratch.data();
  FramesOf(model, q, tool, [&](int i) { return IsRevoluteZ(model.joints[i]); }, G);
  J_pose_frames->setZero(6, 6 * model.num_frames());
  for (int f = 0; f <= n; ++f) {
    const int col = 6 * (f < n ? f : n + tool);
    for (int k = 0; k < 6; ++k) AdjointColumn(G[f], k, J_pose_frames->col(col + k).data());  // (18)
  }
  return SE3d(G[n].R, G[n].t);
}

// ---- KinematicChain.

KinematicChain::KinematicChain(const RobotModel& model) : model_(&model) {
  CHECK_GT(model.num_joints(), 0);
  z_revolute_.resize(model.num_joints());
  all_z_ = true;
  for (int i = 0; i < model.num_joints(); ++i) {
    z_revolute_[i] = IsRevoluteZ(model.joints[i]);
    all_z_ = all_z_ && z_revolute_[i];
  }
}

SE3d KinematicChain::Pose(const double* q, int tool) const {
  DCHECK(tool >= 0 && tool < model_->num_tools());
  if (all_z_) return PoseOf(*model_, q, tool, [](int) { return true; });
  const unsigned char* z = z_revolute_.data();
  return PoseOf(*model_, q, tool, [z](int i) { return z[i] != 0; });
}

Eigen::Vector3d KinematicChain::Position(const double* q, int tool) const {
  DCHECK(tool >= 0 && tool < model_->num_tools());
  if (all_z_) {
    return BackwardPosition(*model_, q, [](int) { return true; }, model_->tools[tool].origin.t);
  }
  const unsigned char* z = z_revolute_.data();
  return BackwardPosition(*model_, q, [z](int i) { return z[i] != 0; },
                          model_->tools[tool].origin.t);
}

void KinematicChain::Frames(const double* q, int tool, FrameRt* frames) const {
  DCHECK(tool >= 0 && tool < model_->num_tools());
  if (all_z_) return FramesOf(*model_, q, tool, [](int) { return true; }, frames);
  const unsigned char* z = z_revolute_.data();
  FramesOf(*model_, q, tool, [z](int i) { return z[i] != 0; }, frames);
}

// ---- BasisJacobian.

BasisJacobian::BasisJacobian(const RobotModel& model, const Parameterization& p)
    : chain_(model), num_parameters_(p.num_parameters), num_joints_(model.num_joints()) {
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
  const int n = num_joints_;
  chain_.Frames(q, tool, frames);
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

SE3d BasisJacobian::Pose(const double* q, int tool, double* J, int ld, FrameRt* frames) const {
  const int n = num_joints_;
  chain_.Frames(q, tool, frames);
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

JointMotions::JointMotions(const RobotModel& model, const double* q)
    : motions_(model.num_joints()) {
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

// The forward-kinematics templates, instantiated for double here (the tests instantiate them for
// ceres::Jet; the residuals library for its own Jets).
template SE3d ChainPose<double>(const RobotModel&, const SE3d*, const SE3d&, const double*);
template Eigen::Vector3d ChainPosition<double, SE3d>(const RobotModel&, const SE3d*,
                                                     const Eigen::Vector3d&, const double*);

}  // namespace lpoe
