// The four-row position kernels (lpoe/kernels.h): the forward pass of four configurations at once,
// one per AVX2 lane, and the per-pose products of the joint-space slots, for the linear solver's
// normal equations (solvers/src/normal_equations_assembly.cc). The reference path is the same
// algebra one row at a time (BasisJacobian::Position, then Eigen's rank update); tests/kernels_test.cc
// compares the two.
#include <cstddef>

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define LPOE_KERNELS_X86 1
#else
#include <glog/logging.h>
#endif

#include "lpoe/kernels.h"
#include "lpoe/kinematics.h"
#include "lpoe/robot_model.h"

namespace lpoe {
namespace kernels {
#ifdef LPOE_KERNELS_X86
namespace {

// X <- X M for 4-lane transforms (R column-major in X[0..8], t in X[9..11]).
__attribute__((target("avx2,fma"))) inline void RightMultiply4(__m256d* X, const __m256d* M) {
  __m256d R[9];
  for (int c = 0; c < 3; ++c) {
    for (int r = 0; r < 3; ++r) {
      R[3 * c + r] = _mm256_fmadd_pd(
          X[6 + r], M[3 * c + 2],
          _mm256_fmadd_pd(X[3 + r], M[3 * c + 1], _mm256_mul_pd(X[r], M[3 * c])));
    }
  }
  for (int r = 0; r < 3; ++r) {
    X[9 + r] = _mm256_fmadd_pd(
        X[6 + r], M[11],
        _mm256_fmadd_pd(X[3 + r], M[10], _mm256_fmadd_pd(X[r], M[9], X[9 + r])));
  }
  for (int k = 0; k < 9; ++k) X[k] = R[k];
}

// The same transform in every lane.
__attribute__((target("avx2,fma"))) inline void Broadcast4(const SE3d& O, __m256d* out) {
  for (int k = 0; k < 9; ++k) out[k] = _mm256_set1_pd(O.R.data()[k]);
  for (int k = 0; k < 3; ++k) out[9 + k] = _mm256_set1_pd(O.t(k));
}

}  // namespace

// Four rows (lanes) of the position Jacobian into A (column c, component i of lane l at
// A[c * ld + i * stride + l]; lanes from `valid` on get zeros) and their positions into P
// (P[4 i + l]). sin_q, cos_q: n values per lane, lane after lane. With jq_column >= 0 the joint
// Jacobian dP/dq too, in the same layout from column jq_column on: joint j's column is
// z_j x (P - t_j) with z_j, t_j the axis and origin of the joint's frame G_j (the frame's rotation
// column about z, w_j x P + v_j).
__attribute__((target("avx2,fma"))) void PositionRows4(const RobotModel& model,
                                                       const FourRowPlan& plan,
                                                       const double* sin_q, const double* cos_q,
                                                       const int* tool, int valid, double* A,
                                                       int ld, int stride, double* P,
                                                       int jq_column) {
  const int n = model.num_joints();
  __m256d F[kMaxGivenSinCosJoints + 1][12];
  __m256d X[12], M[12];
  Broadcast4(model.joints[0].origin, X);
  for (int i = 0; i < n; ++i) {
    if (i > 0) {
      Broadcast4(model.joints[i].origin, M);
      RightMultiply4(X, M);
    }
    for (int k = 0; k < 12; ++k) F[i][k] = X[k];
    // R <- R Rz(q_i): columns 0 and 1.
    const __m256d c = _mm256_set_pd(cos_q[3 * n + i], cos_q[2 * n + i], cos_q[n + i], cos_q[i]);
    const __m256d s = _mm256_set_pd(sin_q[3 * n + i], sin_q[2 * n + i], sin_q[n + i], sin_q[i]);
    for (int r = 0; r < 3; ++r) {
      const __m256d x0 = X[r], x1 = X[3 + r];
      X[r] = _mm256_fmadd_pd(s, x1, _mm256_mul_pd(c, x0));
      X[3 + r] = _mm256_fnmadd_pd(s, x0, _mm256_mul_pd(c, x1));
    }
  }
  // The tool frame of each lane's target.
  const SE3d* T[4];
  for (int l = 0; l < 4; ++l) T[l] = &model.tools[tool[l]].origin;
  for (int k = 0; k < 9; ++k) {
    M[k] = _mm256_set_pd(T[3]->R.data()[k], T[2]->R.data()[k], T[1]->R.data()[k],
                         T[0]->R.data()[k]);
  }
  for (int k = 0; k < 3; ++k) M[9 + k] = _mm256_set_pd(T[3]->t(k), T[2]->t(k), T[1]->t(k), T[0]->t(k));
  RightMultiply4(X, M);
  for (int k = 0; k < 12; ++k) F[n][k] = X[k];
  for (int i = 0; i < 3; ++i) _mm256_storeu_pd(P + 4 * i, X[9 + i]);

  const __m256d lane = _mm256_set_pd(3, 2, 1, 0);
  const __m256d valid_mask = _mm256_cmp_pd(lane, _mm256_set1_pd(valid), _CMP_LT_OQ);
  const __m256d* p = X + 9;
  for (int f = 0; f < static_cast<int>(plan.frames.size()); ++f) {
    const FourRowPlan::Frame& fr = plan.frames[f];
    if (fr.select.empty()) continue;
    const __m256d* G = F[f < n ? f : n];
    __m256d mask = valid_mask;
    if (f >= n) {  // a tool: only the lanes measuring it
      const int t = f - n;
      mask = _mm256_and_pd(
          mask, _mm256_castsi256_pd(_mm256_set_epi64x(-(tool[3] == t), -(tool[2] == t),
                                                      -(tool[1] == t), -(tool[0] == t))));
    }
    const __m256d d[3] = {_mm256_sub_pd(p[0], G[9]), _mm256_sub_pd(p[1], G[10]),
                          _mm256_sub_pd(p[2], G[11])};
    double* out = A + static_cast<std::ptrdiff_t>(fr.offset) * ld;
    for (size_t c = 0; c < fr.select.size(); ++c) {
      const int k = fr.select[c];
      __m256d col[3];
      if (k < 3) {  // R_k x (P - t)
        const __m256d* Rk = G + 3 * k;
        col[0] = _mm256_fmsub_pd(Rk[1], d[2], _mm256_mul_pd(Rk[2], d[1]));
        col[1] = _mm256_fmsub_pd(Rk[2], d[0], _mm256_mul_pd(Rk[0], d[2]));
        col[2] = _mm256_fmsub_pd(Rk[0], d[1], _mm256_mul_pd(Rk[1], d[0]));
      } else {  // R_k
        for (int i = 0; i < 3; ++i) col[i] = G[3 * (k - 3) + i];
      }
      double* o = out + static_cast<std::ptrdiff_t>(c) * ld;
      for (int i = 0; i < 3; ++i) _mm256_storeu_pd(o + i * stride, _mm256_and_pd(col[i], mask));
    }
  }
  if (jq_column >= 0) {
    for (int j = 0; j < n; ++j) {
      const __m256d* G = F[j];
      const __m256d d[3] = {_mm256_sub_pd(p[0], G[9]), _mm256_sub_pd(p[1], G[10]),
                            _mm256_sub_pd(p[2], G[11])};
      const __m256d* z = G + 6;
      __m256d col[3];
      col[0] = _mm256_fmsub_pd(z[1], d[2], _mm256_mul_pd(z[2], d[1]));
      col[1] = _mm256_fmsub_pd(z[2], d[0], _mm256_mul_pd(z[0], d[2]));
      col[2] = _mm256_fmsub_pd(z[0], d[1], _mm256_mul_pd(z[1], d[0]));
      double* o = A + static_cast<std::ptrdiff_t>(jq_column + j) * ld;
      for (int i = 0; i < 3; ++i) {
        _mm256_storeu_pd(o + i * stride, _mm256_and_pd(col[i], valid_mask));
      }
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
