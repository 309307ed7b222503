// The exponential kernel (lpoe/kernels.h): exp of a vector in 4-wide AVX2/FMA lanes, for the
// residual layer's kernel vector (m exponentials a predicted point: its hot spot). Cody-Waite
// reduction x = n ln2 + r, |r| <= ln2 / 2, a degree-13 Taylor polynomial of exp(r) (truncation
// below 1e-17 relative) and 2^n from the exponent bits. Arguments below -708 give 0 (the kernel of
// a far point), above 709 are clamped. The reference path is std::exp; tests/kernels_test.cc
// compares the two (within a few units in the last place).
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define LPOE_KERNELS_X86 1
#else
#include <glog/logging.h>
#endif

#include "lpoe/kernels.h"

namespace lpoe {
namespace kernels {
#ifdef LPOE_KERNELS_X86
namespace {

constexpr double kLog2e = 1.4426950408889634074;
constexpr double kLn2Hi = 6.93145751953125e-1, kLn2Lo = 1.42860682030941723212e-6;
constexpr double kMagic = 6755399441055744.0;  // 1.5 * 2^52: rounds to an integer in the low bits
constexpr double kLow = -708.0, kHigh = 709.0;
constexpr double kInvFactorial[14] = {1.0,
                                      1.0,
                                      1.0 / 2,
                                      1.0 / 6,
                                      1.0 / 24,
                                      1.0 / 120,
                                      1.0 / 720,
                                      1.0 / 5040,
                                      1.0 / 40320,
                                      1.0 / 362880,
                                      1.0 / 3628800,
                                      1.0 / 39916800,
                                      1.0 / 479001600,
                                      1.0 / 6227020800.0};

__attribute__((target("avx2,fma"))) inline void FourLanes(double* at) {
  const __m256d low = _mm256_set1_pd(kLow), high = _mm256_set1_pd(kHigh);
  const __m256d magic = _mm256_set1_pd(kMagic);
  __m256d x = _mm256_loadu_pd(at);
  const __m256d under = _mm256_cmp_pd(x, low, _CMP_LT_OQ);
  x = _mm256_min_pd(_mm256_max_pd(x, low), high);
  const __m256d t = _mm256_fmadd_pd(x, _mm256_set1_pd(kLog2e), magic);
  const __m256d n = _mm256_sub_pd(t, magic);
  const __m256d r = _mm256_fnmadd_pd(n, _mm256_set1_pd(kLn2Lo),
                                     _mm256_fnmadd_pd(n, _mm256_set1_pd(kLn2Hi), x));
  __m256d p = _mm256_set1_pd(kInvFactorial[13]);
  for (int k = 12; k >= 0; --k) p = _mm256_fmadd_pd(p, r, _mm256_set1_pd(kInvFactorial[k]));
  const __m256i exponent = _mm256_slli_epi64(
      _mm256_add_epi64(_mm256_sub_epi64(_mm256_castpd_si256(t),
                                        _mm256_set1_epi64x(0x4338000000000000LL)),
                       _mm256_set1_epi64x(1023)),
      52);
  p = _mm256_mul_pd(p, _mm256_castsi256_pd(exponent));
  _mm256_storeu_pd(at, _mm256_andnot_pd(under, p));
}

}  // namespace

__attribute__((target("avx2,fma"))) void ExpAvx2(double* v, int count) {
  int i = 0;
  for (; i + 4 <= count; i += 4) FourLanes(v + i);
  if (i < count) {  // the last one to three through the same lanes
    double pad[4] = {0.0, 0.0, 0.0, 0.0};
    for (int k = i; k < count; ++k) pad[k - i] = v[k];
    FourLanes(pad);
    for (int k = i; k < count; ++k) v[k] = pad[k - i];
  }
}
#else
void ExpAvx2(double*, int) { LOG(FATAL) << "ExpAvx2 without x86-64"; }
#endif

}  // namespace kernels
}  // namespace lpoe
