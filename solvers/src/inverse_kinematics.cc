#include "lpoe/inverse_kinematics.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <glog/logging.h>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif
#if defined(__GNUC__) && defined(__x86_64__)
#include <immintrin.h>
#endif

#include "lpoe/joint_errors.h"

namespace lpoe {
namespace {

constexpr int kMax = InverseKinematics::kMaxJoints;
// Weighted task error (mm) below which a step is accepted even if it raised the error.
constexpr double kNullSpaceSlack = 1e-2;
// Revolute-z joints: sin and cos of the joint value are carried from one iterate to the next by
// the addition theorem with the step's sin/cos from a series (|step| below kIncrementalStep, error
// below 1e-21), and recomputed by sincos after kIncrementalRefresh such updates (round-off of a few
// 1e-16 rad in all).
constexpr double kIncrementalStep = 0.25;
constexpr int kIncrementalRefresh = 8;
// The null-space pull toward the seed is halved (down to this) when successive steps reverse.
constexpr double kMinPull = 1.0 / 64;
// Square tasks: after a damped step (a rejected step before it; no step of the run cut at a joint
// limit) that achieved at least this fraction of the reduction of the merit its linear model
// predicted, the next step is Newton's again (damping zero) instead of a damping that decays by 10
// per step. The pull toward the seed in the damped step holds the error near lambda^2 times the
// pull, so a slowly decaying damping made the error fall by only 10 per iteration.
constexpr double kGoodModel = 0.75;

#if defined(__GNUC__) && defined(__x86_64__)
// AVX code (the sweep, the 6 x 6 LU, the Gram matrix, the sin/cos updates) is compiled for AVX
// alone and chosen at run time; multiplications and additions stay separate (no FMA), in the
// scalar code's order, so both give the same bits.
#define LPOE_IK_AVX 1
bool HaveAvx() {
  static const bool have = __builtin_cpu_supports("avx");
  return have;
}
#endif

// sin(d), cos(d) for |d| <= kIncrementalStep: Taylor series to d^13 and d^14.
inline void SinCosSmall(double d, double* s, double* c) {
  const double d2 = d * d;
  *s = d * (1 + d2 * (-1.0 / 6 + d2 * (1.0 / 120 + d2 * (-1.0 / 5040 + d2 * (1.0 / 362880 +
       d2 * (-1.0 / 39916800 + d2 * (1.0 / 6227020800.0)))))));
  *c = 1 + d2 * (-0.5 + d2 * (1.0 / 24 + d2 * (-1.0 / 720 + d2 * (1.0 / 40320 +
       d2 * (-1.0 / 3628800 + d2 * (1.0 / 479001600 + d2 * (-1.0 / 87178291200.0)))))));
}

// The same for the small steps of the last iterations: below 0.01 rad the series to d^7 and d^8
// (next terms below 3e-24) replace the long one.
inline void SinCosStep(double d, double* s, double* c) {
  const double d2 = d * d;
  if (d2 < 1e-4) {
    *s = d * (1 + d2 * (-1.0 / 6 + d2 * (1.0 / 120 + d2 * (-1.0 / 5040))));
    *c = 1 + d2 * (-0.5 + d2 * (1.0 / 24 + d2 * (-1.0 / 720 + d2 * (1.0 / 40320))));
    return;
  }
  SinCosSmall(d, s, c);
}

#if defined(__SSE2__)
// SinCosStep of d[0..5] into s, c, two lanes at a time in SSE2 registers: the short series in every
// lane, the long one only for a pair with a lane at d^2 >= 1e-4, each lane taking the series the
// scalar code takes, with the scalar code's operations in its order, so its bits.
inline void SinCosStep6(const double* d_in, double* s_out, double* c_out) {
  static constexpr double kSinLong[] = {1.0 / 6227020800.0, -1.0 / 39916800, 1.0 / 362880,
                                        -1.0 / 5040, 1.0 / 120, -1.0 / 6, 1};
  static constexpr double kCosLong[] = {-1.0 / 87178291200.0, 1.0 / 479001600, -1.0 / 3628800,
                                        1.0 / 40320, -1.0 / 720, 1.0 / 24, -0.5, 1};
  static constexpr double kSinShort[] = {-1.0 / 5040, 1.0 / 120, -1.0 / 6, 1};
  static constexpr double kCosShort[] = {1.0 / 40320, -1.0 / 720, 1.0 / 24, -0.5, 1};
  // Horner's rule, highest degree first.
  auto horner = [](__m128d d2, const double* a, int count) {
    __m128d p = _mm_set1_pd(a[0]);
    for (int k = 1; k < count; ++k) p = _mm_add_pd(_mm_set1_pd(a[k]), _mm_mul_pd(d2, p));
    return p;
  };
#pragma GCC unroll 3
  for (int h = 0; h < 6; h += 2) {
    const __m128d d = _mm_loadu_pd(d_in + h);
    const __m128d d2 = _mm_mul_pd(d, d);
    __m128d s = _mm_mul_pd(d, horner(d2, kSinShort, 4));
    __m128d c = horner(d2, kCosShort, 5);
    const __m128d long_lane = _mm_cmpnlt_pd(d2, _mm_set1_pd(1e-4));  // !(d2 < 1e-4), as scalar
    if (_mm_movemask_pd(long_lane) != 0) {
      const __m128d s_long = _mm_mul_pd(d, horner(d2, kSinLong, 7));
      const __m128d c_long = horner(d2, kCosLong, 8);
      s = _mm_or_pd(_mm_and_pd(long_lane, s_long), _mm_andnot_pd(long_lane, s));
      c = _mm_or_pd(_mm_and_pd(long_lane, c_long), _mm_andnot_pd(long_lane, c));
    }
    _mm_storeu_pd(s_out + h, s);
    _mm_storeu_pd(c_out + h, c);
  }
}
#endif

// sin and cos of x[j] for the `count` joints j in idx, into s[j] and c[j]: gathered into one
// SinCosMany call (four values per polynomial evaluation where the processor has AVX2 and FMA; each
// value's result depends on that value only, so both paths get the same bits).
inline void SinCosOf(const double* x, const int* idx, int count, double* s, double* c) {
  if (count == 0) return;
  double xs[kMax], ss[kMax], cs[kMax];
  for (int k = 0; k < count; ++k) xs[k] = x[idx[k]];
  SinCosMany(xs, count, ss, cs);
  for (int k = 0; k < count; ++k) {
    s[idx[k]] = ss[k];
    c[idx[k]] = cs[k];
  }
}

// log(R_target R^T)^vee. Near the target (angle below 0.01 rad) from the skew part alone:
// v = sin(theta) axis and theta / sin(theta) = arcsin(s) / s = 1 + s^2/6 + 3 s^4/40 + 5 s^6/112 +
// 35 s^8/1152 (s = |v|; the next term is below 1e-21), without the quaternion and atan2 of LogSO3;
// below 0.2 rad the longer series.
inline Eigen::Vector3d RotationError(const Eigen::Matrix3d& R_target, const Eigen::Matrix3d& R) {
  const Eigen::Matrix3d E = R_target * R.transpose();
  const Eigen::Vector3d v(0.5 * (E(2, 1) - E(1, 2)), 0.5 * (E(0, 2) - E(2, 0)),
                          0.5 * (E(1, 0) - E(0, 1)));
  const double s2 = v.squaredNorm();
  if (s2 < 1e-4 && E.trace() > 1) {
    return v * (1 + s2 * (1.0 / 6 + s2 * (3.0 / 40 + s2 * (5.0 / 112 + s2 * (35.0 / 1152)))));
  }
  // Up to 0.2 rad (the first iterates from seeds a few degrees away): the same series to s^22
  // (coefficients C(2k, k) / (4^k (2k + 1)); the next term below 3e-18).
  if (s2 < 0.04 && E.trace() > 1) {
    return v * (1 + s2 * (1.0 / 6 + s2 * (3.0 / 40 + s2 * (5.0 / 112 + s2 * (35.0 / 1152 +
                s2 * (63.0 / 2816 + s2 * (231.0 / 13312 + s2 * (143.0 / 10240 +
                s2 * (6435.0 / 557056 + s2 * (12155.0 / 1245184 + s2 * (46189.0 / 5505024 +
                s2 * (88179.0 / 12058624))))))))))));
  }
  return LogSO3<double>(E);
}

// Cholesky factor of a symmetric positive definite M x M matrix (lower triangle read), with the
// reciprocals of its diagonal; Ok() false when a pivot is not positive.
template <int M>
class SmallCholesky {
 public:
  using MatM = Eigen::Matrix<double, M, M>;
  using VecM = Eigen::Matrix<double, M, 1>;

  explicit SmallCholesky(const MatM& A) : L_(A) {
    for (int j = 0; j < M; ++j) {
      double d = L_(j, j);
      for (int k = 0; k < j; ++k) d -= L_(j, k) * L_(j, k);
      if (!(d > 0)) {
        ok_ = false;
        return;
      }
      inv_[j] = 1 / std::sqrt(d);
      for (int i = j + 1; i < M; ++i) {
        double x = L_(i, j);
        for (int k = 0; k < j; ++k) x -= L_(i, k) * L_(j, k);
        L_(i, j) = x * inv_[j];
      }
    }
  }
  bool Ok() const { return ok_; }
  // x <- A^-1 x.
  void Solve(VecM* x) const {
    VecM& y = *x;
    for (int i = 0; i < M; ++i) {
      double v = y(i);
      for (int k = 0; k < i; ++k) v -= L_(i, k) * y(k);
      y(i) = v * inv_[i];
    }
    for (int i = M - 1; i >= 0; --i) {
      double v = y(i);
      for (int k = i + 1; k < M; ++k) v -= L_(k, i) * y(k);
      y(i) = v * inv_[i];
    }
  }

