// Internal to lpoe_solvers: the gravity tilt (docs/joint_errors.md, "Gravity tilt") in the linear
// solver's normal equations and the tilt's identifiability check.
//
// The tilt t turns the model's gravity, g'(t) = exp([U t]^) g; the compliance offsets are then
// bilinear, dq_c = Y(g'(t)) B x_c = sum_a g'_a(t) Z_a x_c with Z_a = Y_a(q) B (B the compliance
// block's basis). Linearised for Gauss-Newton, the tilt contributes *extra joint-space columns*:
//
//   d(dq)/dt = sum_a (dg'/dt)_a Z_a x_c             (n x 2; the tilt's Jacobian columns are J_q times it)
//   d(dq)/dx_c = Y(g0) B + sum_a (g'(t) - g0)_a Z_a  (the compliance columns at the current tilt)
//
// and q_eff gains sum_a (g'(t) - g0)_a Z_a x_c. ApplyGravityTiltColumns is the one function that
// turns a row's linear joint-space columns R (n x K) into these: whatever structure accumulates
// J_q * R (dense columns per row, or per-row sparse blocks), it calls this per row first.
#ifndef LPOE_SOLVERS_SRC_GRAVITY_TILT_H_
#define LPOE_SOLVERS_SRC_GRAVITY_TILT_H_

#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "lpoe/calibration.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/measurements/measurements.h"
#include "lpoe/model/parameterization.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/status.h"

namespace lpoe {
namespace internal {

// For one row at commanded joints q: `R` (n x K) holds the linear joint-space columns
// [Y_b(q) basis_b] with the tilt's two columns zero; on return the compliance block's columns are
// taken at the current tilt and the tilt's columns hold d(dq)/dt. `q_eff` (q + R x, from the
// linear columns) gains the tilt's change of the compliance offsets. `joint_state`: the K
// joint-space coordinates (p's order, the tilt last; empty: zero). No-op without a tilt in p.
void ApplyGravityTiltColumns(const Parameterization& p, const double* q,
                             const Eigen::VectorXd& joint_state, Eigen::Ref<Eigen::MatrixXd> R,
                             Eigen::VectorXd* q_eff);

// The tilt's Z_a = Y_a(q) B (a = x, y, z) for one row: what both solvers evaluate the tilt from.
void GravityTiltRowRegressors(const Parameterization& p, const double* q, Eigen::MatrixXd Z[3]);

// Adds options' gravity tilt to p, bilinear with the joint block whose term is named
// "compliance". An error when there is no such block or it keeps no combination.
Status AddSolverGravityTilt(std::shared_ptr<const GravityTiltModel> tilt, Parameterization* p);

// The joint-space coordinates (p.num_joint_parameters(), the tilt's zero) of `initial` (values of
// p's joint blocks' terms, matched by name; empty: zero): x_b = basis_b^T theta_b.
Eigen::VectorXd InitialJointState(const Parameterization& p,
                                  const std::vector<JointTermValues>& initial);

// The solved tilt of p at the joint-space coordinates `joint_state`, with standard deviations from
// `covariance` (p's numbering; empty: none). No-op without a tilt in p.
void FillGravityTiltResult(const Parameterization& p, const Eigen::VectorXd& joint_state,
                           const Eigen::MatrixXd& covariance, GravityTiltResult* out);

// Whether the data determine the tilt at a solution `r0` with the compliance term (the tilt's
// columns vanish without compliance values, so this is asked after that solve): the tilt's two
// columns at r0's frames and compliance values, everything else projected out (Schur complement of
// the column-scaled normal equations, a pseudo-inverse for the gauge of the full
// parameterization). Identifiable when the smallest kept fraction is at least `tolerance` (the
// joint terms' rule) and each angle's standard deviation (noise estimated from r0's residuals) is
// at most `max_sigma` (rad). Fills out->kept_fraction, predicted_standard_deviation, axes,
// gravity_before and, when not identifiable, message.
bool CheckGravityTilt(const RobotModel& start, const MeasurementSet& data,
                      const CalibrationResult& r0, bool use_orientation, double orientation_weight,
                      double tolerance, double max_sigma, GravityTiltResult* out);

}  // namespace internal
}  // namespace lpoe

#endif  // LPOE_SOLVERS_SRC_GRAVITY_TILT_H_
