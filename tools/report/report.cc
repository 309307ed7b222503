#include "report/report.h"

#include "lpoe/model/residual_layer.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>

#include <sys/stat.h>

#include <nlohmann/json.hpp>
#include <tinyxml2.h>

#include "lpoe/analysis.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/version.h"
#include "report/json_text.h"
#include "report/plot.h"


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

Json VectorJson(const Eigen::Vector3d& v) { return Json::array({v.x(), v.y(), v.z()}); }

std::string ToolName(const RobotModel& model, int target) {
  return target >= 0 && target < model.num_tools() ? model.tools[target].name
                                                    : std::to_string(target);
}

ErrorStatistics StatsOf(const std::vector<PointResidual>& points, int target, bool after) {
  std::vector<Eigen::Vector3d> e;
  for (const PointResidual& p : points)
    if (target < 0 || p.target == target) e.push_back(after ? p.after : p.before);
  return ComputeStatistics(e);
}

Json PointsJson(const RobotModel& model, const std::vector<PointResidual>& points) {
  Json a = Json::array();
  for (const PointResidual& p : points) {
    a.push_back({{"line", p.line},
                 {"target", ToolName(model, p.target)},
                 {"before", VectorJson(p.before)},
                 {"after", VectorJson(p.after)}});
  }
  return a;
}

// The local frame f of a model (joints first, then tools).
const SE3d& FrameOrigin(const RobotModel& m, int f) {
  return f < m.num_joints() ? m.joints[f].origin : m.tools[f - m.num_joints()].origin;
}

Json BuildJson(const RunSummary& s, bool with_points);

constexpr double kDegrees = 180.0 / M_PI;

Json Vector3Json(const Eigen::Vector3d& v) { return Json::array({v(0), v(1), v(2)}); }

// The gravity tilt (docs/joint_errors.md, "Gravity tilt"): null unless asked for.
Json GravityTiltJson(const GravityTiltResult& t) {
  if (!t.requested) return nullptr;
  const double finite_sd0 = std::isfinite(t.predicted_standard_deviation(0))
                                ? t.predicted_standard_deviation(0) * kDegrees
                                : -1.0;
  const double finite_sd1 = std::isfinite(t.predicted_standard_deviation(1))
                                ? t.predicted_standard_deviation(1) * kDegrees
                                : -1.0;
  return {{"identified", t.identified},
          {"tilt_deg", Json::array({t.tilt(0) * kDegrees, t.tilt(1) * kDegrees})},
          {"std_dev_deg", Json::array({t.standard_deviation(0) * kDegrees,
                                       t.standard_deviation(1) * kDegrees})},
          {"std_dev_form", "a posteriori"},
          {"std_dev_deg_a_priori",
           t.a_priori_standard_deviation.maxCoeff() > 0
               ? Json::array({t.a_priori_standard_deviation(0) * kDegrees,
                              t.a_priori_standard_deviation(1) * kDegrees})
               : Json(nullptr)},
          {"angle_deg", t.tilt.norm() * kDegrees},
          {"axes", Json::array({Vector3Json(t.axes.col(0)), Vector3Json(t.axes.col(1))})},
          {"gravity_before", Vector3Json(t.gravity_before)},
          {"gravity_after", Vector3Json(t.gravity_after)},
          {"kept_fraction", t.kept_fraction},
          {"predicted_std_dev_deg", Json::array({finite_sd0, finite_sd1})},
          {"message", t.message}};
}

// One candidate of an automatic choice (--joint_errors=auto, --residual_model=auto): its label
// and success under the keys its section names them by, the failure, `middle`'s keys, the
// cross-validated score, then `tail`'s keys.
Json CandidateJson(const CrossValidatedCandidate& c, const char* label_key, const char* ok_key,
                   const Json& middle, const Json& tail) {
  Json j = {{label_key, c.label}, {ok_key, c.ok}, {"failure", c.failure}};
  for (const auto& item : middle.items()) j[item.key()] = item.value();
  j["cv_rms"] = c.cv_rms;
  j["cv_mse"] = c.cv_mse;
  j["cv_mse_standard_error"] = c.cv_mse_se;
  j["fold_rms"] = c.fold_rms;
  for (const auto& item : tail.items()) j[item.key()] = item.value();
  return j;
}

