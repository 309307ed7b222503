// A row's joint-term columns (joint_term_columns.h).
#include "linearization/joint_term_columns.h"

#include <glog/logging.h>

#include "linearization/normal_equations.h"
#include "lpoe/terms/joint_term.h"

namespace lpoe {
namespace internal {

JointTermColumns::JointTermColumns(const Parameterization& p, int num_joints, int num_columns)
    : n_(num_joints) {
  int column = 0;
  for (const JointBlock& block : p.joint_blocks) {
    const int kb = static_cast<int>(block.basis.cols());
    if (kb == 0) continue;
    CHECK_EQ(block.term->num_joints(), n_) << block.term->name();
    CHECK_EQ(block.basis.rows(), block.term->num_parameters()) << block.term->name();
    blocks_.push_back({&block, column, block.basis.rows() == kb && block.basis.isIdentity(0),
                       block.basis.transpose(),
                       Eigen::MatrixXd(n_, block.term->num_parameters())});
    column += kb;
  }
  columns_ = num_columns < 0 ? column : num_columns;
  CHECK_GE(columns_, column);
  R_t_.setZero(columns_, n_);
}

void JointTermColumns::UseSlots(const JointSpaceRegressors* slots) {
  slots_ = slots;
  if (slots == nullptr) {
    slot_basis_t_.resize(0, 0);
    return;
  }
  CHECK_EQ(slots->num_joints, n_);
  CHECK_LE(slots->slot_basis.cols(), columns_);
  slot_basis_t_ = slots->slot_basis.transpose();
}

void JointTermColumns::Evaluate(int r, const double* q, Eigen::MatrixXd* R) {
  if (slots_ != nullptr) {
    const JointSpaceRegressors& s = *slots_;
    R_t_.setZero();
    const Eigen::Index k = slot_basis_t_.rows();
    for (int j = 0; j < n_; ++j) {
      for (int t = s.slot_begin[j]; t < s.slot_begin[j + 1]; ++t) {
        const double v = s.values(t, r);
        if (v != 0) R_t_.col(j).head(k) += v * slot_basis_t_.col(t);
      }
    }
    *R = R_t_.transpose();
    return;
  }
  for (Block& b : blocks_) {
    b.block->term->Regressor(q, b.Y.data());
    const int kb = static_cast<int>(b.basis_t.rows());
    auto Rt = R_t_.middleRows(b.column, kb);
    if (b.identity) {
      Rt = b.Y.transpose();
      continue;
    }
    Rt.setZero();
    for (int c = 0; c < b.Y.cols(); ++c) {
      for (int j = 0; j < n_; ++j) {
        const double y = b.Y(j, c);
        if (y != 0) Rt.col(j) += y * b.basis_t.col(c);
      }
    }
  }
  // Columns past the blocks' (the block kinds') stay zero: set once in the constructor.
  *R = R_t_.transpose();
}

}  // namespace internal
}  // namespace lpoe
