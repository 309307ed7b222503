// What a user needs to trust a calibration: identifiability of the parameters by the data,
// uncertainty and correlation of the identified ones, points that do not fit, and data splits for
// verification.
#ifndef LPOE_ANALYSIS_H_
#define LPOE_ANALYSIS_H_

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "lpoe/calibration.h"
#include "lpoe/measurements/measurements.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/model/statistics.h"

namespace lpoe {

struct CorrelatedPair {
  std::string a, b;
  double correlation = 0;
};

struct IdentifiabilityReport {
  int num_parameters = 0;
  int rank = 0;
  double condition_number = 0;
  Eigen::VectorXd singular_values;            // column-scaled Jacobian, descending
  std::vector<Direction> unidentifiable;      // directions no data can determine, with reasons
  std::vector<std::string> parameter_names;   // identified directions
  Eigen::VectorXd standard_deviation;         // of each identified direction (rad / mm); empty
                                              // when no covariance was computed
  std::vector<CorrelatedPair> most_correlated;  // largest |correlation| first
  std::vector<std::string> warnings;          // poorly exciting data, e.g. a joint that barely moves
  // The prior (lpoe/model/prior.h) when the calibration used one (empty otherwise): per identified
  // direction the prior's standard deviation and the data's share of the information (1: the
  // data alone), the directions the prior held (share below kWeaklyDeterminedShare, "weakly
  // determined": they stay near the start model) and the data's standard deviation per axis the
  // prior was weighed against (mm).
  Eigen::VectorXd prior_standard_deviation;
  Eigen::VectorXd data_share;
  std::vector<std::string> weakly_determined;
  double prior_data_sigma = 0;
};

// A direction whose information comes less than half from the data is weakly determined.
constexpr double kWeaklyDeterminedShare = 0.5;

// Revolute joints moving less than this over the data set are flagged (rad); prismatic: mm.
constexpr double kMinRevoluteExcursion = 0.35;  // 20 degrees
constexpr double kMinPrismaticExcursion = 20.0;
// Condition numbers of the column-scaled Jacobian above this are flagged (still solved).
constexpr double kWarnConditionNumber = 1e4;

IdentifiabilityReport AnalyzeIdentifiability(const RobotModel& nominal, const MeasurementSet& data,
                                             const CalibrationResult& result, int max_pairs = 5);

// Points whose error stays far out after the fit: |e| > t * s, with s a robust (median absolute
// deviation) estimate of the per-axis noise and t the larger of `threshold` and the level Gaussian
// noise alone reaches once in 100 data sets of this size (so that 10^6 clean points list nothing).
// Listed, never silently dropped.
struct Outlier {
  int row = 0;
  int64_t line = 0;  // line in the input file (0 when unknown)
  double error = 0;  // mm
  double sigmas = 0;
};
std::vector<Outlier> FindOutliers(const RobotModel& model, const MeasurementSet& data,
                                  double threshold = 5.0, double* robust_sigma = nullptr);
// The same from the errors of `model` on `data` collected by a pass that computed them
// (PositionErrorRows, e.g. the linear solver's last linearization): forward kinematics only for the
// rows above the threshold, which are decided and reported from their exact errors.
std::vector<Outlier> FindOutliers(const RobotModel& model, const MeasurementSet& data,
                                  const PositionErrorRows& errors, double threshold,
                                  double* robust_sigma);

// How rows are split for verification and cross-validation.
//   kRandom:     a seeded shuffle (portable: the same everywhere for a seed).
//   kSequential: contiguous blocks in file order (the held-out fraction is the last rows; fold i is
//                the i-th block). The honest estimate when the rows were measured one after another
//                and the cell drifts (temperature, settling): neighbours in time are not held out
//                together with their twins, as a random split would do.
enum class SplitKind { kRandom, kSequential };
bool ParseSplitKind(const std::string& text, SplitKind* kind);  // "random" | "sequential"
const char* SplitKindName(SplitKind kind);

std::vector<int> ShuffledIndices(int n, uint64_t seed);
// Rows held out for verification (a fraction of n, rounded) and the rest, both in file order.
void HoldoutSplit(int n, double fraction, uint64_t seed, std::vector<int>* identification,
                  std::vector<int>* verification, SplitKind kind = SplitKind::kRandom);
// k folds (sizes differ by at most one); fold i's verification rows, in file order.
std::vector<std::vector<int>> KFolds(int n, int k, uint64_t seed,
                                     SplitKind kind = SplitKind::kRandom);
// A frame direction left out because no configuration of this chain, with the measured tools
// where the data put them, can determine it (solvers/src/identifiability/structural_identifiability.h; "kept as
// given"), as opposed to the identifiable parameterization's own removals, a tool never measured
// or a joint-space combination.
bool IsStructurallyLost(const Direction& d);
// A direction of a fixed tool (Tool::fixed, --fixed_tools; its reason kFixedToolReason): held as
// given by the user, listed with the left-out directions but not counted as not identifiable.
bool IsHeldFixedTool(const Direction& d);

// The complement of `rows` in [0, n).
std::vector<int> Complement(int n, const std::vector<int>& rows);

// Splits by configuration: rows measured at the same joint values (several SMRs at one pose, or a
// pose measured twice) are one configuration and always go to the same side, so that no
// configuration is both identified and verified. group[r] is the configuration of row r, numbered
// in order of first appearance (joint values compared exactly, as read). Returns the number of
// configurations.
int ConfigurationGroups(const MeasurementSet& data, std::vector<int>* group);
// HoldoutSplit and KFolds over the configurations of `data` (the fraction and the folds count
// configurations, not rows); rows in file order. With one row per configuration they are the row
// splits above.
void HoldoutSplit(const MeasurementSet& data, double fraction, uint64_t seed,
                  std::vector<int>* identification, std::vector<int>* verification,
                  SplitKind kind = SplitKind::kRandom);
std::vector<std::vector<int>> KFolds(const MeasurementSet& data, int k, uint64_t seed,
                                     SplitKind kind = SplitKind::kRandom);

// Position-error covariance predicted at configuration q from the covariance of the identified
// parameters: J_q C J_q^T with J_q the position Jacobian restricted to the parameterization.
Eigen::Matrix3d PredictedPositionCovariance(const CalibrationResult& result, const double* q,
                                            int tool);

}  // namespace lpoe

#endif  // LPOE_ANALYSIS_H_