// The "selection" of an automatic choice: its folds, every candidate (written by `candidate`), the
// best and the chosen one and why.
template <typename Selection, typename CandidateWriter>
Json SelectionJson(const Selection& sel, CandidateWriter candidate) {
  const CrossValidationChoice& choice = sel;
  Json candidates = Json::array();
  for (const auto& c : sel.candidates) candidates.push_back(candidate(c));
  return {{"folds", choice.folds},
          {"split", SplitKindName(choice.split)},
          {"seed", choice.seed},
          {"candidates", candidates},
          {"best", sel.candidates[choice.best < 0 ? choice.chosen : choice.best].label},
          {"chosen", sel.candidates[choice.chosen].label},
          {"reason", choice.reason}};
}

// The joint-error terms: what was asked, the auto choice, and each term's identifiable combinations.
Json JointErrorsJson(const RunSummary& s) {
  Json terms = Json::array();
  const Parameterization& par = s.result.parameterization;
  for (size_t b = 0; b < par.joint_blocks.size(); ++b) {
    const JointBlock& block = par.joint_blocks[b];
    Json lost = Json::array();
    for (const Direction& d : par.unidentifiable) {
      if (d.joint_block == static_cast<int>(b)) lost.push_back({{"name", d.name}, {"reason", d.reason}});
    }
    terms.push_back({{"name", block.term->name()},
                     {"parameters", block.term->num_parameters()},
                     {"identified_combinations", block.basis.cols()},
                     {"not_identifiable", lost}});
  }
  Json j = {{"requested", s.joint_errors_requested}, {"terms", terms}};
  j["gravity_tilt"] = GravityTiltJson(s.result.gravity_tilt);
  const JointErrorSelection& sel = s.joint_error_selection;
  if (!sel.ran) {
    j["selection"] = nullptr;
    return j;
  }
  j["selection"] = SelectionJson(sel, [](const JointErrorCandidate& c) {
    return CandidateJson(c, "terms", "converged",
                         Json::object({{"identified_combinations", c.parameters}}),
                         Json::object({{"tilt_identified_folds",
                                        c.IdentifiedFolds(kGravityTiltName)}}));
  });
  const BilinearCandidacy tilt = sel.Bilinear(kGravityTiltName);
  j["selection"]["tilt_candidates"] = tilt.candidates;
  j["selection"]["tilt_message"] = tilt.message;
  return j;
}

// The residual layer: what was asked, the auto choice and the fitted layer's figures.
Json ResidualModelJson(const RunSummary& s) {
  const ResidualLayerSummary& l = s.residual_layer;
  Json j = {{"requested", s.residual_model_requested},
            {"fitted", l.fitted},
            {"message", l.message}};
  const ResidualLayer* layer = s.result.model.residual_layer.get();
  if (l.fitted && layer != nullptr) {
    std::vector<double> scales(layer->length_scales.data(),
                               layer->length_scales.data() + layer->length_scales.size());
    j["layer"] = {{"kernel", ResidualLayer::kKernel},
                  {"frame", ResidualLayer::kFrame},
                  {"inducing", layer->num_inducing()},
                  {"length_scales", scales},
                  {"tool_correlation", layer->tool_correlation},
                  {"signal_std", layer->signal_std},
                  {"noise_std", layer->noise_std},
                  {"hyperparameter_rows", l.fit.hyperparameter_rows},
                  {"iterations", l.fit.iterations},
                  {"log_marginal_likelihood", l.fit.log_marginal_likelihood},
                  {"configurations", l.fit.configurations},
                  {"configuration_std", l.fit.configuration_std},
                  {"start_loo_rms", l.fit.start_loo_rms},
                  {"chosen_start", l.fit.chosen_start},
                  {"inducing_coverage", l.fit.inducing_coverage}};
    std::vector<double> spacing(l.fit.spacing.data(), l.fit.spacing.data() + l.fit.spacing.size());
    j["layer"]["spacing"] = spacing;
    std::vector<int> short_joints;
    for (int joint : JointsBelowSpacing(layer->length_scales, l.fit.spacing)) {
      short_joints.push_back(joint + 1);
    }
    j["layer"]["length_scales_below_spacing"] = short_joints;
    j["identification_with_layer"] = StatsJson(l.identification_with_layer);
    j["verification_without_layer"] =
        s.has_verification ? StatsJson(l.verification_parametric) : Json(nullptr);
  } else {
    j["layer"] = nullptr;
  }
  const ResidualModelSelection& sel = s.residual_model_selection;
  if (!sel.ran) {
    j["selection"] = nullptr;
    return j;
  }
  j["selection"] = SelectionJson(sel, [](const ResidualModelCandidate& c) {
    return CandidateJson(c, "model", "ok", Json::object(), Json::object());
  });
  return j;
}

