// The prior (lpoe/model/prior.h) in a solver's coordinates: the whitened prior rows of the identified
// parameters (the linear solver adds them to its normal equations; the Ceres solver adds the same
// rows as residual blocks on its parameter blocks), and what the prior contributed per parameter.
#ifndef LPOE_SOLVERS_PRIOR_TERMS_H_
#define LPOE_SOLVERS_PRIOR_TERMS_H_

#include <memory>
#include <vector>

#include <Eigen/Core>

#include "lpoe/measurements/measurements.h"
#include "lpoe/model/parameterization.h"
#include "lpoe/model/prior.h"
#include "lpoe/model/robot_model.h"

namespace lpoe {
namespace internal {

// The prior resolved for one parameterization: per frame the reference transform and L_f (upper
// Cholesky factor of the information, so that |L_f xi_f|^2 is the frame's Mahalanobis norm), per
// joint block of p the reference values and L_b (P x P).
struct ResolvedPrior {
  bool active = false;
  RobotModel reference;
  std::vector<Matrix6d> frame_sqrt;
  std::vector<Eigen::VectorXd> term_reference;
  std::vector<Eigen::MatrixXd> term_sqrt;
  double data_sigma = 0;  // mm; 0: estimated from the residuals
  bool informative = false;
};

// `start`: the model the solver starts from (the reference when prior.reference is null); the
// joint terms' default scales are evaluated on the rows of `data`.
ResolvedPrior ResolvePrior(const ParameterPrior& prior, const RobotModel& start,
                           const MeasurementSet& data, const Parameterization& p);

// The whitened prior residuals r = L (deviation) and their Jacobian A = dr/dx (x in p's
// numbering) at `model` and the joint blocks' coordinates `joint_state` (p's joint columns, in
// order). Frames without columns in p and the gravity tilt have no rows.
struct PriorRows {
  Eigen::MatrixXd A;
  Eigen::VectorXd r;
  double cost() const { return 0.5 * r.squaredNorm(); }
};
PriorRows LinearizePrior(const ResolvedPrior& prior, const Parameterization& p,
                         const RobotModel& model, const Eigen::VectorXd& joint_state);

// H += s2 A^T A, g -= s2 A^T r (g = J^T y, y = measured - predicted; g may be null).
void AddPrior(const PriorRows& rows, double s2, Eigen::MatrixXd* H, Eigen::VectorXd* g);

// The data's variance per axis the prior is weighted with: data_sigma^2 when given, else
// 2 cost / dof (at least a tiny positive number; that number when dof <= 0).
double PriorDataVariance(const ResolvedPrior& prior, double data_cost, long dof);

// The data variance to weigh the prior with for a Gauss-Newton step from a linearization (J^T J
// `H`, J^T y `g`, data cost `cost`): the fixed point of s2 = 2 c(x) / dof, c(x) the linearized data
// cost at the end of the step x that the prior weighted with s2 takes. At a solution (x = 0) it
// is the residuals' variance, the fixed point both solvers converge to; before it, it is what
// the step is expected to leave, so that the prior is not weighed with a start model's
// millimetres. data_sigma when the prior fixes it.
double PriorStepDataVariance(const ResolvedPrior& prior, const Eigen::MatrixXd& H,
                             const Eigen::VectorXd& g, double cost, const PriorRows& rows,
                             long dof);

// Per parameter: the prior's standard deviation (x units; infinity without a prior row) and the
// data's share of the information, 1 - posterior variance / prior variance (1 where no prior),
// from the data's J^T J `H_data` and the data variance s2 the prior was weighted with.
void PriorContribution(const PriorRows& rows, const Eigen::MatrixXd& H_data, double s2,
                       Eigen::VectorXd* prior_sd, Eigen::VectorXd* data_share);

}  // namespace internal
}  // namespace lpoe

#endif  // LPOE_SOLVERS_PRIOR_TERMS_H_
