// The HTML report: one self-contained page (inline SVG from PLplot, inline CSS, no scripts),
// rendered from the JSON report document (parsed back, so the JSON is the single source of every
// figure on the page) plus the per-point joint values and positions the JSON leaves out.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "report/plot.h"
#include "lpoe/model/residual_layer.h"
#include "report/report.h"
#include "common/tool_common.h"

namespace lpoe {
namespace tools {
namespace {

using Json = nlohmann::ordered_json;

// Plotted points per scatter panel: beyond this, the per-bucket extremes of the error (in point
// order) are kept, so outliers stay visible and 10^5 points stay well below 5 MB of SVG.
constexpr int kMaxScatterPoints = 700;

std::string Esc(const std::string& raw) {
  const std::string text = ValidUtf8(raw);  // names and paths may hold any bytes
  std::string out;
  out.reserve(text.size());
  for (char c : text) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      default:
        out.push_back(c);
    }
  }
  return out;
}

std::string Fmt(const char* format, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, format, v);
  return buf;
}

std::string Mm(const Json& v) { return v.is_number() ? Fmt("%.4f", v.get<double>()) : "&ndash;"; }
std::string Sci(const Json& v) { return v.is_number() ? Fmt("%.3g", v.get<double>()) : "&ndash;"; }
std::string Str(const Json& v) { return v.is_string() ? v.get<std::string>() : v.dump(); }

// A table row of before/after statistics (norm: RMS, mean, p95, max; per-axis RMS).
std::string StatsRows(const std::string& name, const Json& before_after) {
  std::string h;
  for (const char* when : {"before", "after"}) {
    const Json& s = before_after[when];
    h += "<tr><td>" + Esc(name) + "</td><td>" + when + "</td><td>" + Str(s["count"]) + "</td>";
    for (const char* k : {"rms", "mean", "p95", "max"}) h += "<td>" + Mm(s["norm"][k]) + "</td>";
    for (const char* a : {"x", "y", "z"}) h += "<td>" + Mm(s[a]["rms"]) + "</td>";
    h += "</tr>\n";
  }
  return h;
}

const char* kStatsHead =
    "<tr><th>set</th><th></th><th>points</th><th>RMS</th><th>mean</th><th>p95</th><th>max</th>"
    "<th>RMS x</th><th>RMS y</th><th>RMS z</th></tr>\n";

struct PlotInput {
  std::vector<double> after_norm;  // all points, identification first
  std::vector<const PointResidual*> points;
  std::vector<bool> verification;
};

// A scatter series of the points in `rows` (already decimated).
Series Scatter(const std::string& label, uint32_t rgb) {
  Series s;
  s.label = label;
  s.rgb = rgb;
  s.lines = false;
  s.markers = true;
  return s;
}

// Rows of `in` to plot: decimated on the after-calibration error, per set.
std::vector<int> Rows(const PlotInput& in, bool verification) {
  std::vector<int> rows;
  std::vector<double> err;
  for (size_t i = 0; i < in.points.size(); ++i) {
    if (in.verification[i] != verification) continue;
    rows.push_back(static_cast<int>(i));
    err.push_back(in.after_norm[i]);
  }
  std::vector<int> out;
  for (int k : DecimatedIndices(err, kMaxScatterPoints / 2)) out.push_back(rows[k]);
  return out;
}

Status Svg(const Figure& f, int* figures, std::string* html) {
  std::string svg;
  if (Status s = RenderFigure(f, ImageFormat::kSvg, &svg); !s.ok()) return s;
  // Unique clip-path ids per figure on the page (PLplot numbers them from 0 in every SVG).
  static const std::string kId = "text-clipping";
  const std::string tag = "f" + std::to_string((*figures)++) + "-";
  size_t at = 0;
  while ((at = svg.find(kId, at)) != std::string::npos) {
    svg.insert(at, tag);
    at += tag.size() + kId.size();
  }
  *html += "<figure>" + svg + "</figure>\n";
  return Status::Ok();
}

// The page of one run, written section by section: each method appends its section to html_.
class HtmlPage {
 public:
  explicit HtmlPage(const RunSummary& summary)
      : summary_(summary),
        j_(Json::parse(RunSummaryToJsonWithoutPoints(summary))),
        model_(summary.result.model) {
    html_.reserve(1 << 20);
  }
  Status Write(std::string* out) {
    Head();
    VerdictAndKeyFigures();
    Statistics();
    Comparison();
    if (Status s = Plots(); !s.ok()) return s;
    Parameters();
    JointErrors();
    ResidualModel();
    Outliers();
    NextSteps();
    Inputs();
    *out = std::move(html_);
    return Status::Ok();
  }

