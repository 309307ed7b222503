// The planning workflow as one library call (docs/planning.md), shared by lpoe_plan and lpoe.plan as
// RunCalibrationPipeline is shared by lpoe_calibrate and lpoe.calibrate: the joint-space terms and
// the gravity tilt planned for, the candidates and workspace (given, or sampled with the request's
// seed), the pool of feasible candidates, the plan (of a given size, or the smallest that reaches a
// target accuracy), its refusals, the random comparison plans (seeds seed + 1000 + k) and the
// tilt's predicted standard deviations. It reads and writes no file.
#ifndef LPOE_PLANNING_WORKFLOW_H_
#define LPOE_PLANNING_WORKFLOW_H_

#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "lpoe/planning.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/status.h"

namespace lpoe {

struct PlanRequest {
  RobotModel model;
  std::string model_source;  // names the model in messages (its file)
  // The size of the plan, or (count_auto) the smallest plan predicted to reach target_accuracy
  // (mm) with noise_sigma (mm per axis).
  int count = 0;
  bool count_auto = false;
  double target_accuracy = 0;
  double noise_sigma = 0;  // > 0: the predicted accuracy in mm too
  // Candidates and workspace, row-major (rad / mm); when not given, sampled within the joint
  // ranges (seed and seed + 1).
  bool has_candidates = false;
  std::vector<double> candidates;
  int candidate_count = 5000;
  bool has_workspace = false;
  std::vector<double> workspace;
  int workspace_count = 1000;
  uint64_t seed = 1;
  PlanOptions options;  // criterion, exchange, threads
  PlanConstraints constraints;
  // none | a comma-separated list of the registry's terms (with ",tilt" after compliance) | auto.
  std::string joint_errors = "none";
  int random_draws = 30;
  // What the calibrated model will not explain (docs/planning.md, "Unmodelled error"): from the
  // model's residual layer when it carries one and unmodelled_given is false, else
  // unmodelled_error (mm per axis; 0: none) varying over unmodelled_length (rad / mm) per joint.
  bool unmodelled_given = false;
  double unmodelled_error = 0.03;
  double unmodelled_length = 1.0;
  // lpoe_plan --prior (docs/recalibration.md): a prior (a previous calibration, a fleet), whose
  // information the plan starts from: the poses go where it is weak. Its information is weighed
  // against noise_sigma, else the prior's data_sigma_mm, else kPlanDefaultNoiseSigma. With a prior
  // the plan needs full rank with it, not more rows than parameters, and the unmodelled-error
  // exchange is not run (its prediction is that of a least-squares calibration). Null: none.
  std::shared_ptr<const ParameterPrior> prior;
};

// The noise (mm per axis) the predicted error assumes when the request gives none.
constexpr double kPlanDefaultNoiseSigma = 0.01;

// What kind of failure RunPlanning met: the front ends map it (lpoe_plan: exit 1, 2, 3).
enum class PlanFailure { kNone, kUsage, kInput, kNoPlan };

struct PlanningResult {
  std::vector<std::string> term_names;  // in registry order
  bool tilt = false;                    // the gravity tilt planned for
  std::string tilt_note;                // auto without it: why not
  int offered = 0;                      // candidates offered (given or sampled)
  std::vector<double> candidates;       // those candidates, row-major
  int workspace_configurations = 0;
  std::unique_ptr<PlanningModel> planning;
  CandidatePool pool;
  Eigen::MatrixXd workspace_moment;
  int count = 0;  // the plan's size (count_auto: the one found)
  PlanResult plan;
  PlanQuality quality;
  // The random plans of the same size: the first one's quality, every draw's predicted RMS per
  // unit noise (sorted), and their RMS over the finite draws (infinite without any).
  PlanQuality random_quality;
  std::vector<double> random_rms;
  double random_rms_mean = 0;
  // The unmodelled error planned for, where it came from ("residual layer", "given", "default"),
  // the noise assumed (request's, else kPlanDefaultNoiseSigma), the predicted error of the plan and
  // of each random plan (total, sorted) and their RMS, and the swaps the exchange on the predicted
  // error made (starting from the best of the criterion's plan and the random plans; `start` says
  // which: "criterion" or "random draw k").
  UnmodelledErrorModel unmodelled;
  std::string unmodelled_source;
  double prediction_sigma = 0;
  PlanErrorPrediction prediction;
  std::vector<double> random_total_rms;
  double random_total_rms_mean = 0;
  std::string unmodelled_start;
  int unmodelled_swaps = 0;
  // With a prior (PlanRequest::prior): the noise its information was weighed against (mm).
  double prior_sigma = 0;
  // With the tilt: its two angles' predicted standard deviations, degrees per mm of noise.
  double tilt_sd_deg_per_unit[2] = {0, 0};
  // The planned terms as written in reports ("none", "compliance,harmonics,tilt").
  std::string PlannedTerms() const;
};

// Checks the request's numbers against the option table (lpoe/options.h: lpoe_plan's ranges) and
// their combinations (count or auto, a tracker for its options): a usage error naming the flag.
Status CheckPlanRequest(const PlanRequest& request);

// Narrows the model's joint limits to `ranges` (one per joint, lo < hi, revolute in rad; a pair of
// NaN keeps the joint's limits): an error names the joint whose range is not lo < hi or does not
// overlap its limits.
Status NarrowJointRanges(const std::vector<std::pair<double, double>>& ranges, RobotModel* model);

// The whole workflow. On failure `failure` (optional) says which kind; the message is the
// front ends'.
Status RunPlanning(const PlanRequest& request, PlanningResult* result,
                   PlanFailure* failure = nullptr);

}  // namespace lpoe

#endif  // LPOE_PLANNING_WORKFLOW_H_
