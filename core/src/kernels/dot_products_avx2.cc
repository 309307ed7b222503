// The dot-product kernels (lpoe/kinematics/kernels.h): J^T J (SYRK) and weighted column dot products in 2 x 4
// tiles of 4-wide fused multiply-adds, for the linear solver's normal equations. The reference path
// is Eigen's rank update and matrix products (compiled for baseline x86-64: two lanes, no FMA);
// tests/kinematics/kernels_test.cc compares the two.
#include <algorithm>
#include <cstddef>

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define LPOE_KERNELS_X86 1
#else
#include <glog/logging.h>
#endif

#include "lpoe/kinematics/kernels.h"

namespace lpoe {
namespace kernels {
#ifdef LPOE_KERNELS_X86
namespace {

// out(a, b) += sum_k X_a[k] w[k] Y_b[k] (w[k] = 1 unless kWeighted) for a < nx, b < ny, over k < len:
// columns X_a = X + a ldx, Y_b = Y + b ldy contiguous, out column-major with leading dimension
// ldo. `lower`: only the entries a >= b are formed and written (nx == ny). Tiles of 2 x 4 dot
// products in 4-wide fused multiply-adds.
template <bool kWeighted>
__attribute__((target("avx2,fma"))) void DotProductsTiles(const double* X, int ldx, int nx,
                                                          const double* Y, int ldy, int ny,
                                                         const double* w, int len, bool lower,
                                                         double* out, int ldo) {
  constexpr int kTi = 2, kTj = 4;
  const int k4 = len & ~3;
  for (int b0 = 0; b0 < ny; b0 += kTj) {
    for (int a0 = lower ? b0 : 0; a0 < nx; a0 += kTi) {  // b0 is even
      // Columns past the last are read again from the last one and their results dropped.
      const double* a[kTi];
      const double* b[kTj];
      for (int t = 0; t < kTi; ++t) a[t] = X + static_cast<std::ptrdiff_t>(std::min(a0 + t, nx - 1)) * ldx;
      for (int t = 0; t < kTj; ++t) b[t] = Y + static_cast<std::ptrdiff_t>(std::min(b0 + t, ny - 1)) * ldy;
      __m256d acc[kTi][kTj];
      for (auto& row : acc) {
        for (__m256d& v : row) v = _mm256_setzero_pd();
      }
      for (int k = 0; k < k4; k += 4) {
        __m256d bv[kTj];
        for (int t = 0; t < kTj; ++t) bv[t] = _mm256_loadu_pd(b[t] + k);
        __m256d wv = _mm256_set1_pd(1.0);
        if constexpr (kWeighted) wv = _mm256_loadu_pd(w + k);
        for (int s = 0; s < kTi; ++s) {
          __m256d av = _mm256_loadu_pd(a[s] + k);
          if constexpr (kWeighted) av = _mm256_mul_pd(av, wv);
          for (int t = 0; t < kTj; ++t) acc[s][t] = _mm256_fmadd_pd(av, bv[t], acc[s][t]);
        }
      }
      for (int s = 0; s < kTi; ++s) {
        for (int t = 0; t < kTj; ++t) {
          const int i = a0 + s, j = b0 + t;
          if (i >= nx || j >= ny || (lower && i < j)) continue;
          alignas(32) double lanes[4];
          _mm256_store_pd(lanes, acc[s][t]);
          double sum = (lanes[0] + lanes[1]) + (lanes[2] + lanes[3]);
          for (int k = k4; k < len; ++k) sum += (kWeighted ? a[s][k] * w[k] : a[s][k]) * b[t][k];
          out[static_cast<std::ptrdiff_t>(j) * ldo + i] += sum;
        }
      }
    }
  }
}

}  // namespace

void DotProductsAvx2(const double* X, int ldx, int nx, const double* Y, int ldy, int ny,
                     const double* w, int len, bool lower, double* out, int ldo) {
  if (w != nullptr) {
    DotProductsTiles<true>(X, ldx, nx, Y, ldy, ny, w, len, lower, out, ldo);
  } else {
    DotProductsTiles<false>(X, ldx, nx, Y, ldy, ny, nullptr, len, lower, out, ldo);
  }
}

// The unweighted lower-triangle case with X = Y = A (flattened: the loop is specialized for it, as
// fast as a kernel of its own).
__attribute__((target("avx2,fma"), flatten)) void SyrkLowerAvx2(const double* A, int ld, int rows,
                                                                int P, double* H, int ldh) {
  DotProductsTiles<false>(A, ld, P, A, ld, P, nullptr, rows, true, H, ldh);
}
#else
void DotProductsAvx2(const double*, int, int, const double*, int, int, const double*, int, bool,
                     double*, int) {
  LOG(FATAL) << "no AVX2 kernels on this target";
}
void SyrkLowerAvx2(const double*, int, int, int, double*, int) {
  LOG(FATAL) << "no AVX2 kernels on this target";
}
#endif
}  // namespace kernels
}  // namespace lpoe
