// The learned residual layer (docs/residual_layer.md): a sparse Gaussian process over the joint
// configuration and the measured tool (SMR) that predicts what the parametric model (geometry and
// joint-space terms) leaves of the tool position error. A model that carries one
// (RobotModel::residual_layer) predicts
//
//   P(q, tool) = FK(q_eff) p_tool + m(q, tool)          (mm, the calibrated model's base frame)
//
// Kernel (squared exponential, automatic relevance determination; the tool as a one-hot coordinate
// with its own length scale):
//
//   k(x, x') = s_f^2 exp(-1/2 sum_j ((q_j - q'_j) / l_j)^2) * (tool == tool' ? 1 : rho)
//
// with rho = exp(-1 / l_tool^2) in [0, 1]. The three position components are independent outputs
// sharing the hyperparameters (l_j, rho, s_f, noise s_n). Prediction (deterministic training
// conditional, DTC, with m inducing inputs z_i chosen among the identification rows):
//
//   m(x)      = k_m(x)^T alpha                  alpha = (m x 3) weights
//   var(x)    = s_f^2 - k_m(x)^T W k_m(x)       W = K_mm^-1 - (K_mm + s_n^-2 K_mn K_nm)^-1
//   dm/dq_j   = -sum_i alpha_i k_i(x) (q_j - z_ij) / l_j^2
//
// Far from every inducing input k_m(x) -> 0: the correction returns to zero (the parametric
// model's prediction) and the standard deviation to s_f.
#ifndef LPOE_RESIDUAL_LAYER_H_
#define LPOE_RESIDUAL_LAYER_H_

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "lpoe/status.h"

namespace lpoe {

class ResidualLayer {
 public:
  // The frame of the corrections: the calibrated model's base frame (for a registered calibration,
  // the measurement frame its data were in). The only value written and read.
  static constexpr const char* kFrame = "base";
  static constexpr const char* kKernel = "se_ard";

  int num_joints = 0;
  int num_tools = 0;
  Eigen::VectorXd length_scales;  // per joint: rad (revolute) / mm (prismatic)
  double tool_correlation = 1.0;  // rho in [0, 1]
  double signal_std = 0;          // s_f, mm
  double noise_std = 0;           // s_n, mm
  Eigen::MatrixXd inducing_q;     // m x num_joints
  std::vector<int> inducing_tool; // m tool indices
  Eigen::MatrixXd weights;        // m x 3 (alpha)
  Eigen::MatrixXd variance;       // m x m symmetric (W)
  int fitted_rows = 0;            // identification rows it was fitted on (information only)

  int num_inducing() const { return static_cast<int>(inducing_q.rows()); }

  // The correction m(q, tool) (mm). With `dm_dq` (3 x num_joints, column-major, leading dimension
  // 3), also its derivative.
  Eigen::Vector3d Mean(const double* q, int tool, double* dm_dq = nullptr) const;
  // The predictive standard deviation of each component of the correction (mm; the same for x, y
  // and z). Between 0 and signal_std.
  double Std(const double* q, int tool) const;
  // The smallest distance from q to an inducing configuration in length-scale units
  // (sqrt(sum_j ((q_j - z_ij) / l_j)^2)); the kernel between them is exp(-d^2 / 2) s_f^2.
  double KernelDistance(const double* q) const;

  // Sizes, finite values, positive length scales, rho in [0, 1], tool indices in range, W
  // symmetric. Messages say what is wrong, without file or line.
  Status Validate(int model_joints, int model_tools) const;