 private:
  MatM L_;
  double inv_[M];
  bool ok_ = true;
};

// LU factors with partial pivoting of a square M x M matrix (column-major, A[M c + r]): Newton's
// step of a regular square task, and its second-order correction with the same factors. Ok() false
// when a pivot is below `tiny` (then the damped form is used). Both paths use it, so their steps
// agree to the bit.
template <int M>
class SquareLu {
 public:
  SquareLu(const double* A_in, double tiny) {
    for (int k = 0; k < M * M; ++k) A_[k] = A_in[k];
#pragma GCC unroll 6
    for (int k = 0; k < M; ++k) {
      int p = k;
      double best = std::abs(A_[M * k + k]);
#pragma GCC unroll 6
      for (int i = k + 1; i < M; ++i) {
        const double v = std::abs(A_[M * k + i]);
        if (v > best) {
          best = v;
          p = i;
        }
      }
      pivot_[k] = p;
      if (!(best > tiny)) {
        ok_ = false;
        return;
      }
      if (p != k) {  // columns k.. only: the multipliers of earlier columns stay where they were
#pragma GCC unroll 6
        for (int c = k; c < M; ++c) std::swap(A_[M * c + p], A_[M * c + k]);
      }
      const double inv = 1 / A_[M * k + k];
#pragma GCC unroll 6
      for (int i = k + 1; i < M; ++i) A_[M * k + i] *= inv;  // the multipliers
#pragma GCC unroll 6
      for (int c = k + 1; c < M; ++c) {
        const double a = A_[M * c + k];
#pragma GCC unroll 6
        for (int i = k + 1; i < M; ++i) A_[M * c + i] -= A_[M * k + i] * a;
      }
    }
  }
  bool Ok() const { return ok_; }
  // d = A^-1 b (d may alias b).
  void Solve(const double* b_in, double* d) const {
    double b[M];
    for (int k = 0; k < M; ++k) b[k] = b_in[k];
#pragma GCC unroll 6
    for (int k = 0; k < M; ++k) {
      std::swap(b[pivot_[k]], b[k]);
#pragma GCC unroll 6
      for (int i = k + 1; i < M; ++i) b[i] -= A_[M * k + i] * b[k];
    }
#pragma GCC unroll 6
    for (int i = M - 1; i >= 0; --i) {
      double v = b[i];
#pragma GCC unroll 6
      for (int c = i + 1; c < M; ++c) v -= A_[M * c + i] * b[c];
      b[i] = v / A_[M * i + i];
    }
    for (int k = 0; k < M; ++k) d[k] = b[k];
  }

 private:
  double A_[M * M];
  int pivot_[M];
  bool ok_ = true;
};

// The 6 x 6 case (both paths' Newton steps), with implicit row pivoting: no rows are swapped; step
// k takes as pivot the row (among those not yet pivots, the "free" rows) with the largest |A(i, k)|,
// the first such row on ties, and eliminates column k from the other free rows. U's row k is then
// row pivot_[k] of A_ (columns 8 apart: two AVX registers, rows 6-7 zero), L_ column k holds the
// multipliers in the rows free after step k and zeros elsewhere, so each column update is one
// vector operation on the whole column (zero multipliers leave the other rows as they are). The
// same arithmetic as partial pivoting with swapped rows; where the processor has AVX the search and
// the updates run in its registers without branches on the data (no mispredicted pivot choices, no
// stalls on rows swapped in memory), else scalar loops compute the same values. The pivot's
// reciprocal comes from a division of the whole column started before the search ends, and the
// substitutions run on L and U gathered in the pivots' order, U's rows divided by their pivots (no
// division on the solves' serial chains).
template <>
class SquareLu<6> {
 public:
  SquareLu(const double* A_in, double tiny) {
#ifdef LPOE_IK_AVX
    if (HaveAvx()) {
      ok_ = FactorAvx(A_in, tiny);
      return;
    }
#endif
    ok_ = FactorScalar(A_in, tiny);
  }
  bool Ok() const { return ok_; }
  // d = A^-1 b (d may alias b).
  void Solve(const double* b_in, double* d) const {
    // Forward substitution in the pivots' order: y_m = b(pivot_m) - sum_{k<m} l(pivot_m, k) y_k
    // (the column updates of the elimination applied to b; scalar, its serial chain one
    // multiplication and subtraction per step).
    double y[6];
#pragma GCC unroll 6
    for (int m = 0; m < 6; ++m) y[m] = b_in[pivot_[m]];
#pragma GCC unroll 6
    for (int k = 0; k < 6; ++k) {
#pragma GCC unroll 6
      for (int m = k + 1; m < 6; ++m) y[m] -= lower_[6 * m + k] * y[k];
    }
    // Back substitution with U's rows divided by their pivots (x_k = y_k / u_kk - sum_c
    // (u_kc / u_kk) x_c), the last unknown found subtracted last: the serial chain is one product
    // and one difference per unknown. Each unknown is stored to d as it is found (b was read
    // before): copied from a local array afterwards, the compiler's 16-byte copies each read two
    // separate 8-byte stores, which the processor cannot forward (a stall per pair on every solve).
    double x[6];
#pragma GCC unroll 6
    for (int k = 5; k >= 0; --k) {
      double v = y[k] * inv_[k];
#pragma GCC unroll 6
      for (int c = 5; c > k; --c) v -= upper_[6 * k + c] * x[c];
      x[k] = v;
      d[k] = v;
    }
  }

 private:
  bool FactorScalar(const double* A_in, double tiny) {
    for (int c = 0; c < 6; ++c) {
      for (int r = 0; r < 6; ++r) A_[8 * c + r] = A_in[6 * c + r];
      A_[8 * c + 6] = A_[8 * c + 7] = 0;
    }
    bool free_row[6] = {true, true, true, true, true, true};
    for (int k = 0; k < 6; ++k) {
      int p = -1;
      double best = 0;
      for (int i = 0; i < 6; ++i) {
        const double v = std::abs(A_[8 * k + i]);
        if (free_row[i] && (p < 0 || v > best)) {
          best = v;
          p = i;
        }
      }
      if (!(best > tiny)) return false;
      pivot_[k] = p;
      free_row[p] = false;
      inv_[k] = 1 / A_[8 * k + p];
      for (int i = 0; i < 8; ++i) {
        L_[8 * k + i] = i < 6 && free_row[i] ? A_[8 * k + i] * inv_[k] : 0.0;
      }
      for (int c = k + 1; c < 6; ++c) {
        const double a = A_[8 * c + p];
        for (int i = 0; i < 6; ++i) {
          if (free_row[i]) A_[8 * c + i] -= L_[8 * k + i] * a;
        }
      }
    }
    GatherLower();
    return true;
  }
#ifdef LPOE_IK_AVX
  __attribute__((target("avx"))) bool FactorAvx(const double* A_in, double tiny) {
    const __m256i two = _mm256_set_epi64x(0, 0, -1, -1);
    for (int c = 0; c < 6; ++c) {
      _mm256_storeu_pd(A_ + 8 * c, _mm256_loadu_pd(A_in + 6 * c));
      _mm256_storeu_pd(A_ + 8 * c + 4, _mm256_maskload_pd(A_in + 6 * c + 4, two));
    }
    const __m256d row_lo = _mm256_set_pd(3, 2, 1, 0), row_hi = _mm256_set_pd(7, 6, 5, 4);
    const __m256d magnitude = _mm256_castsi256_pd(_mm256_set1_epi64x(0x7fffffffffffffffLL));
    __m256d free_lo = _mm256_castsi256_pd(_mm256_set1_epi64x(-1));
    __m256d free_hi = _mm256_castsi256_pd(_mm256_set_epi64x(0, 0, -1, -1));
#pragma GCC unroll 6
    for (int k = 0; k < 6; ++k) {
      const __m256d lo = _mm256_loadu_pd(A_ + 8 * k), hi = _mm256_loadu_pd(A_ + 8 * k + 4);
      // The reciprocals of the whole column, computed while the pivot is searched (the division
      // off the step's critical path); the pivot's is then read from them.
      alignas(32) double recip[8];
      const __m256d one = _mm256_set1_pd(1.0);
      _mm256_store_pd(recip, _mm256_div_pd(one, lo));
      _mm256_store_pd(recip + 4, _mm256_div_pd(one, hi));
      // The pivot: the first free row with the largest magnitude (non-free rows count as 0).
      const __m256d a_lo = _mm256_and_pd(_mm256_and_pd(lo, magnitude), free_lo);
      const __m256d a_hi = _mm256_and_pd(_mm256_and_pd(hi, magnitude), free_hi);
      const __m256d m4 = _mm256_max_pd(a_lo, a_hi);
      const __m128d m2 = _mm_max_pd(_mm256_castpd256_pd128(m4), _mm256_extractf128_pd(m4, 1));
      const double best = std::max(_mm_cvtsd_f64(m2), _mm_cvtsd_f64(_mm_unpackhi_pd(m2, m2)));
      if (!(best > tiny)) return false;
      const __m256d b = _mm256_set1_pd(best);
      const int at = _mm256_movemask_pd(_mm256_and_pd(_mm256_cmp_pd(a_lo, b, _CMP_EQ_OQ), free_lo)) |
                     _mm256_movemask_pd(_mm256_and_pd(_mm256_cmp_pd(a_hi, b, _CMP_EQ_OQ), free_hi))
                         << 4;
      if (at == 0) return false;  // not reached for finite entries
      const int p = __builtin_ctz(static_cast<unsigned>(at));
      pivot_[k] = p;
      const __m256d pp = _mm256_set1_pd(p);
      free_lo = _mm256_andnot_pd(_mm256_cmp_pd(row_lo, pp, _CMP_EQ_OQ), free_lo);
      free_hi = _mm256_andnot_pd(_mm256_cmp_pd(row_hi, pp, _CMP_EQ_OQ), free_hi);
      const double inv_p = recip[p];  // 1 / A(p, k), correctly rounded as the scalar division
      inv_[k] = inv_p;
      const __m256d inv = _mm256_set1_pd(inv_p);
      const __m256d l_lo = _mm256_and_pd(_mm256_mul_pd(lo, inv), free_lo);
      const __m256d l_hi = _mm256_and_pd(_mm256_mul_pd(hi, inv), free_hi);
      _mm256_storeu_pd(L_ + 8 * k, l_lo);
      _mm256_storeu_pd(L_ + 8 * k + 4, l_hi);
#pragma GCC unroll 6
      for (int c = k + 1; c < 6; ++c) {
        double* col = A_ + 8 * c;
        const __m256d a = _mm256_broadcast_sd(col + p);
        _mm256_storeu_pd(col, _mm256_sub_pd(_mm256_loadu_pd(col), _mm256_mul_pd(l_lo, a)));
        _mm256_storeu_pd(col + 4, _mm256_sub_pd(_mm256_loadu_pd(col + 4), _mm256_mul_pd(l_hi, a)));
      }
    }
    GatherLower();
    return true;
  }
#endif