// "<k>-fold cross-validation<how> on the identification rows (<seed or contiguous folds>),
// held-out position error\n": the first line of a selection's table.
std::string FoldsHeading(const CrossValidationChoice& sel, const char* how,
                         const std::string& error = "position error") {
  return std::to_string(sel.folds) + "-fold cross-validation" + how +
         " on the identification rows (" +
         (sel.split == SplitKind::kSequential ? std::string("contiguous folds")
                                              : "seed " + std::to_string(sel.seed)) +
         "), held-out " + error + "\n";
}

}  // namespace

std::string ResidualModelSelectionTable(const ResidualModelSelection& sel) {
  std::string out = "residual model (auto): " + FoldsHeading(sel, " by configuration");
  out += "  model   CV rms (mm)   CV mse (mm^2)   std error\n";
  char line[512];
  for (size_t k = 0; k < sel.candidates.size(); ++k) {
    const ResidualModelCandidate& c = sel.candidates[k];
    if (!c.ok) {
      std::snprintf(line, sizeof(line), "  %-5s   FAILED: %s\n", c.label.c_str(),
                    c.failure.c_str());
    } else {
      std::snprintf(line, sizeof(line), "  %-5s   %11.5f   %13.6g   %9.3g%s\n", c.label.c_str(),
                    c.cv_rms, c.cv_mse, c.cv_mse_se,
                    static_cast<int>(k) == sel.chosen ? "   <- chosen" : "");
    }
    out += line;
  }
  out += "  " + sel.reason + "\n";
  return out;
}

std::string ResidualLayerLengthScalesText(const ResidualLayer& layer, const ResidualLayerFit& fit,
                                          const RobotModel& model) {
  std::string out = "  length scales (rad; mm for prismatic joints):";
  char buf[96];
  for (int j = 0; j < layer.length_scales.size(); ++j) {
    const std::string name =
        j < model.num_joints() ? model.joints[j].name : "joint" + std::to_string(j + 1);
    std::snprintf(buf, sizeof(buf), " %s %.3g", name.c_str(), layer.length_scales(j));
    out += buf;
  }
  std::snprintf(buf, sizeof(buf), "; tool correlation %.3g; configuration error %.3g mm\n",
                layer.tool_correlation, fit.configuration_std);
  out += buf;
  if (fit.chosen_start == 2) {
    return out + "  the fit's leave-one-configuration-out check found no signal it can predict: "
                 "the layer's corrections are nil (docs/residual_layer.md)\n";
  }
  for (int j : JointsBelowSpacing(layer.length_scales, fit.spacing)) {
    const std::string name =
        j < model.num_joints() ? model.joints[j].name : "joint" + std::to_string(j + 1);
    std::snprintf(buf, sizeof(buf), "%.3g below the data's spacing %.3g", layer.length_scales(j),
                  fit.spacing(j));
    out += "  warning: the length scale of " + name + " is " + buf +
           ": the layer reproduces its identification rows there and predicts little between "
           "them (docs/residual_layer.md); trust held-out figures only\n";
  }
  return out;
}

std::string ResidualLayerSummaryText(const PipelineResult& run) {
  const ResidualLayerSummary& l = run.residual_layer;
  if (!l.requested) return "";
  if (!l.fitted) return "residual layer: none (" + l.message + ")\n";
  char line[512];
  std::snprintf(line, sizeof(line),
                "residual layer: Gaussian process, %d inducing inputs, signal %.4g mm, noise %.4g "
                "mm; identification RMS %.5f -> %.5f mm with the layer\n",
                l.inducing, run.result.model.residual_layer->signal_std,
                run.result.model.residual_layer->noise_std, run.identification_after.norm.rms,
                l.identification_with_layer.norm.rms);
  std::string out = line;
  out += ResidualLayerLengthScalesText(*run.result.model.residual_layer, l.fit,
                                       run.result.model);
  if (run.has_verification) {
    std::snprintf(line, sizeof(line),
                  "  verification RMS %.5f mm without the layer, %.5f mm with it (fitted on the "
                  "identification rows only)\n",
                  l.verification_parametric.norm.rms, run.verification_after.norm.rms);
    out += line;
  }
  return out;
}

void AddPointResiduals(const RobotModel& before, const RobotModel& after,
                       const MeasurementSet& identification, const MeasurementSet& verification,
                       RunSummary* summary) {
  summary->before_model = before;
  auto fill = [&](const MeasurementSet& data, std::vector<PointResidual>* out) {
    out->clear();
    out->reserve(data.size());
    for (int r = 0; r < data.size(); ++r) {
      PointResidual p;
      p.line = data.source_line(r);
      p.target = data.target(r);
      p.measured = data.position(r);
      p.before = p.measured - ToolPosition(before, data.q(r), p.target);
      p.after = p.measured - PredictToolPosition(after, data.q(r), p.target);  // joint errors too
      p.q.assign(data.q(r), data.q(r) + data.num_joints());
      out->push_back(std::move(p));
    }
  };
  fill(identification, &summary->identification_points);
  fill(verification, &summary->verification_points);
}

