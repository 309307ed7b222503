// Plots for the calibration report (PLplot): each figure renders to a PNG that reads back with the
// right size, real content and the series colors, and to well-formed SVG; the bytes are the same on
// every run; failures leave nothing behind.
#include "report/plot.h"
#include "report/text_safety.h"

#include <gtest/gtest.h>
#include <png.h>
#include <sys/stat.h>
#include <unistd.h>
#include <tinyxml2.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <random>
#include <regex>
#include <string>
#include <vector>

namespace lpoe {
namespace tools {
namespace {
namespace plot_test {

struct Image {
  int width = 0, height = 0;
  std::vector<uint8_t> rgb;

  uint32_t At(int x, int y) const {
    const uint8_t* p = &rgb[(static_cast<size_t>(y) * width + x) * 3];
    return (uint32_t(p[0]) << 16) | (uint32_t(p[1]) << 8) | p[2];
  }
  double FractionNotWhite() const {
    size_t n = 0;
    for (int y = 0; y < height; ++y)
      for (int x = 0; x < width; ++x) n += At(x, y) != 0xFFFFFF;
    return double(n) / (double(width) * height);
  }
  size_t CountColor(uint32_t c) const {
    size_t n = 0;
    for (int y = 0; y < height; ++y)
      for (int x = 0; x < width; ++x) n += At(x, y) == c;
    return n;
  }
};

::testing::AssertionResult ReadPng(const std::string& path, Image* out) {
  png_image image;
  std::memset(&image, 0, sizeof image);
  image.version = PNG_IMAGE_VERSION;
  if (!png_image_begin_read_from_file(&image, path.c_str()))
    return ::testing::AssertionFailure() << "cannot open " << path << ": " << image.message;
  image.format = PNG_FORMAT_RGB;
  out->width = static_cast<int>(image.width);
  out->height = static_cast<int>(image.height);
  out->rgb.assign(PNG_IMAGE_SIZE(image), 0);
  if (!png_image_finish_read(&image, nullptr, out->rgb.data(), 0, nullptr)) {
    const std::string msg = image.message;
    png_image_free(&image);
    return ::testing::AssertionFailure() << "cannot read " << path << ": " << msg;
  }
  return ::testing::AssertionSuccess();
}

::testing::AssertionResult ReadPngBytes(const std::string& bytes, Image* out) {
  // One file per process: ctest runs the cases of this binary in parallel processes.
  const std::string path =
      ::testing::TempDir() + "lpoe_plot_test_bytes_" + std::to_string(::getpid()) + ".png";
  FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr) return ::testing::AssertionFailure() << "cannot write " << path;
  std::fwrite(bytes.data(), 1, bytes.size(), f);
  std::fclose(f);
  const auto r = ReadPng(path, out);
  std::remove(path.c_str());
  return r;
}

bool Exists(const std::string& path) {
  struct stat st;
  return stat(path.c_str(), &st) == 0;
}

std::string TempPath(const std::string& name) {
  return ::testing::TempDir() + "lpoe_plot_test_" + std::to_string(::getpid()) + "_" + name;
}

// Realistic-looking report data: a systematic, pose-dependent error before calibration and
// sub-0.1 mm noise after.
struct ReportData {
  std::vector<int> iteration;
  std::vector<double> max_err, mean_err;
  std::vector<Eigen::Vector3d> before, after;
  std::vector<double> before_norm, after_norm;
};

ReportData MakeReportData(int poses) {
  ReportData d;
  const double max0 = 6.3, mean0 = 2.4;
  for (int k = 0; k <= 7; ++k) {
    d.iteration.push_back(k);
    d.max_err.push_back(0.081 + max0 * std::pow(0.12, k));
    d.mean_err.push_back(0.031 + mean0 * std::pow(0.1, k));
  }
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0.0, 1.0);
  for (int i = 0; i < poses; ++i) {
    const double t = 0.21 * i;
    Eigen::Vector3d b(1.8 * std::sin(t) + 0.3 * noise(rng), -1.1 + 1.2 * std::cos(0.7 * t),
                      0.9 * std::sin(0.5 * t + 1.0) + 0.5);
    Eigen::Vector3d a{0.04 * noise(rng), 0.04 * noise(rng), 0.05 * noise(rng)};
    d.before.push_back(b);
    d.after.push_back(a);
    d.before_norm.push_back(b.norm());
    d.after_norm.push_back(a.norm());
  }
  return d;
}

Series MakeSeries(const std::string& label, std::vector<double> x, std::vector<double> y,
                  uint32_t rgb, bool markers = false) {
  Series s;
  s.label = label;
  s.x = std::move(x);
  s.y = std::move(y);
  s.rgb = rgb;
  s.markers = markers;
  return s;
}

Panel MakePanel(const std::string& title, bool log_y, bool integer_x, std::vector<Series> series) {
  Panel p;
  p.title = title;
  p.x_label = "x";
  p.y_label = "y";
  p.log_y = log_y;
  p.integer_x = integer_x;
  p.series = std::move(series);
  return p;
}

void ExpectGoodImage(const Image& img, int width, int height, const std::vector<uint32_t>& colors,
                     const std::string& what) {
  EXPECT_EQ(img.width, width) << what;
  EXPECT_EQ(img.height, height) << what;
  const double ink = img.FractionNotWhite();
  EXPECT_GT(ink, 0.01) << what;  // axes, text and data
  EXPECT_LT(ink, 0.6) << what;   // but mostly white background
  for (uint32_t c : colors) EXPECT_GT(img.CountColor(c), 30u) << what << " color " << std::hex << c;
}

// Renders `figure` as PNG (checked as above) and SVG (parsed as XML), twice each: same bytes.
void ExpectGoodFigure(const Figure& figure, const std::vector<uint32_t>& colors,
                      const std::string& what) {
  std::string png, png2, svg, svg2;
  ASSERT_TRUE(RenderFigure(figure, ImageFormat::kPng, &png).ok()) << what;
  ASSERT_TRUE(RenderFigure(figure, ImageFormat::kPng, &png2).ok()) << what;
  EXPECT_EQ(png, png2) << what << ": PNG bytes differ between two renderings";
  EXPECT_EQ(png.find("tIME"), std::string::npos) << what << ": PNG carries a timestamp";
  Image img;
  ASSERT_TRUE(ReadPngBytes(png, &img)) << what;
  ExpectGoodImage(img, figure.width, figure.height, colors, what);

  ASSERT_TRUE(RenderFigure(figure, ImageFormat::kSvg, &svg).ok()) << what;
  ASSERT_TRUE(RenderFigure(figure, ImageFormat::kSvg, &svg2).ok()) << what;
  EXPECT_EQ(svg, svg2) << what << ": SVG bytes differ between two renderings";
  tinyxml2::XMLDocument doc;
  ASSERT_EQ(doc.Parse(svg.c_str(), svg.size()), tinyxml2::XML_SUCCESS)
      << what << ": " << doc.ErrorStr();
  ASSERT_NE(doc.RootElement(), nullptr);
  EXPECT_STREQ(doc.RootElement()->Name(), "svg") << what;
  for (uint32_t c : colors) {
    char hex[8];
    std::snprintf(hex, sizeof hex, "#%06X", c);
    EXPECT_NE(svg.find(hex), std::string::npos) << what << ": no " << hex << " in the SVG";
  }
}

TEST(PlotTest, ConvergenceFigure) {
  const ReportData d = MakeReportData(40);
  const Figure f = ConvergenceFigure(d.iteration, d.max_err, d.mean_err);
  ExpectGoodFigure(f, {kColorMax, kColorMean}, "convergence");
}

// Names of any length and bytes: a 2,000-character joint name in a title or axis label
// crashed PLplot (fixed-size text buffers); invalid UTF-8 made the SVG unparsable. Every label is
// cut, made valid UTF-8 and has PLplot's escape '#' doubled before PLplot sees it.
TEST(PlotTest, LongAndInvalidLabelsRender) {
  const ReportData d = MakeReportData(30);
  Figure f = ConvergenceFigure(d.iteration, d.max_err, d.mean_err);
  f.panels[0].title = std::string(2000, 'j') + "\xff\xfe#u";
  f.panels[0].x_label = std::string(5000, 'x');
  f.panels[0].y_label = "error \xc3 #[0x25c6] [mm]";
  f.panels[0].series[0].label = std::string(3000, 's') + "\x80";
  for (ImageFormat format : {ImageFormat::kSvg, ImageFormat::kPng}) {
    std::string bytes;
    ASSERT_TRUE(RenderFigure(f, format, &bytes).ok());
    EXPECT_GT(bytes.size(), 1000u);
    if (format == ImageFormat::kSvg) {
      tinyxml2::XMLDocument doc;
      EXPECT_EQ(doc.Parse(bytes.c_str(), bytes.size()), tinyxml2::XML_SUCCESS);
      EXPECT_EQ(bytes.find(std::string(200, 'j')), std::string::npos) << "the title was not cut";
    }
  }
  EXPECT_EQ(PlotLabel("a#u"), "a##u");
  EXPECT_EQ(PlotLabel(std::string(500, 'z')).size(), kMaxPlotLabelBytes + 3);
}

TEST(PlotTest, AxisErrorFigureHasAfterOnItsOwnScale) {
  const ReportData d = MakeReportData(60);
  const Figure f = AxisErrorFigure(d.before, d.after);
  ASSERT_EQ(f.panels.size(), 2u);
  ExpectGoodFigure(f, {kColorX, kColorY, kColorZ}, "axis errors");
  // The "after" panel's own window: its y tick labels are below 1 mm (the "before" errors reach
  // several mm), and there are several of them.
  std::string svg;
  Figure after_only = f;
  after_only.panels.erase(after_only.panels.begin());
  ASSERT_TRUE(RenderFigure(after_only, ImageFormat::kSvg, &svg).ok());
  const std::regex label(">(-?[0-9]*\\.[0-9]+)<");
  int fractional = 0;
  for (auto it = std::sregex_iterator(svg.begin(), svg.end(), label); it != std::sregex_iterator();
       ++it) {
    EXPECT_LT(std::abs(std::stod((*it)[1])), 1.0) << (*it)[0];
    ++fractional;
  }
  EXPECT_GE(fractional, 3) << "no fractional mm tick labels on the after panel";
  // The after panel is not flat: its markers span more than a third of the plot height.
  Image img;
  std::string png;
  ASSERT_TRUE(RenderFigure(after_only, ImageFormat::kPng, &png).ok());
  ASSERT_TRUE(ReadPngBytes(png, &img));
  int top = img.height, bottom = 0;
  for (int y = 0; y < img.height; ++y)
    for (int x = 0; x < img.width; ++x)
      if (img.At(x, y) == kColorZ) {
        top = std::min(top, y);
        bottom = std::max(bottom, y);
      }
  EXPECT_GT(bottom - top, img.height / 3);
}

TEST(PlotTest, ErrorHistogramFigure) {
  const ReportData d = MakeReportData(200);
  const Figure f = ErrorHistogramFigure(d.before_norm, d.after_norm);
  ASSERT_EQ(f.panels.size(), 2u);
  ExpectGoodFigure(f, {kColorBefore, kColorAfter}, "histogram");
}

TEST(PlotTest, HistogramSeriesCountsEveryFiniteValue) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const Series s = HistogramSeries("h", {1, 2, 2, 3, 3, 3, nan, 4}, 3, 0);
  ASSERT_EQ(s.y.size(), 3u);
  ASSERT_EQ(s.x.size(), 4u);
  EXPECT_DOUBLE_EQ(s.x.front(), 1.0);
  EXPECT_DOUBLE_EQ(s.x.back(), 4.0);
  EXPECT_DOUBLE_EQ(s.y[0] + s.y[1] + s.y[2], 7.0);
  EXPECT_DOUBLE_EQ(s.y[2], 4.0);  // 3, 3, 3 and 4 (the last edge belongs to the last bin)
  const Series logs = HistogramSeries("h", {0.01, 0.1, 1, 10, 0, -1}, 3, 0, true);
  EXPECT_DOUBLE_EQ(logs.y[0] + logs.y[1] + logs.y[2], 4.0);  // non-positive values left out
  EXPECT_NEAR(logs.x[1], 0.1, 1e-12);
}

TEST(PlotTest, DecimationKeepsExtremesAndOrder) {
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0.0, 1.0);
  std::vector<double> v(100000);
  for (double& a : v) a = noise(rng);
  v[51234] = 40.0;  // an outlier
  v[777] = -35.0;
  const std::vector<int> k = DecimatedIndices(v, 1000);
  EXPECT_LE(k.size(), 1000u);
  EXPECT_GT(k.size(), 900u);
  EXPECT_TRUE(std::is_sorted(k.begin(), k.end()));
  EXPECT_NE(std::find(k.begin(), k.end(), 51234), k.end());
  EXPECT_NE(std::find(k.begin(), k.end(), 777), k.end());
  EXPECT_EQ(DecimatedIndices({3, 1, 2}, 1000), (std::vector<int>{0, 1, 2}));
}