  // L in the pivots' order, lower_[6 m + k] = l(pivot_m, k) for k < m, and U with its rows
  // divided by the pivots, upper_[6 k + c] = u_kc / u_kk for c > k.
  void GatherLower() {
#pragma GCC unroll 6
    for (int m = 1; m < 6; ++m) {
#pragma GCC unroll 6
      for (int k = 0; k < m; ++k) lower_[6 * m + k] = L_[8 * k + pivot_[m]];
    }
#pragma GCC unroll 6
    for (int k = 0; k < 5; ++k) {
#pragma GCC unroll 6
      for (int c = k + 1; c < 6; ++c) upper_[6 * k + c] = A_[8 * c + pivot_[k]] * inv_[k];
    }
  }

  double A_[48];  // U(k, c) = A_[8 c + pivot_[k]] for c >= k
  double L_[48];  // column k: step k's multipliers in the rows free after it, else 0
  double lower_[36];
  double upper_[36];
  double inv_[6];
  int pivot_[6];
  bool ok_ = true;
};

// The second-order term Q(dx) of the weighted pose error along a step dx of the chain's joint
// values, from the weighted Jacobian Jx (6 x n, column-major; column j is (u_j, L w_j): the tool
// point's velocity and L times the axis). With the axes at x, FK(x + dx) = exp(dx_1 xi_1) ...
// exp(dx_n xi_n) FK(x) (spatial twists xi_j), so with b_j = dx_j w_j and a_j = dx_j u_j
//   p(x + dx) - p          = sum_j a_j + sum_i b_i x (a_i / 2 + sum_{j>i} a_j) + O(dx^3),
//   log(R(x + dx) R(x)^T)  = sum_j b_j + 1/2 sum_i b_i x sum_{j>i} b_j + O(dx^3)  (Baker-Campbell-
// Hausdorff), and Q = [the second-order position term; L times the second-order rotation term].
// One backward pass of cross products (prismatic joints: w_j = 0, the formulas hold as they are).
#ifdef LPOE_IK_AVX
// (x, y, z, .) -> (y, z, x, .) in AVX (no cross-lane permute without AVX2: four operations).
__attribute__((target("avx"))) inline __m256d Yzx(__m256d v) {
  const __m256d t = _mm256_permute2f128_pd(v, v, 0x01);  // (z, ., x, .)
  return _mm256_blend_pd(_mm256_permute_pd(v, 0x1), _mm256_permute_pd(t, 0x0), 0x6);
}

// PoseSecondOrder for 6 joints in AVX registers (lanes x, y, z). Every cross product is
// a x b = (a * b.yzx - a.yzx * b).yzx, and the sums of them take the outer .yzx once at the end,
// so each joint needs the permuted column u.yzx and w.yzx only (the running sums of the permuted
// a and b are the permuted running sums). The scalar routine's sums in another order: the two
// agree to round-off.
__attribute__((target("avx"))) void PoseSecondOrder6Avx(const double* Jx, const double* dx,
                                                        double L, double* Q) {
  const __m256i three = _mm256_set_epi64x(0, -1, -1, -1);
  const __m256d half = _mm256_set1_pd(0.5);
  const double inv_l = 1 / L;
  __m256d sa = _mm256_setzero_pd(), sa_y = sa, sb = sa, sb_y = sa, qp = sa, qr = sa;
  for (int i = 5; i >= 0; --i) {
    const __m256d u = _mm256_maskload_pd(Jx + 6 * i, three);
    const __m256d w = _mm256_maskload_pd(Jx + 6 * i + 3, three);
    const __m256d s = _mm256_set1_pd(dx[i]), t = _mm256_set1_pd(dx[i] * inv_l);
    const __m256d a = _mm256_mul_pd(s, u), a_y = _mm256_mul_pd(s, Yzx(u));
    const __m256d b = _mm256_mul_pd(t, w), b_y = _mm256_mul_pd(t, Yzx(w));
    const __m256d h = _mm256_add_pd(_mm256_mul_pd(half, a), sa);
    const __m256d h_y = _mm256_add_pd(_mm256_mul_pd(half, a_y), sa_y);
    qp = _mm256_add_pd(qp, _mm256_sub_pd(_mm256_mul_pd(b, h_y), _mm256_mul_pd(b_y, h)));
    qr = _mm256_add_pd(qr, _mm256_sub_pd(_mm256_mul_pd(b, sb_y), _mm256_mul_pd(b_y, sb)));
    sa = _mm256_add_pd(sa, a);
    sa_y = _mm256_add_pd(sa_y, a_y);
    sb = _mm256_add_pd(sb, b);
    sb_y = _mm256_add_pd(sb_y, b_y);
  }
  alignas(32) double p[4], r[4];
  _mm256_store_pd(p, Yzx(qp));
  _mm256_store_pd(r, _mm256_mul_pd(_mm256_set1_pd(0.5 * L), Yzx(qr)));
  for (int k = 0; k < 3; ++k) {
    Q[k] = p[k];
    Q[3 + k] = r[k];
  }
}
#endif

inline void PoseSecondOrder(const double* Jx, const double* dx, int n, double L, double* Q) {
#ifdef LPOE_IK_AVX
  if (n == 6 && HaveAvx()) {
    PoseSecondOrder6Avx(Jx, dx, L, Q);
    return;
  }
#endif
  double sa[3] = {0, 0, 0}, sb[3] = {0, 0, 0}, qp[3] = {0, 0, 0}, qr[3] = {0, 0, 0};
  const double inv_l = 1 / L;
  for (int i = n - 1; i >= 0; --i) {
    const double* c = Jx + 6 * i;
    const double t = dx[i] * inv_l;
    const double a[3] = {dx[i] * c[0], dx[i] * c[1], dx[i] * c[2]};
    const double b[3] = {t * c[3], t * c[4], t * c[5]};
    const double h[3] = {0.5 * a[0] + sa[0], 0.5 * a[1] + sa[1], 0.5 * a[2] + sa[2]};
    qp[0] += b[1] * h[2] - b[2] * h[1];
    qp[1] += b[2] * h[0] - b[0] * h[2];
    qp[2] += b[0] * h[1] - b[1] * h[0];
    qr[0] += b[1] * sb[2] - b[2] * sb[1];
    qr[1] += b[2] * sb[0] - b[0] * sb[2];
    qr[2] += b[0] * sb[1] - b[1] * sb[0];
    for (int r = 0; r < 3; ++r) {
      sa[r] += a[r];
      sb[r] += b[r];
    }
  }
  const double half_l = 0.5 * L;
  for (int r = 0; r < 3; ++r) {
    Q[r] = qp[r];
    Q[3 + r] = half_l * qr[r];
  }
}

// x, kept out of the compiler's vectors (x86: an empty asm on an SSE register), so a value stored
// alone is loaded alone; elsewhere x itself.
inline double OneLane(double x) {
#if defined(__GNUC__) && defined(__SSE2__)
  asm("" : "+x"(x));
#endif
  return x;
}

// Newton's step of a square pose task (6 x 6, weighted J = Jx dg/dq, error e) with its second-order
// correction: d0 = J^-1 e, then d = d0 - J^-1 Q(dg/dq d0) (Chebyshev's method: the error after the
// step is of third order in d0 instead of second). The correction is dropped when it is not small
// against the step (|c|_inf > |d0|_inf / 2: far from the solution, where the expansion says
// nothing). Jx: the Jacobian before the chain rule; dg_dq: null for the identity.
inline void CorrectedNewtonStep6(const SquareLu<6>& lu, const double* e, const double* Jx,
                                 const double* dg_dq, double L, double* d) {
  lu.Solve(e, d);
  double dx[6], Q[6], c[6];
  const double* step = d;
  if (dg_dq != nullptr) {
    for (int r = 0; r < 6; ++r) {
      double v = 0;
      for (int k = 0; k < 6; ++k) v += dg_dq[6 * k + r] * d[k];
      dx[r] = v;
    }
    step = dx;
  }
  PoseSecondOrder(Jx, step, 6, L, Q);
  lu.Solve(Q, c);
  double dmax = 0, cmax = 0;
  for (int j = 0; j < 6; ++j) {
    dmax = std::max(dmax, std::abs(d[j]));
    cmax = std::max(cmax, std::abs(c[j]));
  }
  if (cmax <= 0.5 * dmax) {
    // One load per value: d and c were just stored one value at a time (the solves), and the
    // compiler's paired 16-byte loads of them could not be forwarded from those stores (a stall).
#pragma GCC unroll 6
    for (int j = 0; j < 6; ++j) d[j] = OneLane(d[j]) - OneLane(c[j]);
  }
}

#ifdef LPOE_IK_AVX
// The 6 x 6 Gram matrix J J^T of a 6 x n column-major J, whole (A[j] its column j), in AVX: the
// scalar loop's sums in the same order (over the columns of J), so the same values.
__attribute__((target("avx"))) void Gram6Avx(const double* J, int n, double (*A)[6]) {
  // Column j of A in lo_j (rows 0-3) and hi_j (rows 4-5), twelve named registers.
  __m256d lo0 = _mm256_setzero_pd(), lo1 = lo0, lo2 = lo0, lo3 = lo0, lo4 = lo0, lo5 = lo0;
  __m128d hi0 = _mm_setzero_pd(), hi1 = hi0, hi2 = hi0, hi3 = hi0, hi4 = hi0, hi5 = hi0;
  for (int k = 0; k < n; ++k) {
    const double* c = J + 6 * k;
    const __m256d c_lo = _mm256_loadu_pd(c);
    const __m128d c_hi = _mm_loadu_pd(c + 4);
#define LPOE_GRAM_COLUMN(j)                                             \
  {                                                                     \
    const __m256d b = _mm256_broadcast_sd(c + j);                       \
    lo##j = _mm256_add_pd(lo##j, _mm256_mul_pd(c_lo, b));               \
    hi##j = _mm_add_pd(hi##j, _mm_mul_pd(c_hi, _mm256_castpd256_pd128(b))); \
  }
    LPOE_GRAM_COLUMN(0)
    LPOE_GRAM_COLUMN(1)
    LPOE_GRAM_COLUMN(2)
    LPOE_GRAM_COLUMN(3)
    LPOE_GRAM_COLUMN(4)
    LPOE_GRAM_COLUMN(5)
#undef LPOE_GRAM_COLUMN
  }
  _mm256_storeu_pd(A[0], lo0);
  _mm256_storeu_pd(A[1], lo1);
  _mm256_storeu_pd(A[2], lo2);
  _mm256_storeu_pd(A[3], lo3);
  _mm256_storeu_pd(A[4], lo4);
  _mm256_storeu_pd(A[5], lo5);
  _mm_storeu_pd(A[0] + 4, hi0);
  _mm_storeu_pd(A[1] + 4, hi1);
  _mm_storeu_pd(A[2] + 4, hi2);
  _mm_storeu_pd(A[3] + 4, hi3);
  _mm_storeu_pd(A[4] + 4, hi4);
  _mm_storeu_pd(A[5] + 4, hi5);
}
#endif

// Smallest eigenvalue of the Gram matrix A = J J^T of an M x n column-major J (sigma_min^2 of J for
// M <= n; a diagnostic and a threshold). Householder reflections reduce A to a tridiagonal T with the same
// eigenvalues; Laguerre's iteration on det(T - x I) then climbs from x = 0 to the smallest one. For
// a polynomial with only real roots, Laguerre's step from below the smallest root stays below it
// and converges to it monotonically, cubically (in one step when all roots coincide), so no test of
// which eigenvalue was found is needed. Its sums G = sum_i 1 / (lambda_i - x) and
// H = sum_i 1 / (lambda_i - x)^2 come from the leading principal minors p_i of T - x I (the
// three-term recurrence, differentiated twice); all p_i positive (so all pivots p_i / p_{i-1} of
// its LDL^T) is the proof that x is below the smallest eigenvalue (Sylvester's law of inertia). 0
// when A is singular to round-off (a minor of T itself not positive).
template <int M>
double SmallestEigenvalueOfGram(const double* J, int n) {
  // A = J J^T (lower triangle, A[i][j] for j <= i, read), as a sum of the columns' outer products.
  double A[M][M];
#ifdef LPOE_IK_AVX
  if (M == 6 && HaveAvx()) {
    Gram6Avx(J, n, reinterpret_cast<double(*)[6]>(A));
  } else
#endif
  {
    for (int i = 0; i < M; ++i) {
      for (int j = 0; j < M; ++j) A[i][j] = 0;
    }
    for (int k = 0; k < n; ++k) {
      const double* c = J + M * k;
#pragma GCC unroll 6
      for (int i = 0; i < M; ++i) {
#pragma GCC unroll 6
        for (int j = 0; j <= i; ++j) A[i][j] += c[i] * c[j];
      }
    }
  }
  auto at = [&A](int i, int j) -> double& { return i >= j ? A[i][j] : A[j][i]; };
  double diag[M], off2[M];  // T's diagonal and squared off-diagonal
#pragma GCC unroll 4
  for (int k = 0; k + 2 < M; ++k) {
    // The reflection H = I - beta v v^T that zeroes A[k+2.., k]; A <- H A H on rows/columns k+1...
    double s = 0;
    for (int i = k + 2; i < M; ++i) s += A[i][k] * A[i][k];
    const double x0 = A[k + 1][k];
    if (s == 0) {  // already tridiagonal in this column
      off2[k] = x0 * x0;
      continue;
    }
    const double norm = std::sqrt(x0 * x0 + s);
    const double alpha = x0 > 0 ? -norm : norm;
    double v[M], p[M];
    v[k + 1] = x0 - alpha;
    for (int i = k + 2; i < M; ++i) v[i] = A[i][k];
    const double beta = 1 / (norm * norm - x0 * alpha);  // 2 / (v^T v)
    double vp = 0;
#pragma GCC unroll 6
    for (int i = k + 1; i < M; ++i) {
      double t = 0;
#pragma GCC unroll 6
      for (int j = k + 1; j < M; ++j) t += at(i, j) * v[j];
      p[i] = beta * t;
      vp += v[i] * p[i];
    }
    const double half = 0.5 * beta * vp;
    for (int i = k + 1; i < M; ++i) p[i] -= half * v[i];
#pragma GCC unroll 6
    for (int i = k + 1; i < M; ++i) {
#pragma GCC unroll 6
      for (int j = k + 1; j <= i; ++j) A[i][j] -= v[i] * p[j] + p[i] * v[j];
    }
    off2[k] = alpha * alpha;
  }
  if (M >= 2) off2[M - 2] = A[M - 1][M - 2] * A[M - 1][M - 2];
  for (int i = 0; i < M; ++i) diag[i] = A[i][i];

  // Laguerre's step at x from the leading principal minors of T - x I, p_i = (a_i - x) p_{i-1} -
  // b_{i-1}^2 p_{i-2}, and their first two derivatives in x (p = p_M = prod (lambda_i - x)):
  // with G = -p'/p and H = G^2 - p''/p, the step M / (G + sqrt((M-1)(M H - G^2))) is, multiplied
  // through by p > 0, M p / (-p' + sqrt((M-1)((M-1) p'^2 - M p p''))): one division (the step's)
  // on the iteration's chain, none on the recurrence's. False when a minor is not positive (then a
  // pivot p_i / p_{i-1} is not: x is not below every eigenvalue). The entries (mm^2) keep p and
  // p'^2 far from overflow.
  auto step_at = [&](double x, double* step) {
    double p1 = 1, d1 = 0, e1 = 0;  // p_{i-1}, p'_{i-1}, p''_{i-1}
    double p2 = 0, d2 = 0, e2 = 0;  // p_{i-2}, ...
    bool positive = true;
#pragma GCC unroll 6
    for (int i = 0; i < M; ++i) {
      const double t = diag[i] - x, b2 = i > 0 ? off2[i - 1] : 0.0;
      const double p = t * p1 - b2 * p2;
      const double d = t * d1 - p1 - b2 * d2;
      const double e = t * e1 - 2 * d1 - b2 * e2;
      positive &= p > 0;
      p2 = p1;
      d2 = d1;
      e2 = e1;
      p1 = p;
      d1 = d;
      e1 = e;
    }
    if (!positive) return false;
    const double root = std::sqrt(std::max(0.0, (M - 1) * ((M - 1) * (d1 * d1) - M * (p1 * e1))));
    *step = M * p1 / (root - d1);
    return true;
  };
  double step;
  if (!step_at(0.0, &step)) return 0.0;
  double x = 0;
  for (int k = 0; k < 100; ++k) {
    const double next = x + step;
    // Converged: the convergence is cubic, so after a step below 1e-6 of x what is left is of the
    // order of 1e-18 of it (times the spread of the eigenvalues; far below the 1e-13 the routine
    // resolves, and one evaluation of the sums fewer than with the next step's 1e-18). Or `next`
    // lies on the eigenvalue to round-off (a minor not positive there).
    if (!(step > 1e-6 * next) || !step_at(next, &step)) return next;
    x = next;
  }
  return x;
}

// max |J_k| over the 36 entries of a 6 x 6 matrix (two lanes at a time where SSE2 is there).
inline double MaxAbs36(const double* J) {
#if defined(__SSE2__)
  const __m128d magnitude = _mm_castsi128_pd(_mm_set1_epi64x(0x7fffffffffffffffLL));
  __m128d m0 = _mm_setzero_pd(), m1 = _mm_setzero_pd();
#pragma GCC unroll 9
  for (int k = 0; k < 36; k += 4) {
    m0 = _mm_max_pd(m0, _mm_and_pd(_mm_loadu_pd(J + k), magnitude));
    m1 = _mm_max_pd(m1, _mm_and_pd(_mm_loadu_pd(J + k + 2), magnitude));
  }
  m0 = _mm_max_pd(m0, m1);
  return std::max(_mm_cvtsd_f64(m0), _mm_cvtsd_f64(_mm_unpackhi_pd(m0, m0)));
#else
  double amax = 0;
  for (int k = 0; k < 36; ++k) amax = std::max(amax, std::abs(J[k]));
  return amax;
#endif
}

int Sign(double x) { return x > 0 ? 1 : (x < 0 ? -1 : 0); }

// ---- The fast path (6 revolute-z joints, pose target; IkOptions::fast_path).

// One iterate of the fast path: joints, the chain's joint values x with their sin/cos, the joint
// axes w_i and points t_i of the frames G_i, the tool frame, weighted task error and Jacobian
// (column-major 6 x 6).
struct FastIterate {
  double q[6], x[6], sin_x[6], cos_x[6];
  int age[6];
  double w[6][4], t[6][4];  // the fourth value is padding (the AVX sweep stores four)
  double R[12], P[4];       // R column-major in R[0..8]
  double J[36];
  double Jx[36], dg_dq[36];  // with a joint map: J before the chain rule, and dg/dq
  double e[6];
  double merit;
};

#ifdef LPOE_IK_AVX
#define LPOE_IK_AVX_SWEEP 1
// Sweep6 with each column of the running frame (and its origin) in one AVX register, lanes 0-2:
// the SSE2 sweep's multiplications and additions in the same order, so the same bits with half the
// instructions. Lane 3 carries junk that is never read.
__attribute__((target("avx"))) void Sweep6Avx(const RobotModel& model, int tool,
                                               FastIterate* it) {
  const SE3d& O0 = model.joints[0].origin;
  const __m256i three = _mm256_set_epi64x(0, -1, -1, -1);
  __m256d r[4];
  for (int k = 0; k < 3; ++k) r[k] = _mm256_maskload_pd(O0.R.data() + 3 * k, three);
  r[3] = _mm256_maskload_pd(O0.t.data(), three);
  for (int i = 0; i < 6; ++i) {
    _mm256_storeu_pd(it->w[i], r[2]);
    _mm256_storeu_pd(it->t[i], r[3]);
    const __m256d c = _mm256_set1_pd(it->cos_x[i]), ns = _mm256_set1_pd(-it->sin_x[i]);
    const __m256d x0 = r[0];  // R <- R Rz(x_i) (internal::PlaneRotation(c, -s, ...))
    r[0] = _mm256_sub_pd(_mm256_mul_pd(c, x0), _mm256_mul_pd(ns, r[1]));
    r[1] = _mm256_add_pd(_mm256_mul_pd(ns, x0), _mm256_mul_pd(c, r[1]));
    const SE3d& O = i < 5 ? model.joints[i + 1].origin : model.tools[tool].origin;
    const double* M = O.R.data();
    __m256d n[3];
    for (int col = 0; col < 3; ++col) {
      const __m256d a = _mm256_broadcast_sd(M + 3 * col);
      const __m256d b = _mm256_broadcast_sd(M + 3 * col + 1);
      const __m256d d = _mm256_broadcast_sd(M + 3 * col + 2);
      n[col] = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(r[0], a), _mm256_mul_pd(r[1], b)),
                             _mm256_mul_pd(r[2], d));
    }
    const __m256d a = _mm256_broadcast_sd(O.t.data());
    const __m256d b = _mm256_broadcast_sd(O.t.data() + 1);
    const __m256d d = _mm256_broadcast_sd(O.t.data() + 2);
    r[3] = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(r[0], a), r[3]),
                         _mm256_add_pd(_mm256_mul_pd(r[1], b), _mm256_mul_pd(r[2], d)));
    for (int col = 0; col < 3; ++col) r[col] = n[col];
  }
  for (int k = 0; k < 3; ++k) _mm256_storeu_pd(it->R + 3 * k, r[k]);  // in order: lane 3 rewritten
  _mm256_storeu_pd(it->P, r[3]);
}

