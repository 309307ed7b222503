// The joint-space terms' blocks as a block kind (block_kind.h): one block per joint-space term that
// keeps identifiable combinations, k_b numbers x_b (theta_b = basis_b x_b), Euclidean, starting at
// the request's initial values (zero otherwise); columns J_q(q_eff) Y_b(q) basis_b, the row's
// JointTermColumns (the compliance block's at the current gravity tilt when there is one).
#include "calibration/block_kind.h"
#include "calibration/problem_setup.h"

namespace lpoe {
namespace internal {
namespace {

class JointTermBlockKindImpl : public BlockKind {
 public:
  const char* name() const override { return "joint_term"; }

  void AppendBlocks(const ProblemSetup& setup, const RobotModel& /*nominal*/,
                    std::vector<ProblemBlock>* out) const override {
    const Parameterization& p = setup.all;
    const int F = p.num_frame_parameters();
    for (size_t b = 0; b < p.joint_blocks.size(); ++b) {
      const JointBlock& block = p.joint_blocks[b];
      const int k = static_cast<int>(block.basis.cols());
      if (k == 0) continue;  // no combination kept: no block
      ProblemBlock pb;
      pb.kind = this;
      pb.index = static_cast<int>(b);
      pb.offset = block.offset;
      pb.tangent_size = k;
      pb.values.resize(k);
      for (int c = 0; c < k; ++c) pb.values[c] = setup.initial_joint_state(block.offset - F + c);
      pb.initial = pb.values;
      out->push_back(std::move(pb));
    }
  }

  void Columns(const BlockColumnsContext& ctx, const ProblemBlock& block,
               const MeasurementSet& data, int r, Eigen::MatrixXd* J) const override {
    RowLinearization row;
    LinearizeRow(ctx, data, r, &row);
    const int F = ctx.p->num_frame_parameters();
    *J = row.J_q * row.R.middleCols(block.offset - F, block.tangent_size);
  }
};

}  // namespace

const BlockKind& JointTermBlockKind() {
  static const JointTermBlockKindImpl kind;
  return kind;
}

}  // namespace internal
}  // namespace lpoe