TEST(PlotTest, ScatterWithColorScaleAndEqualAxes) {
  Panel p;
  p.title = "workspace";
  p.x_label = "x [mm]";
  p.y_label = "y [mm]";
  p.equal_axes = true;
  p.color_label = "error [mm]";
  Series s;
  s.lines = false;
  s.markers = true;
  for (int i = 0; i < 300; ++i) {
    s.x.push_back(800 * std::cos(0.1 * i));
    s.y.push_back(300 * std::sin(0.1 * i));
    s.color_value.push_back(0.001 * i);
  }
  s.color_min = 0;
  s.color_max = 0.3;
  p.series = {s};
  Figure f;
  f.panels = {p};
  f.width = 600;
  f.height = 500;
  ExpectGoodFigure(f, {}, "scatter");
}

TEST(PlotTest, EdgeCasesStillRender) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  // Empty series, all-equal values, NaN/inf, zeros and negatives on a log axis, one point.
  const Panel empty = MakePanel("empty", false, false, {MakeSeries("nothing", {}, {}, 0xFF0000)});
  const Panel flat =
      MakePanel("flat", false, true,
                {MakeSeries("flat", {0, 1, 2, 3}, {2.5, 2.5, 2.5, 2.5}, 0x009E73, true)});
  const Panel logp = MakePanel(
      "log", true, false,
      {MakeSeries("mixed", {0, 1, 2, 3, 4, 5}, {1.0, 0.0, -2.0, nan, 0.01, inf}, 0xCC79A7, true)});
  const Panel single =
      MakePanel("single point", true, false, {MakeSeries("one", {3}, {0.5}, 0x0072B2, true)});
  Figure f;
  f.panels = {empty, flat, logp, single};
  f.width = 900;
  f.height = 1000;
  ExpectGoodFigure(f, {0x009E73, 0xCC79A7, 0x0072B2}, "edge cases");
  // Builders with empty inputs.
  std::string bytes;
  EXPECT_TRUE(RenderFigure(ConvergenceFigure({}, {}, {}), ImageFormat::kPng, &bytes).ok());
  EXPECT_TRUE(RenderFigure(AxisErrorFigure({}, {}), ImageFormat::kSvg, &bytes).ok());
  EXPECT_TRUE(RenderFigure(ErrorHistogramFigure({}, {}), ImageFormat::kPng, &bytes).ok());
}