#endif

// The forward sweep of a chain of 6 revolute-z joints: G_i = T_0,i-1(q) T_{i-1,i}(0) as its axis
// w_i (third column) and point t_i, then the tool frame (the values of KinematicChain::Frames).
inline void Sweep6(const RobotModel& model, int tool, FastIterate* it) {
#ifdef LPOE_IK_AVX_SWEEP
  if (HaveAvx()) {
    Sweep6Avx(model, tool, it);
    return;
  }
#endif
  const SE3d& O0 = model.joints[0].origin;
#if defined(__SSE2__)
  // The running product in SSE2 registers as kinematics.cc's accumulator: rows 0 and 1 of each
  // column of R (and of t) as a pair, row 2 in the low lane of a second register; the same
  // operations in the same order, so the frames are KinematicChain::Frames' to the bit.
  __m128d lo[4], hi[4];
  for (int k = 0; k < 3; ++k) {
    lo[k] = _mm_loadu_pd(O0.R.data() + 3 * k);
    hi[k] = _mm_load_sd(O0.R.data() + 3 * k + 2);
  }
  lo[3] = _mm_loadu_pd(O0.t.data());
  hi[3] = _mm_load_sd(O0.t.data() + 2);
  for (int i = 0; i < 6; ++i) {
    _mm_storeu_pd(it->w[i], lo[2]);
    _mm_store_sd(it->w[i] + 2, hi[2]);
    _mm_storeu_pd(it->t[i], lo[3]);
    _mm_store_sd(it->t[i] + 2, hi[3]);
    const __m128d c = _mm_set1_pd(it->cos_x[i]), ns = _mm_set1_pd(-it->sin_x[i]);
    internal::PlaneRotation(c, ns, &lo[0], &lo[1]);  // R <- R Rz(x_i)
    internal::PlaneRotation(c, ns, &hi[0], &hi[1]);
    const SE3d& O = i < 5 ? model.joints[i + 1].origin : model.tools[tool].origin;
    const double* M = O.R.data();
    __m128d nlo[3], nhi[3];
    for (int col = 0; col < 3; ++col) {
      const __m128d a = _mm_set1_pd(M[3 * col]);
      const __m128d b = _mm_set1_pd(M[3 * col + 1]);
      const __m128d d = _mm_set1_pd(M[3 * col + 2]);
      nlo[col] = _mm_add_pd(_mm_add_pd(_mm_mul_pd(lo[0], a), _mm_mul_pd(lo[1], b)),
                            _mm_mul_pd(lo[2], d));
      nhi[col] = _mm_add_sd(_mm_add_sd(_mm_mul_sd(hi[0], a), _mm_mul_sd(hi[1], b)),
                            _mm_mul_sd(hi[2], d));
    }
    const __m128d a = _mm_set1_pd(O.t(0));
    const __m128d b = _mm_set1_pd(O.t(1));
    const __m128d d = _mm_set1_pd(O.t(2));
    lo[3] = _mm_add_pd(_mm_add_pd(_mm_mul_pd(lo[0], a), lo[3]),
                       _mm_add_pd(_mm_mul_pd(lo[1], b), _mm_mul_pd(lo[2], d)));
    hi[3] = _mm_add_sd(_mm_add_sd(_mm_mul_sd(hi[0], a), hi[3]),
                       _mm_add_sd(_mm_mul_sd(hi[1], b), _mm_mul_sd(hi[2], d)));
    for (int col = 0; col < 3; ++col) {
      lo[col] = nlo[col];
      hi[col] = nhi[col];
    }
  }
  for (int k = 0; k < 3; ++k) {
    _mm_storeu_pd(it->R + 3 * k, lo[k]);
    _mm_store_sd(it->R + 3 * k + 2, hi[k]);
  }
  _mm_storeu_pd(it->P, lo[3]);
  _mm_store_sd(it->P + 2, hi[3]);
#else
  double R[9], t[3];
  for (int k = 0; k < 9; ++k) R[k] = O0.R.data()[k];
  for (int k = 0; k < 3; ++k) t[k] = O0.t(k);
  for (int i = 0; i < 6; ++i) {
    for (int r = 0; r < 3; ++r) {
      it->w[i][r] = R[6 + r];
      it->t[i][r] = t[r];
    }
    const double c = it->cos_x[i], s = it->sin_x[i];
    for (int r = 0; r < 3; ++r) internal::PlaneRotation(c, -s, &R[r], &R[3 + r]);
    const SE3d& O = i < 5 ? model.joints[i + 1].origin : model.tools[tool].origin;
    const double* M = O.R.data();
    double N[9];
    for (int col = 0; col < 3; ++col) {
      const double a = M[3 * col], b = M[3 * col + 1], d = M[3 * col + 2];
      for (int r = 0; r < 3; ++r) N[3 * col + r] = R[r] * a + R[3 + r] * b + R[6 + r] * d;
    }
    for (int r = 0; r < 3; ++r) t[r] += R[r] * O.t(0) + R[3 + r] * O.t(1) + R[6 + r] * O.t(2);
    for (int k = 0; k < 9; ++k) R[k] = N[k];
  }
  for (int k = 0; k < 9; ++k) it->R[k] = R[k];
  for (int k = 0; k < 3; ++k) it->P[k] = t[k];
#endif
}

