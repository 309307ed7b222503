// Internal to lpoe_solvers: the registry of parameter-block kinds (docs/architecture.md, "Where to
// add a block kind"). Every parameter block of a CalibrationProblem is of one kind of this registry,
// in registry order (block_kind_registry.inc): the local frames (joints, then the tools some row
// measures: frame_block_kind.cc), the joint-space terms' blocks (joint_term_block_kind.cc), the
// gravity tilt (gravity_tilt.cc). Every kind supplies, through this one interface:
//
//   - its blocks in a problem (offset in the numbering, tangent size, start values);
//   - its manifold in a Ceres problem (none: Euclidean), its step (Update) and where its values go
//     (the model's frames, or the joint-space coordinates);
//   - its columns of a row given the current values (Columns: the frames' J B_f, a joint-space
//     term's J_q Y_b(q) basis_b, the tilt's J_q d(dq)/dt). The linear solver's normal equations do
//     not call it per row: they are assembled in bulk for every kind at once (NormalEquationsOf,
//     the frames' optimised assembly with the joint-space columns from JointTermColumns), the same
//     columns; Columns is each kind's statement of them (tested against central differences).
//
// A kind of an effect bilinear with a joint-space term (lpoe/terms/bilinear_term.h: the gravity
// tilt) derives from BilinearBlockKind below, which does everything the solvers need from the
// effect alone: its blocks (the parameterization's bilinear_blocks made from the request's
// bilinear_effects of the kind's name), its columns for both solvers (BilinearJointColumns), the
// partner check. The kind itself supplies:
//
//   - its name (the effect's, the `--joint_errors` item that asks for it) and its partner term;
//   - its entry in the result (FillResult, ScaleToAPosteriori);
//   - its identifiability rule at a solution without it (Identifiable; BilinearInformation does
//     the arithmetic);
//   - the pipeline's staged solve: the effect on the start model, its entry after the stages, its
//     values in the calibrated model (MakeEffect, Record, ApplyToModel).
//
// Adding a kind: one source file that defines the effect, a BlockKind and a function returning it,
// plus one line in block_kind_registry.inc.
#ifndef LPOE_SOLVERS_SRC_CALIBRATION_BLOCK_KIND_H_
#define LPOE_SOLVERS_SRC_CALIBRATION_BLOCK_KIND_H_

#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <ceres/problem.h>

#include "lpoe/calibration.h"
#include "lpoe/terms/bilinear_term.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/measurement_residual.h"
#include "lpoe/measurements/measurements.h"
#include "lpoe/model/parameterization.h"
#include "lpoe/problem_builder.h"
#include "lpoe/problem_options.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/status.h"

namespace lpoe {
namespace internal {

struct ProblemSetup;  // problem_setup.h
class BilinearBlockKind;

// What a kind's Columns needs of the problem at its current values.
struct BlockColumnsContext {
  const RobotModel* model = nullptr;        // the model at the current values (Model())
  const Parameterization* p = nullptr;      // parameterization() (every frame's basis)
  const Eigen::VectorXd* joint_state = nullptr;  // JointState()
  bool use_orientation = false;
  double orientation_weight = 1000.0;
};

class BlockKind {
 public:
  virtual ~BlockKind() = default;

  // The kind's name: for a kind a calibration asks for, the `--joint_errors` item that asks for it
  // ("tilt"); "frame" and "joint_term" otherwise.
  virtual const char* name() const = 0;
  // What messages call it ("gravity tilt"); the name by default.
  virtual const char* description() const { return name(); }

  // --- Every kind: its blocks in a CalibrationProblem ---