std::vector<std::string> UrdfFrameElements(const UrdfSource& source, const RobotModel& model) {
  tinyxml2::XMLDocument doc;
  if (doc.Parse(source.xml.c_str(), source.xml.size()) != tinyxml2::XML_SUCCESS) return {};
  const tinyxml2::XMLElement* robot = doc.FirstChildElement("robot");
  if (robot == nullptr) return {};
  auto attribute = [](const tinyxml2::XMLElement* e, const char* name) {
    const char* v = e != nullptr ? e->Attribute(name) : nullptr;
    return std::string(v != nullptr ? v : "");
  };
  // joint name -> child link, and child link -> joint name.
  std::map<std::string, std::string> child_of, joint_to;
  for (const tinyxml2::XMLElement* j = robot->FirstChildElement("joint"); j != nullptr;
       j = j->NextSiblingElement("joint")) {
    const std::string link = attribute(j->FirstChildElement("child"), "link");
    child_of[attribute(j, "name")] = link;
    joint_to[link] = attribute(j, "name");
  }
  std::vector<std::string> out;
  for (const Joint& joint : model.joints) {
    const auto child = child_of.find(joint.name);
    out.push_back("joint '" + joint.name + "'" +
                  (child != child_of.end() ? " (child link '" + child->second + "')" : ""));
  }
  for (const Tool& tool : model.tools) {
    const auto joint = joint_to.find(tool.name);
    out.push_back(joint != joint_to.end()
                      ? "joint '" + joint->second + "' (link '" + tool.name + "')"
                      : "link '" + tool.name + "'");
  }
  return out;
}

void AddPipelineResult(const PipelineResult& run, RunSummary* s) {
  static_cast<PipelineResult&>(*s) = run;
}

std::string JointErrorSelectionTable(const JointErrorSelection& sel, const std::string& error) {
  std::string out = "joint errors (auto): " + FoldsHeading(sel, "", error);
  // The terms column: 25 wide, wider when a label needs it (every registry subset is a candidate).
  int width = 25;
  for (const JointErrorCandidate& c : sel.candidates) {
    width = std::max(width, static_cast<int>(c.label.size()));
  }
  out += "  " + std::string("terms") + std::string(width - 5, ' ') +
         " combinations   CV rms (mm)   CV mse (mm^2)   std error\n";
  char line[512];
  for (size_t k = 0; k < sel.candidates.size(); ++k) {
    const JointErrorCandidate& c = sel.candidates[k];
    if (!c.ok) {
      std::snprintf(line, sizeof(line), "  %-*s %12d   FAILED: %s\n", width, c.label.c_str(),
                    c.parameters, c.failure.c_str());
    } else {
      std::snprintf(line, sizeof(line), "  %-*s %12d   %11.5f   %13.6g   %9.3g%s\n", width,
                    c.label.c_str(), c.parameters, c.cv_rms, c.cv_mse, c.cv_mse_se,
                    static_cast<int>(k) == sel.chosen ? "   <- chosen" : "");
    }
    out += line;
  }
  // A tilt candidate whose folds could not identify the tilt is the model without it.
  for (const JointErrorCandidate& c : sel.candidates) {
    const bool with_tilt =
        std::find(c.terms.begin(), c.terms.end(), kGravityTiltName) != c.terms.end();
    const int tilt_folds = c.IdentifiedFolds(kGravityTiltName);
    if (!with_tilt || !c.ok || tilt_folds == sel.folds) continue;
    out += "  " + c.label +
           (tilt_folds == 0
                ? ": the gravity tilt was identified in none of the " + std::to_string(sel.folds) +
                      " folds, which kept the model's gravity: the same model as without the tilt\n"
                : ": the gravity tilt was identified in " + std::to_string(tilt_folds) + " of " +
                      std::to_string(sel.folds) + " folds (the others kept the model's gravity)\n");
  }
  out += "  " + sel.reason + "\n";
  const BilinearCandidacy tilt = sel.Bilinear(kGravityTiltName);
  if (!tilt.candidates && !tilt.message.empty()) out += "  " + tilt.message + "\n";
  return out;
}

