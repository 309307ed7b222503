#include "lpoe/kinematics.h"

#include <cmath>

#include <glog/logging.h>

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

// R <- R * M, t <- R * m + t for a general joint motion or frame (R, t) x (M, m).
inline void RightMultiply(const SE3d& M, Eigen::Matrix3d* R, Eigen::Vector3d* t) {
  *t += *R * M.t;
  *R = (*R * M.R).eval();
}

// The forward pass shared by every double path: X = prod_i T_{i-1,i}(0) exp(s_i^ q_i), with
// `is_z(i)` telling which joints take the 2-column update. When `frames` is given, frames[i] receives
// G_i = T_0,i-1(q) T_{i-1,i}(0) (before joint i moves).
template <typename IsZ>
inline void ForwardPass(const RobotModel& model, const double* q, IsZ is_z, Eigen::Matrix3d* R,
                        Eigen::Vector3d* t, FrameRt* frames) {
  const int n = model.num_joints();
  *R = model.joints[0].origin.R;
  *t = model.joints[0].origin.t;
  for (int i = 0; i < n; ++i) {
    const Joint& joint = model.joints[i];
    if (i > 0) RightMultiply(joint.origin, R, t);
    if (frames != nullptr) {
      frames[i].R = *R;
      frames[i].t = *t;
    }
    if (is_z(i)) {
      double s, c;
      SinCos(q[i], &s, &c);
      internal::RightMultiplyRotZ(c, s, R);
    } else {
      RightMultiply(JointMotion(joint, q[i]), R, t);
    }
  }
}

// P = T_0,n(q) p, from the tool back to the base with vectors only (as ChainPosition).
template <typename IsZ>
inline Eigen::Vector3d BackwardPosition(const RobotModel& model, const double* q, IsZ is_z,
                                        const Eigen::Vector3d& tool_point) {
  Eigen::Vector3d p = tool_point;
  for (int i = model.num_joints() - 1; i >= 0; --i) {
    const Joint& joint = model.joints[i];
    if (is_z(i)) {
      double s, c;
      SinCos(q[i], &s, &c);
      const double x = p(0);
      p(0) = c * x - s * p(1);
      p(1) = s * x + c * p(1);
    } else {
      const SE3d M = JointMotion(joint, q[i]);
      p = M.R * p + M.t;
    }
    p = joint.origin.R * p + joint.origin.t;
  }
  return p;
}

template <typename IsZ>
inline SE3d PoseOf(const RobotModel& model, const double* q, int tool, IsZ is_z) {
  SE3d X;
  ForwardPass(model, q, is_z, &X.R, &X.t, nullptr);
  const SE3d& T = model.tools[tool].origin;
  return SE3d(X.R * T.R, X.R * T.t + X.t);
}

template <typename IsZ>
inline void FramesOf(const RobotModel& model, const double* q, int tool, IsZ is_z,
                     FrameRt* frames) {
  const int n = model.num_joints();
  Eigen::Matrix3d R;
  Eigen::Vector3d t;
  ForwardPass(model, q, is_z, &R, &t, frames);
  const SE3d& T = model.tools[tool].origin;
  frames[n].R.noalias() = R * T.R;
  frames[n].t.noalias() = R * T.t;
  frames[n].t += t;
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
  for (int i = 0; i < model.num_joints(); ++i) z_revolute_[i] = IsRevoluteZ(model.joints[i]);
}

SE3d KinematicChain::Pose(const double* q, int tool) const {
  DCHECK(tool >= 0 && tool < model_->num_tools());
  const unsigned char* z = z_revolute_.data();
  return PoseOf(*model_, q, tool, [z](int i) { return z[i] != 0; });
}

Eigen::Vector3d KinematicChain::Position(const double* q, int tool) const {
  DCHECK(tool >= 0 && tool < model_->num_tools());
  const unsigned char* z = z_revolute_.data();
  return BackwardPosition(*model_, q, [z](int i) { return z[i] != 0; },
                          model_->tools[tool].origin.t);
}

void KinematicChain::Frames(const double* q, int tool, FrameRt* frames) const {
  DCHECK(tool >= 0 && tool < model_->num_tools());
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

}  // namespace lpoe
