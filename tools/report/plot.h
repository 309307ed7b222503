// Plots of the calibration report, drawn with PLplot (Debian's libplplot-dev): PNG through the
// cairo driver `pngcairo` (plplot-driver-cairo) for the plot files, SVG through PLplot's own `svg`
// driver for the HTML report. A figure is described once (panels of series) and rendered to
// either format in memory; the bytes are deterministic (no timestamps: cairo writes no tIME chunk
// and the SVG driver no date) and files are written with WriteFileAtomically.
//
// Figures of the paper:
//   - ConvergenceFigure: Fig. 6, max and mean error per iteration (log y axis).
//   - AxisErrorFigure:   Figs. 7/9, x/y/z position error per pose, before and after calibration
//                        each in its own panel on its own scale.
//   - ErrorHistogramFigure: distribution of the position error norm, before and after, each in
//                        its own panel.
#ifndef LPOE_TOOLS_PLOT_H_
#define LPOE_TOOLS_PLOT_H_

#include <Eigen/Core>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "lpoe/status.h"

namespace lpoe {
namespace tools {

// Colors as 0xRRGGBB (Okabe-Ito, color-blind safe).
constexpr uint32_t kColorBefore = 0xD55E00;  // vermillion
constexpr uint32_t kColorAfter = 0x0072B2;   // blue
constexpr uint32_t kColorMax = 0xD55E00;
constexpr uint32_t kColorMean = 0x0072B2;
constexpr uint32_t kColorX = 0xD55E00;  // x, y, z error components
constexpr uint32_t kColorY = 0x009E73;
constexpr uint32_t kColorZ = 0x0072B2;

struct Series {
  std::string label;      // shown in the legend; an empty label is left out of the legend
  std::vector<double> x;  // same length as y; non-finite points are skipped (the line breaks)
  std::vector<double> y;
  uint32_t rgb = 0x000000;
  bool markers = false;  // small filled circles at the points
  bool lines = true;     // connect consecutive points
  // Bars (histograms): x holds the y.size() + 1 bin edges, y the counts.
  bool bars = false;
  // When not empty (same length as y): each marker is colored by its value on a continuous
  // scale from `color_min` (dark blue) to `color_max` (yellow); `rgb` is then unused.
  std::vector<double> color_value;
  double color_min = 0, color_max = 1;
};

struct Panel {
  std::string title, x_label, y_label;  // labels carry their unit, e.g. "error [mm]"
  bool log_y = false;                   // decades; values <= 0 are left out
  bool integer_x = false;               // x ticks at whole numbers only (iterations, pose indices)
  bool zero_line = false;               // a thin line at y = 0 (signed errors)
  bool log_x = false;                   // decades; values <= 0 are left out
  bool equal_axes = false;              // same scale on x and y (workspace views)
  std::string color_label;  // label of the color bar drawn for a series with color values
  std::vector<Series> series;
};

// Panels laid out on a grid of `columns` columns (rows filled first), in a width x height image.
struct Figure {
  std::vector<Panel> panels;
  int width = 1000, height = 600;  // pixels (PNG) or points (SVG)
  int columns = 1;
};

enum class ImageFormat { kPng, kSvg };

// Renders `figure` to PNG or SVG bytes. Fails (with a message) on inconsistent series, an image
// size outside [100, 8000], or when the PLplot driver is not installed.
Status RenderFigure(const Figure& figure, ImageFormat format, std::string* bytes);

// Renders `figure` as PNG and writes it to `path` atomically (WriteFileAtomically: a temporary
// created exclusively in the target directory, then renamed). The message names `path`.
Status WriteFigurePng(const std::string& path, const Figure& figure);

// Indices of at most `max_points` of `values` (in order) that draw the same picture: when there
// are more, the minimum and maximum of each of max_points / 2 consecutive buckets. Deterministic.
std::vector<int> DecimatedIndices(const std::vector<double>& values, int max_points);

// A histogram panel: each sample set binned over [min, max] of its finite values (log-spaced over
// the positive values with `log_x`).
Series HistogramSeries(const std::string& label, const std::vector<double>& values, int bins,
                       uint32_t rgb, bool log_x = false);

// Fig. 6: max and mean position error (mm) vs iteration, log y.
Figure ConvergenceFigure(const std::vector<int>& iteration, const std::vector<double>& max_err,
                         const std::vector<double>& mean_err);

// Figs. 7/9: signed x, y, z position error (mm) per pose index; before and after calibration in
// two panels, each on its own scale. `set_name` names the poses ("verification").
Figure AxisErrorFigure(const std::vector<Eigen::Vector3d>& before,
                       const std::vector<Eigen::Vector3d>& after,
                       const std::string& set_name = "verification");

// Histograms of the position error norm (mm) before and after, each in its own panel.
Figure ErrorHistogramFigure(const std::vector<double>& before_norm,
                            const std::vector<double>& after_norm);

}  // namespace tools
}  // namespace lpoe

#endif  // LPOE_TOOLS_PLOT_H_
