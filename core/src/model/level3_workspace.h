// Eigen's triangular solve, triangular product and general matrix product on dense blocks, with
// their packing buffers kept between calls (internal to the library; used by the residual layer's
// likelihood and the planning selector's updates).
//
// Eigen's level-3 kernels pack their operands into two buffers sized by the cache blocking of the
// call (kc x mc and kc x cols doubles). Above EIGEN_STACK_ALLOCATION_LIMIT (128 KB, a few hundred
// rows) each call allocates them afresh and frees them on return. The likelihood's hyperparameter
// search makes hundreds of such calls per fit, each on matrices of the same size: about 10,000
// allocations of 100-500 KB in one residual-layer test. Under AddressSanitizer every one of them is
// its own mapping (mmap, page faults on every page, munmap), a third of that test's run time
// (docs/testing.md).
//
// The planning selector's rank updates multiply each chunk of 256 candidates' rows by a P x r
// matrix, hundreds of times per plan, with buffers of the same kind.
//
// These functions call the very kernels Eigen's expressions dispatch to, with the blocking sizes
// those expressions compute (gemm_blocking_space with the same rows, columns, depth and one
// thread), so each performs the same operations in the same order as the expression named beside
// it and the results are bit-identical (tests/model/residual_layer_test.cc, Level3Workspace.*); only
// the buffers come from the workspace, grown to the largest size asked for and kept.
// This uses Eigen's internal interface of Eigen 3.4 (Debian 12's libeigen3-dev).
#ifndef LPOE_CORE_MODEL_LEVEL3_WORKSPACE_H_
#define LPOE_CORE_MODEL_LEVEL3_WORKSPACE_H_

#include <type_traits>

#include <Eigen/Core>

namespace lpoe {
namespace internal {

static_assert(EIGEN_WORLD_VERSION == 3 && EIGEN_MAJOR_VERSION == 4,
              "level3_workspace.h calls Eigen 3.4's internal level-3 kernels");

class Level3Workspace {
 public:
  // other := L^-1 other, L the lower triangle of `tri` (square):
  // tri.triangularView<Eigen::Lower>().solveInPlace(other).
  template <typename Tri, typename Other>
  void LowerSolveInPlace(const Tri& tri, Other&& other) {
    SolveInPlace<Eigen::Lower, Eigen::ColMajor>(tri.data(), tri.outerStride(), tri.rows(), other);
  }

  // other := L^-T other, L the lower triangle of `tri`:
  // tri.transpose().triangularView<Eigen::Upper>().solveInPlace(other).
  template <typename Tri, typename Other>
  void LowerTransposeSolveInPlace(const Tri& tri, Other&& other) {
    SolveInPlace<Eigen::Upper, Eigen::RowMajor>(tri.data(), tri.outerStride(), tri.rows(), other);
  }

  // dst := U^T rhs, U^T the upper triangle of lower^T (lower square, its strict upper triangle not
  // read): dst.noalias() = lower.transpose().triangularView<Eigen::Upper>() * rhs.
  template <typename Lower, typename Rhs, typename Dst>
  void LowerTransposeTimes(const Lower& lower, const Rhs& rhs, Dst&& dst) {
    static_assert(!(Eigen::internal::traits<std::decay_t<Rhs>>::Flags & Eigen::RowMajorBit) &&
                      !(Eigen::internal::traits<std::decay_t<Dst>>::Flags & Eigen::RowMajorBit),
                  "column-major operands");
    eigen_assert(lower.rows() == lower.cols() && rhs.rows() == lower.rows() &&
                 dst.rows() == lower.rows() && dst.cols() == rhs.cols() && rhs.innerStride() == 1 &&
                 dst.innerStride() == 1);
    dst.setZero();  // as Eigen's product evaluator does before adding the product
    if (lower.rows() == 0 || rhs.cols() == 0) return;
    const Eigen::Index rows = lower.rows(), cols = rhs.cols(), depth = lower.rows();
    Blocking blocking(rows, cols, depth, this);
    Eigen::internal::product_triangular_matrix_matrix<
        double, Eigen::Index, Eigen::Upper, true, Eigen::RowMajor, false, Eigen::ColMajor, false,
        Eigen::ColMajor, 1>::run(rows, cols, depth, lower.data(), lower.outerStride(), rhs.data(),
                                 rhs.outerStride(), dst.data(), 1, dst.outerStride(), 1.0,
                                 blocking);
  }