 private:
  // The rows the scatter plots draw and the frame they are drawn in.
  struct Scatters {
    PlotInput in;
    std::vector<int> rows_id, rows_ver;
    SE3d T_base_measurement;
  };
  void Head();
  void VerdictAndKeyFigures();
  void Statistics();
  void Comparison();
  Status Plots();
  Status ErrorAgainstJointsFigure(const Scatters& sc);
  Status WorkspaceFigure(const Scatters& sc);
  Status ResidualLayerFigure(const Scatters& sc);
  static Figure TopAndSideFigure(const Scatters& sc, const std::vector<double>& value, double lo,
                                 double hi, const std::string& top_title,
                                 const std::string& side_title, const std::string& color_label);
  void Parameters();
  void JointErrors();
  void ResidualModel();
  void Outliers();
  void NextSteps();
  void Inputs();
  // The set the key figures and the axis plot show: verification when there is one.
  bool HasVerification() const { return !j_["verification"].is_null(); }
  std::string SetName() const { return HasVerification() ? "verification" : "identification"; }

  const RunSummary& summary_;
  const Json j_;
  const RobotModel& model_;
  std::string html_;
  int figures_ = 0;  // figures on the page so far (their SVG ids must differ)
};

void HtmlPage::Head() {
  std::string& h = html_;
  const RobotModel& model = model_;
  const std::string name = model.name.empty() ? std::string("robot") : model.name;
  h += "<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\"/>\n"
       "<title>Calibration report: " +
       Esc(name) +
       "</title>\n<style>\n"
       "body{font-family:'DejaVu Sans',Helvetica,Arial,sans-serif;color:#222;max-width:1080px;"
       "margin:24px auto;padding:0 16px;line-height:1.4}\n"
       "h1{font-size:24px;margin:0 0 8px}h2{font-size:18px;border-bottom:1px solid #ccc;"
       "padding-bottom:4px;margin-top:28px}\n"
       ".verdict{padding:12px 16px;border-radius:6px;font-size:17px;margin:12px 0}\n"
       ".pass{background:#e3f4e6;border-left:8px solid #1b8a3a}"
       ".check{background:#fff4d6;border-left:8px solid #d08a00}"
       ".fail{background:#fbe3e0;border-left:8px solid #c0392b}\n"
       ".verdict b{text-transform:uppercase;margin-right:8px}\n"
       "table{border-collapse:collapse;font-size:13px;margin:8px 0}"
       "td,th{border:1px solid #ddd;padding:3px 8px;text-align:right}"
       "th{background:#f3f3f3}td:first-child,th:first-child{text-align:left}\n"
       ".key{display:flex;gap:16px;flex-wrap:wrap}.key div{background:#f6f8fa;border:1px solid "
       "#e1e4e8;border-radius:6px;padding:8px 14px}.key span{display:block;font-size:22px;"
       "font-weight:bold}\n"
       "figure{margin:12px 0}figure svg{width:100%;height:auto}\n"
       ".flag{color:#c0392b;font-weight:bold}.note{color:#555;font-size:13px}\n"
       "code{background:#f3f3f3;padding:0 3px}\n"
       "</style>\n</head>\n<body>\n";

}

void HtmlPage::VerdictAndKeyFigures() {
  std::string& h = html_;
  const Json& j = j_;
  const std::string name = model_.name.empty() ? std::string("robot") : model_.name;
  // ---- Verdict and key figures.
  const Json& verdict = j["verdict"];
  const std::string level = Str(verdict["level"]);
  h += "<h1>Calibration report: " + Esc(name) + "</h1>\n";
  h += "<p class=\"note\">" + Esc(Str(j["tool"]["name"])) + " " + Esc(Str(j["tool"]["version"])) +
       " &middot; " + Esc(Str(j["solver"]["name"])) + " solver, " + Esc(Str(j["solver"]["data"])) +
       " data &middot; model " + Esc(Str(j["inputs"]["model"])) + " &middot; measurements " +
       Esc(Str(j["inputs"]["measurements"])) + "</p>\n";
  // An output that carries less than the calibration (a URDF after joint-space terms) is said
  // in the verdict box, with its own RMS against the calibration's.
  std::string reduced;
  if (j.contains("output_models")) {
    double full = -1;
    for (const Json& o : j["output_models"]) {
      if (!o.value("carries_less", false)) full = o.value("rms_mm", -1.0);
    }
    for (const Json& o : j["output_models"]) {
      if (!o.value("carries_less", false)) continue;
      char buf[160];
      std::snprintf(buf, sizeof(buf), " predicts with RMS %.3g mm", o.value("rms_mm", 0.0));
      std::string line = "<br>Warning: " + Esc(Str(o["flag"])) + " <code>" + Esc(Str(o["path"])) +
                         "</code>" + buf;
      if (full >= 0) {
        std::snprintf(buf, sizeof(buf), " against %.3g mm for the YAML model", full);
        line += buf;
      }
      line += " (" + Esc(Str(o["set"])) + " set): " + Esc(Str(o["note"]));
      reduced += line;
    }
  }
  h += "<div class=\"verdict " + Esc(level) + "\"><b>" + Esc(level) + "</b>" +
       Esc(Str(verdict["reason"])) + reduced + "</div>\n";
  if (verdict.contains("checks") && !verdict["checks"].empty()) {
    h += "<details><summary>Plausibility checks</summary><table>\n<tr><th>check</th><th>level"
         "</th><th>value</th><th>limit</th><th>message</th></tr>\n";
    for (const Json& c : verdict["checks"]) {
      h += "<tr><td>" + Esc(Str(c["name"])) + "</td><td>" + Esc(Str(c["level"])) + "</td><td>" +
           Sci(c["value"]) + "</td><td>" + Sci(c["limit"]) + "</td><td style=\"text-align:left\">" +
           Esc(Str(c["message"])) + "</td></tr>\n";
    }
    h += "</table></details>\n";
  }
  const bool has_ver = !j["verification"].is_null();
  const Json& main_set = has_ver ? j["verification"] : j["identification"];
  const std::string set_name = has_ver ? "verification" : "identification";
  h += "<div class=\"key\">\n";
  h += "<div>" + set_name + " RMS before<span>" + Mm(main_set["before"]["norm"]["rms"]) +
       " mm</span></div>\n";
  h += "<div>" + set_name + " RMS after<span>" + Mm(main_set["after"]["norm"]["rms"]) +
       " mm</span></div>\n";
  h += "<div>" + set_name + " max after<span>" + Mm(main_set["after"]["norm"]["max"]) +
       " mm</span></div>\n";
  h += "<div>solver<span>" + Esc(Str(j["solver"]["termination"])) + "</span>" +
       Str(j["solver"]["iterations"]) + " iterations</div>\n";
  h += "</div>\n";

}

