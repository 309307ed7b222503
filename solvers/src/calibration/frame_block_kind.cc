// The local frames as a block kind (block_kind.h): one block per solved frame (every joint frame,
// and the tools some row measures; a tool no row measures is left out), 7 numbers
// [qx qy qz qw tx ty tz] with the Se3Manifold of the frame's basis B_f (right perturbation,
// eq. (19)), columns J B_f (eq. (29)). Tools are frames of this kind: they differ only in being
// left out when unmeasured, which the problem's decisions (frame_solved) already say.
#include <glog/logging.h>

#include "calibration/block_kind.h"
#include "calibration/problem_setup.h"
#include "lpoe/kinematics/se3.h"
#include "lpoe/se3_manifold.h"

namespace lpoe {
namespace internal {
namespace {

SE3d& FrameBlockOrigin(RobotModel* model, int f) {
  const int n = model->num_joints();
  return f < n ? model->joints[f].origin : model->tools[f - n].origin;
}

const SE3d& FrameBlockOrigin(const RobotModel& model, int f) {
  const int n = model.num_joints();
  return f < n ? model.joints[f].origin : model.tools[f - n].origin;
}

class FrameBlockKindImpl : public BlockKind {
 public:
  const char* name() const override { return "frame"; }
  bool joint_space() const override { return false; }

  void AppendBlocks(const ProblemSetup& setup, const RobotModel& nominal,
                    std::vector<ProblemBlock>* out) const override {
    const Parameterization& p = setup.all;
    for (int f = 0; f < nominal.num_frames(); ++f) {
      if (!setup.frame_solved[f]) continue;
      ProblemBlock b;
      b.kind = this;
      b.index = f;
      b.offset = p.offset[f];
      b.tangent_size = static_cast<int>(p.basis[f].cols());
      b.values.resize(kSe3AmbientSize);
      Se3ToArray(FrameBlockOrigin(nominal, f), b.values.data());
      b.initial = b.values;
      out->push_back(std::move(b));
    }
  }

  void AddManifold(const Parameterization& p, ProblemBlock* block,
                   ceres::Problem* problem) const override {
    // A solved frame no row reaches (cannot happen for joints with data) is added explicitly.
    problem->AddParameterBlock(block->values.data(), kSe3AmbientSize);
    if (p.basis[block->index].cols() == 0) {  // every direction left out (or a fixed tool)
      problem->SetParameterBlockConstant(block->values.data());
      return;
    }
    problem->SetManifold(block->values.data(), new Se3Manifold(p.basis[block->index]));
  }

  void Plus(const Parameterization& p, const Eigen::VectorXd& x, int offset, ProblemBlock* block,
            RobotModel* model) const override {
    // T_f <- T_f exp((B_f x_f)^) (eq. (19)) on the model's frame itself (no quaternion round
    // trip), as ApplyUpdate computes it, then the block's numbers from it.
    SE3d& T = FrameBlockOrigin(model, block->index);
    const Eigen::MatrixXd& B = p.basis[block->index];
    if (B.cols() > 0) {
      const Vector6d dp = B * x.segment(offset, B.cols());
      T = T * ExpSE3(dp);
    }
    Se3ToArray(T, block->values.data());
  }

  void WriteModel(const ProblemBlock& block, RobotModel* model) const override {
    FrameBlockOrigin(model, block.index) = Se3FromArray(block.values.data());
  }

  void WriteCoordinates(const ProblemBlock& /*block*/, Eigen::VectorXd* /*x*/) const override {}

  bool AtReductionPoint(const ProblemBlock& block) const override {
    return block.values == block.initial;
  }

  void Columns(const BlockColumnsContext& ctx, const ProblemBlock& block,
               const MeasurementSet& data, int r, Eigen::MatrixXd* J) const override {
    RowLinearization row;
    LinearizeRow(ctx, data, r, &row);
    *J = row.J.middleCols(block.offset, block.tangent_size);
  }
};

}  // namespace

const BlockKind& FrameBlockKind() {
  static const FrameBlockKindImpl kind;
  return kind;
}

}  // namespace internal
}  // namespace lpoe
