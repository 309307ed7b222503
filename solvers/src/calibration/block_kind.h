// Internal to lpoe_solvers: the registry of parameter-block kinds whose columns are not linear in
// the calibration state (docs/architecture.md, "Where to add a block kind"). Such a kind's Jacobian
// columns depend on the current values of other blocks (the gravity tilt: bilinear with the
// compliance coordinates), so neither the frames' linearisation nor a joint-space term's fixed
// regressor can supply them. Each kind supplies, through this one interface:
//
//   - whether a calibration asks for it, and the joint-space term it needs (checked once);
//   - its block in the parameterization (ProblemSetup makes it, both solvers use it);
//   - its columns given the current values (the linear solver's normal equations);
//   - its per-row data for the Ceres residual;
//   - its entry in the result (value, standard deviation);
//   - its identifiability rule at a solution without it.
//
// Adding a kind: one source file that defines a BlockKind and a function returning it, plus one
// line in block_kind_registry.inc (gravity_tilt.cc is the one kind today).
//
// Not kinds of this registry (yet): the frames (their columns come from the kinematics'
// linearisation, measurement kind by measurement kind) and the linear joint-space terms (their
// columns are the JointTerm registry's regressors times the block's basis, core/src/terms).
#ifndef LPOE_SOLVERS_SRC_CALIBRATION_BLOCK_KIND_H_
#define LPOE_SOLVERS_SRC_CALIBRATION_BLOCK_KIND_H_

#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "lpoe/calibration.h"
#include "lpoe/joint_term.h"
#include "lpoe/measurement_residual.h"
#include "lpoe/measurements.h"
#include "lpoe/parameterization.h"
#include "lpoe/robot_model.h"
#include "lpoe/status.h"

namespace lpoe {
namespace internal {

struct ProblemSetupRequest;  // problem_setup.h

class BlockKind {
 public:
  virtual ~BlockKind() = default;

  // The `--joint_errors` item that asks for the kind ("tilt").
  virtual const char* name() const = 0;
  // The joint-space term whose values the kind's columns need (nullptr: none).
  virtual const char* partner_term() const = 0;
  // The message when the kind is asked for without its partner term.
  virtual const char* needs_partner_message() const = 0;

  // Whether the solvers' request asks for the kind.
  virtual bool Requested(const ProblemSetupRequest& request) const = 0;
  // Whether `p` holds the kind's block (after the joint blocks).
  virtual bool In(const Parameterization& p) const = 0;
  // Appends the kind's block to `p`. An error (the reason) when the data leave nothing for it.
  virtual Status Add(const ProblemSetupRequest& request, Parameterization* p) const = 0;

  // The linear solver's columns of one row at commanded joints q, given the current joint-space
  // coordinates `joint_state` (p's order; empty: zero): `R` (n x K) holds the linear joint-space
  // columns with this kind's zero; on return it holds the kind's columns and the partner's at the
  // current values, and `q_eff` (q + R x) the kind's change of the joint offsets.
  virtual void RowColumns(const Parameterization& p, const double* q,
                          const Eigen::VectorXd& joint_state, Eigen::Ref<Eigen::MatrixXd> R,
                          Eigen::VectorXd* q_eff) const = 0;
  // The Ceres residual's data of one row; `partner_block`: the partner's index among the row's
  // joint-space parameter blocks.
  virtual std::shared_ptr<const GravityTiltRow> CeresRow(const Parameterization& p, const double* q,
                                                         int partner_block) const = 0;

  // The kind's entry of `out` at the joint-space coordinates `joint_state`, standard deviations
  // from `covariance` (p's numbering; empty: none). Called only when In(p).
  virtual void FillResult(const Parameterization& p, const Eigen::VectorXd& joint_state,
                          const Eigen::MatrixXd& covariance, CalibrationResult* out) const = 0;
  // The kind's rule, asked at a solution `r0` without the kind: whether the data determine it.
  // Fills the kind's entry of `out` (the reason when not).
  virtual bool Identifiable(const RobotModel& start, const MeasurementSet& data,
                            const CalibrationResult& r0, bool use_orientation,
                            double orientation_weight, double tolerance, double max_sigma,
                            CalibrationResult* out) const = 0;
};

// The registry's entries, in registry order (block_kind_registry.inc).
const std::vector<const BlockKind*>& BlockKinds();
// The entry named `name`, nullptr when there is none.
const BlockKind* FindBlockKind(const std::string& name);

// Whether p holds a block of any registered kind (columns that change with the state: the
// solvers' linear shortcuts, which evaluate the rows' columns once, are off then).
bool HasNonlinearBlocks(const Parameterization& p);
// Each registered kind asked for with its partner term among `terms`; the first kind's message
// otherwise.
Status CheckBlockKindPartners(const std::vector<std::shared_ptr<const JointTerm>>& terms,
                              const ProblemSetupRequest& request);
// Every kind in p: RowColumns in registry order.
void AddNonlinearRowColumns(const Parameterization& p, const double* q,
                            const Eigen::VectorXd& joint_state, Eigen::Ref<Eigen::MatrixXd> R,
                            Eigen::VectorXd* q_eff);
// Every kind in p: FillResult.
void FillBlockKindResults(const Parameterization& p, const Eigen::VectorXd& joint_state,
                          const Eigen::MatrixXd& covariance, CalibrationResult* out);

}  // namespace internal
}  // namespace lpoe

#endif  // LPOE_SOLVERS_SRC_CALIBRATION_BLOCK_KIND_H_