  // Appends the kind's blocks of a problem with these decisions to `out` (kind, index, offset in
  // setup.all's numbering, tangent size, start values; solved_offset is set by the caller).
  virtual void AppendBlocks(const ProblemSetup& setup, const RobotModel& nominal,
                            std::vector<ProblemBlock>* out) const = 0;
  // A joint-space block (the residuals' joint-space parameters after the chain's frames, part of
  // JointState()); false: a frame of the chain.
  virtual bool joint_space() const { return true; }
  // Gives the block its manifold in `problem` (after the residual blocks were added), or holds it
  // constant. Default (Euclidean): nothing.
  virtual void AddManifold(const Parameterization& p, ProblemBlock* block,
                           ceres::Problem* problem) const;
  // Applies the step x.segment(offset, block->tangent_size) to the block's values; `model` is the
  // model the values stand for, exactly (CalibrationProblem::Model()), and a kind that lives in
  // the model (a frame) applies the step to it too, so that the model is the step's result without
  // a round trip through the block's numbers. Default: added to the values.
  virtual void Plus(const Parameterization& p, const Eigen::VectorXd& x, int offset,
                    ProblemBlock* block, RobotModel* model) const;
  // Writes the block's values into `model` (a frame: its origin from the 7 numbers). Default:
  // nothing.
  virtual void WriteModel(const ProblemBlock& block, RobotModel* model) const;
  // Writes the block's coordinates into `x` (num_parameters, at block.offset). Default: the values.
  virtual void WriteCoordinates(const ProblemBlock& block, Eigen::VectorXd* x) const;
  // Whether the block is where the reduction's normal equations were taken (the frames at their
  // start, the joint-space coordinates zero). Default: every value zero.
  virtual bool AtReductionPoint(const ProblemBlock& block) const;
  // The block's columns of row `r` of `data` at the current values (ctx): rows = the row's
  // residuals (3 position, 6 pose: the solvers' residual, unweighted by sigma), block.tangent_size
  // columns, into J (resized).
  virtual void Columns(const BlockColumnsContext& ctx, const ProblemBlock& block,
                       const MeasurementSet& data, int r, Eigen::MatrixXd* J) const = 0;

  // The kind as a bilinear effect's kind (BilinearBlockKind, below: its request, its result entry,
  // its rule and the pipeline's staged solve); nullptr for the frames' and the terms' kinds.
  virtual const BilinearBlockKind* bilinear() const { return nullptr; }
};

// The kinds of effects bilinear with a joint-space term: blocks, columns and partner from the
// effect (lpoe/terms/bilinear_term.h), one block per effect of the request's bilinear_effects whose
// name() is the kind's; ProblemBlock::index is the block's index in p.bilinear_blocks.
class BilinearBlockKind : public BlockKind {
 public:
  const BilinearBlockKind* bilinear() const final { return this; }

  // --- Its blocks, from the effect (bilinear_block_kind.cc) ---

  // Whether the options ask for the kind.
  bool Requested(const ProblemDefinitionOptions& options) const;
  // Whether `p` holds a block of the kind (after the joint blocks).
  bool In(const Parameterization& p) const;
  // Appends the kind's blocks the options ask for to `p`. An error (the reason) when the data
  // leave nothing for one.
  Status Add(const ProblemDefinitionOptions& options, Parameterization* p) const;
  void AppendBlocks(const ProblemSetup& setup, const RobotModel& nominal,
                    std::vector<ProblemBlock>* out) const override;
  // J_q(q_eff) d(dq)/dt at the current values.
  void Columns(const BlockColumnsContext& ctx, const ProblemBlock& block,
               const MeasurementSet& data, int r, Eigen::MatrixXd* J) const override;

  // --- What is particular to the effect (the kind's own source file) ---

  // The joint-space term whose values the kind's columns need.
  virtual const char* partner_term() const = 0;
  // The message when the kind is asked for without its partner term.
  virtual const char* needs_partner_message() const = 0;
  // The effect on the calibration's start model.
  virtual std::shared_ptr<const BilinearJointEffect> MakeEffect(const RobotModel& start) const = 0;

  // The kind's entry of `out` at the joint-space coordinates `joint_state`, standard deviations
  // from `covariance` (p's numbering; empty: none). Called only when In(p).
  virtual void FillResult(const Parameterization& p, const Eigen::VectorXd& joint_state,
                          const Eigen::MatrixXd& covariance, CalibrationResult* out) const = 0;
  // Scales the standard deviations of the kind's entry, from a covariance with the given noise
  // (sigma) to the one the residuals estimate (factor), keeping the a-priori ones beside them.
  virtual void ScaleToAPosteriori(double factor, CalibrationResult* out) const = 0;
  // The kind's rule, asked at a solution `r0` without the kind: whether the data determine it.
  // Fills the kind's entry of `out` (marked requested; the reason when not).
  virtual bool Identifiable(const RobotModel& start, const MeasurementSet& data,
                            const CalibrationResult& r0, bool use_orientation,
                            double orientation_weight, double tolerance, double max_sigma,
                            CalibrationResult* out) const = 0;