void HtmlPage::Statistics() {
  std::string& h = html_;
  const Json& j = j_;
  const RunSummary& summary = summary_;
  const bool has_ver = HasVerification();
  // ---- Statistics.
  h += "<h2>Position error before and after calibration [mm]</h2>\n<table>\n";
  h += kStatsHead;
  h += StatsRows("identification", j["identification"]);
  if (has_ver) h += StatsRows("verification", j["verification"]);
  h += "</table>\n<p class=\"note\">Before: the nominal model";
  h += summary.registered && summary.registration.moved ? " after the rigid registration" : "";
  h += ". Norm statistics of the Euclidean error; p95 is the 95th percentile.</p>\n";
  h += "<h2>Per SMR [mm]</h2>\n<table>\n" + std::string(kStatsHead);
  for (const Json& t : j["per_smr"]) {
    h += StatsRows(Str(t["target"]) + " identification", t["identification"]);
    if (!t["verification"].is_null())
      h += StatsRows(Str(t["target"]) + " verification", t["verification"]);
  }
  h += "</table>\n";

}

void HtmlPage::Comparison() {
  std::string& h = html_;
  const Json& j = j_;
  // ---- lpoe_compare: the two solvers.
  if (j.contains("comparison")) {
    const Json& c = j["comparison"];
    h += "<h2>Linear (paper) and Ceres solver on the same data</h2>\n<p>" +
         std::string(c["agree"].get<bool>() ? "The predicted positions agree within the tolerance."
                                            : "<span class=\"flag\">The predicted positions "
                                              "disagree.</span>") +
         " The rest of this page shows the Ceres calibration.</p>\n<table>\n"
         "<tr><th></th><th>linear</th><th>ceres</th><th>|difference|</th></tr>\n";
    for (const Json& r : c["rows"])
      h += "<tr><td>" + Esc(Str(r["quantity"])) + "</td><td>" + Esc(Str(r["linear"])) +
           "</td><td>" + Esc(Str(r["ceres"])) + "</td><td>" + Esc(Str(r["difference"])) +
           "</td></tr>\n";
    h += "</table>\n";
  }

}

