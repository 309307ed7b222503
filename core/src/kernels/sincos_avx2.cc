// SinCos4Avx2 (lpoe/kernels.h): sin and cos of four values in one polynomial evaluation, for
// SinCosMany (kinematics.h) on processors with AVX2 and FMA. The reference path is libm's sincos per
// value; tests/kernels_test.cc compares the two (within 2 ulp).
#include <cmath>

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define LPOE_KERNELS_X86 1
#else
#include <glog/logging.h>
#endif

#include "lpoe/kernels.h"
#include "lpoe/kinematics.h"

namespace lpoe {
namespace kernels {
#ifdef LPOE_KERNELS_X86

// Largest |x| the vector path reduces: k = round(x 2 / pi) then has at most 19 bits, so that k times
// each 33-bit part of pi/2 is exact (fdlibm's medium-size reduction, __ieee754_rem_pio2).
namespace {
constexpr double kMaxVectorArgument = 524288.0;  // 2^19
}  // namespace

// sin and cos of x[0..3] into s, c; lanes beyond kMaxVectorArgument (or non-finite) are recomputed
// with libm.
__attribute__((target("avx2,fma"))) void SinCos4Avx2(const double* x, double* s, double* c) {
  // pi/2 in three parts of 33 bits and the rest (fdlibm's pio2_1, pio2_2, pio2_3, pio2_3t).
  const __m256d p1 = _mm256_set1_pd(1.57079632673412561417e+00);
  const __m256d p2 = _mm256_set1_pd(6.07710050630396597660e-11);
  const __m256d p3 = _mm256_set1_pd(2.02226624871116645580e-21);
  const __m256d p3t = _mm256_set1_pd(8.47842766036889956997e-32);
  const __m256d v = _mm256_loadu_pd(x);
  const __m256d k = _mm256_round_pd(_mm256_mul_pd(v, _mm256_set1_pd(6.36619772367581382433e-01)),
                                    _MM_FROUND_TO_NEAREST_INT | _MM_FROUND_NO_EXC);
  // r = x - k pi/2: the first two products are exact and the first difference too (Sterbenz).
  __m256d r = _mm256_fnmadd_pd(k, p1, v);
  r = _mm256_fnmadd_pd(k, p2, r);
  r = _mm256_fnmadd_pd(k, p3, r);
  r = _mm256_fnmadd_pd(k, p3t, r);
  // fdlibm's __kernel_sin and __kernel_cos (no tail) on r in [-pi/4, pi/4].
  const __m256d z = _mm256_mul_pd(r, r);
  __m256d ps = _mm256_set1_pd(1.58969099521155010221e-10);
  ps = _mm256_fmadd_pd(ps, z, _mm256_set1_pd(-2.50507602534068634195e-08));
  ps = _mm256_fmadd_pd(ps, z, _mm256_set1_pd(2.75573137070700676789e-06));
  ps = _mm256_fmadd_pd(ps, z, _mm256_set1_pd(-1.98412698298579493134e-04));
  ps = _mm256_fmadd_pd(ps, z, _mm256_set1_pd(8.33333333332248946124e-03));
  ps = _mm256_fmadd_pd(ps, z, _mm256_set1_pd(-1.66666666666666324348e-01));
  const __m256d sin_r = _mm256_fmadd_pd(_mm256_mul_pd(z, r), ps, r);
  __m256d pc = _mm256_set1_pd(-1.13596475577881948265e-11);
  pc = _mm256_fmadd_pd(pc, z, _mm256_set1_pd(2.08757232129817482790e-09));
  pc = _mm256_fmadd_pd(pc, z, _mm256_set1_pd(-2.75573143513906633035e-07));
  pc = _mm256_fmadd_pd(pc, z, _mm256_set1_pd(2.48015872894767294178e-05));
  pc = _mm256_fmadd_pd(pc, z, _mm256_set1_pd(-1.38888888888741095749e-03));
  pc = _mm256_fmadd_pd(pc, z, _mm256_set1_pd(4.16666666666666019037e-02));
  const __m256d one = _mm256_set1_pd(1.0);
  const __m256d hz = _mm256_mul_pd(_mm256_set1_pd(0.5), z);
  const __m256d w = _mm256_sub_pd(one, hz);
  // cos r = w + ((1 - w) - hz + z^2 pc), the rounding of 1 - hz recovered.
  const __m256d cos_r = _mm256_add_pd(
      w, _mm256_fmadd_pd(_mm256_mul_pd(z, z), pc, _mm256_sub_pd(_mm256_sub_pd(one, w), hz)));
  // Quadrant n = k mod 4: (sin, cos) = (S, C), (C, -S), (-S, -C), (-C, S).
  const __m256i n = _mm256_cvtepi32_epi64(_mm256_cvtpd_epi32(k));
  const __m256d swap =
      _mm256_castsi256_pd(_mm256_cmpeq_epi64(_mm256_and_si256(n, _mm256_set1_epi64x(1)),
                                             _mm256_set1_epi64x(1)));
  const __m256i two = _mm256_set1_epi64x(2);
  const __m256d sin_sign = _mm256_castsi256_pd(_mm256_slli_epi64(_mm256_and_si256(n, two), 62));
  const __m256d cos_sign = _mm256_castsi256_pd(
      _mm256_slli_epi64(_mm256_and_si256(_mm256_add_epi64(n, _mm256_set1_epi64x(1)), two), 62));
  _mm256_storeu_pd(s, _mm256_xor_pd(_mm256_blendv_pd(sin_r, cos_r, swap), sin_sign));
  _mm256_storeu_pd(c, _mm256_xor_pd(_mm256_blendv_pd(cos_r, sin_r, swap), cos_sign));
  const __m256d abs_v = _mm256_andnot_pd(_mm256_set1_pd(-0.0), v);
  const int in_range =
      _mm256_movemask_pd(_mm256_cmp_pd(abs_v, _mm256_set1_pd(kMaxVectorArgument), _CMP_LE_OQ));
  if (in_range != 0xF) {
    for (int l = 0; l < 4; ++l) {
      if (!(in_range & (1 << l))) SinCos(x[l], &s[l], &c[l]);
    }
  }
}

#else
void SinCos4Avx2(const double*, double*, double*) { LOG(FATAL) << "no AVX2 kernels on this target"; }
#endif
}  // namespace kernels
}  // namespace lpoe
