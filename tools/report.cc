#include "report.h"

#include <nlohmann/json.hpp>

namespace lpoe {
namespace tools {
namespace {

// ordered_json keeps keys in insertion order, so reports diff cleanly.
using Json = nlohmann::ordered_json;

Json AxisJson(const AxisStatistics& a) {
  return Json{{"max", a.max_abs}, {"mean", a.mean_abs}, {"rms", a.rms}, {"p95", a.p95_abs}};
}

Json StatsJson(const ErrorStatistics& s) {
  return Json{{"count", s.count},
              {"x", AxisJson(s.axis[0])},
              {"y", AxisJson(s.axis[1])},
              {"z", AxisJson(s.axis[2])},
              {"norm", AxisJson(s.norm)}};
}

Json PoseJson(const SE3d& T) {
  const Eigen::Vector4d q = RotationToQuaternion(T.R);
  return Json{{"xyz", {T.t.x(), T.t.y(), T.t.z()}}, {"quaternion", {q(0), q(1), q(2), q(3)}}};
}

}  // namespace

std::string RunSummaryToJson(const RunSummary& s) {
  Json j;
  j["schema"] = "lpoe-calib/report/1";
  j["inputs"] = {{"model", s.model_path},
                 {"measurements", s.measurements_path},
                 {"verification", s.verification_source},
                 {"angle_unit", s.angle_unit},
                 {"skipped_rows", s.skipped.skipped_zero_rows},
                 {"skipped_lines", s.skipped.skipped_lines}};
  j["solver"] = {{"name", s.solver},
                 {"parameterization", s.parameterization},
                 {"data", s.data_kind},
                 {"termination", TerminationName(s.result.termination)},
                 {"converged", s.result.converged()},
                 {"message", s.result.message},
                 {"stop_rule", StopRuleName(s.result.stop_rule)},
                 {"iterations", s.result.iterations},
                 {"final_cost", s.result.final_cost}};
  // (No wall time: the same input must give a byte-identical report.)
  Json history = Json::array();
  for (const IterationRecord& r : s.result.history) {
    history.push_back({{"iteration", r.iteration},
                       {"max_error", r.max_error},
                       {"mean_error", r.mean_error},
                       {"cost", r.cost},
                       {"step_norm", r.step_norm}});
  }
  j["history"] = history;
  if (s.registered) {
    j["registration"] = {{"applied", s.registration.moved},
                         {"T_measurement_base", PoseJson(s.registration.T_measurement_base)},
                         {"rms_nominal", s.registration.rms_nominal},
                         {"rms_rigid", s.registration.rms_rigid},
                         {"rms_base_tools", s.registration.rms_base_tools}};
  } else {
    j["registration"] = nullptr;
  }
  const IdentifiabilityReport& id = s.identifiability;
  Json unident = Json::array();
  for (const Direction& d : id.unidentifiable) {
    unident.push_back({{"name", d.name}, {"reason", d.reason}});
  }
  Json params = Json::array();
  for (size_t k = 0; k < id.parameter_names.size(); ++k) {
    Json p = {{"name", id.parameter_names[k]}};
    p["std_dev"] = id.standard_deviation.size() > static_cast<Eigen::Index>(k)
                       ? Json(id.standard_deviation(k))
                       : Json(nullptr);
    params.push_back(p);
  }
  Json pairs = Json::array();
  for (const CorrelatedPair& c : id.most_correlated) {
    pairs.push_back({{"a", c.a}, {"b", c.b}, {"correlation", c.correlation}});
  }
  std::vector<double> sv(id.singular_values.data(),
                         id.singular_values.data() + id.singular_values.size());
  j["identifiability"] = {{"parameters", id.num_parameters},
                          {"rank", id.rank},
                          {"condition_number", id.condition_number},
                          {"singular_values", sv},
                          {"unidentifiable", unident},
                          {"identified", params},
                          {"most_correlated", pairs},
                          {"warnings", id.warnings}};
  j["identification"] = {{"before", StatsJson(s.identification_before)},
                         {"after", StatsJson(s.identification_after)}};
  if (s.has_verification) {
    j["verification"] = {{"before", StatsJson(s.verification_before)},
                         {"after", StatsJson(s.verification_after)}};
  } else {
    j["verification"] = nullptr;
  }
  Json outliers = Json::array();
  for (const Outlier& o : s.outliers) {
    outliers.push_back({{"line", o.line}, {"error", o.error}, {"sigmas", o.sigmas}});
  }
  j["outliers"] = {{"robust_sigma", s.robust_sigma}, {"points", outliers}};
  Json folds = Json::array();
  for (const FoldResult& f : s.folds) {
    folds.push_back({{"fold", f.fold},
                     {"identification_rows", f.identification_rows},
                     {"termination", f.termination},
                     {"verification_after", StatsJson(f.verification_after)}});
  }
  j["cross_validation"] = folds;
  Json frames = Json::array();
  for (const Joint& jt : s.result.model.joints) {
    frames.push_back({{"name", jt.name}, {"origin", PoseJson(jt.origin)}});
  }
  for (const Tool& t : s.result.model.tools) {
    frames.push_back({{"name", t.name}, {"origin", PoseJson(t.origin)}});
  }
  j["calibrated_frames"] = frames;
  Json checks = Json::array();
  for (const VerdictCheck& c : s.verdict.checks) {
    checks.push_back({{"name", c.name},
                      {"level", VerdictLevelName(c.level)},
                      {"value", c.value},
                      {"limit", c.limit},
                      {"message", c.message}});
  }
  j["verdict"] = {{"level", VerdictLevelName(s.verdict.level)},
                  {"reason", s.verdict.reason},
                  {"checks", checks}};
  j["outputs"] = s.outputs;
  return j.dump(2) + "\n";
}

}  // namespace tools
}  // namespace lpoe