Status HtmlPage::Plots() {
  std::string& h = html_;
  const Json& j = j_;
  const RunSummary& summary = summary_;
  int& figures = figures_;
  const std::string set_name = SetName();
  // ---- Plots.
  Scatters sc;
  PlotInput& in = sc.in;
  for (const auto* set : {&summary.identification_points, &summary.verification_points}) {
    for (const PointResidual& p : *set) {
      in.points.push_back(&p);
      in.after_norm.push_back(p.after.norm());
      in.verification.push_back(set == &summary.verification_points);
    }
  }
  h += "<h2>Plots</h2>\n";
  {
    std::vector<int> it;
    std::vector<double> mx, mn;
    for (const Json& r : j["history"]) {
      it.push_back(r["iteration"].get<int>());
      mx.push_back(r["max_error"].get<double>());
      mn.push_back(r["mean_error"].get<double>());
    }
    Figure f = ConvergenceFigure(it, mx, mn);
    f.height = 380;
    if (Status s = Svg(f, &figures, &h); !s.ok()) return s;
  }
  std::vector<Eigen::Vector3d> eb, ea;
  std::vector<double> nb, na;
  for (const PointResidual& p :
       HasVerification() ? summary.verification_points : summary.identification_points) {
    eb.push_back(p.before);
    ea.push_back(p.after);
    nb.push_back(eb.back().norm());
    na.push_back(ea.back().norm());
  }
  if (Status s = Svg(AxisErrorFigure(eb, ea, set_name), &figures, &h); !s.ok()) return s;
  {
    Figure f = ErrorHistogramFigure(nb, na);
    f.columns = 2;
    f.height = 380;
    if (Status s = Svg(f, &figures, &h); !s.ok()) return s;
  }
  sc.rows_id = Rows(in, false);
  sc.rows_ver = Rows(in, true);
  h += "<p class=\"note\">Below: the error after calibration against each joint value, the reach "
       "and the position in the workspace. A trend here is an error the geometric model does not "
       "describe (compliance, gear errors, thermal drift). Scatter plots show at most " +
       std::to_string(kMaxScatterPoints) +
       " points each (per set, the smallest and largest error of consecutive groups).</p>\n";
  // Positions in the robot's base frame (the measurement frame when there was no registration).
  sc.T_base_measurement = summary.registered && summary.registration.moved
                                      ? summary.registration.T_measurement_base.Inverse()
                                      : SE3d();
  if (Status s = ErrorAgainstJointsFigure(sc); !s.ok()) return s;
  if (Status s = WorkspaceFigure(sc); !s.ok()) return s;
  if (Status s = ResidualLayerFigure(sc); !s.ok()) return s;
  return Status::Ok();
}

Status HtmlPage::ErrorAgainstJointsFigure(const Scatters& sc) {
  std::string& h = html_;
  const RobotModel& model = model_;
  int& figures = figures_;
  const PlotInput& in = sc.in;
  const std::vector<int>& rows_id = sc.rows_id;
  const std::vector<int>& rows_ver = sc.rows_ver;
  const SE3d& T_base_measurement = sc.T_base_measurement;
  // The error after calibration against each joint value and against the reach.
  Figure f;
  f.columns = 3;
  f.width = 1000;
  const int nj = model.num_joints();
  f.height = 290 * ((nj + 3) / 3);
  for (int q = 0; q <= nj; ++q) {
    const bool reach = q == nj;
    const bool revolute = !reach && model.joints[q].type == JointType::kRevolute;
    Panel p;
    p.title = reach ? std::string("error after calibration vs reach")
                    : "error after calibration vs " + model.joints[q].name;
    p.x_label = reach ? std::string("distance from the base origin [mm]")
                      : model.joints[q].name + (revolute ? " [deg]" : " [mm]");
    p.y_label = "error [mm]";
    Series a = Scatter(q == 0 ? "identification" : "", kColorAfter);
    Series b = Scatter(q == 0 ? "verification" : "", kColorBefore);
    for (auto [rows, s] : {std::pair{&rows_id, &a}, std::pair{&rows_ver, &b}}) {
      for (int r : *rows) {
        const PointResidual& pt = *in.points[r];
        s->x.push_back(reach      ? (T_base_measurement * pt.measured).norm()
                       : revolute ? pt.q[q] * 180.0 / M_PI
                                  : pt.q[q]);
        s->y.push_back(in.after_norm[r]);
      }
    }
    p.series = {a, b};
    f.panels.push_back(p);
  }
  if (Status s = Svg(f, &figures, &h); !s.ok()) return s;
  return Status::Ok();
}

// Two views of the plotted points in the robot's base frame, from the top (x, y) and from the side
// (x, z), coloured by value[r] on one scale [lo, hi] (one colour bar for both).
Figure HtmlPage::TopAndSideFigure(const Scatters& sc, const std::vector<double>& value, double lo,
                                  double hi, const std::string& top_title,
                                  const std::string& side_title, const std::string& color_label) {
  Figure f;
  f.columns = 2;
  f.width = 1000;
  f.height = 460;
  Panel top, side;
  top.title = top_title;
  side.title = side_title;
  top.x_label = side.x_label = "x [mm]";
  top.y_label = "y [mm]";
  side.y_label = "z [mm]";
  top.equal_axes = side.equal_axes = true;
  top.color_label = color_label;
  Series ct = Scatter("", 0), cs = Scatter("", 0);
  for (const std::vector<int>* rows : {&sc.rows_id, &sc.rows_ver}) {
    for (int r : *rows) {
      const Eigen::Vector3d pb = sc.T_base_measurement * sc.in.points[r]->measured;
      ct.x.push_back(pb.x());
      ct.y.push_back(pb.y());
      cs.x.push_back(pb.x());
      cs.y.push_back(pb.z());
      ct.color_value.push_back(value[r]);
      cs.color_value.push_back(value[r]);
    }
  }
  for (Series* s : {&ct, &cs}) {
    s->color_min = lo;
    s->color_max = hi;
  }
  top.series = {ct};
  side.series = {cs};
  f.panels = {top, side};
  return f;
}