  // k_m(x) into `k` (m values).
  void KernelVector(const double* q, int tool, Eigen::VectorXd* k) const;
};

struct ResidualLayerOptions {
  // Inducing inputs: farthest-point among the identification rows in length-scale units, until
  // every row is within `inducing_radius` of one (kernel correlation exp(-r^2 / 2)) or there are
  // `max_inducing`; the stored layer (the variance triangle, m^2 / 2 numbers) and the prediction
  // cost grow with it (docs/residual_layer.md).
  int max_inducing = 1024;
  double inducing_radius = 0.5;
  // Rows of the exact marginal likelihood the hyperparameters maximize: whole configurations (every
  // tool measured there), a seeded sample of them when there are more.
  int max_hyperparameter_rows = 360;
  int max_iterations = 60;  // L-BFGS-B iterations per start (LBFGSpp)
  uint64_t seed = 1;
};

struct ResidualLayerFit {
  double log_marginal_likelihood = 0;  // at the chosen optimum, on the hyperparameter rows
  int hyperparameter_rows = 0;
  int iterations = 0;              // of the chosen start
  // The candidates of the hyperparameter search: its two starts (long length scales, the joints'
  // spread) and no signal (2: the layer predicts nothing), each with the held-out RMS (mm,
  // |residual| norm) of the exact GP that chose between them: on validation configurations (as many
  // rows as the hyperparameter rows, of configurations not among them) when there are at least 30,
  // else leave-one-configuration-out on the hyperparameter rows; `chosen_start` indexes them.
  std::vector<double> start_loo_rms;
  int chosen_start = 0;
  // The standard deviation (mm per axis) of an error shared by the tools of one configuration and
  // independent between configurations (the arm's repeatability, a tracker drift between stops):
  // a hyperparameter like the noise, not part of the correction. 0 when no configuration has more
  // than one row.
  double configuration_std = 0;
  int configurations = 0;          // distinct configurations among the rows
  int validation_rows = 0;         // rows of the choice's validation configurations (0: LOO)
  // Per joint, the spacing of the data: the median over configurations of |q_j - q'_j| to the
  // nearest other configuration in the layer's length-scale units (ResidualLayerSpacing). A length
  // scale below it correlates no measured configuration with its neighbours through that joint: the
  // layer then interpolates its own rows and predicts nothing between them.
  Eigen::VectorXd spacing;
  double inducing_coverage = 0;    // largest distance of a row to its nearest inducing input
  double residual_rms_before = 0;  // RMS of |residual| on the fitting rows, mm
  double residual_rms_after = 0;   // after subtracting the layer's mean, mm
};

// The joints (0-based) whose length scale is below the data's spacing (ResidualLayerFit::spacing).
std::vector<int> JointsBelowSpacing(const Eigen::VectorXd& length_scales,
                                    const Eigen::VectorXd& spacing);

// The spacing of configurations `q` (rows x num_joints, row-major; repeated configurations count
// once) for the length scales `l`: per joint, the median over (at most 1000 seeded) configurations
// of |q_j - q'_j| for q' the nearest other configuration in length-scale units.
Eigen::VectorXd ResidualLayerSpacing(const std::vector<double>& q, int num_joints,
                                     const Eigen::VectorXd& l);

// Fits the layer on `rows` residuals (measured - parametric prediction, mm, base frame) at the
// joint values q (rows x num_joints, row-major) of tools `tools` (rows indices). Rows with the
// same joint values are one configuration. Hyperparameters by the exact marginal likelihood with
// weak log-normal priors on at most options.max_hyperparameter_rows rows (LBFGSpp's L-BFGS-B,
// analytic gradient) from two starts, the one that predicts held-out configurations best
// (leave-one-configuration-out) kept; then the sparse (DTC) posterior on every row. Fails on wrong
// sizes, fewer than 3 rows or non-finite values.
Status FitResidualLayer(const std::vector<double>& q, const std::vector<int>& tools,
                        const std::vector<Eigen::Vector3d>& residuals, int num_joints,
                        int num_tools, const ResidualLayerOptions& options, ResidualLayer* layer,
                        ResidualLayerFit* fit = nullptr);

// Fits the layer on projected observations: row r sees one number along a direction,
//   values[r] = directions[r] . m(q_r, tools[r]) + noise
// (a ballbar distance's residual along the bar, a probe contact's along the plane's normal;
// docs/residual_layer.md, "Projected observations"). The kernel of the observations is
// (u_a . u_b) k(x_a, x_b); hyperparameters, their choice and the inducing inputs as in
// FitResidualLayer, then the DTC posterior of the three components of m at the inducing inputs
// (3m inducing variables). The stored layer has the same form (m(x) = k_m(x)^T alpha, alpha m x 3);
// its variance matrix gives the mean over the three axes of the components' posterior variances.
// A component that no row's direction has gets weights exactly 0: the layer predicts nothing
// along directions the data never observe. Fails as FitResidualLayer does, and on a zero direction.
Status FitResidualLayerProjected(const std::vector<double>& q, const std::vector<int>& tools,
                                 const std::vector<Eigen::Vector3d>& directions,
                                 const std::vector<double>& values, int num_joints,
                                 int num_tools, const ResidualLayerOptions& options,
                                 ResidualLayer* layer, ResidualLayerFit* fit = nullptr);

namespace internal {

// Projected observations (FitResidualLayerProjected): with U (rows x 3) the rows observe
// y_a = u_a . m(x_a) (Y has one column) and every kernel term between rows a and b is multiplied
// by u_a . u_b (validation rows: their own directions Uv).
// The hyperparameter vector of the fit: log l_1..log l_n, log l_tool (only when `with_tool`),
// log s_f, log s_n, and log s_c (only with `configuration`: the standard deviation of an error
// shared by the rows of one configuration).
// Log marginal likelihood of the three outputs Y (rows x 3) at inputs X (rows x n) and tools under
// the kernel above (exact GP) plus s_c^2 between rows of the same configuration
// (configuration[a] == configuration[b]), and its gradient with respect to theta.
double GpLogMarginalLikelihood(const Eigen::VectorXd& theta, bool with_tool,
                               const Eigen::MatrixXd& X, const std::vector<int>& tools,
                               const Eigen::MatrixXd& Y, Eigen::VectorXd* gradient,
                               const std::vector<int>* configuration = nullptr,
                               const Eigen::MatrixXd* U = nullptr);

// The exact GP's leave-one-configuration-out prediction errors at theta (same arguments; the rows
// of a configuration left out together): the mean over rows of |y - prediction from the other
// configurations|^2 (mm^2). Closed form: e_g = (K^-1)_gg^-1 (K^-1 Y)_g.
double GpLeaveOneConfigurationOut(const Eigen::VectorXd& theta, bool with_tool,
                                  const Eigen::MatrixXd& X, const std::vector<int>& tools,
                                  const Eigen::MatrixXd& Y,
                                  const std::vector<int>* configuration,
                                  const Eigen::MatrixXd* U = nullptr);

// The exact GP's prediction errors at validation rows Xv (tools `validation_tools`, values Yv) from
// the rows X (same arguments as above): mean over the validation rows of |y - prediction|^2 (mm^2).
// The validation rows are other configurations: their shared error does not reach them.
double GpValidationError(const Eigen::VectorXd& theta, bool with_tool, const Eigen::MatrixXd& X,
                         const std::vector<int>& tools, const Eigen::MatrixXd& Y,
                         const std::vector<int>* configuration, const Eigen::MatrixXd& Xv,
                         const std::vector<int>& validation_tools, const Eigen::MatrixXd& Yv,
                         const Eigen::MatrixXd* U = nullptr, const Eigen::MatrixXd* Uv = nullptr);

}  // namespace internal
}  // namespace lpoe

#endif  // LPOE_RESIDUAL_LAYER_H_
