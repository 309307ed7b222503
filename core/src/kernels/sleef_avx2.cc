// SinCos4Avx2 and ExpAvx2 (lpoe/kinematics/kernels.h): thin adapters to SLEEF's AVX2 functions (Debian's
// libsleef-dev), the vectorized libm the project uses instead of polynomial code of its own.
//   sin, cos: Sleef_sincosd4_u10avx2, within 1.0 ulp of the exact value for every double
//             (Payne-Hanek reduction for large arguments); NaN for NaN and +-inf; sin(-0.0) = -0.0.
//   exp:      Sleef_expd4_u10avx2, within 1.0 ulp (subnormal results included); +inf above about
//             709.78, NaN for NaN. Arguments below -708 then give 0 here (the kernel of a far
//             point: no subnormal operands in the products that follow).
// The reference paths (libm's sincos, std::exp) stay with the callers; tests/kinematics/kernels_test.cc runs
// both. This file is compiled with -mavx2 -mfma (LPOE_SLEEF_ADAPTER_FLAGS: SLEEF declares its AVX2
// functions only where __AVX__ is defined), so it must not define any inline function or template
// shared with other files: the linker could keep this file's AVX2 copy for every caller.
#include "lpoe/kinematics/kernels.h"

#if defined(__x86_64__)
#if !defined(__AVX2__) || !defined(__FMA__)
#error "compile this file with -mavx2 -mfma (LPOE_SLEEF_ADAPTER_FLAGS in CMakeLists.txt)"
#endif
#include <immintrin.h>
#include <sleef.h>

namespace lpoe {
namespace kernels {
namespace {

constexpr double kExpFlushBelow = -708.0;

inline void ExpFourLanes(double* at) {
  const __m256d x = _mm256_loadu_pd(at);
  const __m256d below = _mm256_cmp_pd(x, _mm256_set1_pd(kExpFlushBelow), _CMP_LT_OQ);
  _mm256_storeu_pd(at, _mm256_andnot_pd(below, Sleef_expd4_u10avx2(x)));
}

}  // namespace

void SinCos4Avx2(const double* x, double* s, double* c) {
  const Sleef___m256d_2 sc = Sleef_sincosd4_u10avx2(_mm256_loadu_pd(x));
  _mm256_storeu_pd(s, sc.x);
  _mm256_storeu_pd(c, sc.y);
}

void ExpAvx2(double* v, int count) {
  int i = 0;
  for (; i + 4 <= count; i += 4) ExpFourLanes(v + i);
  if (i < count) {  // the last one to three through the same lanes
    double pad[4] = {0.0, 0.0, 0.0, 0.0};
    for (int k = i; k < count; ++k) pad[k - i] = v[k];
    ExpFourLanes(pad);
    for (int k = i; k < count; ++k) v[k] = pad[k - i];
  }
}

}  // namespace kernels
}  // namespace lpoe

#else
#include <glog/logging.h>

namespace lpoe {
namespace kernels {
void SinCos4Avx2(const double*, double*, double*) { LOG(FATAL) << "no AVX2 kernels here"; }
void ExpAvx2(double*, int) { LOG(FATAL) << "no AVX2 kernels here"; }
}  // namespace kernels
}  // namespace lpoe
#endif