// The workspace from the top and from the side, points colored by the error.
Status HtmlPage::WorkspaceFigure(const Scatters& sc) {
  double lo = 1e300, hi = -1e300;
  for (double e : sc.in.after_norm) {
    lo = std::min(lo, e);
    hi = std::max(hi, e);
  }
  const Figure f = TopAndSideFigure(sc, sc.in.after_norm, lo, hi, "workspace from the top",
                                    "workspace from the side", "error after calibration [mm]");
  if (Status s = Svg(f, &figures_, &html_); !s.ok()) return s;
  html_ +=
      "<p class=\"note\">Measured positions in the robot's base frame, identification and "
      "verification points, colored by the error after calibration (one color scale for both "
      "views).</p>\n";
  return Status::Ok();
}

// The residual layer's predicted accuracy over the workspace: its predictive standard deviation
// at each measured configuration (docs/residual_layer.md).
Status HtmlPage::ResidualLayerFigure(const Scatters& sc) {
  const ResidualLayer* layer = model_.residual_layer.get();
  if (layer == nullptr) return Status::Ok();
  std::vector<double> sd(sc.in.points.size(), 0.0);
  double lo = 1e300, hi = -1e300;
  for (const std::vector<int>* rows : {&sc.rows_id, &sc.rows_ver}) {
    for (int r : *rows) {
      const PointResidual& pt = *sc.in.points[r];
      sd[r] = layer->Std(pt.q.data(), pt.target);
      lo = std::min(lo, sd[r]);
      hi = std::max(hi, sd[r]);
    }
  }
  if (!(hi > lo)) hi = lo + 1e-9;
  const Figure f = TopAndSideFigure(sc, sd, lo, hi, "residual layer: predicted accuracy, top",
                                    "residual layer: predicted accuracy, side",
                                    "layer's predictive std. dev. per axis [mm]");
  if (Status s = Svg(f, &figures_, &html_); !s.ok()) return s;
  html_ += "<p class=\"note\">The learned residual layer's predictive standard deviation (per axis, "
           "mm) at the measured configurations: small where the identification data are dense, "
           "up to " +
           Fmt("%.4f", layer->signal_std) +
           " mm (the layer's prior) far from them, where the correction fades and the parametric "
           "model's accuracy applies.</p>\n";
  return Status::Ok();
}