std::string GravityTiltSummary(const GravityTiltResult& t) {
  if (!t.requested) return "";
  if (!t.identified) return t.message + "\n";
  char line[512];
  std::snprintf(line, sizeof(line),
                "gravity tilt: t1 = %.4f +- %.4f deg about (%.3f, %.3f, %.3f), t2 = %.4f +- %.4f deg "
                "about (%.3f, %.3f, %.3f) of the model's base; %.4f deg in all; gravity now "
                "[%.6g, %.6g, %.6g]\n",
                t.tilt(0) * kDegrees, t.standard_deviation(0) * kDegrees, t.axes(0, 0),
                t.axes(1, 0), t.axes(2, 0), t.tilt(1) * kDegrees,
                t.standard_deviation(1) * kDegrees, t.axes(0, 1), t.axes(1, 1), t.axes(2, 1),
                t.tilt.norm() * kDegrees, t.gravity_after(0), t.gravity_after(1),
                t.gravity_after(2));
  std::string out = line;
  if (t.a_priori_standard_deviation.maxCoeff() > 0) {
    std::snprintf(line, sizeof(line),
                  "  (standard deviations a posteriori, noise estimated from the residuals; a "
                  "priori with --sigma: %.4f and %.4f deg)\n",
                  t.a_priori_standard_deviation(0) * kDegrees,
                  t.a_priori_standard_deviation(1) * kDegrees);
  } else {
    std::snprintf(line, sizeof(line),
                  "  (standard deviations a posteriori, noise estimated from the residuals)\n");
  }
  return out + line;
}

std::string JointErrorTermNames(const RobotModel& model) {
  std::string out;
  for (const std::string& name : JointTermNames()) {
    if (model.joint_errors.Has(name)) out += out.empty() ? name : ", " + name;
  }
  return out;
}

std::string JointTermsIdentifiability(const CalibrationResult& result) {
  std::string out;
  const Parameterization& par = result.parameterization;
  for (size_t b = 0; b < par.joint_blocks.size(); ++b) {
    const JointBlock& block = par.joint_blocks[b];
    out += "  joint-space term " + block.term->name() + ": " +
           std::to_string(block.term->num_parameters()) + " parameters, " +
           std::to_string(block.basis.cols()) + " identifiable combinations";
    int lost = 0;
    for (const Direction& d : par.unidentifiable) lost += d.joint_block == static_cast<int>(b);
    if (lost > 0) out += ", " + std::to_string(lost) + " left out (above)";
    out += "\n";
  }
  return out;
}

std::string RunSummaryToJson(const RunSummary& s) { return JsonText(BuildJson(s, true)); }

std::string RunSummaryToJsonWithoutPoints(const RunSummary& s) {
  return JsonText(BuildJson(s, false));
}

Status RenderPlotFiles(const RunSummary& s, std::vector<std::pair<std::string, std::string>>* files) {
  std::vector<int> it;
  std::vector<double> mx, mn;
  for (const IterationRecord& r : s.result.history) {
    it.push_back(r.iteration);
    mx.push_back(r.max_error);
    mn.push_back(r.mean_error);
  }
  const bool ver = !s.verification_points.empty();
  const std::vector<PointResidual>& shown = ver ? s.verification_points : s.identification_points;
  std::vector<Eigen::Vector3d> eb, ea;
  std::vector<double> nb, na;
  for (const PointResidual& p : shown) {
    eb.push_back(p.before);
    ea.push_back(p.after);
    nb.push_back(p.before.norm());
    na.push_back(p.after.norm());
  }
  const std::pair<const char*, Figure> plots[] = {
      {kPlotFileNames[0], ConvergenceFigure(it, mx, mn)},
      {kPlotFileNames[1], AxisErrorFigure(eb, ea, ver ? "verification" : "identification")},
      {kPlotFileNames[2], ErrorHistogramFigure(nb, na)},
  };
  files->clear();
  for (const auto& [name, figure] : plots) {
    std::string bytes;
    if (Status st = RenderFigure(figure, ImageFormat::kPng, &bytes); !st.ok())
      return Status::Error(std::string(name) + ": " + st.message());
    files->emplace_back(name, std::move(bytes));
  }
  return Status::Ok();
}

Status WritePlotFiles(const std::string& dir, RunSummary* s) {
  struct stat st;
  if (::stat(dir.c_str(), &st) != 0 ? ::mkdir(dir.c_str(), 0755) != 0 : !S_ISDIR(st.st_mode))
    return Status::Error(dir + ": cannot create the plot directory");
  std::vector<std::pair<std::string, std::string>> files;
  if (Status r = RenderPlotFiles(*s, &files); !r.ok()) return Status::Error(dir + "/" + r.message());
  for (const auto& [name, bytes] : files) {
    const std::string path = dir + "/" + name;
    if (Status w = WriteFileAtomically(path, bytes); !w.ok()) return w;
    s->outputs.push_back(path);
  }
  return Status::Ok();
}

