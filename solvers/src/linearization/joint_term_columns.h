// A row's joint-term columns: R = [Y_b(q) basis_b] over the joint blocks (n x K), the one place
// both solvers take them from (the Ceres problem's residuals, CalibrationProblem::AddTo; the
// linear assembly, NormalEquationsOf and JointRegressorRows).
#ifndef LPOE_SOLVERS_CALIBRATION_JOINT_TERM_COLUMNS_H_
#define LPOE_SOLVERS_CALIBRATION_JOINT_TERM_COLUMNS_H_

#include <vector>

#include <Eigen/Core>

#include "lpoe/model/parameterization.h"

namespace lpoe {
namespace internal {

struct JointSpaceRegressors;

// R = [Y_b(q) basis_b], the blocks in order (a block without columns adds none), then zero columns
// up to num_columns (the block kinds', set at the current values elsewhere: block_kind.h). Y_b(q)
// is data (the recorded joint values), so R is too. Built once per call and thread (the bases
// transposed, which of them are the identity, a regressor buffer per block): Evaluate allocates
// nothing but R on its first call (none when R has its size).
//
// Y_b basis_b is formed over the non-zero entries of Y_b only: a physical regressor is sparse (a
// joint's offset depends on its own parameters), and a dense product per row would repack the
// basis every time. It is accumulated transposed, on basis_b^T, so that the inner loop runs over
// contiguous memory. An identity basis copies Y_b: the same numbers, since y * 1 + 0 = y.
// With the reduction's slots (JointSpaceRegressors: the rows' non-zero regressor entries, stored
// once) row r's columns are read from them instead: joint j's row of R is
// sum_{s in j} values(s, r) slot_basis row s, the same sums in the same order.
class JointTermColumns {
 public:
  JointTermColumns() = default;
  // p's joint blocks for num_joints joints; num_columns < 0: the blocks' columns alone. It keeps
  // pointers to p's blocks: p outlives it.
  JointTermColumns(const Parameterization& p, int num_joints, int num_columns = -1);
  // Read the rows' columns from these slots (null: from the terms' regressors). They must be of
  // this parameterization's joint blocks (slot_basis num_slots x the blocks' columns).
  void UseSlots(const JointSpaceRegressors* slots);

  int num_joints() const { return n_; }
  int num_columns() const { return columns_; }
  // Row r's columns (q: its recorded joint values; r: its index in the slots' rows) into R,
  // resized to num_joints x num_columns.
  void Evaluate(int r, const double* q, Eigen::MatrixXd* R);

 private:
  struct Block {
    const JointBlock* block;
    int column;     // first column in R
    bool identity;  // basis is the identity
    Eigen::MatrixXd basis_t;
    Eigen::MatrixXd Y;  // n x P_b: the term's regressor at the row (its own: no resize per row)
  };
  int n_ = 0;
  int columns_ = 0;
  std::vector<Block> blocks_;  // the blocks with columns
  const JointSpaceRegressors* slots_ = nullptr;
  Eigen::MatrixXd slot_basis_t_;  // slots_->slot_basis^T: slot s's row contiguous
  Eigen::MatrixXd R_t_;           // R transposed, accumulated first
};

}  // namespace internal
}  // namespace lpoe

#endif  // LPOE_SOLVERS_CALIBRATION_JOINT_TERM_COLUMNS_H_