// (D_arm, D_wrist) signs of one fast iterate (BranchSignsOf on the same frames): c = t_4.
inline void BranchSigns6(const FastIterate& it, int signs[2]) {
  Eigen::Matrix3d arm, wrist;
  for (int j = 0; j < 3; ++j) {
    const Eigen::Vector3d w(it.w[j][0], it.w[j][1], it.w[j][2]);
    const Eigen::Vector3d d(it.t[4][0] - it.t[j][0], it.t[4][1] - it.t[j][1],
                            it.t[4][2] - it.t[j][2]);
    arm.col(j) = w.cross(d);
    wrist.col(j) = Eigen::Vector3d(it.w[3 + j][0], it.w[3 + j][1], it.w[3 + j][2]);
  }
  signs[0] = Sign(arm.determinant());
  signs[1] = Sign(wrist.determinant());
}


// (D_arm, D_wrist) signs from the frames of one configuration (see the header): the joint Jacobian
// of the point c (the first three position columns) and the last three joint axes.
void BranchSignsOf(const KinematicChain& chain, const FrameRt* frames, int signs[2]) {
  const int n = chain.num_joints();
  FrameRt at_c[kMax + 1];
  std::copy(frames, frames + n, at_c);
  at_c[n].t = frames[n - 2].t;
  Eigen::Matrix<double, 6, Eigen::Dynamic, 0, 6, kMax> J(6, n);
  chain.ToolJointJacobian(at_c, J.data(), 6);
  signs[0] = Sign(J.topLeftCorner<3, 3>().determinant());
  const Eigen::Matrix3d axes = J.bottomRightCorner<3, 3>();
  signs[1] = Sign(axes.determinant());
}

// The joint-error terms a model carries (RobotModel::joint_errors): g(q) = q + dq(q), dg/dq by
// forward differences of dq (its derivatives are of the order of the offsets themselves, 1e-4, so
// the differences' error is far below what would slow Newton's convergence).
class ModelJointErrors : public EffectiveJointMap {
 public:
  explicit ModelJointErrors(const RobotModel& model) : model_(&model) {}
  void Evaluate(const double* q, double* q_eff, double* dg_dq) const override {
    const int n = model_->num_joints();
    double dq[kMax], qh[kMax], dqh[kMax];
    JointErrorOffsets(*model_, q, dq);
    for (int j = 0; j < n; ++j) q_eff[j] = q[j] + dq[j];
    if (dg_dq == nullptr) return;
    constexpr double kStep = 1e-6;  // rad or mm
    for (int j = 0; j < n; ++j) qh[j] = q[j];
    for (int c = 0; c < n; ++c) {
      qh[c] = q[c] + kStep;
      JointErrorOffsets(*model_, qh, dqh);
      qh[c] = q[c];
      for (int r = 0; r < n; ++r) dg_dq[c * n + r] = (r == c) + (dqh[r] - dq[r]) / kStep;
    }
  }