  // *dst := lhs * rhs, as `*dst = lhs * rhs` evaluates it (dst column-major, lhs and rhs of either
  // storage order, inner stride 1). Where Eigen runs its blocked matrix product the packing buffers
  // come from the workspace; the sizes it evaluates otherwise (a coefficient-based product when
  // depth + rows + columns < EIGEN_GEMM_TO_COEFFBASED_THRESHOLD, matrix-vector for one row or
  // column, an empty operand) are left to the expression itself.
  template <typename Lhs, typename Rhs>
  void Product(const Lhs& lhs, const Rhs& rhs, Eigen::MatrixXd* dst) {
    using LhsTraits = Eigen::internal::traits<std::decay_t<Lhs>>;
    using RhsTraits = Eigen::internal::traits<std::decay_t<Rhs>>;
    constexpr int kLhsOrder = (LhsTraits::Flags & Eigen::RowMajorBit) ? Eigen::RowMajor : Eigen::ColMajor;
    constexpr int kRhsOrder = (RhsTraits::Flags & Eigen::RowMajorBit) ? Eigen::RowMajor : Eigen::ColMajor;
    eigen_assert(lhs.cols() == rhs.rows() && lhs.innerStride() == 1 && rhs.innerStride() == 1);
    const Eigen::Index rows = lhs.rows(), cols = rhs.cols(), depth = lhs.cols();
#ifdef EIGEN_HAS_OPENMP
    constexpr bool kEigenParallel = true;  // Eigen may split its product over OpenMP's threads
#else
    constexpr bool kEigenParallel = false;
#endif
    if (kEigenParallel || depth + rows + cols < EIGEN_GEMM_TO_COEFFBASED_THRESHOLD || rows <= 1 ||
        cols <= 1 || depth == 0) {
      dst->noalias() = lhs * rhs;
      return;
    }
    dst->resize(rows, cols);
    dst->setZero();  // as Eigen's product evaluator does before adding the product
    GemmBlocking blocking(rows, cols, depth, this);
    Eigen::internal::general_matrix_matrix_product<Eigen::Index, double, kLhsOrder, false, double,
                                                   kRhsOrder, false, Eigen::ColMajor, 1>::
        run(rows, cols, depth, lhs.data(), lhs.outerStride(), rhs.data(), rhs.outerStride(),
            dst->data(), 1, dst->outerStride(), 1.0, blocking, nullptr);
  }

 private:
  static double* Grow(Eigen::VectorXd* buffer, Eigen::Index size) {
    if (buffer->size() < size) buffer->resize(size);
    return buffer->data();
  }

  // The blocking Eigen's general product constructs (KcFactor 1, one thread, L3 blocking), lending
  // the workspace's buffers (kc x mc and kc x nc doubles).
  using GemmBlockingBase = Eigen::internal::gemm_blocking_space<Eigen::ColMajor, double, double,
                                                                Eigen::Dynamic, Eigen::Dynamic,
                                                                Eigen::Dynamic, 1>;
  class GemmBlocking : public GemmBlockingBase {
   public:
    GemmBlocking(Eigen::Index rows, Eigen::Index cols, Eigen::Index depth, Level3Workspace* w)
        : GemmBlockingBase(rows, cols, depth, 1, true) {
      this->m_blockA = Grow(&w->a_, this->kc() * this->mc());
      this->m_blockB = Grow(&w->b_, this->kc() * this->nc());
    }
    ~GemmBlocking() {
      this->m_blockA = nullptr;
      this->m_blockB = nullptr;
    }
    GemmBlocking(const GemmBlocking&) = delete;
    GemmBlocking& operator=(const GemmBlocking&) = delete;
  };

  // The blocking Eigen's triangular expressions construct (KcFactor 4, one thread, no L3
  // blocking), lending the workspace's buffers; handed back (not freed) on destruction.
  using BlockingBase = Eigen::internal::gemm_blocking_space<Eigen::ColMajor, double, double,
                                                            Eigen::Dynamic, Eigen::Dynamic,
                                                            Eigen::Dynamic, 4>;
  class Blocking : public BlockingBase {
   public:
    Blocking(Eigen::Index rows, Eigen::Index cols, Eigen::Index depth, Level3Workspace* w)
        : BlockingBase(rows, cols, depth, 1, false) {
      // The kernels use kc x min(rows, mc) doubles of A and at most kc x cols + one aligned
      // packet of B.
      this->m_blockA = Grow(&w->a_, this->kc() * this->mc());
      this->m_blockB = Grow(&w->b_, this->kc() * cols + EIGEN_MAX_ALIGN_BYTES / sizeof(double));
    }
    ~Blocking() {
      this->m_blockA = nullptr;
      this->m_blockB = nullptr;
    }
    Blocking(const Blocking&) = delete;
    Blocking& operator=(const Blocking&) = delete;
  };

  template <int Mode, int TriStorage, typename Other>
  void SolveInPlace(const double* tri, Eigen::Index tri_stride, Eigen::Index size, Other& other) {
    static_assert(!(Eigen::internal::traits<std::decay_t<Other>>::Flags & Eigen::RowMajorBit),
                  "column-major right-hand side");
    eigen_assert(other.rows() == size && other.innerStride() == 1);
    if (size == 0 || other.cols() == 0) return;
    Blocking blocking(other.rows(), other.cols(), size, this);
    Eigen::internal::triangular_solve_matrix<double, Eigen::Index, Eigen::OnTheLeft, Mode, false,
                                             TriStorage, Eigen::ColMajor, 1>::run(
        size, other.cols(), tri, tri_stride, other.data(), 1, other.outerStride(), blocking);
  }

  Eigen::VectorXd a_, b_;
};

}  // namespace internal
}  // namespace lpoe

#endif  // LPOE_CORE_MODEL_LEVEL3_WORKSPACE_H_
