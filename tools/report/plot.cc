#include "report/plot.h"

#include <plplot.h>
#include <stdio.h>  // open_memstream (POSIX)

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>

#include "lpoe/io/io.h"
#include "common/tool_common.h"

namespace lpoe {
namespace tools {
namespace {

bool Finite(double v) { return std::isfinite(v); }

// cmap0 slots: 0 background, 1 axes and text, 2 grid, 3.. series colors.
constexpr int kColorText = 1;
constexpr int kColorGrid = 2;
constexpr int kFirstSeriesColor = 3;
constexpr double kMarkerRadiusPx = 2.6;

const char* DeviceName(ImageFormat f) { return f == ImageFormat::kPng ? "pngcairo" : "svg"; }

bool DeviceInstalled(const char* name) {
  // plgDevs lists the drivers PLplot finds at run time; plinit would otherwise prompt on stdin.
  const int kMaxDevices = 128;
  const char* menu[kMaxDevices];
  const char* devs[kMaxDevices];
  int n = kMaxDevices;
  const char** menu_list = menu;
  const char** dev_list = devs;
  plgDevs(&menu_list, &dev_list, &n);
  for (int k = 0; k < n; ++k)
    if (std::strcmp(devs[k], name) == 0) return true;
  return false;
}

void SetColor(int slot, uint32_t rgb) {
  plscol0(slot, (rgb >> 16) & 0xFF, (rgb >> 8) & 0xFF, rgb & 0xFF);
}

Status CheckFigure(const Figure& fig) {
  if (fig.panels.empty()) return Status::Error("plot: no panels");
  if (fig.width < 100 || fig.height < 100 || fig.width > 8000 || fig.height > 8000)
    return Status::Error("plot: image size " + std::to_string(fig.width) + " x " +
                         std::to_string(fig.height) + " outside [100, 8000]");
  if (fig.columns < 1) return Status::Error("plot: columns must be >= 1");
  for (const Panel& p : fig.panels) {
    for (const Series& s : p.series) {
      const size_t nx = s.bars ? s.y.size() + 1 : s.y.size();
      if (s.x.size() != nx && !(s.bars && s.y.empty() && s.x.empty()))
        return Status::Error("plot '" + p.title + "': series '" + s.label + "' has " +
                             std::to_string(s.x.size()) + " x and " + std::to_string(s.y.size()) +
                             " y values");
      if (!s.color_value.empty() && s.color_value.size() != s.y.size())
        return Status::Error("plot '" + p.title + "': series '" + s.label +
                             "' has color values of the wrong length");
    }
  }
  return Status::Ok();
}

// Value as plotted: log10 on a log axis (NaN for values <= 0, which are then left out).
double AxisValue(double v, bool log) {
  if (!log) return v;
  return v > 0 ? std::log10(v) : std::numeric_limits<double>::quiet_NaN();
}

struct Range {
  double lo = std::numeric_limits<double>::infinity();
  double hi = -std::numeric_limits<double>::infinity();
  void Add(double v) {
    if (!Finite(v)) return;
    lo = std::min(lo, v);
    hi = std::max(hi, v);
  }
  bool empty() const { return !(lo <= hi); }
};

// A non-degenerate window around the data, padded by `pad` of the span on each side.
void Window(const Range& r, double pad, bool include_zero, double* lo, double* hi) {
  double a = r.empty() ? 0.0 : r.lo, b = r.empty() ? 1.0 : r.hi;
  if (include_zero) {
    a = std::min(a, 0.0);
    b = std::max(b, 0.0);
  }
  if (b - a <= 1e-12 * std::max(1.0, std::abs(a))) {
    const double h = a == 0 ? 1.0 : 0.1 * std::abs(a);
    a -= h;
    b += h;
  }
  const double span = b - a;
  *lo = include_zero && a == 0 ? 0 : a - pad * span;
  *hi = b + pad * span;
}

// A filled marker (diamond) of kMarkerRadiusPx at every finite point. Drawn as polygons so the
// SVG stays small (one element per point).
void DrawMarkers(const std::vector<double>& x, const std::vector<double>& y, const Series& s,
                 int page_w, int page_h, int color_slot) {
  PLFLT vx0, vx1, vy0, vy1, wx0, wx1, wy0, wy1;
  plgvpd(&vx0, &vx1, &vy0, &vy1);
  plgvpw(&wx0, &wx1, &wy0, &wy1);
  const double rx = kMarkerRadiusPx / page_w * (wx1 - wx0) / (vx1 - vx0);
  const double ry = kMarkerRadiusPx / page_h * (wy1 - wy0) / (vy1 - vy0);
  const double span = s.color_max - s.color_min;
  for (size_t i = 0; i < x.size(); ++i) {
    if (!Finite(x[i]) || !Finite(y[i])) continue;
    if (!s.color_value.empty()) {
      const double t = span > 0 ? (s.color_value[i] - s.color_min) / span : 0.5;
      plcol1(std::clamp(Finite(t) ? t : 0.0, 0.0, 1.0));
    } else {
      plcol0(color_slot);
    }
    PLFLT px[4] = {x[i] - rx, x[i], x[i] + rx, x[i]};
    PLFLT py[4] = {y[i], y[i] + ry, y[i], y[i] - ry};
    plfill(4, px, py);
  }
}

// Consecutive finite points as one polyline each.
void DrawLines(const std::vector<double>& x, const std::vector<double>& y) {
  std::vector<PLFLT> px, py;
  auto flush = [&]() {
    if (px.size() >= 2) plline(static_cast<PLINT>(px.size()), px.data(), py.data());
    px.clear();
    py.clear();
  };
  for (size_t i = 0; i < x.size(); ++i) {
    if (!Finite(x[i]) || !Finite(y[i])) {
      flush();
      continue;
    }
    px.push_back(x[i]);
    py.push_back(y[i]);
  }
  flush();
}

void DrawBars(const std::vector<double>& edges, const std::vector<double>& counts, double y0,
              bool log_y) {
  for (size_t i = 0; i < counts.size(); ++i) {
    const double top = AxisValue(counts[i], log_y);
    if (!Finite(top) || !Finite(edges[i]) || !Finite(edges[i + 1]) || top <= y0) continue;
    PLFLT px[4] = {edges[i], edges[i], edges[i + 1], edges[i + 1]};
    PLFLT py[4] = {y0, top, top, y0};
    plfill(4, px, py);
  }
  // White separators between the bars.
  plcol0(0);
  plwidth(1.0);
  for (size_t i = 0; i + 1 < edges.size(); ++i) {
    const double top = AxisValue(counts[i], log_y);
    if (!Finite(top) || top <= y0) continue;
    PLFLT px[2] = {edges[i], edges[i]}, py[2] = {y0, top};
    plline(2, px, py);
  }
}

void DrawLegend(const Panel& p, const std::vector<int>& slots) {
  std::vector<PLINT> opt, text_colors, line_colors, line_styles, symbol_colors, symbol_numbers,
      box_colors, box_patterns;
  std::vector<PLFLT> line_widths, symbol_scales, box_scales, box_widths;
  std::vector<const char*> text, symbols;
  for (size_t k = 0; k < p.series.size(); ++k) {
    const Series& s = p.series[k];
    if (s.label.empty()) continue;
    PLINT o = 0;
    if (s.bars) o |= PL_LEGEND_COLOR_BOX;
    if (!s.bars && s.lines) o |= PL_LEGEND_LINE;
    if (!s.bars && (s.markers || !s.lines)) o |= PL_LEGEND_SYMBOL;
    opt.push_back(o);
    text.push_back(s.label.c_str());
    text_colors.push_back(kColorText);
    line_colors.push_back(slots[k]);
    line_styles.push_back(1);
    line_widths.push_back(1.5);
    symbol_colors.push_back(slots[k]);
    symbol_scales.push_back(0.6);
    symbol_numbers.push_back(1);
    symbols.push_back("#[0x25c6]");  // a filled diamond, as the markers
    box_colors.push_back(slots[k]);
    box_patterns.push_back(0);
    box_scales.push_back(0.8);
    box_widths.push_back(1.0);
  }
  if (opt.empty()) return;
  PLFLT w, h;
  plscol0a(0, 255, 255, 255, 0.85);  // a translucent white legend box
  pllegend(&w, &h, PL_LEGEND_BACKGROUND | PL_LEGEND_BOUNDING_BOX,
           PL_POSITION_TOP | PL_POSITION_RIGHT | PL_POSITION_INSIDE, 0.01, 0.01, 0.06, 0,
           kColorGrid, 1, 1, static_cast<PLINT>(opt.size()), static_cast<PLINT>(opt.size()),
           opt.data(), 0.6, 0.75, 2.0, 0.0, text_colors.data(), text.data(), box_colors.data(),
           box_patterns.data(), box_scales.data(), box_widths.data(), line_colors.data(),
           line_styles.data(), line_widths.data(), symbol_colors.data(), symbol_scales.data(),
           symbol_numbers.data(), symbols.data());
  plscol0a(0, 255, 255, 255, 1.0);
}

// The continuous color scale of `s` beside the plot, labelled `label`.
void DrawColorBar(const Series& s, const std::string& label) {
  PLFLT w, h;
  PLINT label_opts[1] = {PL_COLORBAR_LABEL_RIGHT};
  const char* labels[1] = {label.c_str()};
  const char* axis_opts[1] = {"bcvtm"};
  PLFLT ticks[1] = {0};
  PLINT sub_ticks[1] = {0};
  PLINT n_values[1] = {2};
  PLFLT range[2] = {s.color_min, s.color_max > s.color_min ? s.color_max : s.color_min + 1e-9};
  const PLFLT* values[1] = {range};
  plcol0(kColorText);
  plcolorbar(&w, &h, PL_COLORBAR_GRADIENT, PL_POSITION_RIGHT | PL_POSITION_OUTSIDE, 0.03, 0.0, 0.04,
             0.9, 0, kColorText, 1, 0, 0, 0, 0, 1, label_opts, labels, 1, axis_opts, ticks,
             sub_ticks, n_values, values);
}

void RenderPanel(const Panel& p, const Figure& fig, int* next_slot) {
  // The data as plotted (log10 on log axes), the window, the legend's head room.
  std::vector<std::vector<double>> xs(p.series.size()), ys(p.series.size());
  Range rx, ry;
  bool bars = false;
  for (size_t k = 0; k < p.series.size(); ++k) {
    const Series& s = p.series[k];
    bars |= s.bars;
    for (double v : s.x) xs[k].push_back(AxisValue(v, p.log_x));
    for (double v : s.y) ys[k].push_back(AxisValue(v, p.log_y));
    for (double v : xs[k]) rx.Add(v);
    for (double v : ys[k]) ry.Add(v);
  }
  const bool has_legend = std::any_of(p.series.begin(), p.series.end(),
                                      [](const Series& s) { return !s.label.empty(); });
  double x0, x1, y0, y1;
  Window(rx, bars ? 0.0 : 0.02, false, &x0, &x1);
  Window(ry, 0.05, bars && !p.log_y, &y0, &y1);
  if (has_legend) y1 += 0.18 * (y1 - y0);  // head room for the legend row

  const Series* colored = nullptr;
  for (const Series& s : p.series)
    if (!s.color_value.empty()) colored = &s;
  pladv(0);
  plschr(0, 0.75);
  plvsta();
  if (colored) plvpor(0.14, 0.80, 0.14, 0.88);  // room for the color bar on the right
  if (p.equal_axes) {
    // Same scale on both axes: widen the shorter range to the viewport's aspect.
    PLFLT vx0, vx1, vy0, vy1;
    plgvpd(&vx0, &vx1, &vy0, &vy1);
    const double aspect = ((vy1 - vy0) * fig.height) / ((vx1 - vx0) * fig.width);
    const double cx = 0.5 * (x0 + x1), cy = 0.5 * (y0 + y1);
    const double half = 0.5 * std::max(x1 - x0, (y1 - y0) / aspect);
    x0 = cx - half;
    x1 = cx + half;
    y0 = cy - half * aspect;
    y1 = cy + half * aspect;
  }
  plwind(x0, x1, y0, y1);

  const std::string xopt = std::string("bcnst") + (p.log_x ? "l" : "");
  const std::string yopt = std::string("bcnstv") + (p.log_y ? "l" : "");
  plcol0(kColorGrid);
  plwidth(0.5);
  plbox((std::string("g") + (p.log_x ? "l" : "")).c_str(), 0, 0,
        (std::string("g") + (p.log_y ? "l" : "")).c_str(), 0, 0);
  if (p.zero_line && y0 < 0 && y1 > 0) {
    plcol0(kColorText);
    PLFLT zx[2] = {x0, x1}, zy[2] = {0, 0};
    plline(2, zx, zy);
  }

  std::vector<int> slots(p.series.size());
  bool any = false;
  for (size_t k = 0; k < p.series.size(); ++k) {
    const Series& s = p.series[k];
    slots[k] = (*next_slot)++;
    SetColor(slots[k], s.rgb);
    plcol0(slots[k]);
    plwidth(1.5);
    if (s.bars) {
      DrawBars(xs[k], s.y, p.log_y ? y0 : 0.0, p.log_y);
    } else {
      if (s.lines) DrawLines(xs[k], ys[k]);
      if (s.markers || !s.lines) DrawMarkers(xs[k], ys[k], s, fig.width, fig.height, slots[k]);
    }
    for (size_t i = 0; i < ys[k].size(); ++i) any |= Finite(ys[k][i]);
  }
  if (!any) {
    plcol0(kColorText);
    plptex(0.5 * (x0 + x1), 0.5 * (y0 + y1), 1, 0, 0.5, "no data");
  }
  plcol0(kColorText);
  plwidth(1.0);
  plbox(xopt.c_str(), 0, 0, yopt.c_str(), 0, 0);
  plschr(0, 0.85);
  pllab(p.x_label.c_str(), p.y_label.c_str(), p.title.c_str());
  plschr(0, 0.75);
  DrawLegend(p, slots);
  if (colored) DrawColorBar(*colored, p.color_label);
}

// PLplot's svg driver writes one attribute per line and every character of a text as a character
// reference (&#x30;). This collapses the indentation and writes printable ASCII as itself (a
// third of the size, and the page's text becomes searchable).
std::string CompactSvg(const std::string& svg) {
  std::string out;
  out.reserve(svg.size());
  size_t i = svg.find("<svg");
  if (i == std::string::npos) i = 0;  // drop the XML declaration and DOCTYPE (inline use)
  for (; i < svg.size(); ++i) {
    const char c = svg[i];
    if (c == '&' && svg.compare(i, 3, "&#x") == 0) {
      const size_t end = svg.find(';', i);
      if (end != std::string::npos && end - i <= 8) {
        const long code = std::strtol(svg.substr(i + 3, end - i - 3).c_str(), nullptr, 16);
        if (code >= 0x20 && code < 0x7F &&
            std::strchr("<>&\"'", static_cast<int>(code)) == nullptr) {
          out.push_back(static_cast<char>(code));
          i = end;
          continue;
        }
      }
    }
    if (c == '\n') {
      while (i + 1 < svg.size() && svg[i + 1] == ' ') ++i;
      if (!out.empty() && out.back() != '>' && out.back() != ' ')
        out.push_back(' ');
      else if (!out.empty() && out.back() == '>')
        out.push_back('\n');
      continue;
    }
    out.push_back(c);
  }
  // "  />" after collapsing: drop the space before "/>".
  std::string tidy;
  tidy.reserve(out.size());
  for (size_t k = 0; k < out.size(); ++k) {
    if (out[k] == ' ' && k + 1 < out.size() && (out[k + 1] == '/' || out[k + 1] == '>') &&
        !tidy.empty() && tidy.back() != '"' && tidy.back() != ' ')
      continue;
    if (out[k] == ' ' && !tidy.empty() && tidy.back() == ' ') continue;
    tidy.push_back(out[k]);
  }
  return tidy;
}

std::string Num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", v);
  return buf;
}

}  // namespace

Status RenderFigure(const Figure& figure, ImageFormat format, std::string* bytes) {
  // Every text of the figure made safe for PLplot in this one place.
  Figure fig = figure;
  for (Panel& p : fig.panels) {
    for (std::string* t : {&p.title, &p.x_label, &p.y_label, &p.color_label}) *t = PlotLabel(*t);
    for (Series& s : p.series) s.label = PlotLabel(s.label);
  }
  if (Status s = CheckFigure(fig); !s.ok()) return s;
  const char* device = DeviceName(format);
  if (!DeviceInstalled(device))
    return Status::Error(std::string("plot: the PLplot driver '") + device +
                         "' is not installed (Debian: plplot-driver-cairo for pngcairo)");
  char* buffer = nullptr;
  size_t size = 0;
  FILE* memory = open_memstream(&buffer, &size);
  if (memory == nullptr) return Status::Error("plot: cannot open a memory stream");

  PLINT previous = 0, stream = 0;
  plgstrm(&previous);
  plmkstrm(&stream);
  plsdev(device);
  plsfile(memory);  // PLplot writes to (and closes) this stream instead of opening a file
  plspage(0, 0, fig.width, fig.height, 0, 0);
  plscolbg(255, 255, 255);
  size_t slots = kFirstSeriesColor;
  for (const Panel& p : fig.panels) slots += p.series.size();
  plscmap0n(static_cast<PLINT>(std::max<size_t>(16, slots)));
  SetColor(kColorText, 0x333333);
  SetColor(kColorGrid, 0xDDDDDD);
  // cmap1: dark blue -> teal -> yellow (viridis-like, readable in grey scale).
  PLFLT pos[3] = {0, 0.5, 1}, r[3] = {0.27, 0.13, 0.99}, g[3] = {0.0, 0.57, 0.91},
        b[3] = {0.33, 0.55, 0.14};
  plscmap1l(1, 3, pos, r, g, b, nullptr);
  const int rows = static_cast<int>((fig.panels.size() + fig.columns - 1) / fig.columns);
  plssub(fig.columns, rows);
  plinit();
  plfontld(1);
  plsxax(6, 0);  // up to 6 digits before the labels switch to a common (x10^n) factor
  plsyax(6, 0);
  int next_slot = kFirstSeriesColor;
  for (const Panel& p : fig.panels) RenderPanel(p, fig, &next_slot);
  plend1();  // writes the page and closes `memory`
  plsstrm(previous);

  std::string raw(buffer, size);
  std::free(buffer);
  if (format == ImageFormat::kSvg) raw = CompactSvg(raw);
  *bytes = std::move(raw);
  return Status::Ok();
}

Status WriteFigurePng(const std::string& path, const Figure& figure) {
  std::string bytes;
  if (Status s = RenderFigure(figure, ImageFormat::kPng, &bytes); !s.ok())
    return Status::Error(path + ": " + s.message());
  return WriteFileAtomically(path, bytes);
}

std::vector<int> DecimatedIndices(const std::vector<double>& values, int max_points) {
  const int n = static_cast<int>(values.size());
  std::vector<int> out;
  if (n <= max_points || max_points < 2) {
    for (int i = 0; i < n; ++i) out.push_back(i);
    return out;
  }
  const int buckets = max_points / 2;
  for (int b = 0; b < buckets; ++b) {
    const int begin = static_cast<int>(static_cast<int64_t>(n) * b / buckets);
    const int end = static_cast<int>(static_cast<int64_t>(n) * (b + 1) / buckets);
    int lo = begin, hi = begin;
    for (int i = begin; i < end; ++i) {
      if (values[i] < values[lo]) lo = i;
      if (values[i] > values[hi]) hi = i;
    }
    out.push_back(std::min(lo, hi));
    if (hi != lo) out.push_back(std::max(lo, hi));
  }
  return out;
}

Series HistogramSeries(const std::string& label, const std::vector<double>& values, int bins,
                       uint32_t rgb, bool log_x) {
  Series s;
  s.label = label;
  s.rgb = rgb;
  s.bars = true;
  Range r;
  for (double v : values)
    if (!log_x || v > 0) r.Add(log_x ? std::log10(v) : v);
  if (r.empty() || bins < 1) return s;
  double lo = r.lo, hi = r.hi;
  if (hi - lo <= 1e-12 * std::max(1.0, std::abs(lo))) {
    lo -= 0.5;
    hi += 0.5;
  }
  s.y.assign(bins, 0.0);
  for (int k = 0; k <= bins; ++k) {
    const double e = lo + (hi - lo) * k / bins;
    s.x.push_back(log_x ? std::pow(10.0, e) : e);
  }
  for (double v : values) {
    if (log_x && !(v > 0)) continue;
    const double a = log_x ? std::log10(v) : v;
    if (!Finite(a)) continue;
    const int k = std::clamp(static_cast<int>((a - lo) / (hi - lo) * bins), 0, bins - 1);
    s.y[k] += 1;
  }
  return s;
}

Figure ConvergenceFigure(const std::vector<int>& iteration, const std::vector<double>& max_err,
                         const std::vector<double>& mean_err) {
  Panel p;
  p.title = "Convergence: position error per iteration (identification set)";
  p.x_label = "iteration";
  p.y_label = "position error [mm]";
  p.log_y = true;
  p.integer_x = true;
  std::vector<double> it(iteration.begin(), iteration.end());
  const bool markers = iteration.size() <= 100;
  for (int k = 0; k < 2; ++k) {
    Series s;
    s.label = k == 0 ? "max error" : "mean error";
    s.x = it;
    s.y = k == 0 ? max_err : mean_err;
    s.rgb = k == 0 ? kColorMax : kColorMean;
    s.markers = markers;
    p.series.push_back(std::move(s));
  }
  Figure f;
  f.panels = {p};
  f.width = 1000;
  f.height = 600;
  return f;
}

Figure AxisErrorFigure(const std::vector<Eigen::Vector3d>& before,
                       const std::vector<Eigen::Vector3d>& after, const std::string& set_name) {
  static const char* kAxis[3] = {"x", "y", "z"};
  static const uint32_t kColors[3] = {kColorX, kColorY, kColorZ};
  constexpr int kMaxPoints = 1200;  // per series: min/max envelope beyond this
  Figure f;
  f.width = 1000;
  f.height = 900;
  const std::vector<Eigen::Vector3d>* sets[2] = {&before, &after};
  const char* names[2] = {"before calibration", "after calibration"};
  for (int k = 0; k < 2; ++k) {
    const std::vector<Eigen::Vector3d>& set = *sets[k];
    Panel p;
    p.title = std::string("Position error per ") + set_name + " pose, " + names[k];
    p.x_label = "pose index";
    p.y_label = "error [mm]";
    p.integer_x = true;
    p.zero_line = true;
    for (int a = 0; a < 3; ++a) {
      std::vector<double> all(set.size());
      double sum2 = 0;
      for (size_t i = 0; i < set.size(); ++i) {
        all[i] = set[i][a];
        sum2 += all[i] * all[i];
      }
      Series s;
      s.rgb = kColors[a];
      s.markers = set.size() <= 80;
      s.label = std::string(kAxis[a]) +
                (set.empty() ? "" : " (rms " + Num(std::sqrt(sum2 / set.size())) + " mm)");
      for (int i : DecimatedIndices(all, kMaxPoints)) {
        s.x.push_back(i);
        s.y.push_back(all[i]);
      }
      p.series.push_back(std::move(s));
    }
    f.panels.push_back(std::move(p));
  }
  return f;
}

Figure ErrorHistogramFigure(const std::vector<double>& before_norm,
                            const std::vector<double>& after_norm) {
  Figure f;
  f.width = 1000;
  f.height = 700;
  const std::vector<double>* sets[2] = {&before_norm, &after_norm};
  const char* names[2] = {"before calibration", "after calibration"};
  const uint32_t colors[2] = {kColorBefore, kColorAfter};
  for (int k = 0; k < 2; ++k) {
    size_t n = 0;
    double sum = 0, mx = 0;
    for (double v : *sets[k])
      if (Finite(v)) {
        ++n;
        sum += v;
        mx = std::max(mx, v);
      }
    const int bins = std::clamp(static_cast<int>(std::ceil(2.0 * std::sqrt(double(n)))), 8, 40);
    Panel p;
    p.title = std::string("Position error norm, ") + names[k];
    p.x_label = "position error norm [mm]";
    p.y_label = "poses";
    const std::string label = n == 0 ? std::string("no data")
                                     : "n=" + std::to_string(n) + ", mean " + Num(sum / n) +
                                           " mm, max " + Num(mx) + " mm";
    p.series.push_back(HistogramSeries(label, *sets[k], bins, colors[k]));
    f.panels.push_back(std::move(p));
  }
  return f;
}

}  // namespace tools
}  // namespace lpoe
