// The four-row position kernels (lpoe/kinematics/kernels.h): the forward pass of four configurations at once,
// one per AVX2 lane, and the per-pose products of the joint-space slots, for the linear solver's
// normal equations (solvers/src/linearization/normal_equations_assembly.cc). The reference path is the same
// algebra one row at a time (BasisJacobian::Position, then Eigen's rank update); tests/kinematics/kernels_test.cc
// compares the two.
#include <cstddef>
#include <cstring>

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define LPOE_KERNELS_X86 1
#else
#include <glog/logging.h>
#endif

// Lane4 values pass between the templates of kinematics.h inlined into the kernel below: no call
// crosses an ABI boundary with them (GCC warns where such templates are instantiated).
#pragma GCC diagnostic ignored "-Wpsabi"

#include "lpoe/kinematics/kernels.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/model/robot_model.h"

namespace lpoe {
namespace kernels {
#ifdef LPOE_KERNELS_X86
namespace {

// Four doubles, one configuration per lane (GCC/Clang vector arithmetic): the lane type the chain
// and column templates of kinematics.h are instantiated on here. Inside the AVX2/FMA function below
// (flatten: every template it calls is inlined into it) each operation is one AVX2 instruction and
// a product followed by a sum is fused.
typedef double Lane4 __attribute__((vector_size(32)));
typedef long long Mask4 __attribute__((vector_size(32)));

inline void Store(double* p, const Lane4& v) { std::memcpy(p, &v, sizeof v); }
inline Lane4 Masked(const Lane4& v, const Mask4& mask) {
  return reinterpret_cast<Lane4>(reinterpret_cast<Mask4>(v) & mask);
}

}  // namespace

// Four rows (lanes) of the position Jacobian into A (column c, component i of lane l at
// A[c * ld + i * stride + l]; lanes from `valid` on get zeros) and their positions into P
// (P[4 i + l]). sin_q, cos_q: n values per lane, lane after lane. With jq_column >= 0 the joint
// Jacobian dP/dq too, in the same layout from column jq_column on. The chain is kinematics.h's
// ForwardChain on LaneAccumulator<Lane4>, the columns its PositionColumn: the reference path
// (BasisJacobian::Position) instantiated on doubles.
__attribute__((target("avx2,fma"), flatten)) void PositionRows4(
    const RobotModel& model, const FourRowPlan& plan, const double* sin_q, const double* cos_q,
    const int* tool, int valid, double* A, int ld, int stride, double* P, int jq_column) {
  const int n = model.num_joints();
  Lane4 s[kMaxGivenSinCosJoints], c[kMaxGivenSinCosJoints];
  for (int i = 0; i < n; ++i) {
    s[i] = Lane4{sin_q[i], sin_q[n + i], sin_q[2 * n + i], sin_q[3 * n + i]};
    c[i] = Lane4{cos_q[i], cos_q[n + i], cos_q[2 * n + i], cos_q[3 * n + i]};
  }
  // The frames G_0..G_n-1 (before each joint moves), then the tool frame of each lane's target.
  LaneAccumulator<Lane4> F[kMaxGivenSinCosJoints + 1];
  LaneAccumulator<Lane4> X;
  const Joint* joints = model.joints.data();
  ForwardChain(
      n, [joints](int i) -> const SE3d& { return joints[i].origin; },
      RevoluteZMotions<Lane4>(s, c), &X,
      [&F](int i, const LaneAccumulator<Lane4>& G) { F[i] = G; });
  Lane4 tool_R[9], tool_t[3];
  const SE3d* T[4];
  for (int l = 0; l < 4; ++l) T[l] = &model.tools[tool[l]].origin;
  for (int k = 0; k < 9; ++k) {
    tool_R[k] = Lane4{T[0]->R.data()[k], T[1]->R.data()[k], T[2]->R.data()[k], T[3]->R.data()[k]};
  }
  for (int k = 0; k < 3; ++k) tool_t[k] = Lane4{T[0]->t(k), T[1]->t(k), T[2]->t(k), T[3]->t(k)};
  X.RightMultiplyBy(tool_R, tool_t);
  F[n] = X;
  for (int i = 0; i < 3; ++i) Store(P + 4 * i, X.t[i]);

  const Mask4 lane = {0, 1, 2, 3};
  const Mask4 valid_mask = lane < static_cast<long long>(valid);
  const Lane4* p = X.t;
  auto store_column = [&](const Lane4* col, const Mask4& mask, double* o) {
    for (int i = 0; i < 3; ++i) Store(o + static_cast<std::ptrdiff_t>(i) * stride, Masked(col[i], mask));
  };
  for (int f = 0; f < static_cast<int>(plan.frames.size()); ++f) {
    const FourRowPlan::Frame& fr = plan.frames[f];
    if (fr.select.empty()) continue;
    const LaneAccumulator<Lane4>& G = F[f < n ? f : n];
    Mask4 mask = valid_mask;
    if (f >= n) {  // a tool: only the lanes measuring it
      const long long t = f - n;
      const Mask4 tools = {tool[0], tool[1], tool[2], tool[3]};
      mask &= tools == t;
    }
    const Lane4 d[3] = {p[0] - G.t[0], p[1] - G.t[1], p[2] - G.t[2]};
    double* out = A + static_cast<std::ptrdiff_t>(fr.offset) * ld;
    for (size_t k = 0; k < fr.select.size(); ++k) {
      Lane4 col[3];
      PositionColumn(G.R, d, fr.select[k], col);
      store_column(col, mask, out + static_cast<std::ptrdiff_t>(k) * ld);
    }
  }
  if (jq_column >= 0) {  // every joint revolute about its frame's z (the plan): its model's column
    for (int j = 0; j < n; ++j) {
      const LaneAccumulator<Lane4>& G = F[j];
      const Lane4 d[3] = {p[0] - G.t[0], p[1] - G.t[1], p[2] - G.t[2]};
      Lane4 col[3];
      RevoluteZJoint::PositionColumn(G.R, d, joints[j].twist, col);
      store_column(col, valid_mask, A + static_cast<std::ptrdiff_t>(jq_column + j) * ld);
    }
  }
}

namespace {
// sum_c x[c * stride + lane] * b[c](lane) over the three components, four lanes.
__attribute__((target("avx2,fma"))) inline __m256d Dot3Lanes(const double* x, int stride,
                                                            const __m256d* b) {
  return _mm256_fmadd_pd(_mm256_loadu_pd(x + 2 * stride), b[2],
                         _mm256_fmadd_pd(_mm256_loadu_pd(x + stride), b[1],
                                         _mm256_mul_pd(_mm256_loadu_pd(x), b[0])));
}

}  // namespace

// The per-pose products of a block written by PositionRows4 with J_q from column F + 1 and y in
// column F (lanes k in [0, stride), zero past the block's poses), into rows row + k of h, G and C
// (leading dimension ldo); G and C only with `blocks`.
__attribute__((target("avx2,fma"))) void PoseProducts4(const double* A, int ld, int stride, int F,
                                                       int n, bool blocks, double* h, double* G,
                                                       double* C, int ldo, int row) {
  const double* Y = A + static_cast<std::ptrdiff_t>(F) * ld;
  const double* JQ = A + static_cast<std::ptrdiff_t>(F + 1) * ld;
  for (int k = 0; k < stride; k += 4) {
    for (int j = 0; j < n; ++j) {
      const double* jq = JQ + static_cast<std::ptrdiff_t>(j) * ld + k;
      const __m256d a[3] = {_mm256_loadu_pd(jq), _mm256_loadu_pd(jq + stride),
                            _mm256_loadu_pd(jq + 2 * stride)};
      const std::ptrdiff_t out = row + k;
      _mm256_storeu_pd(h + static_cast<std::ptrdiff_t>(j) * ldo + out, Dot3Lanes(Y + k, stride, a));
      if (!blocks) continue;
      for (int i = 0; i <= j; ++i) {
        _mm256_storeu_pd(G + static_cast<std::ptrdiff_t>(j * (j + 1) / 2 + i) * ldo + out,
                         Dot3Lanes(JQ + static_cast<std::ptrdiff_t>(i) * ld + k, stride, a));
      }
      for (int f = 0; f < F; ++f) {
        _mm256_storeu_pd(C + static_cast<std::ptrdiff_t>(j * F + f) * ldo + out,
                         Dot3Lanes(A + static_cast<std::ptrdiff_t>(f) * ld + k, stride, a));
      }
    }
  }
}

#else
void PositionRows4(const RobotModel&, const FourRowPlan&, const double*, const double*, const int*,
                   int, double*, int, int, double*, int) {
  LOG(FATAL) << "no AVX2 kernels on this target";
}
void PoseProducts4(const double*, int, int, int, int, bool, double*, double*, double*, int, int) {
  LOG(FATAL) << "no AVX2 kernels on this target";
}
#endif
}  // namespace kernels
}  // namespace lpoe