TEST(PlotTest, RejectsBadArguments) {
  std::string bytes;
  Figure none;
  EXPECT_FALSE(RenderFigure(none, ImageFormat::kPng, &bytes).ok());
  Figure tiny;
  tiny.panels = {Panel{}};
  tiny.width = tiny.height = 10;
  EXPECT_FALSE(RenderFigure(tiny, ImageFormat::kPng, &bytes).ok());
  Figure bad;
  bad.panels = {Panel{}};
  bad.panels[0].series.push_back(MakeSeries("xy", {1, 2}, {1}, 0));
  const Status s = RenderFigure(bad, ImageFormat::kSvg, &bytes);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("2 x and 1 y"), std::string::npos) << s.message();
  Figure colors;
  colors.panels = {Panel{}};
  Series c = MakeSeries("c", {1, 2}, {1, 2}, 0);
  c.color_value = {1};
  colors.panels[0].series = {c};
  EXPECT_FALSE(RenderFigure(colors, ImageFormat::kPng, &bytes).ok());
}

TEST(PlotTest, UnwritableDirectoryReportsErrorAndLeavesNothing) {
  const std::string dir = TempPath("no_such_dir");
  const std::string path = dir + "/plot.png";
  const ReportData d = MakeReportData(10);
  const Status s = WriteFigurePng(path, ConvergenceFigure(d.iteration, d.max_err, d.mean_err));
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find(path), std::string::npos) << s.message();
  EXPECT_FALSE(Exists(dir));
  EXPECT_FALSE(Exists(path));
}

