// The default lpoe_calibrate run produces the report a user reads: plots as PNG images of
// the expected size with content, and a JSON report following the schema of docs/report.md.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "file_util.h"

namespace {
namespace calibrate_report_test {

constexpr int kPlotWidth = 1000;
constexpr int kConvergenceHeight = 600;
constexpr int kAxisErrorsHeight = 900;
constexpr int kHistogramHeight = 700;
constexpr long kMinPngBytes = 4000;  // a blank 1000x600 PNG compresses to ~3 KB

using ::lpoe::testing::ReadAll;

// Width and height from the PNG signature and IHDR chunk.
bool PngSize(const std::string& bytes, int* w, int* h) {
  static const unsigned char kSig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (bytes.size() < 24 || bytes.compare(0, 8, reinterpret_cast<const char*>(kSig), 8) != 0 ||
      bytes.compare(12, 4, "IHDR") != 0) {
    return false;
  }
  auto be32 = [&](size_t o) {
    return (static_cast<unsigned char>(bytes[o]) << 24) |
           (static_cast<unsigned char>(bytes[o + 1]) << 16) |
           (static_cast<unsigned char>(bytes[o + 2]) << 8) | static_cast<unsigned char>(bytes[o + 3]);
  };
  *w = static_cast<int>(be32(16));
  *h = static_cast<int>(be32(20));
  return true;
}

class CalibrateReport : public ::testing::Test {
 protected:
  ::lpoe::testing::TempDir temp_{"lpoe_report"};
  std::string dir_ = temp_.path();
};

TEST_F(CalibrateReport, DefaultRunWritesPlotsAndJson) {
  // The report's plots and JSON, with the leak check at exit.
  lpoe::testing::ScopedToolLeakCheck leak_check;
  const std::string cmd = "cd " + dir_ + " && " LPOE_CALIBRATE_PATH " --report=report.json > out.txt 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << ReadAll(dir_ + "/out.txt");
  struct Expected {
    const char* name;
    int w, h;
  };
  for (const Expected& e : {Expected{"convergence.png", kPlotWidth, kConvergenceHeight},
                            Expected{"axis_errors.png", kPlotWidth, kAxisErrorsHeight},
                            Expected{"error_histogram.png", kPlotWidth, kHistogramHeight}}) {
    const std::string bytes = ReadAll(dir_ + "/lpoe_plots/" + e.name);
    int w = 0, h = 0;
    ASSERT_TRUE(PngSize(bytes, &w, &h)) << e.name << " is not a PNG";
    EXPECT_EQ(w, e.w) << e.name;
    EXPECT_EQ(h, e.h) << e.name;
    EXPECT_GT(static_cast<long>(bytes.size()), kMinPngBytes) << e.name << " looks empty";
  }
  const nlohmann::json j = nlohmann::json::parse(ReadAll(dir_ + "/report.json"));
  EXPECT_EQ(j["schema"], "lpoe-calib/report/2");
  EXPECT_TRUE(j["solver"]["converged"].get<bool>());
  EXPECT_EQ(j["identifiability"]["unidentifiable"].size(), 15u);
  EXPECT_EQ(j["identifiability"]["rank"], 27);
  EXPECT_EQ(j["identifiability"]["identified"].size(), 27u);
  EXPECT_LT(j["verification"]["after"]["x"]["max"].get<double>(), 0.15);
  EXPECT_GT(j["verification"]["before"]["x"]["max"].get<double>(), 1.0);
  EXPECT_GE(j["history"].size(), 2u);
  EXPECT_EQ(j["calibrated_frames"].size(), 7u);
}

TEST_F(CalibrateReport, UrdfOutputReadsBack) {
  const std::string cmd = "cd " + dir_ + " && " LPOE_CALIBRATE_PATH
                          " --plots_dir= --output=cal.yaml --urdf_output=cal.urdf --prior_scale=0"
                          " > out.txt 2>&1"
                          " && " LPOE_CALIBRATE_PATH " --plots_dir= --model=cal.urdf --noregister"
                          " --max_iterations=3 --prior_scale=0 > again.txt 2>&1";
  // Calibrating again from the calibrated URDF starts at the optimum: converged at once. (Both
  // without the prior: with it, the second run's prior is centred on the first run's result and
  // releases part of the first prior's pull, a step of 1e-4 mm, docs/identifiability.md.)
  ASSERT_EQ(std::system(cmd.c_str()), 0) << ReadAll(dir_ + "/out.txt") << ReadAll(dir_ + "/again.txt");
  const std::string again = ReadAll(dir_ + "/again.txt");
  EXPECT_NE(again.find("converged after 0 iteration"), std::string::npos) << again;
}

// --joint_errors=compliance,harmonics,tilt on simulated data of a base tilted by 0.6 deg (800 poses:
// with the default hold-out, 300 would leave the tilt's standard deviation just above the 0.1 deg
// the check requires; no geometric errors, so that the base is exactly the nominal one and the
// tilt the simulated one): stderr
// prints the tilt in degrees with its standard deviation, the JSON and HTML reports carry it, and the
// calibrated YAML's gravity is the tilted vector.
TEST_F(CalibrateReport, GravityTiltInEveryReport) {
  const std::string cmd =
      "cd " + dir_ + " && " LPOE_SIMULATE_PATH
      " --errors=none --joint_errors=compliance,harmonics --gravity_tilt_deg=0.6,0 --count=800 "
      "--noise_sigma=0.01 --model_out=nominal.yaml --output=data.csv > sim.txt 2>&1 && " LPOE_CALIBRATE_PATH
      " --model=nominal.yaml --measurements=data.csv --joint_errors=compliance,harmonics,tilt "
      "--plots_dir= --report=report.json --html_report=report.html --output=cal.yaml "
      "> out.txt 2> err.txt";
  ASSERT_EQ(std::system(cmd.c_str()), 0)
      << ReadAll(dir_ + "/sim.txt") << ReadAll(dir_ + "/out.txt") << ReadAll(dir_ + "/err.txt");
  const std::string err = ReadAll(dir_ + "/err.txt");
  EXPECT_NE(err.find("gravity tilt: t1 = "), std::string::npos) << err;
  const nlohmann::json j = nlohmann::json::parse(ReadAll(dir_ + "/report.json"));
  const nlohmann::json& t = j["joint_errors"]["gravity_tilt"];
  ASSERT_TRUE(t.is_object()) << j["joint_errors"].dump();
  ASSERT_TRUE(t["identified"].get<bool>()) << t.dump();
  const double t1 = t["tilt_deg"][0].get<double>(), sd1 = t["std_dev_deg"][0].get<double>();
  EXPECT_GT(sd1, 0);
  EXPECT_LT(std::abs(t1 - 0.6), 4 * sd1) << t.dump();
  // The form of the standard deviation is stated (a posteriori for both solvers; the linear
  // solver has no a-priori form).
  EXPECT_EQ(t["std_dev_form"], "a posteriori") << t.dump();
  EXPECT_TRUE(t["std_dev_deg_a_priori"].is_null()) << t.dump();
  EXPECT_NE(err.find("standard deviations a posteriori"), std::string::npos) << err;
  EXPECT_NE(ReadAll(dir_ + "/report.html").find("Gravity tilt: "), std::string::npos);
  const std::string yaml = ReadAll(dir_ + "/cal.yaml");
  EXPECT_NE(yaml.find("gravity: ["), std::string::npos) << yaml;
}

// --split=sequential holds out the file's last rows (the section-4 file: 70 data rows on lines
// 3-72, so a quarter is lines 55-72) and says so in the report; auto's folds are contiguous.
TEST_F(CalibrateReport, SequentialHoldoutIsTheLastRows) {
  const std::string cmd = "cd " + dir_ + " && " LPOE_CALIBRATE_PATH
                          " --measurements=" LPOE_DATA_DIR "/section4/identification.csv"
                          " --holdout=0.25 --split=sequential --joint_errors=auto --plots_dir="
                          " --report=report.json > out.txt 2>&1";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << ReadAll(dir_ + "/out.txt");
  EXPECT_NE(ReadAll(dir_ + "/out.txt").find("contiguous folds"), std::string::npos)
      << ReadAll(dir_ + "/out.txt");
  const nlohmann::json j = nlohmann::json::parse(ReadAll(dir_ + "/report.json"));
  EXPECT_EQ(j["inputs"]["split"], "sequential");
  EXPECT_EQ(j["joint_errors"]["selection"]["split"], "sequential");
  const auto& held = j["points"]["verification"];
  ASSERT_EQ(held.size(), 18u);
  for (size_t i = 0; i < held.size(); ++i) EXPECT_EQ(held[i]["line"], 55 + static_cast<int>(i));
  for (const auto& p : j["points"]["identification"]) EXPECT_LT(p["line"].get<int>(), 55);
}

}  // namespace calibrate_report_test
}  // namespace
