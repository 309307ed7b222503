// The HTML report a person reads: the default job's page renders in a real browser
// (headless chromium) to a non-blank image, carries the JSON report's figures, is well-formed
// (a strict parser), is the same bytes on every run, and stays below 5 MB with 10^5 points.
#include <gtest/gtest.h>
#include <png.h>
#include <sys/stat.h>
#include <sys/wait.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "file_util.h"
#include "lpoe/io/io.h"
#include "lpoe/model/residual_layer.h"
#include "lpoe/model/simulation.h"
#include "lpoe/io/urdf.h"
#include "report/report.h"

namespace lpoe {
namespace tools {
namespace {
namespace report_html_test {

constexpr size_t kMaxHtmlBytes = 5u << 20;  // 5 MB
constexpr int kLargeRunPoints = 100000;
constexpr int kShotWidth = 1200, kShotHeight = 3000;

using ::lpoe::testing::ReadAll;
using ::lpoe::testing::WriteAll;

std::string Mm(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.4f", v);
  return buf;
}

// Runs the strict HTML checker; returns its message (empty when the file is well-formed).
std::string HtmlProblems(const std::string& path) {
  const std::string out = path + ".check.txt";
  const std::string cmd = "python3 " LPOE_CHECK_HTML " " + path + " > " + out + " 2>&1";
  const int rc = std::system(cmd.c_str());
  const std::string text = ReadAll(out);
  return rc == 0 ? "" : (text.empty() ? "checker failed to run" : text);
}

class ReportHtml : public ::testing::Test {
 protected:
  int Run(const std::string& args, const std::string& log) {
    return std::system(("cd " + dir_ + " && " + args + " > " + log + " 2>&1").c_str());
  }
  ::lpoe::testing::TempDir temp_{"lpoe_report_html"};
  std::string dir_ = temp_.path();
};

TEST_F(ReportHtml, DefaultJobPageCarriesTheJsonFiguresAndIsDeterministic) {
  ASSERT_EQ(Run(LPOE_CALIBRATE_PATH " --plots_dir= --report=r.json --html_report=r.html", "a.txt"),
            0)
      << ReadAll(dir_ + "/a.txt");
  ASSERT_EQ(Run(LPOE_CALIBRATE_PATH " --plots_dir= --html_report=again.html", "b.txt"), 0);
  const std::string html = ReadAll(dir_ + "/r.html");
  EXPECT_EQ(html, ReadAll(dir_ + "/again.html")) << "the same input gave different bytes";
  EXPECT_EQ(HtmlProblems(dir_ + "/r.html"), "");
  EXPECT_LE(html.size(), kMaxHtmlBytes);

  const nlohmann::json j = nlohmann::json::parse(ReadAll(dir_ + "/r.json"));
  // The verdict, with its reason, at the top (before the first plot).
  const std::string level = j["verdict"]["level"];
  EXPECT_EQ(level, "pass") << j["verdict"]["reason"];  // section-4 data: 0.03 mm tracker noise
  EXPECT_FALSE(j["verdict"]["checks"].empty());
  const size_t verdict_at = html.find("<b>" + level + "</b>");
  ASSERT_NE(verdict_at, std::string::npos);
  EXPECT_LT(verdict_at, html.find("<svg"));
  EXPECT_NE(html.find(j["verdict"]["reason"].get<std::string>()), std::string::npos);
  // The statistics of the JSON report, as printed on the page.
  for (const char* set : {"identification", "verification"}) {
    for (const char* when : {"before", "after"}) {
      const double rms = j[set][when]["norm"]["rms"];
      EXPECT_NE(html.find("<td>" + Mm(rms) + "</td>"), std::string::npos)
          << set << " " << when << " RMS " << Mm(rms) << " is not on the page";
    }
  }
  // A passing page ends with what to do next: deploy, and what accuracy to expect.
  EXPECT_NE(html.find("<h2>Outputs and next steps</h2>"), std::string::npos);
  EXPECT_NE(html.find("Deploy the calibrated YAML model"), std::string::npos);
  EXPECT_EQ(html.find("Do not deploy"), std::string::npos);
  const double after_rms = j["verification"]["after"]["norm"]["rms"];
  EXPECT_LT(after_rms, 0.1);
  EXPECT_NE(html.find(Mm(after_rms) + " mm</span>"), std::string::npos);  // key figure on top
  // Parameter changes with standard deviations, per SMR statistics, the inputs and the version.
  ASSERT_EQ(j["parameter_changes"].size(), 27u);
  for (const auto& c : j["parameter_changes"]) {
    EXPECT_NE(html.find("<td>" + c["name"].get<std::string>() + "</td>"), std::string::npos);
  }
  ASSERT_EQ(j["per_smr"].size(), 1u);
  EXPECT_NE(html.find("smr1 verification"), std::string::npos);
  EXPECT_NE(html.find(j["inputs"]["measurements"].get<std::string>()), std::string::npos);
  EXPECT_NE(html.find(j["tool"]["version"].get<std::string>()), std::string::npos);
  // Per-point residuals in the JSON: one per row, with its file line.
  ASSERT_EQ(j["points"]["identification"].size(), 70u);
  ASSERT_EQ(j["points"]["verification"].size(), 30u);
  EXPECT_EQ(j["points"]["identification"][0]["line"], 3);  // after the comment and the header
  EXPECT_EQ(j["points"]["identification"][0]["target"], "smr1");
  EXPECT_EQ(html.find("<script"), std::string::npos);
  // Five figures: convergence, axis errors, histograms, joints and reach, workspace.
  size_t figures = 0;
  for (size_t at = html.find("<svg"); at != std::string::npos; at = html.find("<svg", at + 1))
    ++figures;
  EXPECT_EQ(figures, 5u);

  // ---- In a real browser: the page renders to a PNG that is not blank and shows the verdict box.
  if (std::system("command -v chromium > /dev/null 2>&1") != 0)
    GTEST_SKIP() << "chromium is not installed (scripts/setup.sh installs it): not rendered";
  const std::string shot = dir_ + "/shot.png";
  const std::string cmd =
      "chromium --headless --no-sandbox --disable-gpu --hide-scrollbars "
      "--screenshot=" +
      shot + " --window-size=" + std::to_string(kShotWidth) + "," + std::to_string(kShotHeight) +
      " file://" + dir_ + "/r.html";
  ASSERT_EQ(Run(cmd, "chromium.txt"), 0) << ReadAll(dir_ + "/chromium.txt");
  png_image image;
  std::memset(&image, 0, sizeof image);
  image.version = PNG_IMAGE_VERSION;
  ASSERT_TRUE(png_image_begin_read_from_file(&image, shot.c_str())) << image.message;
  image.format = PNG_FORMAT_RGB;
  std::vector<uint8_t> rgb(PNG_IMAGE_SIZE(image));
  ASSERT_TRUE(png_image_finish_read(&image, nullptr, rgb.data(), 0, nullptr)) << image.message;
  EXPECT_EQ(static_cast<int>(image.width), kShotWidth);
  EXPECT_EQ(static_cast<int>(image.height), kShotHeight);
  size_t ink = 0, verdict_green = 0, plot_blue = 0;
  for (size_t p = 0; p + 2 < rgb.size(); p += 3) {
    const int r = rgb[p], g = rgb[p + 1], b = rgb[p + 2];
    ink += r < 200 || g < 200 || b < 200;
    verdict_green += std::abs(r - 0xe3) <= 4 && std::abs(g - 0xf4) <= 4 && std::abs(b - 0xe6) <= 4;
    plot_blue += std::abs(r - 0x00) <= 8 && std::abs(g - 0x72) <= 8 && std::abs(b - 0xb2) <= 8;
  }
  const double pixels = double(image.width) * image.height;
  EXPECT_GT(ink / pixels, 0.02) << "the page looks blank";
  EXPECT_GT(verdict_green, 5000u) << "no pass-verdict box";
  EXPECT_GT(plot_blue, 500u) << "no after-calibration data drawn";
}

// --residual_model=gp: the page has the layer's section (its figures from the JSON) and its picture
// of the predicted accuracy over the workspace, one more plot than without; the page stays
// well-formed and deterministic.
TEST_F(ReportHtml, ResidualLayerSectionAndPicture) {
  ASSERT_EQ(Run(LPOE_CALIBRATE_PATH " --plots_dir= --html_report=none.html", "a.txt"), 0);
  ASSERT_EQ(Run(LPOE_CALIBRATE_PATH
                " --plots_dir= --residual_model=gp --report=gp.json --html_report=gp.html",
                "b.txt"),
            0)
      << ReadAll(dir_ + "/b.txt");
  ASSERT_EQ(Run(LPOE_CALIBRATE_PATH " --plots_dir= --residual_model=gp --html_report=again.html",
                "c.txt"),
            0);
  const std::string none = ReadAll(dir_ + "/none.html"), gp = ReadAll(dir_ + "/gp.html");
  EXPECT_EQ(gp, ReadAll(dir_ + "/again.html"));
  EXPECT_EQ(HtmlProblems(dir_ + "/gp.html"), "");
  auto count = [](const std::string& text, const std::string& what) {
    size_t n = 0;
    for (size_t at = text.find(what); at != std::string::npos; at = text.find(what, at + 1)) ++n;
    return n;
  };
  EXPECT_EQ(count(gp, "<svg"), count(none, "<svg") + 1);
  EXPECT_EQ(none.find("<h2>Residual layer</h2>"), std::string::npos);
  EXPECT_NE(gp.find("<h2>Residual layer</h2>"), std::string::npos);
  EXPECT_NE(gp.find("predicted accuracy"), std::string::npos);
  const nlohmann::json j = nlohmann::json::parse(ReadAll(dir_ + "/gp.json"));
  const nlohmann::json& rm = j["residual_model"];
  ASSERT_TRUE(rm["fitted"].get<bool>()) << rm["message"];
  EXPECT_EQ(rm["requested"], "gp");
  EXPECT_TRUE(rm["selection"].is_null());
  EXPECT_NE(gp.find(Mm(rm["verification_without_layer"]["norm"]["rms"].get<double>()) + " mm"),
            std::string::npos);
  EXPECT_NE(gp.find(Mm(j["verification"]["after"]["norm"]["rms"].get<double>()) + " mm"),
            std::string::npos);
  // The tool's own lines: the layer's summary on stdout.
  const std::string text = ReadAll(dir_ + "/b.txt");
  EXPECT_NE(text.find("residual layer: Gaussian process"), std::string::npos);
  // The length scales per joint with the data's spacing, in the JSON, the text and the page; a
  // warning in both for each joint whose length scale is below it.
  const nlohmann::json& layer = rm["layer"];
  ASSERT_EQ(layer["length_scales"].size(), 6u);
  ASSERT_EQ(layer["spacing"].size(), 6u);
  EXPECT_NE(text.find("length scales (rad"), std::string::npos) << text;
  EXPECT_NE(gp.find("<th>spacing of the data</th>"), std::string::npos);
  for (int joint = 0; joint < 6; ++joint) {
    const bool below = layer["length_scales"][joint].get<double>() <
                       layer["spacing"][joint].get<double>();
    EXPECT_EQ(text.find("warning: the length scale of joint" + std::to_string(joint + 1)) !=
                  std::string::npos,
              below)
        << joint;
  }
  EXPECT_EQ(gp.find("below the spacing of the data") != std::string::npos,
            !layer["length_scales_below_spacing"].empty());
}

// A layer whose length scale of a joint is below the data's spacing there: the text warns for that
// joint and no other.
TEST(ResidualLayerText, WarnsForTheJointsWhoseLengthScaleIsBelowTheSpacing) {
  const RobotModel model = MakeCobot6();
  ResidualLayer layer;
  layer.num_joints = 6;
  layer.length_scales.resize(6);
  layer.length_scales << 40, 12, 0.9, 0.041, 1.3, 0.028;
  ResidualLayerFit fit;
  fit.spacing.resize(6);
  fit.spacing << 2.1, 1.9, 0.4, 0.17, 0.3, 0.2;
  const std::string text = ResidualLayerLengthScalesText(layer, fit, model);
  EXPECT_NE(text.find(model.joints[3].name + " 0.041"), std::string::npos) << text;
  EXPECT_NE(text.find("warning: the length scale of " + model.joints[3].name + " is 0.041 below "
                      "the data's spacing 0.17"),
            std::string::npos)
      << text;
  EXPECT_NE(text.find("warning: the length scale of " + model.joints[5].name), std::string::npos);
  for (int j : {0, 1, 2, 4}) {
    EXPECT_EQ(text.find("warning: the length scale of " + model.joints[j].name + " "),
              std::string::npos)
        << text;
  }
}

TEST_F(ReportHtml, ComparePageIsWellFormed) {
  ASSERT_EQ(Run(LPOE_COMPARE_PATH " --html_report=c.html", "c.txt"), 0) << ReadAll(dir_ + "/c.txt");
  const std::string html = ReadAll(dir_ + "/c.html");
  EXPECT_EQ(HtmlProblems(dir_ + "/c.html"), "");
  EXPECT_NE(html.find("Linear (paper) and Ceres solver"), std::string::npos);
  EXPECT_NE(html.find("predicted positions (mm)"), std::string::npos);
  EXPECT_NE(html.find("lpoe_compare"), std::string::npos);
  // A page in a missing directory, or one that would overwrite an input, is refused (1).
  int rc = Run(LPOE_COMPARE_PATH " --html_report=no_such_dir/c.html", "d.txt");
  EXPECT_EQ(WEXITSTATUS(rc), 1) << ReadAll(dir_ + "/d.txt");
  ASSERT_TRUE(
      WriteAll(dir_ + "/points.csv", ReadAll(LPOE_DATA_DIR "/section4/identification.csv")));
  rc = Run(LPOE_COMPARE_PATH " --measurements=points.csv --html_report=points.csv", "e.txt");
  EXPECT_EQ(WEXITSTATUS(rc), 1) << ReadAll(dir_ + "/e.txt");
  EXPECT_EQ(ReadAll(dir_ + "/points.csv"), ReadAll(LPOE_DATA_DIR "/section4/identification.csv"));
  rc = Run(LPOE_CALIBRATE_PATH " --plots_dir= --report=r.json --html_report=r.json", "f.txt");
  EXPECT_EQ(WEXITSTATUS(rc), 1) << ReadAll(dir_ + "/f.txt");
}

// A synthetic run of 10^5 points (the section-4 robot, 0.03 mm noise): the page stays below 5 MB
// (plots decimated), well-formed and deterministic; the JSON keeps every point.
TEST_F(ReportHtml, HundredThousandPointsStayBelowFiveMegabytes) {
  RobotModel nominal, actual;
  ASSERT_TRUE(ReadRobotModel(LPOE_DATA_DIR "/cobot6.yaml", &nominal).ok());
  ASSERT_TRUE(ReadRobotModel(LPOE_DATA_DIR "/section4/actual.yaml", &actual).ok());
  SimulationOptions options;
  options.count = kLargeRunPoints;
  options.noise_sigma = 0.03;
  const MeasurementSet all = SimulateMeasurements(actual, std::vector<double>(6, 0.0), options);
  MeasurementSet identification, verification;
  all.SplitAt(kLargeRunPoints * 7 / 10, &identification, &verification);

  RunSummary s;
  s.model_path = "cobot6.yaml";
  s.measurements_path = "large.csv";
  s.result.model = actual;
  s.result.termination = Termination::kConverged;
  s.result.history = {{0, 10.0, 60.0, 30.0, 1.0}, {1, 0.1, 0.15, 0.05, 1e-12}};
  s.has_verification = true;
  AddPointResiduals(nominal, actual, identification, verification, &s);
  std::vector<Eigen::Vector3d> b, a;
  for (const PointResidual& p : s.verification_points) {
    b.push_back(p.before);
    a.push_back(p.after);
  }
  s.verification_before = ComputeStatistics(b);
  s.verification_after = ComputeStatistics(a);
  s.identification_before = PositionErrorStatistics(nominal, identification);
  s.identification_after = PositionErrorStatistics(actual, identification);

  std::string html;
  ASSERT_TRUE(RunSummaryToHtml(s, &html).ok());
  EXPECT_LE(html.size(), kMaxHtmlBytes) << html.size() << " bytes";
  RecordProperty("html_bytes", std::to_string(html.size()));
  ASSERT_TRUE(WriteAll(dir_ + "/large.html", html));
  EXPECT_EQ(HtmlProblems(dir_ + "/large.html"), "");
  const nlohmann::json j = nlohmann::json::parse(RunSummaryToJson(s));
  EXPECT_EQ(j["points"]["verification"].size(), static_cast<size_t>(verification.size()));
  EXPECT_NE(html.find(Mm(s.verification_after.norm.rms)), std::string::npos);
}

// Each output's own RMS is in the JSON report, and an output that carries less than the
// calibration (a URDF after joint-space terms) is a warning in the page's verdict box.
TEST(OutputModels, ReducedOutputIsWarnedInTheVerdictBox) {
  RobotModel nominal;
  ASSERT_TRUE(ReadRobotModel(LPOE_DATA_DIR "/cobot6.yaml", &nominal).ok());
  RunSummary s;
  s.model_path = "cobot6.yaml";
  s.measurements_path = "points.csv";
  s.result.model = nominal;
  s.result.termination = Termination::kConverged;
  s.result.history = {{0, 10.0, 60.0, 30.0, 1.0}, {1, 0.1, 0.15, 0.05, 1e-12}};
  s.verdict.level = VerdictLevel::kPass;
  s.verdict.reason = "every check passed";
  s.output_models.push_back({"--output", "cal.yaml", 0.037, "verification", false, ""});
  s.output_models.push_back({"--urdf_output", "cal.urdf", 0.394, "verification", true,
                             "it cannot carry the joint-error terms (compliance)"});
  const nlohmann::json j = nlohmann::json::parse(RunSummaryToJson(s));
  ASSERT_EQ(j["output_models"].size(), 2u);
  EXPECT_DOUBLE_EQ(j["output_models"][1]["rms_mm"].get<double>(), 0.394);
  EXPECT_TRUE(j["output_models"][1]["carries_less"].get<bool>());
  EXPECT_FALSE(j["output_models"][0]["carries_less"].get<bool>());
  std::string html;
  ASSERT_TRUE(RunSummaryToHtml(s, &html).ok());
  const size_t box = html.find("<div class=\"verdict pass\">");
  ASSERT_NE(box, std::string::npos);
  const std::string verdict = html.substr(box, html.find("</div>", box) - box);
  EXPECT_NE(verdict.find("Warning: --urdf_output <code>cal.urdf</code> predicts with RMS 0.394 mm "
                         "against 0.037 mm for the YAML model"),
            std::string::npos)
      << verdict;
  // Nothing reduced: no warning.
  s.output_models.pop_back();
  ASSERT_TRUE(RunSummaryToHtml(s, &html).ok());
  EXPECT_EQ(html.find("Warning: --urdf_output"), std::string::npos);
}

// The auto table says when a tilt candidate could not identify the tilt in its folds (then it is the
// model without the tilt, and its row repeats that model's figures).
TEST(JointErrorSelectionTable, SaysWhenTheTiltWasNotIdentifiedInTheFolds) {
  JointErrorSelection sel;
  sel.ran = true;
  sel.folds = 5;
  sel.bilinear = {{kGravityTiltName, true, ""}};
  auto candidate = [](std::vector<std::string> terms, const std::string& label, int tilt_folds) {
    JointErrorCandidate c;
    c.terms = std::move(terms);
    c.label = label;
    c.ok = true;
    c.parameters = 30;
    c.cv_rms = 0.06;
    c.cv_mse = 0.0036;
    c.identified_folds[kGravityTiltName] = tilt_folds;
    return c;
  };
  sel.candidates = {candidate({"compliance"}, "compliance", 0),
                    candidate({"compliance", "tilt"}, "compliance,tilt", 0),
                    candidate({"compliance", "harmonics", "tilt"}, "compliance,harmonics,tilt", 5)};
  sel.best = sel.chosen = 0;
  std::string table = JointErrorSelectionTable(sel);
  EXPECT_NE(table.find("compliance,tilt: the gravity tilt was identified in none of the 5 folds, "
                       "which kept the model's gravity: the same model as without the tilt\n"),
            std::string::npos)
      << table;
  EXPECT_EQ(table.find("compliance,harmonics,tilt: the gravity tilt"), std::string::npos) << table;
  sel.candidates[1].identified_folds[kGravityTiltName] = 3;
  table = JointErrorSelectionTable(sel);
  EXPECT_NE(table.find("compliance,tilt: the gravity tilt was identified in 3 of 5 folds (the "
                       "others kept the model's gravity)\n"),
            std::string::npos)
      << table;
}

// A model read from a URDF: each parameter is tied to the URDF element whose <origin> it changes
// (the joint by its name and child link; a tool by the fixed joint to its link), in the JSON report
// and beside the parameter on the page. A YAML model's report has no such column.
TEST_F(ReportHtml, ParametersNameTheUrdfElementTheyChange) {
  const std::string urdf = std::string(LPOE_TEST_DATA_DIR) + "/urdf/cell_ur5e.urdf";
  RobotModel model;
  UrdfSource source;
  UrdfOptions options;
  options.tip_link = "tool0";
  ASSERT_TRUE(ReadRobotModelUrdf(urdf, &model, options, &source).ok());
  const std::vector<std::string> elements = UrdfFrameElements(source, model);
  ASSERT_EQ(elements.size(), static_cast<size_t>(model.num_joints() + model.num_tools()));
  EXPECT_EQ(elements[3], "joint 'wrist_1_joint' (child link 'wrist_1_link')");
  EXPECT_EQ(elements.back(), "joint 'flange-tool0' (link 'tool0')");

  ASSERT_EQ(Run(LPOE_SIMULATE_PATH " --model=" + urdf + " --tip_link=tool0 --count=120 "
                "--noise_sigma=0.02 --errors=random --output=pts.csv",
                "s.txt"),
            0)
      << ReadAll(dir_ + "/s.txt");
  ASSERT_EQ(Run(LPOE_CALIBRATE_PATH " --model=" + urdf + " --tip_link=tool0 --measurements=pts.csv "
                "--holdout=0.3 --plots_dir= --report=r.json --html_report=r.html --quiet",
                "c.txt"),
            0)
      << ReadAll(dir_ + "/c.txt");
  const nlohmann::json j = nlohmann::json::parse(ReadAll(dir_ + "/r.json"));
  const std::string html = ReadAll(dir_ + "/r.html");
  EXPECT_EQ(HtmlProblems(dir_ + "/r.html"), "");
  int tied = 0;
  for (const auto& c : j["parameter_changes"]) {
    const std::string name = c["name"];
    const std::string frame = name.substr(0, name.find('.'));
    ASSERT_TRUE(c.contains("urdf")) << name;
    const std::string element = c["urdf"];
    // wrist_1_joint.ty -> joint 'wrist_1_joint' (child link 'wrist_1_link'); tool0.tx -> the
    // fixed joint whose child is tool0.
    EXPECT_NE(element.find("'" + frame + "'"), std::string::npos) << name << ": " << element;
    // On the page, in the parameter's row.
    const size_t row = html.find("<tr><td>" + name + "</td>");
    ASSERT_NE(row, std::string::npos) << name;
    EXPECT_LT(html.find("<td>" + element + "</td>", row), html.find("</tr>", row)) << name;
    ++tied;
  }
  EXPECT_GE(tied, 20);
  // The shipped YAML job: no URDF column.
  ASSERT_EQ(Run(LPOE_CALIBRATE_PATH " --plots_dir= --report=y.json --html_report=y.html --quiet",
                "y.txt"),
            0);
  EXPECT_EQ(ReadAll(dir_ + "/y.html").find("in the URDF"), std::string::npos);
  EXPECT_FALSE(nlohmann::json::parse(ReadAll(dir_ + "/y.json"))["parameter_changes"][0].contains(
      "urdf"));
}

}  // namespace report_html_test
}  // namespace
}  // namespace tools
}  // namespace lpoe