 private:
  const RobotModel* model_;
};

}  // namespace

const char* IkStatusName(IkStatus status) {
  switch (status) {
    case IkStatus::kOk:
      return "ok";
    case IkStatus::kUnreachable:
      return "unreachable";
    case IkStatus::kLimit:
      return "limit";
    case IkStatus::kSingular:
      return "singular";
    case IkStatus::kBranch:
      return "branch";
  }
  return "unknown";
}

Status InverseKinematics::CheckModel(const RobotModel& model) {
  if (Status s = model.Validate(); !s.ok()) return s;
  if (model.num_joints() > kMax) {
    return Status::Error("inverse kinematics supports at most " + std::to_string(kMax) +
                         " joints; the model has " + std::to_string(model.num_joints()));
  }
  for (const Joint& j : model.joints) {
    if (j.lower > j.upper) {
      return Status::Error("joint " + j.name + ": lower limit above upper limit");
    }
  }
  return Status::Ok();
}

InverseKinematics::InverseKinematics(const RobotModel& model, const IkOptions& options,
                                     const EffectiveJointMap* effective)
    : model_(&model), options_(options), effective_(effective), chain_(model) {
  CHECK(CheckModel(model).ok()) << CheckModel(model).message();
  if (effective_ == nullptr && !model.joint_errors.empty()) {
    own_effective_ = std::make_shared<ModelJointErrors>(model);
    effective_ = own_effective_.get();
  }
  const int n = model.num_joints();
  for (int j = 0; j < n; ++j) z_revolute_[j] = IsRevoluteZ(model.joints[j]);
  fast_ = options_.fast_path && n == 6;
  for (int j = 0; j < n; ++j) fast_ = fast_ && z_revolute_[j];
  branch_defined_ = n >= 6;
  if (branch_defined_) {
    for (int j : {0, 1, 2, n - 3, n - 2, n - 1}) {
      if (model.joints[j].type != JointType::kRevolute) branch_defined_ = false;
    }
  }
}

void InverseKinematics::BranchSigns(const double* q, int signs[2]) const {
  signs[0] = signs[1] = 0;
  if (!branch_defined_) return;
  FrameRt frames[kMax + 1];
  double q_eff[kMax];
  const double* x = q;
  if (effective_ != nullptr) {
    effective_->Evaluate(q, q_eff, nullptr);
    x = q_eff;
  }
  chain_.Frames(x, 0, frames);
  BranchSignsOf(chain_, frames, signs);
}

IkResult InverseKinematics::Solve(const IkTarget& target, const double* seed, double* q) const {
  if (model_->residual_layer) return SolveThroughLayer(target, seed, q);
  return SolveParametric(target, seed, q);
}

IkResult InverseKinematics::SolveParametric(const IkTarget& target, const double* seed,
                                            double* q) const {
  CHECK(target.tool >= 0 && target.tool < model_->num_tools()) << "tool index " << target.tool;
  const int n = chain_.num_joints();
  if (target.has_orientation) {
    if (n == 6) return SolveTask<6, 6>(target, seed, q);
    if (n == 7) return SolveTask<6, 7>(target, seed, q);
    return SolveTask<6, Eigen::Dynamic>(target, seed, q);
  }
  if (n == 6) return SolveTask<3, 6>(target, seed, q);
  if (n == 7) return SolveTask<3, 7>(target, seed, q);
  return SolveTask<3, Eigen::Dynamic>(target, seed, q);
}

template <int M, int N>
IkResult InverseKinematics::SolveTask(const IkTarget& target, const double* seed,
                                      double* q_out) const {
  const int n = chain_.num_joints();
  double start[kMax], best_q[kMax], trial_q[kMax];
  std::copy(seed, seed + n, start);
  IkResult best = Run<M, N>(target, seed, seed, best_q);
  auto reached = [](const IkResult& r) {
    return r.status == IkStatus::kOk || r.status == IkStatus::kBranch ||
           r.status == IkStatus::kSingular;
  };
  int iterations = best.iterations;
  uint64_t state = 0x9E3779B97F4A7C15ull;  // deterministic restarts (xorshift64)
  int k = 1;
  for (; k <= options_.restarts && !reached(best); ++k) {
    for (int j = 0; j < n; ++j) {
      state ^= state << 13;
      state ^= state >> 7;
      state ^= state << 17;
      const double u = static_cast<double>(state >> 11) * 0x1.0p-53 * 2 - 1;
      const double a = options_.restart_step * k *
                       (model_->joints[j].type == JointType::kRevolute ? 1.0 : 10.0);
      start[j] = seed[j] + a * u;
    }
    IkResult r = Run<M, N>(target, seed, start, trial_q);
    iterations += r.iterations;
    // Keep a reached solution closest to the seed; among unreached, the smallest error.
    const bool better =
        reached(r) ? (!reached(best) || (r.status == IkStatus::kOk && best.status != IkStatus::kOk) ||
                      (r.status == best.status && r.correction < best.correction))
                   : (!reached(best) && r.position_error < best.position_error);
    if (better) {
      best = r;
      std::copy(trial_q, trial_q + n, best_q);
    }
  }
  best.iterations = iterations;
  best.restarts = k - 1;
  std::copy(best_q, best_q + n, q_out);
  return best;
}