void HtmlPage::Parameters() {
  std::string& h = html_;
  const Json& j = j_;
  // ---- Parameters.
  const Json& idj = j["identifiability"];
  h += "<h2>Parameter changes against the model before calibration</h2>\n";
  h += "<p class=\"note\">Right perturbation of each local frame, "
       "<code>log(T<sub>before</sub><sup>-1</sup> T<sub>after</sub>)</code>, "
       "along the identified directions (rad for rotations, mm for translations), with the "
       "standard deviation from the covariance.</p>\n<table>\n"
       "<tr><th>parameter</th><th>change</th><th>unit</th><th>std. dev.</th><th>|change| / "
       "std. dev.</th>";
  // A model read from a URDF: the element of the file each parameter changes (its <origin>).
  bool urdf = false;
  for (const Json& c : j["parameter_changes"]) urdf = urdf || c.contains("urdf");
  h += urdf ? "<th>in the URDF: the &lt;origin&gt; of</th></tr>\n" : "</tr>\n";
  for (const Json& c : j["parameter_changes"]) {
    const double v = c["change"].get<double>();
    std::string ratio = "&ndash;";
    if (c["std_dev"].is_number() && c["std_dev"].get<double>() > 0)
      ratio = Fmt("%.1f", std::abs(v) / c["std_dev"].get<double>());
    h += "<tr><td>" + Esc(Str(c["name"])) + "</td><td>" + Fmt("%.6f", v) + "</td><td>" +
         Esc(Str(c["unit"])) + "</td><td>" + Sci(c["std_dev"]) + "</td><td>" + ratio + "</td>" +
         (urdf ? "<td>" + (c.contains("urdf") ? Esc(Str(c["urdf"])) : std::string()) + "</td>"
               : std::string()) +
         "</tr>\n";
  }
  h += "</table>\n";

  std::string held;  // the fixed tools' directions: held by the user, not unidentifiable
  if (idj.contains("held_fixed_tools")) {
    for (const Json& d : idj["held_fixed_tools"]) held += (held.empty() ? "" : ", ") + Str(d);
  }
  h += "<h2>Identifiability</h2>\n<p>" + Str(idj["parameters"]) + " parameters, rank " +
       Str(idj["rank"]) + ", condition number of the column-scaled Jacobian " +
       Sci(idj["condition_number"]) + ". " + std::to_string(idj["unidentifiable"].size()) +
       " directions cannot be identified from this data kind and were left out." +
       (held.empty() ? std::string()
                     : " Held (fixed tools): " + std::to_string(idj["held_fixed_tools"].size()) +
                           " directions (" + Esc(held) + "), as given, not calibrated.") +
       "</p>\n";
  // The prior (docs/identifiability.md): what it held.
  if (j.contains("prior") && j["prior"].is_object()) {
    // A prior file (--prior: a previous calibration or a fleet; then each weakly determined
    // parameter's data share is given) or the start model's tolerances.
    const bool given = j.contains("recalibration") && j["recalibration"].is_object() &&
                       j["recalibration"].contains("prior");
    std::string weak;
    for (const Json& d : j["prior"]["weakly_determined"]) {
      weak += (weak.empty() ? "" : ", ") + Str(d);
      for (const Json& p : idj["identified"]) {
        if (given && p["name"] == d && p["data_share"].is_number()) {
          weak += Fmt(" (data share %.0f %%)", 100 * p["data_share"].get<double>());
        }
      }
    }
    h += "<p>Prior: " +
         (given ? Esc(Str(j["recalibration"]["prior"])) + " (informative)"
                : std::string("the start model's tolerances")) +
         ", weighed against " +
         Sci(j["prior"]["data_sigma"]) + " mm per axis. " +
         (weak.empty() ? std::string("Every direction is determined by the data.")
                       : "Weakly determined (held near the start model by the prior): " +
                             Esc(weak) + ".") +
         "</p>\n";
  }
  if (!idj["correlated_above_0_9"].empty()) {
    h += "<p><span class=\"flag\">Correlations above 0.9</span> (these parameters are hard to "
         "separate; their individual values mean little):</p>\n<table>\n"
         "<tr><th>parameter</th><th>parameter</th><th>correlation</th></tr>\n";
    for (const Json& c : idj["correlated_above_0_9"])
      h += "<tr><td>" + Esc(Str(c["a"])) + "</td><td>" + Esc(Str(c["b"])) +
           "</td><td class=\"flag\">" + Fmt("%.4f", c["correlation"].get<double>()) +
           "</td></tr>\n";
    h += "</table>\n";
  } else {
    h += "<p>No pair of parameters correlates above 0.9.</p>\n";
  }
  if (!idj["unidentifiable"].empty()) {
    h += "<details><summary>Directions left out</summary><table>\n"
         "<tr><th>direction</th><th>reason</th></tr>\n";
    for (const Json& d : idj["unidentifiable"])
      h += "<tr><td>" + Esc(Str(d["name"])) + "</td><td style=\"text-align:left\">" +
           Esc(Str(d["reason"])) + "</td></tr>\n";
    h += "</table></details>\n";
  }
  for (const Json& w : idj["warnings"]) h += "<p class=\"flag\">warning: " + Esc(Str(w)) + "</p>\n";

}

void HtmlPage::JointErrors() {
  std::string& h = html_;
  const Json& j = j_;
  // ---- Joint-space error terms (docs/joint_errors.md): identified combinations, auto's choice.
  const Json& je = j["joint_errors"];
  if (!je["terms"].empty() || !je["selection"].is_null()) {
    h += "<h2>Joint errors</h2>\n";
    const Json& tilt = je["gravity_tilt"];
    if (!tilt.is_null()) {
      if (tilt["identified"].get<bool>()) {
        h += "<p>Gravity tilt: " + Fmt("%.4f", tilt["tilt_deg"][0].get<double>()) + " &plusmn; " +
             Fmt("%.4f", tilt["std_dev_deg"][0].get<double>()) + " deg and " +
             Fmt("%.4f", tilt["tilt_deg"][1].get<double>()) + " &plusmn; " +
             Fmt("%.4f", tilt["std_dev_deg"][1].get<double>()) +
             " deg about the two axes perpendicular to the model's gravity (" +
             Fmt("%.4f", tilt["angle_deg"].get<double>()) +
             " deg in all; standard deviations " +
             (tilt.contains("std_dev_form") ? tilt["std_dev_form"].get<std::string>()
                                            : std::string("a posteriori")) +
             "); the calibrated model carries the tilted gravity.</p>\n";
      } else {
        h += "<p>" + Esc(Str(tilt["message"])) + ".</p>\n";
      }
    }
    for (const Json& t : je["terms"]) {
      h += "<p>" + Esc(Str(t["name"])) + ": " + Str(t["parameters"]) + " parameters, " +
           Str(t["identified_combinations"]) + " identifiable combinations (" +
           std::to_string(t["not_identifiable"].size()) + " left out, listed above).</p>\n";
    }
    const Json& sel = je["selection"];
    if (!sel.is_null()) {
      h += "<p>Chosen by " + Str(sel["folds"]) + "-fold cross-validation: <b>" +
           Esc(Str(sel["chosen"])) + "</b> (" + Esc(Str(sel["reason"])) + ").</p>\n<table>\n" +
           "<tr><th>terms</th><th>combinations</th><th>CV rms [mm]</th><th>CV mse [mm&sup2;]</th>"
           "<th>std error</th></tr>\n";
      for (const Json& c : sel["candidates"]) {
        h += "<tr><td>" + Esc(Str(c["terms"])) + "</td><td>" + Str(c["identified_combinations"]) +
             "</td><td>" + (c["converged"].get<bool>() ? Fmt("%.5f", c["cv_rms"].get<double>())
                                                      : std::string("failed")) +
             "</td><td>" + Sci(c["cv_mse"]) + "</td><td>" + Sci(c["cv_mse_standard_error"]) +
             "</td></tr>\n";
      }
      h += "</table>\n";
    }
  }

}

