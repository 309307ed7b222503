// Recalibration and fleet priors (docs/recalibration.md): the prior of lpoe/model/prior.h built
// from calibrated models, written with them and read back.
//
//   * A calibrated model's YAML carries the estimate's covariance (`covariance:`, docs/file_formats.md):
//     per local frame the 6x6 covariance of its deviation xi = log(T_ref^-1 T) = (omega rad, v mm) in
//     the frame's own coordinates, per joint-space term the P x P covariance of its values.
//   * ReadPrior turns such a file into a ParameterPrior (reference: the model; information: the
//     pseudo-inverse of each block, with the default tolerances in the directions the block does not
//     cover; informative).
//   * Recalibrate runs the pipeline with such a prior and frees the groups of parameters the new data
//     show changed (a frame whose prior discrepancy is far beyond its degrees of freedom: a joint's
//     zero, a joint's frame, a tool), then solves again.
//   * FleetPrior: the mean and covariance of several calibrated robots of one type.
#ifndef LPOE_RECALIBRATION_H_
#define LPOE_RECALIBRATION_H_

#include <string>
#include <vector>

#include <Eigen/Core>

#include "lpoe/calibration.h"
#include "lpoe/model/model_covariance.h"
#include "lpoe/pipeline.h"
#include "lpoe/model/prior.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/status.h"

namespace lpoe {

// The covariance of `result`'s estimate per frame and joint term (ModelCovariance: frames the
// parameterization does not solve, and a result without a covariance, give empty blocks).
ModelCovariance CovarianceOf(const CalibrationResult& result);

// The calibrated model as written (lpoe_calibrate --output): the result's model with the
// registration it was identified in, so that compensation carries nominal poses into that frame.
RobotModel CalibratedModel(const PipelineResult& run);

// Its YAML, with the estimate's covariance block when the result has one (the prior of a later
// recalibration, ReadPrior).
std::string CalibratedModelYaml(const RobotModel& calibrated, const CalibrationResult& result);


// The prior of a model and its covariance: reference = model, informative. Directions a block does
// not cover (and frames without a block) get `scales`' tolerances.
ParameterPrior PriorFromCovariance(const RobotModel& model, const ModelCovariance& covariance,
                                   const PriorScales& scales);

// Reads a calibrated model with its covariance block as a prior (ReadRobotModel, then the block).
Status ReadPrior(const std::string& path, const PriorScales& scales, RobotModel* model,
                 ParameterPrior* prior);

// A group of parameters the new data show changed against an informative prior.
struct ChangedGroup {
  int frame = 0;          // local frame
  std::string name;       // "joint3 zero", "joint5 frame", "smr1"
  double chi2 = 0;        // the frame's prior discrepancy at the MAP estimate
  int dof = 0;            // its degrees of freedom
  // A joint-space term's group (frame -1): the term, and the joint whose parameters it is (-1:
  // the whole term), e.g. "joint3 harmonics".
  std::string term;
  int joint = -1;
};

struct RecalibrationResult {
  PipelineResult run;                  // the final calibration
  std::vector<ChangedGroup> changed;   // groups freed (their prior replaced by the tolerances)
  int solves = 0;
};

// The pipeline with options.prior (informative, with its reference), then, while the MAP estimate
// shows groups whose prior discrepancy chi^2 exceeds dof + 5 sqrt(2 dof) + 10 (far beyond a
// consistent prior), the worst of them (per degree of freedom) freed (held by the tolerances
// only) and solved again (at most six rounds). Groups: a joint's zero (when a frame's discrepancy
// lies mostly along it), a frame, and per joint-space term with a prior the parameters of each
// joint (their marginal discrepancy; freed to the default joint-term tolerance).
RecalibrationResult Recalibrate(const RobotModel& nominal, const MeasurementSet& identification,
                                const MeasurementSet& verification, const PipelineOptions& options);

// The fleet prior of calibrated models of one type: the mean model (each frame's mean deviation
// from the first model, on SE(3)) and per frame the covariance of a NEW robot's deviation from that
// mean (joint terms: mean and the same covariance of their values). Refuses models of different
// chains (joint count and types, names, tools) with a message naming the first difference, and
// fewer than two models.
//
// The covariance is the posterior predictive of the next robot given the fleet's N robots (their
// deviations Gaussian with unknown mean and covariance, the non-informative prior): a multivariate
// t with N - p degrees of freedom whose covariance is the sample covariance S times
//     (N + 1)(N - 1) / (N (N - p - 2))           (FleetPredictiveFactor),
// p the block's estimated directions (EstimatedDimension: a joint frame 4, a tool 3 with position
// data, 6 with pose data; a joint term its P values). It exists for N > p + 2: a block of p
// directions needs p + 3 robots (a joint frame 7: kRobotsForFullCovariance). With fewer the factor
// is (N + 1) / N (the mean's uncertainty only) and the tools warn; below p + 1 robots S has not even
// full rank, and the directions it leaves out get the default tolerances when it is used as a prior
// (PriorFromCovariance). The sample covariance underestimates a new robot's spread by that factor
// (3.9 for a joint frame of 8 robots): used as is, the prior is too confident.
constexpr int kRobotsForFullCovariance = 7;
int EstimatedDimension(const RobotModel& model, int f, const Eigen::MatrixXd& covariance);
double FleetPredictiveFactor(int robots, int p);
Status FleetPrior(const std::vector<RobotModel>& models, RobotModel* mean,
                  ModelCovariance* covariance);

}  // namespace lpoe

#endif  // LPOE_RECALIBRATION_H_