  // The pipeline's staged solve (pipeline.cc: a solve with the partner term, the kind's rule at
  // its solution, then a solve with the effect from there):
  //   - copies the kind's entry of `check` (Identifiable's) into `out`'s; with `solved` (a
  //     converged solve with the kind, may be `out`) its values and standard deviations as well;
  //     a non-empty `why_not`: why the kind's values were not solved;
  virtual void Record(const CalibrationResult& check, const CalibrationResult* solved,
                      const std::string& why_not, CalibrationResult* out) const = 0;
  //   - writes the identified values of `result`'s entry into the calibrated model (the tilt:
  //     its gravity).
  virtual void ApplyToModel(const CalibrationResult& result, RobotModel* model) const = 0;
  // Whether `result` (a calibration that asked for the kind) identified it; else `why_not` (may
  // be null) says why (the joint-error selection's candidacy and folds).
  virtual bool Identified(const CalibrationResult& result, std::string* why_not) const = 0;
};

// What the data say about a bilinear block of `effect` at a solution `r0` with its partner term
// (its columns vanish without the partner's values, so this is asked after that solve): the
// block's columns at r0's frames and partner values, everything else projected out (Schur
// complement of the column-scaled normal equations, a pseudo-inverse for the gauge of the full
// parameterization). `kept_fraction`: the square root of the smallest eigenvalue of the projected
// column-scaled information (the joint terms' rule); `covariance`: its inverse with the noise
// estimated from r0's residuals (m x m; empty when the projection is singular). An error (the
// reason) when the block cannot be formed or moves no measured point.
Status BilinearInformation(std::shared_ptr<const BilinearJointEffect> effect,
                           const MeasurementSet& data, const CalibrationResult& r0,
                           bool use_orientation, double orientation_weight, double* kept_fraction,
                           Eigen::MatrixXd* covariance);

// The frames' kind and the joint-space terms' kind (registry entries; for tests and the problem).
const BlockKind& FrameBlockKind();
const BlockKind& JointTermBlockKind();

// Row r of `data` linearised at ctx's values, as the linear solver's assembly does it: the frame
// columns of every frame in ctx.p's bases (rows x p.num_parameters; the joint-space columns left
// zero), the Jacobian with respect to the effective joint values J_q (rows x n) and the joint-space
// columns R = d(q_eff)/d(joint state) (n x K) at the current values (the block kinds' included).
// What the kinds' Columns pick their columns from (not a hot path: a BasisJacobian per call).
struct RowLinearization {
  Eigen::MatrixXd J;
  Eigen::MatrixXd J_q;
  Eigen::MatrixXd R;
};
void LinearizeRow(const BlockColumnsContext& ctx, const MeasurementSet& data, int r,
                  RowLinearization* out);

// The registry's entries, in registry order (block_kind_registry.inc).
const std::vector<const BlockKind*>& BlockKinds();
// The entry named `name`, nullptr when there is none.
const BlockKind* FindBlockKind(const std::string& name);
// The bilinear kind named `name`, nullptr when there is none.
const BilinearBlockKind* FindBilinearBlockKind(const std::string& name);

// Whether p holds a bilinear block (lpoe/terms/bilinear_term.h; the solvers' linear shortcuts,
// which evaluate the rows' columns once, are off then).
inline bool HasNonlinearBlocks(const Parameterization& p) { return !p.bilinear_blocks.empty(); }
// Whether the options ask for a bilinear block.
inline bool RequestsNonlinearBlocks(const ProblemDefinitionOptions& o) {
  return !o.bilinear_effects.empty();
}
// Each effect of the request with its partner term among `terms` and a registered kind; the
// first failing kind's message otherwise.
Status CheckBlockKindPartners(const std::vector<std::shared_ptr<const JointTerm>>& terms,
                              const ProblemDefinitionOptions& options);
// For one row at commanded joints q: `R` (n x K) holds the linear joint-space columns with the
// bilinear blocks' zero; on return every bilinear block's partner columns are taken at its current
// values, its own columns hold d(dq)/dt, and `q_eff` (q + R x, from the linear columns) gains the
// blocks' change of the partners' offsets. `joint_state`: the K joint-space coordinates (p's order;
// empty: zero). No-op without bilinear blocks.
void AddNonlinearRowColumns(const Parameterization& p, const double* q,
                            const Eigen::VectorXd& joint_state, Eigen::Ref<Eigen::MatrixXd> R,
                            Eigen::VectorXd* q_eff);
// The Ceres residual's data of one row for bilinear block b of p; `partner_block`: its partner's
// index among the row's joint-space parameter blocks.
std::shared_ptr<const BilinearRow> BilinearRowOf(const Parameterization& p, int b, const double* q,
                                                 int partner_block);
// Every kind in p: FillResult.
void FillBlockKindResults(const Parameterization& p, const Eigen::VectorXd& joint_state,
                          const Eigen::MatrixXd& covariance, CalibrationResult* out);

}  // namespace internal
}  // namespace lpoe

#endif  // LPOE_SOLVERS_SRC_CALIBRATION_BLOCK_KIND_H_