void HtmlPage::ResidualModel() {
  std::string& h = html_;
  const Json& j = j_;
  // ---- The residual layer (docs/residual_layer.md): auto's choice and the fitted layer.
  const Json& rm = j["residual_model"];
  if (rm["requested"].get<std::string>() != "none") {
    h += "<h2>Residual layer</h2>\n";
    if (rm["fitted"].get<bool>()) {
      const Json& l = rm["layer"];
      h += "<p>A Gaussian process over the joint configuration and the SMR corrects every "
           "predicted position (" +
           Str(l["inducing"]) + " inducing inputs, signal " + Mm(l["signal_std"]) + " mm, noise " +
           Mm(l["noise_std"]) + " mm). Identification RMS with the layer " +
           Mm(rm["identification_with_layer"]["norm"]["rms"]) + " mm";
      if (!rm["verification_without_layer"].is_null()) {
        h += "; verification RMS " + Mm(rm["verification_without_layer"]["norm"]["rms"]) +
             " mm without it, " + Mm(j["verification"]["after"]["norm"]["rms"]) +
             " mm with it (fitted on the identification rows only)";
      }
      h += ". URDF and UR kinematics outputs cannot carry it.</p>\n";
      // Its length scales per joint, and the joints whose length scale is below the data's
      // spacing (docs/residual_layer.md).
      if (l.contains("length_scales") && l.contains("spacing")) {
        h += "<table>\n<tr><th>joint</th><th>length scale</th><th>spacing of the data</th></tr>\n";
        const Json& scales = l["length_scales"];
        const Json& spacing = l["spacing"];
        for (size_t k = 0; k < scales.size(); ++k) {
          const double ls = scales[k].get<double>();
          const double sp = k < spacing.size() ? spacing[k].get<double>() : 0.0;
          h += "<tr><td>" + std::to_string(k + 1) + "</td><td>" + Fmt("%.3g", ls) + "</td><td>" +
               Fmt("%.3g", sp) + (ls < sp ? " <b>(length scale below it)</b>" : "") +
               "</td></tr>\n";
        }
        h += "</table>\n";
        if (l.contains("length_scales_below_spacing") &&
            !l["length_scales_below_spacing"].empty()) {
          std::string joints;
          for (const Json& jn : l["length_scales_below_spacing"]) {
            joints += (joints.empty() ? "" : ", ") + Str(jn);
          }
          h += "<p class=\"flag\">warning: the length scale of joint " + joints +
               " is below the spacing of the data: the layer reproduces its identification rows "
               "there and predicts little between them. Trust held-out figures only.</p>\n";
        }
      }
    } else {
      h += "<p>No layer: " + Esc(Str(rm["message"])) + ".</p>\n";
    }
    const Json& sel = rm["selection"];
    if (!sel.is_null()) {
      h += "<p>Chosen by " + Str(sel["folds"]) + "-fold cross-validation by configuration: <b>" +
           Esc(Str(sel["chosen"])) + "</b>.</p>\n<table>\n" +
           "<tr><th>model</th><th>CV rms [mm]</th><th>CV mse [mm&sup2;]</th><th>std error</th>"
           "</tr>\n";
      for (const Json& c : sel["candidates"]) {
        h += "<tr><td>" + Esc(Str(c["model"])) + "</td><td>" +
             (c["ok"].get<bool>() ? Fmt("%.5f", c["cv_rms"].get<double>())
                                  : std::string("failed")) +
             "</td><td>" + Sci(c["cv_mse"]) + "</td><td>" + Sci(c["cv_mse_standard_error"]) +
             "</td></tr>\n";
      }
      h += "</table>\n";
    }
  }

}

