// The residual layer of a contact calibration in the reports (report/contact_layer_report.h).
#include "report/contact_layer_report.h"

#include <cstdio>
#include <vector>

#include <nlohmann/json.hpp>

#include "lpoe/model/residual_layer.h"
#include "report/report.h"
#include "report/text_safety.h"

namespace lpoe {
namespace tools {

// The residual layer's lines: the fit, its length scales and, per kind, the figures without and
// with it (identification, held out, k-fold). Empty when no layer was asked for.
std::string ContactLayerText(const ContactPipelineResult& run, int kfold) {
  const ContactLayerSummary& l = run.residual_layer;
  if (!l.requested) return "";
  char line[512];
  std::string selection;
  const ResidualModelSelection& sel = run.residual_model_selection;
  if (sel.ran) {
    std::snprintf(line, sizeof(line),
                  "residual model (auto): %d-fold cross-validation on the identification rows "
                  "(seed %llu), held-out contact error\n  model   CV rms (mm)   CV mse (mm^2)   "
                  "std error\n",
                  sel.folds, static_cast<unsigned long long>(sel.seed));
    selection = line;
    for (size_t k = 0; k < sel.candidates.size(); ++k) {
      const ResidualModelCandidate& c = sel.candidates[k];
      if (!c.ok) {
        std::snprintf(line, sizeof(line), "  %-5s   FAILED: %s\n", c.label.c_str(),
                      c.failure.c_str());
      } else {
        std::snprintf(line, sizeof(line), "  %-5s   %11.5f   %13.6g   %9.3g%s\n",
                      c.label.c_str(), c.cv_rms, c.cv_mse, c.cv_mse_se,
                      static_cast<int>(k) == sel.chosen ? "   <- chosen" : "");
      }
      selection += line;
    }
    selection += "  " + sel.reason + "\n";
  }
  if (!l.fitted) return selection + "residual layer: none (" + l.message + ")\n";
  const ResidualLayer& layer = *run.calibration.model.residual_layer;
  std::snprintf(line, sizeof(line),
                "residual layer: Gaussian process on projected rows (docs/residual_layer.md), %d "
                "inducing inputs, signal %.4g mm, noise %.4g mm\n",
                l.inducing, layer.signal_std, layer.noise_std);
  std::string out = selection + line;
  out += ResidualLayerLengthScalesText(layer, l.fit, run.calibration.model);
  for (const ContactKindSummary& k : run.kinds) {
    std::snprintf(line, sizeof(line), "  %s: RMS %.5f -> %.5f mm with the layer", k.kind->name,
                  k.fit.rms, k.fit_with_layer.rms);
    out += line;
    if (k.held.rows > 0) {
      std::snprintf(line, sizeof(line), "; held-out RMS %.5f mm without it, %.5f mm with it",
                    k.held_parametric.rms, k.held.rms);
      out += line;
    }
    if (kfold > 0) {
      std::snprintf(line, sizeof(line), "; k-fold RMS %.5f mm without it, %.5f mm with it",
                    k.kfold_parametric.rms, k.kfold.rms);
      out += line;
    }
    out += "\n";
  }
  return out;
}

std::string ContactLayerJsonText(const ContactPipelineResult& run, const std::string& requested) {
  const ContactLayerSummary& l = run.residual_layer;
  nlohmann::json j = {{"requested", requested}, {"fitted", l.fitted}, {"message", l.message}};
  const ResidualModelSelection& sel = run.residual_model_selection;
  if (sel.ran) {
    nlohmann::json candidates = nlohmann::json::array();
    for (const ResidualModelCandidate& c : sel.candidates) {
      candidates.push_back({{"model", c.label},
                            {"ok", c.ok},
                            {"failure", c.failure},
                            {"cv_rms", c.cv_rms},
                            {"cv_mse", c.cv_mse},
                            {"cv_mse_standard_error", c.cv_mse_se},
                            {"fold_rms", c.fold_rms}});
    }
    j["selection"] = {{"folds", sel.folds},
                      {"seed", sel.seed},
                      {"candidates", candidates},
                      {"best", sel.best},
                      {"chosen", sel.chosen},
                      {"reason", sel.reason}};
  } else {
    j["selection"] = nullptr;
  }
  if (!l.fitted) {
    j["layer"] = nullptr;
    return j.dump();
  }
  const ResidualLayer& layer = *run.calibration.model.residual_layer;
  std::vector<double> scales(layer.length_scales.data(),
                             layer.length_scales.data() + layer.length_scales.size());
  std::vector<double> spacing(l.fit.spacing.data(), l.fit.spacing.data() + l.fit.spacing.size());
  std::vector<int> short_joints;
  for (int joint : JointsBelowSpacing(layer.length_scales, l.fit.spacing)) {
    short_joints.push_back(joint + 1);
  }
  j["layer"] = {{"kernel", ResidualLayer::kKernel},
                {"frame", ResidualLayer::kFrame},
                {"observations", "projected"},
                {"inducing", layer.num_inducing()},
                {"length_scales", scales},
                {"tool_correlation", layer.tool_correlation},
                {"signal_std", layer.signal_std},
                {"noise_std", layer.noise_std},
                {"hyperparameter_rows", l.fit.hyperparameter_rows},
                {"log_marginal_likelihood", l.fit.log_marginal_likelihood},
                {"start_loo_rms", l.fit.start_loo_rms},
                {"chosen_start", l.fit.chosen_start},
                {"inducing_coverage", l.fit.inducing_coverage},
                {"spacing", spacing},
                {"length_scales_below_spacing", short_joints}};
  nlohmann::json kinds = nlohmann::json::array();
  for (const ContactKindSummary& k : run.kinds) {
    nlohmann::json e = {{"kind", k.kind->name},
                        {"rms_mm_without_layer", k.fit.rms},
                        {"rms_mm_with_layer", k.fit_with_layer.rms}};
    if (k.held.rows > 0) {
      e["held_out_rms_mm_without_layer"] = k.held_parametric.rms;
      e["held_out_rms_mm_with_layer"] = k.held.rms;
    }
    if (k.kfold_parametric.rows > 0) {
      e["kfold_rms_mm_without_layer"] = k.kfold_parametric.rms;
      e["kfold_rms_mm_with_layer"] = k.kfold.rms;
    }
    kinds.push_back(e);
  }
  j["kinds"] = kinds;
  return j.dump();
}

// Keys in insertion order (ordered_json): Python's report keeps them as written; the tool's
// nlohmann::json sorts them as it sorts the rest of its report.
std::string ContactSelectionJsonText(const JointErrorSelection& sel) {
  nlohmann::ordered_json candidates = nlohmann::ordered_json::array();
  for (const JointErrorCandidate& c : sel.candidates) {
    nlohmann::ordered_json j;
    j["terms"] = c.label;
    j["converged"] = c.ok;
    j["failure"] = c.failure;
    j["identified_combinations"] = c.parameters;
    j["fold_rms"] = c.fold_rms;
    if (c.ok) {
      j["cv_rms"] = c.cv_rms;
      j["cv_mse"] = c.cv_mse;
      j["cv_mse_standard_error"] = c.cv_mse_se;
    }
    candidates.push_back(std::move(j));
  }
  nlohmann::ordered_json out;
  out["folds"] = sel.folds;
  out["seed"] = sel.seed;
  out["candidates"] = std::move(candidates);
  out["best"] = sel.best >= 0 ? sel.candidates[sel.best].label : std::string();
  out["chosen"] = sel.candidates[sel.chosen].label;
  out["reason"] = sel.reason;
  out["tilt_message"] = sel.Bilinear(kGravityTiltName).message;
  return out.dump();
}

namespace {

// One pivot's or plane's figures in a kind's entry.
nlohmann::ordered_json ContactFeatureJson(const ContactFeatureSummary& s, int kfold) {
  nlohmann::ordered_json j;
  j["name"] = ValidUtf8(s.name);
  j["rows"] = s.fit.rows;
  j["rms_mm"] = s.fit.rms;
  j["max_abs_mm"] = s.fit.max_abs;
  j["expected_noise_mm"] = s.fit.sigma;
  j["verdict"] = ContactKindVerdict(s.fit);
  if (s.held.rows > 0) {
    j["held_out_rows"] = s.held.rows;
    j["held_out_rms_mm"] = s.held.rms;
  }
  if (kfold > 0) j["kfold_rms_mm"] = s.kfold.rms;
  return j;
}

// One kind's entry: the figures of lpoe_calibrate's table per kind.
nlohmann::ordered_json ContactKindJson(const ContactKindSummary& summary, bool verify_given,
                                       int kfold) {
  const ContactKindFigures& f = summary.fit;
  const ContactKindFigures& h = summary.held;
  nlohmann::ordered_json j;
  j["kind"] = summary.kind->name;
  j["table"] = summary.kind->report_table;
  j["rows"] = f.rows;
  j["rms_mm"] = f.rms;
  j["max_abs_mm"] = f.max_abs;
  j["expected_noise_mm"] = f.sigma;
  j["verdict"] = ContactKindVerdict(f);
  if (h.rows > 0) {
    j["held_out_rows"] = h.rows;
    j["held_out_rms_mm"] = h.rms;
    // The verification table (verify or holdout): the kind's figures on rows not fitted.
    nlohmann::ordered_json v;
    v["source"] = verify_given ? "verify" : "holdout";
    v["rows"] = h.rows;
    v["rms_mm"] = h.rms;
    v["max_abs_mm"] = h.max_abs;
    v["expected_noise_mm"] = h.sigma;
    v["verdict"] = ContactKindVerdict(h);
    j["verification"] = std::move(v);
  }
  if (kfold > 0) {
    const ContactKindFigures& cv = summary.kfold;
    nlohmann::ordered_json k;
    k["folds"] = kfold;
    k["rows"] = cv.rows;
    k["rms_mm"] = cv.rms;
    k["max_abs_mm"] = cv.max_abs;
    j["kfold"] = std::move(k);
  }
  if (!summary.features.empty()) {
    // The kind's figures per pivot (distance) or per plane (plane).
    nlohmann::ordered_json features = nlohmann::ordered_json::array();
    for (const ContactFeatureSummary& s : summary.features) {
      features.push_back(ContactFeatureJson(s, kfold));
    }
    j["features"] = std::move(features);
  }
  return j;
}

}  // namespace

std::string ContactReportJsonText(const ContactPipelineResult& run, bool verify_given, int kfold,
                                  const std::string& residual_model) {
  using Json = nlohmann::ordered_json;
  const ContactCalibrationResult& result = run.calibration;
  const ContactMeasurementSet& identification = run.identification;
  const ContactParameterization& p = result.parameterization;
  Json kinds = Json::array(), pivots = Json::array(), planes = Json::array();
  for (const ContactKindSummary& summary : run.kinds) {
    kinds.push_back(ContactKindJson(summary, verify_given, kfold));
  }
  for (size_t k = 0; k < result.features.pivots.size(); ++k) {
    const Eigen::Vector3d& c = result.features.pivots[k];
    Json e;
    e["name"] = ValidUtf8(identification.pivots[k]);
    e["xyz_mm"] = {c(0), c(1), c(2)};
    pivots.push_back(std::move(e));
  }
  for (size_t k = 0; k < result.features.planes.size(); ++k) {
    const Eigen::Vector4d& pl = result.features.planes[k];
    Json e;
    e["name"] = ValidUtf8(identification.planes[k]);
    e["normal"] = {pl(0), pl(1), pl(2)};
    e["offset_mm"] = pl(3);
    planes.push_back(std::move(e));
  }
  Json left_out = Json::array();
  for (const Direction& d : p.frames.unidentifiable) {
    Json e;
    e["name"] = ValidUtf8(d.name);
    e["reason"] = d.reason;
    left_out.push_back(std::move(e));
  }
  // The joint-space terms' values (what the YAML's joint_errors carries).
  Json joint_terms = Json::array();
  for (size_t b = 0; b < result.joint_terms.size(); ++b) {
    const JointTermValues& t = result.joint_terms[b];
    Json e, values = Json::object();
    e["term"] = t.term->name();
    e["parameters"] = t.term->num_parameters();
    e["identified_combinations"] = static_cast<int>(p.frames.joint_blocks[b].basis.cols());
    for (int k = 0; k < t.theta.size(); ++k) values[t.term->ParameterName(k)] = t.theta(k);
    e["values"] = std::move(values);
    joint_terms.push_back(std::move(e));
  }
  Json j;
  j["solver"] = result.solver;
  j["iterations"] = result.iterations;
  j["cost_before"] = result.initial_cost;
  j["cost_after"] = result.cost;
  j["measurement_kinds"] = std::move(kinds);
  j["features"]["pivots"] = std::move(pivots);
  j["features"]["planes"] = std::move(planes);
  j["parameters"] = p.frames.num_parameters + 3 * p.num_pivots + 3 * p.num_planes;
  j["base"]["directions_left_out"] = p.num_base_directions;
  j["base"]["reason"] = p.base_reason;
  j["scale"]["held"] = p.scale_held;
  j["scale"]["reason"] = p.scale_reason;
  j["scale"]["value"] = result.scale;
  j["left_out"] = std::move(left_out);
  j["joint_errors"] = std::move(joint_terms);
  if (run.joint_error_selection.ran) {
    j["joint_error_selection"] = Json::parse(ContactSelectionJsonText(run.joint_error_selection));
  }
  j["residual_layer"] = Json::parse(ContactLayerJsonText(run, residual_model));
  return j.dump();
}

}  // namespace tools
}  // namespace lpoe
