// Plots for the calibration report: each writer produces a PNG that reads back with the right size,
// real content and the series colors; failures leave nothing behind.
#include "plot.h"

#include <sys/stat.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <png.h>

namespace lpoe {
namespace tools {
namespace {

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

bool Exists(const std::string& path) {
  struct stat st;
  return stat(path.c_str(), &st) == 0;
}

std::string TempPath(const std::string& name) {
  return ::testing::TempDir() + "lpoe_plot_test_" + name;
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
    Eigen::Vector3d a(0.04 * noise(rng), 0.04 * noise(rng), 0.05 * noise(rng));
    d.before.push_back(b);
    d.after.push_back(a);
    d.before_norm.push_back(b.norm());
    d.after_norm.push_back(a.norm());
  }
  return d;
}

void ExpectGoodPlot(const std::string& path, int width, int height,
                    const std::vector<uint32_t>& colors) {
  Image img;
  ASSERT_TRUE(ReadPng(path, &img));
  EXPECT_EQ(img.width, width);
  EXPECT_EQ(img.height, height);
  const double ink = img.FractionNotWhite();
  EXPECT_GT(ink, 0.01) << path;  // axes, text and data
  EXPECT_LT(ink, 0.6) << path;   // but mostly white background
  for (uint32_t c : colors) EXPECT_GT(img.CountColor(c), 50u) << path << " color " << std::hex << c;
  EXPECT_FALSE(Exists(path + ".tmp"));
}

TEST(PlotTest, ConvergencePlot) {
  const ReportData d = MakeReportData(40);
  const std::string path = TempPath("convergence.png");
  ASSERT_TRUE(WriteConvergencePlot(path, d.iteration, d.max_err, d.mean_err).ok());
  ExpectGoodPlot(path, 1000, 600, {kColorMax, kColorMean});
  std::remove(path.c_str());
}

TEST(PlotTest, AxisErrorPlot) {
  const ReportData d = MakeReportData(60);
  const std::string path = TempPath("axis_errors.png");
  ASSERT_TRUE(WriteAxisErrorPlot(path, d.before, d.after).ok());
  ExpectGoodPlot(path, 1000, 900, {kColorBefore, kColorAfter});
  std::remove(path.c_str());
}

TEST(PlotTest, ErrorHistogram) {
  const ReportData d = MakeReportData(200);
  const std::string path = TempPath("histogram.png");
  ASSERT_TRUE(WriteErrorHistogram(path, d.before_norm, d.after_norm).ok());
  ExpectGoodPlot(path, 1000, 600, {kColorBefore, kColorAfter});
  std::remove(path.c_str());
}

TEST(PlotTest, HistogramLinearBinsAndCustomSize) {
  const std::string path = TempPath("histogram_linear.png");
  std::vector<double> a, b;
  for (int i = 0; i < 100; ++i) {
    a.push_back(1.0 + 0.01 * i);
    b.push_back(1.5 + 0.005 * i);
  }
  ASSERT_TRUE(WriteHistogramPng(path, "two sets", "value", {{"a", a}, {"b", b}}, 20, 640, 400).ok());
  ExpectGoodPlot(path, 640, 400, {kColorBefore, kColorAfter});
  std::remove(path.c_str());
}

TEST(PlotTest, GenericMultiPanelPlot) {
  Panel p1{"sine", "t", "y", false, false, false, {}};
  Panel p2{"decay", "t", "y", true, false, false, {}};
  Series s1{"sin", {}, {}, 0x009E73, true, true};
  Series s2{"exp", {}, {}, 0xCC79A7, false, true};
  for (int i = 0; i < 50; ++i) {
    s1.x.push_back(0.1 * i);
    s1.y.push_back(std::sin(0.1 * i));
    s2.x.push_back(0.1 * i);
    s2.y.push_back(std::exp(-0.3 * i));
  }
  p1.series = {s1};
  p2.series = {s2};
  const std::string path = TempPath("panels.png");
  ASSERT_TRUE(WritePlotPng(path, {p1, p2}, 800, 700).ok());
  ExpectGoodPlot(path, 800, 700, {0x009E73, 0xCC79A7});
  std::remove(path.c_str());
}

TEST(PlotTest, EdgeCasesStillRender) {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  const std::string path = TempPath("edge.png");
  // Empty series, all-equal values, NaN/inf, zeros and negatives on a log axis.
  Panel empty{"empty", "x", "y", false, false, false, {Series{"nothing", {}, {}, 0xFF0000}}};
  Panel flat{"flat", "x", "y", false, true, false,
             {Series{"flat", {0, 1, 2, 3}, {2.5, 2.5, 2.5, 2.5}, 0x009E73, true}}};
  Panel logp{"log", "x", "y", true, false, false,
             {Series{"mixed", {0, 1, 2, 3, 4, 5}, {1.0, 0.0, -2.0, nan, 0.01, inf}, 0xCC79A7,
                     true}}};
  Panel single{"single point", "x", "y", true, false, false,
               {Series{"one", {3}, {0.5}, 0x0072B2, true}}};
  ASSERT_TRUE(WritePlotPng(path, {empty, flat, logp, single}, 900, 1000).ok());
  ExpectGoodPlot(path, 900, 1000, {0x009E73, 0xCC79A7, 0x0072B2});

  // Histograms: no data at all, all-equal values, non-positive values on log bins.
  ASSERT_TRUE(WriteHistogramPng(path, "empty", "v", {{"none", {}}}, 10, 600, 400).ok());
  ASSERT_TRUE(WriteHistogramPng(path, "equal", "v", {{"eq", {3, 3, 3}}}, 10, 600, 400).ok());
  ExpectGoodPlot(path, 600, 400, {kColorBefore});
  ASSERT_TRUE(
      WriteHistogramPng(path, "log", "v", {{"pos", {0.1, 1, 10, 0, -1, nan}}}, 10, 600, 400, true)
          .ok());
  ExpectGoodPlot(path, 600, 400, {kColorBefore});

  // Builders with empty inputs.
  ASSERT_TRUE(WriteConvergencePlot(path, {}, {}, {}).ok());
  ASSERT_TRUE(WriteAxisErrorPlot(path, {}, {}).ok());
  ASSERT_TRUE(WriteErrorHistogram(path, {}, {}).ok());
  std::remove(path.c_str());
}

TEST(PlotTest, RejectsBadArguments) {
  const std::string path = TempPath("bad.png");
  EXPECT_FALSE(WriteConvergencePlot(path, {0, 1}, {1.0}, {1.0, 2.0}).ok());
  EXPECT_FALSE(WritePlotPng(path, {}, 800, 600).ok());
  EXPECT_FALSE(WritePlotPng(path, {Panel{}}, 10, 10).ok());
  Panel bad;
  bad.series.push_back(Series{"xy", {1, 2}, {1}, 0});
  EXPECT_FALSE(WritePlotPng(path, {bad}, 800, 600).ok());
  EXPECT_FALSE(WriteHistogramPng(path, "t", "x", {{"a", {1.0}}}, 0, 800, 600).ok());
  EXPECT_FALSE(Exists(path));
}

TEST(PlotTest, UnwritableDirectoryReportsErrorAndLeavesNothing) {
  const std::string dir = TempPath("no_such_dir");
  const std::string path = dir + "/plot.png";
  const ReportData d = MakeReportData(10);
  const Status s = WriteConvergencePlot(path, d.iteration, d.max_err, d.mean_err);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find(path), std::string::npos) << s.message();
  EXPECT_FALSE(WriteAxisErrorPlot(path, d.before, d.after).ok());
  EXPECT_FALSE(WriteErrorHistogram(path, d.before_norm, d.after_norm).ok());
  EXPECT_FALSE(Exists(dir));
  EXPECT_FALSE(Exists(path));
  EXPECT_FALSE(Exists(path + ".tmp"));
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
  ASSERT_TRUE(WriteErrorHistogram(path, d.before_norm, d.after_norm).ok());
  Image img;
  ASSERT_TRUE(ReadPng(path, &img));
  EXPECT_FALSE(Exists(path + ".tmp"));
  std::remove(path.c_str());
}

// Writes one sample of each figure to $LPOE_PLOT_SAMPLE_DIR (for looking at them).
TEST(PlotTest, WritesSamplesWhenAsked) {
  const char* dir = std::getenv("LPOE_PLOT_SAMPLE_DIR");
  if (dir == nullptr || *dir == '\0') GTEST_SKIP() << "LPOE_PLOT_SAMPLE_DIR not set";
  const std::string d = std::string(dir) + "/";
  const ReportData r = MakeReportData(60);
  EXPECT_TRUE(WriteConvergencePlot(d + "convergence.png", r.iteration, r.max_err, r.mean_err).ok());
  EXPECT_TRUE(WriteAxisErrorPlot(d + "axis_errors.png", r.before, r.after).ok());
  EXPECT_TRUE(WriteErrorHistogram(d + "histogram.png", r.before_norm, r.after_norm).ok());
  std::vector<double> a, b;
  for (double v : r.before_norm) a.push_back(v);
  for (double v : r.before_norm) b.push_back(0.8 * v + 0.2);
  EXPECT_TRUE(WriteErrorHistogram(d + "histogram_linear.png", a, b).ok());
  const double nan = std::numeric_limits<double>::quiet_NaN();
  Panel flat{"all-equal values", "x", "y", false, true, false,
             {Series{"flat", {0, 1, 2, 3}, {2.5, 2.5, 2.5, 2.5}, 0x009E73, true}}};
  Panel logp{"log axis with zero, negative and NaN", "x", "y", true, true, false,
             {Series{"mixed", {0, 1, 2, 3, 4, 5}, {1.0, 0.0, -2.0, nan, 0.01, 0.2}, 0xCC79A7,
                     true}}};
  Panel empty{"empty", "x", "y", false, false, false, {}};
  EXPECT_TRUE(WritePlotPng(d + "edge_cases.png", {flat, logp, empty}, 1000, 900).ok());
  // Narrow log range, large magnitudes, many points without markers.
  Panel narrow{"log axis within one decade", "iteration", "cost", true, true, false,
               {Series{"cost", {0, 1, 2, 3}, {0.8, 0.5, 0.35, 0.33}, 0x009E73, true}}};
  Panel big{"large values", "t", "y", false, false, true, {Series{"big", {}, {}, 0x0072B2}}};
  for (int i = 0; i < 400; ++i) {
    big.series[0].x.push_back(1e4 * i);
    big.series[0].y.push_back(2.5e6 * std::sin(0.05 * i));
  }
  EXPECT_TRUE(WritePlotPng(d + "ticks.png", {narrow, big}, 1000, 700).ok());
  const ReportData many = MakeReportData(300);
  EXPECT_TRUE(WriteAxisErrorPlot(d + "axis_errors_300.png", many.before, many.after).ok());
}

}  // namespace
}  // namespace tools
}  // namespace lpoe