void HtmlPage::Outliers() {
  std::string& h = html_;
  const Json& j = j_;
  // ---- Outliers.
  const Json& outl = j["outliers"];
  h += "<h2>Outliers</h2>\n";
  if (outl["points"].empty()) {
    h += "<p>No identification point fits worse than the outlier threshold (robust sigma " +
         Mm(outl["robust_sigma"]) + " mm per axis).</p>\n";
  } else {
    h += "<p>Points that fit worse than the threshold (robust sigma " + Mm(outl["robust_sigma"]) +
         " mm per axis). They were used; check them.</p>\n<table>\n"
         "<tr><th>file:line</th><th>error [mm]</th><th>sigmas</th></tr>\n";
    for (const Json& o : outl["points"])
      h += "<tr><td>" + Esc(Str(j["inputs"]["measurements"])) + ":" + Str(o["line"]) + "</td><td>" +
           Mm(o["error"]) + "</td><td>" + Fmt("%.1f", o["sigmas"].get<double>()) + "</td></tr>\n";
    h += "</table>\n";
  }

}

void HtmlPage::NextSteps() {
  std::string& h = html_;
  const Json& j = j_;
  const std::string level = Str(j["verdict"]["level"]);
  const Json& idj = j["identifiability"];
  // ---- What was written and what to do next, by verdict.
  h += "<h2>Outputs and next steps</h2>\n";
  if (j.contains("outputs") && !j["outputs"].empty()) {
    h += "<p>Written with this page:</p>\n<ul>\n";
    for (const Json& o : j["outputs"]) h += "<li><code>" + Esc(Str(o)) + "</code></li>\n";
    h += "</ul>\n";
  }
  std::vector<std::string> left_out;
  for (const Json& d : idj["unidentifiable"]) {
    if (d.value("structural", false)) {
      left_out.push_back(Str(d["name"]));
    }
  }
  h += "<ul>\n";
  if (level == "pass") {
    h += "<li>Deploy the calibrated YAML model: <code>lpoe_compensate</code> corrects targets, "
         "joint programs and URScript / RAPID programs; <code>lpoe_predict</code> predicts "
         "positions. A URDF or UR calibration file carries the geometry only.</li>\n"
         "<li>Expect the held-out error above (the verification set) at other poses in the "
         "measured workspace; outside it the model is extrapolated.</li>\n"
         "<li>Calibrate again after a collision, a change of tool or mounting, or when a check "
         "measurement drifts.</li>\n";
  } else if (level == "check") {
    h += "<li>The model was written, but read the checks above before deploying it: each says "
         "what it measured against what limit.</li>\n"
         "<li>A residual well above the tracker's noise: outliers (listed above), joint "
         "non-geometric errors (try <code>--joint_errors=auto</code>), the wrong length or angle "
         "unit, or SMRs named wrongly in the measurement file.</li>\n"
         "<li>Large parameter changes: a nominal model that is not this robot, or a measurement "
         "frame mix-up; compare with the nominal drawing.</li>\n";
  } else {
    h += std::string("<li><b>Do not deploy this model.</b> The verdict failed") +
         (j.value("forced", false) ? "; the outputs were written only because of --force" : "") +
         ". Fix the cause the verdict names, then measure and calibrate again.</li>\n";
  }
  if (!left_out.empty()) {
    std::string names;
    for (const std::string& n : left_out) names += (names.empty() ? "" : ", ") + n;
    h += "<li>Left out as not identifiable and kept as in the model: " + Esc(names) +
         ". Their reasons are in the identifiability section; a measured point off the last "
         "axis, or orientation data, identifies a last-axis tilt.</li>\n";
  }
  h += "</ul>\n";

}

void HtmlPage::Inputs() {
  std::string& h = html_;
  const Json& j = j_;
  // ---- Inputs and version.
  const Json& inp = j["inputs"];
  const Json& sol = j["solver"];
  h += "<h2>Inputs</h2>\n<table>\n";
  auto row = [&](const std::string& k, const std::string& v) {
    h += "<tr><td>" + k + "</td><td style=\"text-align:left\">" + Esc(v) + "</td></tr>\n";
  };
  row("model", Str(inp["model"]));
  row("measurements", Str(inp["measurements"]));
  row("verification", Str(inp["verification"]));
  row("angle unit", Str(inp["angle_unit"]));
  row("skipped rows (lost beam)", Str(inp["skipped_rows"]));
  row("solver", Str(sol["name"]) + ", " + Str(sol["parameterization"]) + " parameterization, " +
                    Str(sol["data"]) + " data");
  row("result", Str(sol["termination"]) + " after " + Str(sol["iterations"]) + " iteration(s)");
  row("tool", Str(j["tool"]["name"]) + " " + Str(j["tool"]["version"]));
  h += "</table>\n<p class=\"note\">Generated by lpoe-calib. The JSON report "
       "(<code>--report</code>) "
       "holds every figure of this page and the per-point residuals.</p>\n</body>\n</html>\n";
}

}  // namespace

Status RunSummaryToHtml(const RunSummary& summary, std::string* out) {
  return HtmlPage(summary).Write(out);
}

}  // namespace tools
}  // namespace lpoe