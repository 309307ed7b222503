#include "lpoe/analysis.h"

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <cmath>
#include <numeric>
#include <random>
#include <sstream>
#include <vector>

#include <glog/logging.h>

#include "lpoe/kinematics/kinematics.h"
#include "lpoe/measurements/measurement_model.h"
#include "lpoe/model/parameterization.h"
#include "lpoe/parallel.h"
#include "lpoe/model/statistics.h"

namespace lpoe {
namespace {

// P(|e| > t) for e ~ N(0, I3): erfc(t / sqrt 2) + sqrt(2 / pi) t exp(-t^2 / 2).
double Chi3Survival(double t) {
  return std::erfc(t / std::sqrt(2.0)) + std::sqrt(2.0 / M_PI) * t * std::exp(-0.5 * t * t);
}

// t with Chi3Survival(t) = p, by bisection (p in (0, 1)).
double Chi3Quantile(double p) {
  double lo = 0, hi = 40;
  for (int k = 0; k < 100; ++k) {
    const double mid = 0.5 * (lo + hi);
    (Chi3Survival(mid) > p ? lo : hi) = mid;
  }
  return hi;
}

}  // namespace

IdentifiabilityReport AnalyzeIdentifiability(const RobotModel& nominal, const MeasurementSet& data,
                                             const CalibrationResult& result, int max_pairs) {
  IdentifiabilityReport r;
  const Parameterization& p = result.parameterization;
  r.num_parameters = p.num_parameters;
  r.rank = result.rank;
  r.condition_number = result.condition_number;
  r.singular_values = result.singular_values;
  r.unidentifiable = p.unidentifiable;
  for (const Direction& d : p.parameters) r.parameter_names.push_back(d.name);

  const Eigen::MatrixXd& C = result.covariance;
  if (C.rows() == p.num_parameters && C.rows() > 0) {
    r.standard_deviation = C.diagonal().cwiseMax(0.0).cwiseSqrt();
    std::vector<CorrelatedPair> pairs;
    for (int i = 0; i < C.rows(); ++i) {
      for (int j = i + 1; j < C.cols(); ++j) {
        const double denom = r.standard_deviation(i) * r.standard_deviation(j);
        if (!(denom > 0)) continue;
        pairs.push_back({r.parameter_names[i], r.parameter_names[j], C(i, j) / denom});
      }
    }
    const size_t keep = std::min<size_t>(pairs.size(), std::max(0, max_pairs));
    std::partial_sort(pairs.begin(), pairs.begin() + keep, pairs.end(),
                      [](const CorrelatedPair& a, const CorrelatedPair& b) {
                        return std::abs(a.correlation) > std::abs(b.correlation);
                      });
    pairs.resize(keep);
    r.most_correlated = std::move(pairs);
  }

  // Excitation: a joint that barely moves leaves its frame poorly determined. The ranges of every
  // joint in one pass over the rows (in memory order).
  const int joints = std::min(nominal.num_joints(), data.num_joints());
  std::vector<double> lows(joints), highs(joints);
  if (!data.empty()) {
    for (int i = 0; i < joints; ++i) lows[i] = highs[i] = data.q(0)[i];
    for (int k = 1; k < data.size(); ++k) {
      const double* q = data.q(k);
      for (int i = 0; i < joints; ++i) {
        lows[i] = std::min(lows[i], q[i]);
        highs[i] = std::max(highs[i], q[i]);
      }
    }
  }
  for (int i = 0; i < joints && !data.empty(); ++i) {
    const double lo = lows[i], hi = highs[i];
    const bool revolute = nominal.joints[i].type == JointType::kRevolute;
    const double limit = revolute ? kMinRevoluteExcursion : kMinPrismaticExcursion;
    if (hi - lo < limit) {
      std::ostringstream os;
      os << nominal.joints[i].name << " barely moves over the data ("
         << (revolute ? (hi - lo) * 180.0 / M_PI : hi - lo) << (revolute ? " deg" : " mm")
         << " range, less than " << (revolute ? limit * 180.0 / M_PI : limit)
         << (revolute ? " deg" : " mm")
         << "): the parameters near it are poorly determined; add poses that move it";
      r.warnings.push_back(os.str());
    }
  }
  if (result.has_prior() && result.data_share.size() == p.num_parameters) {
    r.prior_standard_deviation = result.prior_standard_deviation;
    r.data_share = result.data_share;
    r.prior_data_sigma = result.prior_data_sigma;
    for (int k = 0; k < p.num_parameters; ++k) {
      if (result.data_share(k) < kWeaklyDeterminedShare) r.weakly_determined.push_back(p.parameters[k].name);
    }
    // What was done about a joint that barely moves (or any weak direction): the prior held them.
    if (!r.weakly_determined.empty()) {
      for (std::string& w : r.warnings) {
        if (w.find("barely moves") == std::string::npos) continue;
        w += "; the prior held the " + std::to_string(r.weakly_determined.size()) +
             " weakly determined directions at the start model (see 'weakly determined')";
      }
    }
  }
  if (r.condition_number > kWarnConditionNumber) {
    std::ostringstream os;
    os << "the column-scaled Jacobian is poorly conditioned (condition number "
       << r.condition_number << " > " << kWarnConditionNumber
       << "): the data excite some directions weakly";
    r.warnings.push_back(os.str());
  }
  return r;
}

std::vector<Outlier> FindOutliers(const RobotModel& model, const MeasurementSet& data,
                                  double threshold, double* robust_sigma) {
  // Memory: 16 bytes a row (float components and norms), not the 48 of double errors plus their
  // components, so that 10^7 rows fit in 1 GB with their data.
  PositionErrorRows errors;
  CollectPositionErrors(model, data, &errors);
  return FindOutliers(model, data, errors, threshold, robust_sigma);
}

std::vector<Outlier> FindOutliers(const RobotModel& model, const MeasurementSet& data,
                                  const PositionErrorRows& errors, double threshold,
                                  double* robust_sigma) {
  // The median is that of the rounded components (relative 6e-8); the rows above the threshold are
  // then decided and reported from their exact errors.
  CHECK_EQ(errors.size(), data.size()) << "errors collected on other data";
  const int n = data.size();
  std::vector<Outlier> out;
  if (n == 0) return out;
  const double sigma = std::max(1.4826 * errors.MedianAbsComponent(), 1e-9);
  if (robust_sigma) *robust_sigma = sigma;
  // |e| of a 3-D Gaussian exceeds 5 sigma with probability ~1e-5, so large data sets would list
  // noise as outliers: raise the threshold to the level pure noise reaches once in 100 data sets of
  // this size (chi distribution with 3 degrees of freedom).
  const double t = std::max(threshold, Chi3Quantile(0.01 / std::max(1, data.size())));
  constexpr double kFloatMargin = 1e-6;  // candidates by the rounded norm, decided exactly
  for (int k = 0; k < n; ++k) {
    if (static_cast<double>(errors.norm(k)) <= t * sigma * (1 - kFloatMargin)) continue;
    const double e =
        (data.position(k) - ToolPosition(model, data.q(k), data.target(k))).norm();
    if (e > t * sigma) out.push_back({k, data.source_line(k), e, e / sigma});
  }
  std::sort(out.begin(), out.end(),
            [](const Outlier& a, const Outlier& b) { return a.error > b.error; });
  return out;
}

std::vector<int> ShuffledIndices(int n, uint64_t seed) {
  std::vector<int> rows(n);
  std::iota(rows.begin(), rows.end(), 0);
  std::mt19937_64 rng(seed);
  for (int i = n - 1; i > 0; --i) {
    const int j = static_cast<int>(rng() % static_cast<uint64_t>(i + 1));
    std::swap(rows[i], rows[j]);
  }
  return rows;
}

std::vector<int> Complement(int n, const std::vector<int>& rows) {
  std::vector<char> used(n, 0);
  for (int r : rows) used[r] = 1;
  std::vector<int> out;
  for (int r = 0; r < n; ++r) {
    if (!used[r]) out.push_back(r);
  }
  return out;
}

bool IsHeldFixedTool(const Direction& d) { return d.reason == kFixedToolReason; }

bool ParseSplitKind(const std::string& text, SplitKind* kind) {
  if (text == "random") {
    *kind = SplitKind::kRandom;
    return true;
  }
  if (text == "sequential") {
    *kind = SplitKind::kSequential;
    return true;
  }
  return false;
}

const char* SplitKindName(SplitKind kind) {
  return kind == SplitKind::kSequential ? "sequential" : "random";
}

void HoldoutSplit(int n, double fraction, uint64_t seed, std::vector<int>* identification,
                  std::vector<int>* verification, SplitKind kind) {
  const int held = static_cast<int>(std::lround(fraction * n));
  if (kind == SplitKind::kSequential) {
    verification->resize(held);
    std::iota(verification->begin(), verification->end(), n - held);
  } else {
    const std::vector<int> order = ShuffledIndices(n, seed);
    verification->assign(order.begin(), order.begin() + held);
    std::sort(verification->begin(), verification->end());
  }
  *identification = Complement(n, *verification);
}

std::vector<std::vector<int>> KFolds(int n, int k, uint64_t seed, SplitKind kind) {
  CHECK_GE(k, 2);
  std::vector<std::vector<int>> folds(k);
  if (kind == SplitKind::kSequential) {
    // Block f is [f n / k, (f + 1) n / k): sizes differ by at most one, like the random folds.
    for (int f = 0; f < k; ++f) {
      const int begin = static_cast<int>(static_cast<int64_t>(f) * n / k);
      const int end = static_cast<int>(static_cast<int64_t>(f + 1) * n / k);
      for (int i = begin; i < end; ++i) folds[f].push_back(i);
    }
    return folds;
  }
  const std::vector<int> order = ShuffledIndices(n, seed);
  for (int i = 0; i < n; ++i) folds[i % k].push_back(order[i]);
  for (auto& f : folds) std::sort(f.begin(), f.end());
  return folds;
}

int ConfigurationGroups(const MeasurementSet& data, std::vector<int>* group) {
  const int n = data.size();
  const int nj = data.num_joints();
  // Rows sorted by a hash of their joint values (then by row): equal configurations are neighbours
  // with equal hashes; within a run of equal hashes the values are compared. 16 bytes a row.
  std::vector<std::pair<uint64_t, int>> keys(static_cast<size_t>(n));
  for (int r = 0; r < n; ++r) {
    const double* q = data.q(r);
    uint64_t h = 1469598103934665603ull;
    for (int j = 0; j < nj; ++j) {
      const double v = q[j] == 0.0 ? 0.0 : q[j];  // -0 and +0 are one value
      uint64_t bits;
      std::memcpy(&bits, &v, sizeof bits);
      h = (h ^ bits) * 1099511628211ull;
      h ^= h >> 29;
    }
    keys[r] = {h, r};
  }
  std::sort(keys.begin(), keys.end());
  // first[r]: the first row (in file order) with row r's joint values.
  group->assign(static_cast<size_t>(n), -1);
  std::vector<int>& first = *group;
  std::vector<int> firsts_in_run;
  for (size_t a = 0; a < keys.size();) {
    size_t b = a;
    while (b < keys.size() && keys[b].first == keys[a].first) ++b;
    firsts_in_run.clear();
    for (size_t k = a; k < b; ++k) {  // rows ascending within the run
      const int r = keys[k].second;
      const double* q = data.q(r);
      for (int f : firsts_in_run) {
        if (std::equal(q, q + nj, data.q(f))) {
          first[r] = f;
          break;
        }
      }
      if (first[r] < 0) {
        first[r] = r;
        firsts_in_run.push_back(r);
      }
    }
    a = b;
  }
  // Numbered in order of first appearance (first[r] <= r, so its number is known).
  int groups = 0;
  for (int r = 0; r < n; ++r) first[r] = first[r] == r ? groups++ : first[first[r]];
  return groups;
}

namespace {

// The rows of the configurations `chosen` (indices into groups), in file order.
std::vector<int> RowsOfGroups(const std::vector<int>& group, int groups,
                              const std::vector<int>& chosen) {
  std::vector<bool> take(groups, false);
  for (int g : chosen) take[g] = true;
  std::vector<int> rows;
  for (int r = 0; r < static_cast<int>(group.size()); ++r) {
    if (take[group[r]]) rows.push_back(r);
  }
  return rows;
}

}  // namespace

void HoldoutSplit(const MeasurementSet& data, double fraction, uint64_t seed,
                  std::vector<int>* identification, std::vector<int>* verification,
                  SplitKind kind) {
  std::vector<int> group;
  const int groups = ConfigurationGroups(data, &group);
  std::vector<int> id_groups, ver_groups;
  HoldoutSplit(groups, fraction, seed, &id_groups, &ver_groups, kind);
  *verification = RowsOfGroups(group, groups, ver_groups);
  *identification = Complement(data.size(), *verification);
}

std::vector<std::vector<int>> KFolds(const MeasurementSet& data, int k, uint64_t seed,
                                     SplitKind kind) {
  std::vector<int> group;
  const int groups = ConfigurationGroups(data, &group);
  std::vector<std::vector<int>> folds = KFolds(groups, k, seed, kind);
  for (auto& f : folds) f = RowsOfGroups(group, groups, f);
  return folds;
}

Eigen::Matrix3d PredictedPositionCovariance(const CalibrationResult& result, const double* q,
                                            int tool) {
  const Parameterization& p = result.parameterization;
  CHECK_EQ(result.covariance.rows(), p.num_parameters) << "no covariance in this result";
  Eigen::MatrixXd J;
  PredictPositionJacobian(result.model, p, result.joint_terms, q, tool, &J);
  return J * result.covariance * J.transpose();
}

}  // namespace lpoe