template <int M, int N>
IkResult InverseKinematics::Run(const IkTarget& target, const double* seed_in,
                                const double* start_in, double* q_out) const {
  constexpr int kMaxN = N == Eigen::Dynamic ? kMax : N;
  using MatJ = Eigen::Matrix<double, M, N, 0, M, kMaxN>;
  using VecN = Eigen::Matrix<double, N, 1, 0, kMaxN, 1>;
  using VecM = Eigen::Matrix<double, M, 1>;
  using MatM = Eigen::Matrix<double, M, M>;
  if constexpr (M == 6 && N == 6) {
    IkResult fast;
    if (fast_ && RunFast(target, seed_in, start_in, q_out, &fast)) return fast;
  }
  const RobotModel& model = *model_;
  const IkOptions& o = options_;
  const int n = chain_.num_joints();
  const double L = o.orientation_weight;
  const bool redundant = n > M;

  VecN lower, upper, max_step, seed;
  lower.resize(n);
  upper.resize(n);
  max_step.resize(n);
  seed.resize(n);
  for (int j = 0; j < n; ++j) {
    const Joint& joint = model.joints[j];
    lower(j) = o.respect_limits ? joint.lower : -HUGE_VAL;
    upper(j) = o.respect_limits ? joint.upper : HUGE_VAL;
    max_step(j) = joint.type == JointType::kRevolute ? o.max_step_revolute : o.max_step_prismatic;
    seed(j) = std::min(std::max(seed_in[j], lower(j)), upper(j));
  }

  // One iterate: joints, the chain's joint values x (q, or g(q) with joint-space terms) with their
  // sin/cos, frames, weighted task error and Jacobian.
  struct Iterate {
    VecN q;
    double x[kMax], sin_x[kMax], cos_x[kMax];
    int age[kMax];  // incremental sin/cos updates since the last sincos
    FrameRt frames[kMax + 1];
    VecM e;
    MatJ J;
    double merit = 0;
    // Square pose tasks with a joint map: J before the chain rule, and dg/dq (the second order).
    double Jx[M == 6 && N == 6 ? 36 : 1], dg_dq[M == 6 && N == 6 ? 36 : 1];
  };
  Iterate iterates[2];
  Iterate* cur = &iterates[0];
  Iterate* trial = &iterates[1];

  // Evaluates `it` at it->q; `from` (or null) is the iterate whose sin/cos are carried over.
  auto evaluate = [&](const Iterate* from, Iterate* it) {
    double dg_dq[kMax * kMax];
    if (effective_ != nullptr) {
      effective_->Evaluate(it->q.data(), it->x, dg_dq);
    } else {
      for (int j = 0; j < n; ++j) it->x[j] = it->q(j);
    }
    int fresh[kMax], count = 0;  // joints whose sin/cos are computed afresh
    for (int j = 0; j < n; ++j) {
      if (!z_revolute_[j]) continue;
      const double delta = from != nullptr ? it->x[j] - from->x[j] : HUGE_VAL;
      if (std::abs(delta) <= kIncrementalStep && from->age[j] < kIncrementalRefresh) {
        double sd, cd;
        SinCosStep(delta, &sd, &cd);
        it->sin_x[j] = from->sin_x[j] * cd + from->cos_x[j] * sd;
        it->cos_x[j] = from->cos_x[j] * cd - from->sin_x[j] * sd;
        it->age[j] = from->age[j] + 1;
      } else {
        fresh[count++] = j;
        it->age[j] = 0;
      }
    }
    SinCosOf(it->x, fresh, count, it->sin_x, it->cos_x);
    chain_.Frames(it->x, it->sin_x, it->cos_x, target.tool, it->frames);
    const FrameRt& T = it->frames[n];
    it->e.template head<3>() = target.position - T.t;
    it->J.resize(M, n);
    if constexpr (M == 6) {
      chain_.ToolJointJacobian(it->frames, it->J.data(), 6);
      it->J.template bottomRows<3>() *= L;
      it->e.template tail<3>() = L * RotationError(target.rotation, T.R);
    } else {
      Eigen::Matrix<double, 6, N, 0, 6, kMaxN> J6;
      J6.resize(6, n);
      chain_.ToolJointJacobian(it->frames, J6.data(), 6);
      it->J = J6.template topRows<3>();
    }
    if (effective_ != nullptr) {
      if constexpr (M == 6 && N == 6) {  // as the fast path
        std::copy(dg_dq, dg_dq + 36, it->dg_dq);
        std::copy(it->J.data(), it->J.data() + 36, it->Jx);
        double* J = it->J.data();
        for (int c = 0; c < 6; ++c) {
          for (int r = 0; r < 6; ++r) {
            double v = 0;
            for (int k = 0; k < 6; ++k) v += it->Jx[6 * k + r] * dg_dq[6 * c + k];
            J[6 * c + r] = v;
          }
        }
      } else {
        const Eigen::Map<const Eigen::Matrix<double, N, N, 0, kMaxN, kMaxN>> G(dg_dq, n, n);
        const MatJ Jq = it->J * G;
        it->J = Jq;
      }
    }
    it->merit = it->e.squaredNorm();
  };
  auto task_ok = [&](const VecM& e) {
    if (e.template head<3>().norm() > o.position_tolerance) return false;
    if constexpr (M == 6) {
      if (e.template tail<3>().norm() > L * o.orientation_tolerance) return false;
    }
    return true;
  };

  cur->q.resize(n);
  trial->q.resize(n);
  for (int j = 0; j < n; ++j) cur->q(j) = std::min(std::max(start_in[j], lower(j)), upper(j));
  evaluate(nullptr, cur);
  int seed_signs[2] = {0, 0};
  const bool check_branch = o.check_branch && branch_defined_;
  if (check_branch) {
    if (start_in == seed_in) {
      BranchSignsOf(chain_, cur->frames, seed_signs);
    } else {
      BranchSigns(seed.data(), seed_signs);
    }
  }

  // One damped step with the active set of limits (see the header) from `cur`, into *d.
  bool limit_hit = false;  // some step of this run was cut at a joint limit
  auto compute_step = [&](double lambda2, double beta, VecN* d) {
    const MatJ& J = cur->J;
    const VecN& q = cur->q;
    bool locked[kMax] = {};
    bool any_locked = false;
    VecN fixed = VecN::Zero(n);
    MatJ Jf;
    for (int round = 0; round <= n; ++round) {
      // A square task, undamped, no joint held: Newton's step J d = e (the pull toward the seed
      // has no null space to act in).
      bool solved = false;
      if constexpr (N == M) {
        if (!any_locked && lambda2 == 0) {
          const double tiny = 1e-9 * std::max(J.template lpNorm<Eigen::Infinity>(), 1e-30);
          const SquareLu<M> lu(J.data(), tiny);
          solved = lu.Ok();
          if (solved) {
            if constexpr (M == 6) {  // with the second-order correction
              const bool mapped = effective_ != nullptr;
              CorrectedNewtonStep6(lu, cur->e.data(), mapped ? cur->Jx : J.data(),
                                   mapped ? cur->dg_dq : nullptr, L, d->data());
            } else {
              lu.Solve(cur->e.data(), d->data());
            }
          }
        }
      }
      if (!solved) {
        if (any_locked) Jf = J;
        const MatJ& Ju = any_locked ? Jf : J;  // columns of the joints still free
        VecM rhs = cur->e;
        VecN r = beta * (seed - q);
        if (any_locked) {
          for (int j = 0; j < n; ++j) {
            if (!locked[j]) continue;
            rhs -= J.col(j) * fixed(j);
            Jf.col(j).setZero();
            r(j) = 0;
          }
        }
        MatM A = Ju * Ju.transpose();
        const double trace = A.trace();
        A.diagonal().array() += lambda2 + (trace > 0 ? 1e-13 * trace / M : 1e-30);
        VecM y = rhs - Ju * r;
        SmallCholesky<M> llt(A);
        if (!llt.Ok()) {  // round-off on a rank-deficient A: regularize more
          A.diagonal().array() += 1e-9 * std::max(trace, 1e-30) / M;
          llt = SmallCholesky<M>(A);
        }
        if (llt.Ok()) {
          llt.Solve(&y);
        } else {
          y.setZero();
        }
        *d = r + Ju.transpose() * y;
        for (int j = 0; j < n; ++j) {
          if (locked[j]) (*d)(j) = fixed(j);
        }
      }
      // Trust region: scale the whole step (a move toward a limit stays inside when scaled).
      double scale = 1.0;
      for (int j = 0; j < n; ++j) {
        const double a = std::abs((*d)(j));
        if (a > max_step(j)) scale = std::min(scale, max_step(j) / a);
      }
      if (scale < 1.0) *d *= scale;
      if (!o.respect_limits) return;
      bool changed = false;
      for (int j = 0; j < n; ++j) {
        if (locked[j]) continue;
        const double x = q(j) + (*d)(j);
        if (x > upper(j) || x < lower(j)) {
          locked[j] = true;
          any_locked = true;
          fixed(j) = (x > upper(j) ? upper(j) : lower(j)) - q(j);
          changed = true;
          limit_hit = true;
        }
      }
      if (!changed) return;
    }
  };

  IkResult result;
  bool converged = false;
  double lambda2 = 0, pull = 1, beta = 1;
  VecN d, d_prev;
  d.resize(n);
  d_prev.setZero(n);
  int it = 0;
  for (; it < o.max_iterations; ++it) {
    const bool ok = task_ok(cur->e);
    if (ok && !redundant) {
      converged = true;
      break;
    }
    compute_step(lambda2, beta, &d);
    if (ok && d.template lpNorm<Eigen::Infinity>() < o.step_tolerance) {
      converged = true;
      break;
    }
    for (int j = 0; j < n; ++j) {
      trial->q(j) = std::min(std::max(cur->q(j) + d(j), lower(j)), upper(j));
    }
    // Square tasks, damped steps: the linear model's merit after the step (see kGoodModel).
    double predicted = 0;
    if constexpr (N == M) {
      if (lambda2 > 0) predicted = (cur->e - cur->J * d).squaredNorm();
    }
    evaluate(cur, trial);
    // Near the target, a step toward the seed in the null space may raise the task error at
    // second order; the next step removes that, so such steps are accepted (kNullSpaceSlack).
    if (trial->merit <= cur->merit || trial->merit <= kNullSpaceSlack * kNullSpaceSlack ||
        task_ok(trial->e)) {
      const bool model_good = N == M && lambda2 > 0 && !limit_hit &&
                              cur->merit - trial->merit >= kGoodModel * (cur->merit - predicted);
      std::swap(cur, trial);
      lambda2 *= 0.1;
      if (lambda2 < 1e-12 * cur->J.squaredNorm() / M || model_good) lambda2 = 0;
      // The pull toward the seed is a fixed-point iteration that overshoots (successive steps
      // reverse) where the task's curvature times its multiplier exceeds one, e.g. near a
      // singularity: halve it for the rest of the run.
      if (redundant && d.dot(d_prev) < -0.5 * d.norm() * d_prev.norm()) {
        pull = std::max(pull * 0.5, kMinPull);
      }
      d_prev = d;
      beta = pull;
    } else {
      const double scale = std::max(cur->J.squaredNorm() / M, 1e-30);
      lambda2 = std::max(lambda2 * 10, 1e-6 * scale);
      beta *= 0.5;
      if (lambda2 > 1e12 * scale) break;  // no step reduces the error: stalled
    }
  }
  // A redundant task whose null-space pull has not settled still reached the target.
  if (!converged && task_ok(cur->e) && redundant) converged = true;

  // Smallest singular value of the weighted task Jacobian at q.
  const MatJ& J = cur->J;
  if (M <= n) {
    result.sigma_min = std::sqrt(SmallestEigenvalueOfGram<M>(J.data(), n));
  } else {
    const Eigen::Matrix<double, N, N, 0, kMaxN, kMaxN> A = J.transpose() * J;
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, N, N, 0, kMaxN, kMaxN>> eig(
        A, Eigen::EigenvaluesOnly);
    result.sigma_min = std::sqrt(std::max(0.0, eig.eigenvalues()(0)));
  }
  result.position_error = cur->e.template head<3>().norm();
  if constexpr (M == 6) result.orientation_error = cur->e.template tail<3>().norm() / L;
  result.iterations = it;
  double corr2 = 0;
  for (int j = 0; j < n; ++j) {
    const double qj = cur->q(j);
    q_out[j] = qj;
    if (qj == lower(j) || qj == upper(j)) result.at_limit = true;
    corr2 += (qj - seed_in[j]) * (qj - seed_in[j]);
  }
  result.correction = std::sqrt(corr2);
  if (check_branch) {
    int signs[2];
    BranchSignsOf(chain_, cur->frames, signs);
    result.branch_changed = (seed_signs[0] != 0 && signs[0] != seed_signs[0]) ||
                            (seed_signs[1] != 0 && signs[1] != seed_signs[1]);
  }
  const bool singular = result.sigma_min < o.singular_threshold;
  if (converged) {
    result.status = singular                ? IkStatus::kSingular
                    : result.branch_changed ? IkStatus::kBranch
                                            : IkStatus::kOk;
  } else {
    result.status = result.at_limit || limit_hit ? IkStatus::kLimit
                    : singular                   ? IkStatus::kSingular
                                                 : IkStatus::kUnreachable;
  }
  return result;
}

