// The one switch for the vector kernels of core/src/kernels/ (hand-written intrinsics, and
// adapters to SLEEF's vectorized sin/cos and exp) and their callers.
//
// Every kernel has a reference path, the plain C++ (templates, Eigen) that any processor runs, and
// may have a vector path for a processor feature. Which one runs is decided here, once per process:
// the processor's features (one detection, KernelsFeatures) and the environment variable
// LPOE_KERNELS: "reference" forces the reference path everywhere (so that it also runs on an AVX2
// machine, in CI: tests/kinematics/kernels_test.cc runs every kernel both ways), "auto" or unset uses what the
// processor has. docs/performance.md lists the kernels that remain and what each gains end to end.
#ifndef LPOE_KERNELS_H_
#define LPOE_KERNELS_H_

#include <vector>

namespace lpoe {

class RobotModel;

namespace kernels {

enum class Path {
  kReference,  // plain C++ only
  kAvx2Fma,    // AVX2 and FMA kernels where a kernel has one
};

// The path in force: the processor's best unless LPOE_KERNELS=reference (read at first use).
Path Active();
// Shorthand for Active() == Path::kAvx2Fma.
inline bool Avx2Fma() { return Active() == Path::kAvx2Fma; }

// What the processor supports (independent of LPOE_KERNELS).
bool ProcessorHasAvx2Fma();

// For tests (tests/kinematics/kernels_test.cc): forces `path` (kAvx2Fma only where the processor has it) until
// the returned previous path is restored with another call. Not for concurrent use.
Path SetForTesting(Path path);

// ---- The kernels that remain (each earns its place end to end: docs/performance.md). Call them only
// when Avx2Fma() is true; the callers hold the reference path.

// sin and cos of x[0..3] into s[0..3], c[0..3]: SLEEF's Sleef_sincosd4_u10avx2 (Debian's
// libsleef-dev), within 1.0 ulp of the exact values for every double (libm's are within 1 ulp too:
// the two differ by at most 2 ulp, measured 1); NaN for NaN and +-inf, sin(-0.0) = -0.0. Used by
// SinCosMany (kinematics.h).
void SinCos4Avx2(const double* x, double* s, double* c);

// exp(v[i]) in place for i < count: SLEEF's Sleef_expd4_u10avx2, within 1.0 ulp of the exact
// value (std::exp, the reference path, too: the two differ by at most 2 ulp). Arguments below -708
// give 0 (std::exp: at most 3.3e-308, subnormal below -708.4), NaN gives NaN, above about 709.78
// +inf. Used by the residual layer's kernel vector.
void ExpAvx2(double* v, int count);

// Which columns the four-row position path writes: per frame of the model, its parameter offset and
// the canonical direction (0..5) of each basis column (every joint revolute about z, every basis
// column a unit vector; built by the linear solver's MakeFourRowPlan).
struct FourRowPlan {
  bool ok = false;
  struct Frame {
    int offset = 0;
    std::vector<int> select;
  };
  std::vector<Frame> frames;
};

// Four rows (lanes) of the position Jacobian of the error model (eq. (29)) into A (column c,
// component i of lane l at A[c * ld + i * stride + l]; lanes from `valid` on get zeros) and their
// tool positions into P (P[4 i + l]). sin_q, cos_q: the model's n joint values' sines and cosines
// per lane, lane after lane (n <= kMaxGivenSinCosJoints); tool[0..3]: each lane's tool. With
// jq_column >= 0 the joint Jacobian dP/dq too, in the same layout from column jq_column on.
void PositionRows4(const RobotModel& model, const FourRowPlan& plan, const double* sin_q,
                   const double* cos_q, const int* tool, int valid, double* A, int ld, int stride,
                   double* P, int jq_column = -1);

// The per-pose products of a block written by PositionRows4 with y in column F and J_q (n columns)
// from column F + 1 (lanes k in [0, stride)), into rows row + k of h = J_q^T y, G = J_q^T J_q (lower
// triangle, column j (j + 1) / 2 + i) and C = A_frames^T J_q (column j F + f), leading dimension
// ldo; G and C only with `blocks`.
void PoseProducts4(const double* A, int ld, int stride, int F, int n, bool blocks, double* h,
                   double* G, double* C, int ldo, int row);

// H += A^T A, lower triangle only: A is rows x P column-major with leading dimension ld, H is
// P x P column-major with leading dimension ldh (2 x 4 tiles of dot products of A's contiguous
// columns in 4-wide fused multiply-adds; about twice Eigen's SSE2 rank update at P = 27). Sums in
// another order than Eigen's: the two differ in the last bits.
void SyrkLowerAvx2(const double* A, int ld, int rows, int P, double* H, int ldh);

// out(a, b) += sum_k X_a[k] w[k] Y_b[k] (w null: w[k] = 1) for a < nx, b < ny, k < len: columns
// X_a = X + a ldx and Y_b = Y + b ldy contiguous, out column-major with leading dimension ldo.
// `lower`: only the entries a >= b are formed and written (nx == ny).
void DotProductsAvx2(const double* X, int ldx, int nx, const double* Y, int ldy, int ny,
                     const double* w, int len, bool lower, double* out, int ldo);

}  // namespace kernels
}  // namespace lpoe

#endif  // LPOE_KERNELS_H_