Status ComparisonHtml(const ComparisonPage& page, std::string* html) {
  const PipelineResult& run = *page.ceres;
  RunSummary s;
  s.tool_name = "lpoe_compare";
  s.model_path = page.model_path;
  s.measurements_path = page.measurements_path;
  s.verification_source = page.verification_source;
  s.angle_unit = page.angle_unit;
  s.solver = "ceres";
  s.parameterization = page.parameterization;
  s.data_kind = run.result.parameterization.data == DataKind::kPose ? "pose" : "position";
  AddPipelineResult(run, &s);
  if (!page.agree) {
    s.verdict.level = VerdictLevel::kFail;
    s.verdict.reason = "the linear and the Ceres solver disagree on the predicted positions";
  }
  AddPointResiduals(run.before, run.result.model, *page.identification, *page.verification, &s);
  s.comparison = page.rows;
  s.solvers_agree = page.agree;
  return RunSummaryToHtml(s, html);
}

Status WriteHtmlReport(const std::string& path, RunSummary* s) {
  s->outputs.push_back(path);
  std::string html;
  Status st = RunSummaryToHtml(*s, &html);
  if (st.ok()) st = WriteFileAtomically(path, html);
  if (!st.ok()) s->outputs.pop_back();
  return st;
}

namespace {

Json VerdictJson(const Verdict& verdict) {
  Json checks = Json::array();
  for (const VerdictCheck& c : verdict.checks) {
    checks.push_back({{"name", c.name},
                      {"level", VerdictLevelName(c.level)},
                      {"value", c.value},
                      {"limit", c.limit},
                      {"message", c.message}});
  }
  return {{"level", VerdictLevelName(verdict.level)},
          {"reason", verdict.reason},
          {"checks", checks}};
}

Json InputsJson(const RunSummary& s) {
  return {{"model", s.model_path},
          {"measurements", s.measurements_path},
          {"verification", s.verification_source},
          {"split", s.split},
          {"split_by", "configuration"},
          {"angle_unit", s.angle_unit},
          {"skipped_rows", s.skipped.skipped_zero_rows},
          {"skipped_lines", s.skipped.skipped_lines}};
}

Json SolverJson(const RunSummary& s) {
  return {{"name", s.solver},
          {"parameterization", s.parameterization},
          {"data", s.data_kind},
          {"termination", TerminationName(s.result.termination)},
          {"converged", s.result.converged()},
          {"message", s.result.message},
          {"stop_rule", StopRuleName(s.result.stop_rule)},
          {"iterations", s.result.iterations},
          {"final_cost", s.result.final_cost}};
}

Json HistoryJson(const std::vector<IterationRecord>& records) {
  Json history = Json::array();
  for (const IterationRecord& r : records) {
    history.push_back({{"iteration", r.iteration},
                       {"max_error", r.max_error},
                       {"mean_error", r.mean_error},
                       {"cost", r.cost},
                       {"step_norm", r.step_norm}});
    // A record of the linear solver's warm start (linear_solver.h): the rows of its subsample.
    if (r.rows > 0) history.back()["rows"] = r.rows;
  }
  return history;
}

Json RegistrationJson(const RunSummary& s) {
  if (!s.registered) return nullptr;
  return {{"applied", s.registration.moved},
          {"T_measurement_base", PoseJson(s.registration.T_measurement_base)},
          {"rms_nominal", s.registration.rms_nominal},
          {"rms_rigid", s.registration.rms_rigid},
          {"rms_base_tools", s.registration.rms_base_tools}};
}

// All correlations above 0.9 (from the covariance, when there is one).
Json CorrelatedAbove09Json(const CalibrationResult& result) {
  Json high = Json::array();
  const Parameterization& par = result.parameterization;
  const Eigen::MatrixXd& C = result.covariance;
  for (Eigen::Index a = 0; a < C.rows(); ++a) {
    for (Eigen::Index b = a + 1; b < C.cols(); ++b) {
      const double denom = std::sqrt(C(a, a) * C(b, b));
      if (!(denom > 0)) continue;
      const double r = C(a, b) / denom;
      if (std::abs(r) > 0.9 && static_cast<size_t>(b) < par.parameters.size()) {
        high.push_back({{"a", par.parameters[a].name},
                        {"b", par.parameters[b].name},
                        {"correlation", r}});
      }
    }
  }
  return high;
}

Json IdentifiabilityJson(const RunSummary& s) {
  const IdentifiabilityReport& id = s.identifiability;
  // The fixed tools' directions are held by the user, not unidentifiable: listed apart.
  Json unident = Json::array(), held = Json::array();
  for (const Direction& d : id.unidentifiable) {
    if (IsHeldFixedTool(d)) {
      held.push_back(d.name);
    } else {
      unident.push_back(
          {{"name", d.name}, {"reason", d.reason}, {"structural", IsStructurallyLost(d)}});
    }
  }
  Json params = Json::array();
  for (size_t k = 0; k < id.parameter_names.size(); ++k) {
    Json p = {{"name", id.parameter_names[k]}};
    p["std_dev"] = id.standard_deviation.size() > static_cast<Eigen::Index>(k)
                       ? Json(id.standard_deviation(k))
                       : Json(nullptr);
    // The prior's standard deviation (null: none on this direction) and the data's share.
    const bool prior = id.data_share.size() > static_cast<Eigen::Index>(k);
    p["prior_std_dev"] = prior && std::isfinite(id.prior_standard_deviation(k))
                             ? Json(id.prior_standard_deviation(k))
                             : Json(nullptr);
    p["data_share"] = prior ? Json(id.data_share(k)) : Json(nullptr);
    params.push_back(p);
  }
  Json pairs = Json::array();
  for (const CorrelatedPair& c : id.most_correlated) {
    pairs.push_back({{"a", c.a}, {"b", c.b}, {"correlation", c.correlation}});
  }
  std::vector<double> sv(id.singular_values.data(),
                         id.singular_values.data() + id.singular_values.size());
  return {{"parameters", id.num_parameters},
          {"rank", id.rank},
          {"condition_number", id.condition_number},
          {"singular_values", sv},
          {"unidentifiable", unident},
          {"held_fixed_tools", held},
          {"identified", params},
          {"most_correlated", pairs},
          {"warnings", id.warnings},
          {"correlated_above_0_9", CorrelatedAbove09Json(s.result)}};
}

// The prior (docs/identifiability.md): null without one.
Json PriorJson(const IdentifiabilityReport& id) {
  if (id.data_share.size() == 0) return nullptr;
  return {{"data_sigma", id.prior_data_sigma},
          {"weakly_determined", id.weakly_determined},
          {"weak_share", kWeaklyDeterminedShare}};
}

Json OutliersJson(const RunSummary& s) {
  Json outliers = Json::array();
  for (const Outlier& o : s.outliers) {
    outliers.push_back({{"line", o.line}, {"error", o.error}, {"sigmas", o.sigmas}});
  }
  return {{"robust_sigma", s.robust_sigma}, {"points", outliers}};
}

Json FoldsJson(const std::vector<FoldSummary>& fold_summaries) {
  Json folds = Json::array();
  for (const FoldSummary& f : fold_summaries) {
    folds.push_back({{"fold", f.fold},
                     {"identification_rows", f.identification_rows},
                     {"termination", TerminationName(f.termination)},
                     {"verification_after", StatsJson(f.verification_after)}});
  }
  return folds;
}

Json CalibratedFramesJson(const RobotModel& model) {
  Json frames = Json::array();
  for (const Joint& jt : model.joints) {
    frames.push_back({{"name", jt.name}, {"origin", PoseJson(jt.origin)}});
  }
  for (const Tool& t : model.tools) {
    frames.push_back({{"name", t.name}, {"origin", PoseJson(t.origin)}});
  }
  return frames;
}

Json OutputModelsJson(const std::vector<RunSummary::OutputModel>& output_models) {
  Json models = Json::array();
  for (const RunSummary::OutputModel& o : output_models) {
    models.push_back({{"flag", o.flag}, {"path", o.path}, {"rms_mm", o.rms_mm}, {"set", o.set},
                      {"carries_less", o.reduced}, {"note", o.note}});
  }
  return models;
}

// Per SMR (tool): before/after on each set.
Json PerSmrJson(const RunSummary& s) {
  const RobotModel& model = s.result.model;
  Json per_smr = Json::array();
  for (int t = 0; t < model.num_tools(); ++t) {
    Json e = {{"target", model.tools[t].name}};
    e["identification"] = {{"before", StatsJson(StatsOf(s.identification_points, t, false))},
                           {"after", StatsJson(StatsOf(s.identification_points, t, true))}};
    if (s.has_verification) {
      e["verification"] = {{"before", StatsJson(StatsOf(s.verification_points, t, false))},
                           {"after", StatsJson(StatsOf(s.verification_points, t, true))}};
    } else {
      e["verification"] = nullptr;
    }
    per_smr.push_back(e);
  }
  return per_smr;
}

// Parameter changes: each identified direction's component of log(T_before^-1 T_after), the
// right perturbation of the local frame (paper eq. (19)), against the model before calibration.
Json ParameterChangesJson(const RunSummary& s) {
  const RobotModel& model = s.result.model;
  const IdentifiabilityReport& id = s.identifiability;
  Json changes = Json::array();
  const Parameterization& par = s.result.parameterization;
  const int num_frames = s.before_model.num_joints() + s.before_model.num_tools();
  for (size_t k = 0; k < par.parameters.size(); ++k) {
    const Direction& d = par.parameters[k];
    if (d.frame < 0 || d.frame >= num_frames ||
        d.frame >= model.num_joints() + model.num_tools()) {
      continue;  // joint-space parameters and the gravity tilt: not a frame
    }
    const Vector6d dp =
        LogSE3(FrameOrigin(s.before_model, d.frame).Inverse() * FrameOrigin(model, d.frame));
    int dominant = 0;
    d.vector.cwiseAbs().maxCoeff(&dominant);
    const bool rotation = dominant < 3;
    Json c = {{"name", d.name},
              {"change", d.vector.dot(dp)},
              {"unit", rotation ? "rad" : "mm"}};
    if (static_cast<size_t>(d.frame) < s.urdf_frames.size()) c["urdf"] = s.urdf_frames[d.frame];
    c["std_dev"] = id.standard_deviation.size() > static_cast<Eigen::Index>(k)
                       ? Json(id.standard_deviation(k))
                       : Json(nullptr);
    changes.push_back(c);
  }
  return changes;
}

Json ComparisonJson(const RunSummary& s) {
  Json rows = Json::array();
  for (const RunSummary::ComparisonRow& r : s.comparison) {
    rows.push_back({{"quantity", r.quantity},
                    {"linear", r.linear},
                    {"ceres", r.ceres},
                    {"difference", r.difference}});
  }
  return {{"agree", s.solvers_agree}, {"rows", rows}};
}

// The report, section by section, in the order of docs/report.md; `with_points` false leaves the
// per-point arrays empty.
Json BuildJson(const RunSummary& s, bool with_points) {
  Json j;
  j["schema"] = "lpoe-calib/report/2";
  j["tool"] = {{"name", s.tool_name}, {"version", kLpoeVersion}};
  j["verdict"] = VerdictJson(s.verdict);
  j["inputs"] = InputsJson(s);
  j["solver"] = SolverJson(s);
  // (No wall time: the same input must give a byte-identical report.)
  j["history"] = HistoryJson(s.result.history);
  j["registration"] = RegistrationJson(s);
  j["identifiability"] = IdentifiabilityJson(s);
  j["prior"] = PriorJson(s.identifiability);
  if (!s.prior_path.empty()) {
    Json changed = Json::array();
    for (const ChangedGroup& g : s.changed_groups) {
      changed.push_back({{"name", g.name}, {"chi2", g.chi2}, {"dof", g.dof}});
    }
    j["recalibration"] = {{"prior", s.prior_path}, {"changed", changed}};
  }
  j["identification"] = {{"before", StatsJson(s.identification_before)},
                         {"after", StatsJson(s.identification_after)}};
  if (s.has_verification) {
    j["verification"] = {{"before", StatsJson(s.verification_before)},
                         {"after", StatsJson(s.verification_after)}};
  } else {
    j["verification"] = nullptr;
  }
  j["outliers"] = OutliersJson(s);
  j["cross_validation"] = FoldsJson(s.folds);
  j["joint_errors"] = JointErrorsJson(s);
  j["residual_model"] = ResidualModelJson(s);
  j["calibrated_frames"] = CalibratedFramesJson(s.result.model);
  j["outputs"] = s.outputs;
  j["output_models"] = OutputModelsJson(s.output_models);
  j["forced"] = s.forced;
  j["per_smr"] = PerSmrJson(s);
  j["parameter_changes"] = ParameterChangesJson(s);
  if (!s.comparison.empty()) j["comparison"] = ComparisonJson(s);
  if (with_points) {
    j["points"] = {{"identification", PointsJson(s.result.model, s.identification_points)},
                   {"verification", PointsJson(s.result.model, s.verification_points)}};
  } else {
    j["points"] = {{"identification", Json::array()}, {"verification", Json::array()}};
  }
  return j;
}

}  // namespace
}  // namespace tools
}  // namespace lpoe
