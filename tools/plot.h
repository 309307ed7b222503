// A small, dependency-light plotting module for the calibration report: line/marker plots and
// histograms rendered in software (embedded 5x7 bitmap font, anti-aliased thick lines) and written
// as 8-bit RGB PNG files through libpng.
//
// Figures of the paper:
//   - WriteConvergencePlot: Fig. 6, max and mean error per iteration (log y axis).
//   - WriteAxisErrorPlot:   Figs. 7/9, x/y/z position error per verification pose, before/after.
//   - WriteErrorHistogram:  distribution of the position error norm, before/after.
//
// Every writer writes `path + ".tmp"` and renames it onto `path`, so a reader never sees a partial
// image; on failure the temporary file is removed and the Status names the path.
#ifndef LPOE_TOOLS_PLOT_H_
#define LPOE_TOOLS_PLOT_H_

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "lpoe/status.h"

namespace lpoe {
namespace tools {

// Colors as 0xRRGGBB. A color-blind-safe pair for before/after and a few more.
constexpr uint32_t kColorBefore = 0xD55E00;  // vermillion
constexpr uint32_t kColorAfter = 0x0072B2;   // blue
constexpr uint32_t kColorMax = 0xD55E00;
constexpr uint32_t kColorMean = 0x0072B2;

struct Series {
  std::string label;      // shown in the legend; an empty label is left out of the legend
  std::vector<double> x;  // same length as y; non-finite points are skipped (the line breaks)
  std::vector<double> y;
  uint32_t rgb = 0x000000;
  bool markers = false;  // small filled squares at the points
  bool lines = true;     // connect consecutive points
};

struct Panel {
  std::string title, x_label, y_label;
  bool log_y = false;      // decades; values <= 0 are clamped to a floor (noted in the title)
  bool integer_x = false;  // x ticks at whole numbers only (iterations, pose indices)
  bool zero_line = false;  // a thin line at y = 0 (signed errors)
  std::vector<Series> series;
};

// Renders `panels` stacked vertically (equal heights) into one width x height image.
Status WritePlotPng(const std::string& path, const std::vector<Panel>& panels, int width,
                    int height);

// Histogram of each sample set (label, values) over shared bins spanning all finite values;
// the sets are drawn as translucent overlaid bars with opaque outlines. With `log_x` the bins are
// log-spaced over the positive values (non-positive values are dropped and counted in the title).
Status WriteHistogramPng(const std::string& path, const std::string& title,
                         const std::string& x_label,
                         const std::vector<std::pair<std::string, std::vector<double>>>& samples,
                         int bins, int width, int height, bool log_x = false);

// Convenience builders used by lpoe_calibrate. Errors are in mm.
// Fig. 6: max and mean position error (mm) vs iteration, log y. Default size 1000 x 600.
Status WriteConvergencePlot(const std::string& path, const std::vector<int>& iteration,
                            const std::vector<double>& max_err, const std::vector<double>& mean_err,
                            int width = 1000, int height = 600);

// Figs. 7/9: signed x, y, z position error (mm) per pose index, before and after, three panels.
// `before` and `after` may differ in length (either may be empty). Default size 1000 x 900.
// `set_name` names the poses in the titles ("verification", or "identification" when there is no
// verification set).
Status WriteAxisErrorPlot(const std::string& path, const std::vector<Eigen::Vector3d>& before,
                          const std::vector<Eigen::Vector3d>& after, int width = 1000,
                          int height = 900, const std::string& set_name = "verification");

// Histogram of the position error norm (mm) before/after. Uses log-spaced bins when the two
// distributions differ by more than 10x (typical after a calibration), so both stay visible.
// Default size 1000 x 600.
Status WriteErrorHistogram(const std::string& path, const std::vector<double>& before_norm,
                           const std::vector<double>& after_norm, int width = 1000,
                           int height = 600);

}  // namespace tools
}  // namespace lpoe

#endif  // LPOE_TOOLS_PLOT_H_