TEST(PlotTest, ReplacesExistingFileAtomically) {
  const std::string path = TempPath("replace.png");
  {
    FILE* f = std::fopen(path.c_str(), "w");
    ASSERT_NE(f, nullptr);
    std::fputs("old", f);
    std::fclose(f);
  }
  const ReportData d = MakeReportData(10);
  ASSERT_TRUE(WriteFigurePng(path, ErrorHistogramFigure(d.before_norm, d.after_norm)).ok());
  Image img;
  ASSERT_TRUE(ReadPng(path, &img));
  EXPECT_EQ(img.width, 1000);
  std::remove(path.c_str());
}

// Writes one sample of each figure to $LPOE_PLOT_SAMPLE_DIR (for looking at them).
TEST(PlotTest, WritesSamplesWhenAsked) {
  const char* dir = std::getenv("LPOE_PLOT_SAMPLE_DIR");
  if (dir == nullptr || *dir == '\0') GTEST_SKIP() << "LPOE_PLOT_SAMPLE_DIR not set";
  const std::string d = std::string(dir) + "/";
  const ReportData r = MakeReportData(60);
  EXPECT_TRUE(
      WriteFigurePng(d + "convergence.png", ConvergenceFigure(r.iteration, r.max_err, r.mean_err))
          .ok());
  EXPECT_TRUE(WriteFigurePng(d + "axis_errors.png", AxisErrorFigure(r.before, r.after)).ok());
  EXPECT_TRUE(
      WriteFigurePng(d + "histogram.png", ErrorHistogramFigure(r.before_norm, r.after_norm)).ok());
  const ReportData many = MakeReportData(3000);
  EXPECT_TRUE(
      WriteFigurePng(d + "axis_errors_3000.png", AxisErrorFigure(many.before, many.after)).ok());
}

}  // namespace plot_test
}  // namespace
}  // namespace tools
}  // namespace lpoe