// The fast path: Run's iteration for a pose target on 6 revolute-z joints (Newton steps, damped
// after a rejected step, the same formulas in the same order), with one fused sweep per iterate
// (axes, points, tool frame; the Jacobian from them), the unrolled LU and the unrolled smallest-
// eigenvalue routine. A step cut at a joint limit returns false: Run (its active set) then solves
// the target from the start, so the statuses are Run's.
bool InverseKinematics::RunFast(const IkTarget& target, const double* seed_in,
                                const double* start_in, double* q_out, IkResult* out) const {
  const RobotModel& model = *model_;
  const IkOptions& o = options_;
  const double L = o.orientation_weight;
  double lower[6], upper[6], seed[6];
  for (int j = 0; j < 6; ++j) {
    const Joint& joint = model.joints[j];
    lower[j] = o.respect_limits ? joint.lower : -HUGE_VAL;
    upper[j] = o.respect_limits ? joint.upper : HUGE_VAL;
    seed[j] = std::min(std::max(seed_in[j], lower[j]), upper[j]);
  }
  const Eigen::Matrix3d& Rt = target.rotation;

  auto evaluate = [&](const FastIterate* from, FastIterate* it) {
    const double* dg_dq = it->dg_dq;
    if (effective_ != nullptr) {
      effective_->Evaluate(it->q, it->x, it->dg_dq);
    } else {
      // One value per load (q was stored one joint at a time; see OneLane).
#pragma GCC unroll 6
      for (int j = 0; j < 6; ++j) it->x[j] = OneLane(it->q[j]);
    }
    int fresh[6], count = 0;  // joints whose sin/cos are computed afresh
    if (from == nullptr) {
      for (int j = 0; j < 6; ++j) {
        fresh[count++] = j;
        it->age[j] = 0;
      }
    } else {
      // The steps' sin/cos (SinCosStep), two joints at a time where SSE2 is there.
      double delta[6], sd[6], cd[6];
      for (int j = 0; j < 6; ++j) delta[j] = it->x[j] - from->x[j];
#if defined(__SSE2__)
      constexpr bool vector = true;
      SinCosStep6(delta, sd, cd);
#else
      constexpr bool vector = false;
#endif
      for (int j = 0; j < 6; ++j) {
        if (std::abs(delta[j]) <= kIncrementalStep && from->age[j] < kIncrementalRefresh) {
          if (!vector) SinCosStep(delta[j], &sd[j], &cd[j]);
          it->sin_x[j] = from->sin_x[j] * cd[j] + from->cos_x[j] * sd[j];
          it->cos_x[j] = from->cos_x[j] * cd[j] - from->sin_x[j] * sd[j];
          it->age[j] = from->age[j] + 1;
        } else {
          fresh[count++] = j;
          it->age[j] = 0;
        }
      }
    }
    SinCosOf(it->x, fresh, count, it->sin_x, it->cos_x);
    Sweep6(model, target.tool, it);
    const double* P = it->P;
    double* J = it->J;
    for (int i = 0; i < 6; ++i) {  // w_i x (P - t_i), then L w_i
      const double* w = it->w[i];
      const double d0 = P[0] - it->t[i][0], d1 = P[1] - it->t[i][1], d2 = P[2] - it->t[i][2];
      J[6 * i + 0] = w[1] * d2 - w[2] * d1;
      J[6 * i + 1] = w[2] * d0 - w[0] * d2;
      J[6 * i + 2] = w[0] * d1 - w[1] * d0;
      J[6 * i + 3] = L * w[0];
      J[6 * i + 4] = L * w[1];
      J[6 * i + 5] = L * w[2];
    }
    if (effective_ != nullptr) {  // chain rule: J dg/dq (J before it kept for the second order)
      std::copy(J, J + 36, it->Jx);
      for (int c = 0; c < 6; ++c) {
        for (int r = 0; r < 6; ++r) {
          double v = 0;
          for (int k = 0; k < 6; ++k) v += it->Jx[6 * k + r] * dg_dq[6 * c + k];
          J[6 * c + r] = v;
        }
      }
    }
    const Eigen::Map<const Eigen::Matrix3d> R(it->R);
    const Eigen::Vector3d re = L * RotationError(Rt, R);
    // The merit from the values in registers, in the sum's order (0 + e_0^2 + ... + e_5^2): read
    // back from it->e, the compiler's pairs of loads each spanned two separate stores, which the
    // processor cannot forward (a stall of the order of ten cycles each on every evaluation).
    const double e0 = target.position(0) - P[0], e1 = target.position(1) - P[1],
                 e2 = target.position(2) - P[2], e3 = re(0), e4 = re(1), e5 = re(2);
    it->e[0] = e0;
    it->e[1] = e1;
    it->e[2] = e2;
    it->e[3] = e3;
    it->e[4] = e4;
    it->e[5] = e5;
    it->merit = e0 * e0 + e1 * e1 + e2 * e2 + e3 * e3 + e4 * e4 + e5 * e5;
  };
  auto task_ok = [&](const double* e) {
    return std::sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]) <= o.position_tolerance &&
           std::sqrt(e[3] * e[3] + e[4] * e[4] + e[5] * e[5]) <= L * o.orientation_tolerance;
  };

  FastIterate iterates[2];
  FastIterate* cur = &iterates[0];
  FastIterate* trial = &iterates[1];
  for (int j = 0; j < 6; ++j) cur->q[j] = std::min(std::max(start_in[j], lower[j]), upper[j]);
  evaluate(nullptr, cur);
  int seed_signs[2] = {0, 0};
  const bool check_branch = o.check_branch && branch_defined_;
  if (check_branch) {
    if (start_in == seed_in) {
      BranchSigns6(*cur, seed_signs);
    } else {
      BranchSigns(seed, seed_signs);
    }
  }

  // Run's iteration for a square task (no null space, so the pull toward the seed stays 1 after an
  // accepted step): Newton's step by LU while steps are accepted, the damped form after a rejected
  // step; a step cut at a joint limit hands the target to Run.
  using Mat6 = Eigen::Matrix<double, 6, 6>;
  using Vec6 = Eigen::Matrix<double, 6, 1>;
  bool converged = false;
  double lambda2 = 0, beta = 1;
  int it = 0;
  for (; it < o.max_iterations; ++it) {
    if (task_ok(cur->e)) {
      converged = true;
      break;
    }
    const Eigen::Map<const Mat6> J(cur->J);
    double d[6];
    bool solved = false;
    if (lambda2 == 0) {
      const SquareLu<6> lu(cur->J, 1e-9 * std::max(MaxAbs36(cur->J), 1e-30));
      solved = lu.Ok();
      if (solved) {
        const bool mapped = effective_ != nullptr;
        CorrectedNewtonStep6(lu, cur->e, mapped ? cur->Jx : cur->J, mapped ? cur->dg_dq : nullptr,
                             L, d);
      }
    }
    if (!solved) {  // d = r + J^T (J J^T + lambda^2 I)^-1 (e - J r), r = beta (seed - q)
      Vec6 r;
      for (int j = 0; j < 6; ++j) r(j) = beta * (seed[j] - cur->q[j]);
      Mat6 A = J * J.transpose();
      const double trace = A.trace();
      A.diagonal().array() += lambda2 + (trace > 0 ? 1e-13 * trace / 6 : 1e-30);
      Vec6 y = Eigen::Map<const Vec6>(cur->e) - J * r;
      SmallCholesky<6> llt(A);
      if (!llt.Ok()) {
        A.diagonal().array() += 1e-9 * std::max(trace, 1e-30) / 6;
        llt = SmallCholesky<6>(A);
      }
      if (llt.Ok()) {
        llt.Solve(&y);
      } else {
        y.setZero();
      }
      Eigen::Map<Vec6> step(d);
      step = r + J.transpose() * y;
    }
    double scale = 1.0;
    for (int j = 0; j < 6; ++j) {
      const double a = std::abs(d[j]);
      if (a > o.max_step_revolute) scale = std::min(scale, o.max_step_revolute / a);
    }
    for (int j = 0; j < 6; ++j) {
      if (scale < 1.0) d[j] *= scale;
      const double x = cur->q[j] + d[j];
      if (o.respect_limits && (x > upper[j] || x < lower[j])) return false;  // Run's active set
      trial->q[j] = std::min(std::max(x, lower[j]), upper[j]);
    }
    double predicted = 0;  // damped steps: the linear model's merit after the step (kGoodModel)
    if (lambda2 > 0) {
      const Vec6 rest = Eigen::Map<const Vec6>(cur->e) - J * Eigen::Map<const Vec6>(d);
      predicted = rest.squaredNorm();
    }
    evaluate(cur, trial);
    if (trial->merit <= cur->merit || trial->merit <= kNullSpaceSlack * kNullSpaceSlack ||
        task_ok(trial->e)) {
      const bool model_good =
          lambda2 > 0 && cur->merit - trial->merit >= kGoodModel * (cur->merit - predicted);
      std::swap(cur, trial);
      // (Newton's steps, lambda2 = 0, stay undamped: the test, whose outcome is then 0 either
      // way, is skipped with the squared norm of J.)
      if (lambda2 > 0) {
        lambda2 *= 0.1;
        if (lambda2 < 1e-12 * Eigen::Map<const Mat6>(cur->J).squaredNorm() / 6 || model_good) {
          lambda2 = 0;
        }
      }
      beta = 1;
    } else {
      const double s2 = std::max(J.squaredNorm() / 6, 1e-30);
      lambda2 = std::max(lambda2 * 10, 1e-6 * s2);
      beta *= 0.5;
      if (lambda2 > 1e12 * s2) break;  // no step reduces the error: stalled
    }
  }

  // Every field of the result set one by one (assigned from a value-initialized temporary, the
  // copy's 16-byte loads read the temporary's separate stores: a store-forwarding stall).
  IkResult& result = *out;
  result.restarts = 0;
  result.at_limit = false;
  result.branch_changed = false;
  result.sigma_min = std::sqrt(SmallestEigenvalueOfGram<6>(cur->J, 6));
  result.position_error = std::sqrt(cur->e[0] * cur->e[0] + cur->e[1] * cur->e[1] +
                                    cur->e[2] * cur->e[2]);
  result.orientation_error =
      std::sqrt(cur->e[3] * cur->e[3] + cur->e[4] * cur->e[4] + cur->e[5] * cur->e[5]) / L;
  result.iterations = it;
  double corr2 = 0;
  for (int j = 0; j < 6; ++j) {
    const double qj = cur->q[j];
    q_out[j] = qj;
    if (qj == lower[j] || qj == upper[j]) result.at_limit = true;
    corr2 += (qj - seed_in[j]) * (qj - seed_in[j]);
  }
  result.correction = std::sqrt(corr2);
  if (check_branch) {
    int signs[2];
    BranchSigns6(*cur, signs);
    result.branch_changed = (seed_signs[0] != 0 && signs[0] != seed_signs[0]) ||
                            (seed_signs[1] != 0 && signs[1] != seed_signs[1]);
  }
  const bool singular = result.sigma_min < o.singular_threshold;
  if (converged) {
    result.status = singular                ? IkStatus::kSingular
                    : result.branch_changed ? IkStatus::kBranch
                                            : IkStatus::kOk;
  } else {  // no step was cut at a limit (those went to Run)
    result.status = result.at_limit ? IkStatus::kLimit
                    : singular      ? IkStatus::kSingular
                                    : IkStatus::kUnreachable;
  }
  return true;
}

}  // namespace lpoe
