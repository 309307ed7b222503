// The options every tool shares (tools/common/common_flags.cc, lpoe/options.h) mean the same in each:
// --length_unit converts what each tool reads and writes, --quiet silences progress and
// information, --output is the main output (lpoe_compare's: the comparison as JSON), and the option
// table's ranges refuse a value before any work, in every tool that has the flag.
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "file_util.h"
#include "lpoe/io/io.h"
#include "lpoe/options.h"
#include "lpoe/model/robot_model.h"

namespace lpoe {
namespace {
namespace shared_options_test {

using testing::ReadAll;
using testing::RunInDir;
using testing::ToolOutput;
using testing::WriteAll;

std::string Tool(const char* path, const std::string& args) { return std::string(path) + " " + args; }

// The data rows of a CSV as numbers (comment lines and the header skipped; non-numbers as NaN).
std::vector<std::vector<double>> Numbers(const std::string& text) {
  std::vector<std::vector<double>> rows;
  std::stringstream lines(text);
  std::string line;
  bool header = true;
  while (std::getline(lines, line)) {
    if (line.empty() || line[0] == '#') continue;
    if (header) {
      header = false;
      continue;
    }
    std::vector<double> row;
    std::stringstream cells(line);
    for (std::string cell; std::getline(cells, cell, ',');) {
      char* end = nullptr;
      const double v = std::strtod(cell.c_str(), &end);
      row.push_back(end != cell.c_str() && *end == '\0' ? v : NAN);
    }
    rows.push_back(row);
  }
  return rows;
}

class SharedOptions : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = (std::filesystem::temp_directory_path() /
            ("lpoe_shared_options_" + std::to_string(::getpid()) + "_" +
             ::testing::UnitTest::GetInstance()->current_test_info()->name()))
               .string();
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }
  ToolOutput Run(const std::string& command) { return RunInDir(dir_, command); }
  std::string Path(const std::string& name) const { return dir_ + "/" + name; }
  std::string dir_;
};

TEST_F(SharedOptions, LengthUnitConvertsWhatEachToolWritesAndReads) {
  // lpoe_simulate: the same measurements in mm and in m.
  const std::string sim = "--count=40 --noise_sigma=0.02 --errors=random --seed=5 --model_out=nom.yaml "
                          "--actual_out=act.yaml";
  ASSERT_EQ(Run(Tool(LPOE_SIMULATE_PATH, sim + " --output=mm.csv")).exit_code, 0);
  ASSERT_EQ(Run(Tool(LPOE_SIMULATE_PATH, sim + " --output=m.csv --length_unit=m")).exit_code, 0);
  const auto mm = Numbers(ReadAll(Path("mm.csv")));
  const auto m = Numbers(ReadAll(Path("m.csv")));
  ASSERT_EQ(mm.size(), 40u);
  ASSERT_EQ(m.size(), mm.size());
  const std::string header = ReadAll(Path("m.csv"));
  EXPECT_NE(header.find("lengths in m"), std::string::npos);
  // Columns q1..q6, x, y, z (then the target): positions / 1000, joints unchanged.
  for (size_t r = 0; r < mm.size(); ++r) {
    for (int c = 0; c < 6; ++c) EXPECT_EQ(m[r][c], mm[r][c]);
    for (int c = 6; c < 9; ++c) EXPECT_NEAR(m[r][c] * 1000, mm[r][c], 1e-9 * std::abs(mm[r][c]));
  }

  // lpoe_predict: the actual robot's positions in m, at the simulated joints.
  std::string joints = "q1,q2,q3,q4,q5,q6\n";
  for (const auto& row : mm) {
    for (int c = 0; c < 6; ++c) joints += std::to_string(row[c]) + (c < 5 ? "," : "\n");
  }
  ASSERT_TRUE(WriteAll(Path("joints.csv"), joints));
  ASSERT_EQ(Run(Tool(LPOE_PREDICT_PATH, "--model=act.yaml --joints=joints.csv --output=p_mm.csv"))
                .exit_code,
            0);
  const ToolOutput quiet = Run(Tool(LPOE_PREDICT_PATH, "--model=act.yaml --joints=joints.csv "
                                                       "--output=p_m.csv --length_unit=m --quiet"));
  ASSERT_EQ(quiet.exit_code, 0) << quiet.err;
  EXPECT_EQ(quiet.out, "");  // --quiet: no "wrote ..."
  EXPECT_NE(ReadAll(Path("p_m.csv")).find("positions in m "), std::string::npos);
  const auto p_mm = Numbers(ReadAll(Path("p_mm.csv")));
  const auto p_m = Numbers(ReadAll(Path("p_m.csv")));
  ASSERT_EQ(p_m.size(), p_mm.size());
  for (size_t r = 0; r < p_mm.size(); ++r) {
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(p_m[r][c] * 1000, p_mm[r][c], 1e-9 * std::abs(p_mm[r][c]));
  }

  // lpoe_compensate: targets in m give the joints the targets in mm give, the residual in m.
  std::string t_mm = "q1,q2,q3,q4,q5,q6,x,y,z\n", t_m = t_mm;
  for (size_t r = 0; r < p_mm.size(); ++r) {
    std::string q;
    for (int c = 0; c < 6; ++c) q += std::to_string(mm[r][c]) + ",";
    char xyz_mm[128], xyz_m[128];
    std::snprintf(xyz_mm, sizeof(xyz_mm), "%.17g,%.17g,%.17g\n", p_mm[r][0] + 0.5, p_mm[r][1],
                  p_mm[r][2] - 0.3);
    std::snprintf(xyz_m, sizeof(xyz_m), "%.17g,%.17g,%.17g\n", (p_mm[r][0] + 0.5) / 1000,
                  p_mm[r][1] / 1000, (p_mm[r][2] - 0.3) / 1000);
    t_mm += q + xyz_mm;
    t_m += q + xyz_m;
  }
  ASSERT_TRUE(WriteAll(Path("t_mm.csv"), t_mm));
  ASSERT_TRUE(WriteAll(Path("t_m.csv"), t_m));
  const ToolOutput loud = Run(Tool(LPOE_COMPENSATE_PATH, "--model=act.yaml --targets=t_mm.csv "
                                                         "--output=c_mm.csv"));
  ASSERT_EQ(loud.exit_code, 0) << loud.err;
  EXPECT_NE(loud.err.find("lpoe_compensate: 40 rows"), std::string::npos);
  const ToolOutput silent = Run(Tool(LPOE_COMPENSATE_PATH, "--model=act.yaml --targets=t_m.csv "
                                                           "--output=c_m.csv --length_unit=m --quiet"));
  ASSERT_EQ(silent.exit_code, 0) << silent.err;
  EXPECT_EQ(silent.err, "");  // --quiet: no summary
  const auto c_mm = Numbers(ReadAll(Path("c_mm.csv")));
  const auto c_m = Numbers(ReadAll(Path("c_m.csv")));
  ASSERT_EQ(c_m.size(), c_mm.size());
  int ok = 0;
  for (size_t r = 0; r < c_mm.size(); ++r) {
    for (int c = 0; c < 6; ++c) EXPECT_NEAR(c_m[r][c], c_mm[r][c], 1e-9);
    EXPECT_NEAR(c_m[r][7] * 1000, c_mm[r][7], 1e-9);  // residual: mm in one, m in the other
    ok += std::isnan(c_mm[r][6]);                      // the status column
  }
  EXPECT_EQ(ok, 40);
  EXPECT_NE(ReadAll(Path("c_m.csv")).find("lengths in m"), std::string::npos);

  // lpoe_calibrate reads the metre file as the millimetre one.
  const std::string cal = "--model=nom.yaml --holdout=0.25 --noise_sigma=0.02 --quiet";
  ASSERT_EQ(Run(Tool(LPOE_CALIBRATE_PATH, cal + " --measurements=mm.csv --output=cal_mm.yaml"))
                .exit_code,
            0);
  ASSERT_EQ(Run(Tool(LPOE_CALIBRATE_PATH,
                     cal + " --measurements=m.csv --length_unit=m --output=cal_m.yaml"))
                .exit_code,
            0);
  RobotModel a, b;
  ASSERT_TRUE(ReadRobotModel(Path("cal_mm.yaml"), &a).ok());
  ASSERT_TRUE(ReadRobotModel(Path("cal_m.yaml"), &b).ok());
  for (int j = 0; j < a.num_joints(); ++j) {
    EXPECT_LT((a.joints[j].origin.t - b.joints[j].origin.t).norm(), 1e-6) << j;
  }
}

TEST_F(SharedOptions, PlanQuietAndCompareOutput) {
  const ToolOutput plan = Run(Tool(LPOE_PLAN_PATH,
                                   "--model=" LPOE_DATA_DIR "/cobot6.yaml --count=12 "
                                   "--candidate_count=400 --workspace_count=50 --random_draws=2 "
                                   "--output=plan.csv --quiet"));
  ASSERT_EQ(plan.exit_code, 0) << plan.err;
  EXPECT_EQ(plan.out, "");
  EXPECT_EQ(Numbers(ReadAll(Path("plan.csv"))).size(), 12u);

  const ToolOutput compare = Run(Tool(LPOE_COMPARE_PATH, "--output=comparison.json --quiet"));
  ASSERT_EQ(compare.exit_code, 0) << compare.err;
  const nlohmann::json j = nlohmann::json::parse(ReadAll(Path("comparison.json")));
  EXPECT_EQ(j["tool"], "lpoe_compare");
  EXPECT_TRUE(j["agree"].get<bool>());
  EXPECT_LE(j["position_difference_mm"].get<double>(), j["tolerance_mm"].get<double>());
  ASSERT_GE(j["rows"].size(), 5u);
  EXPECT_EQ(j["rows"][0]["quantity"], "iterations");
  // --output is checked against the inputs before any work.
  const ToolOutput over = Run(Tool(LPOE_COMPARE_PATH, "--output=" LPOE_DATA_DIR "/cobot6.yaml"));
  EXPECT_EQ(over.exit_code, 1);
}

TEST_F(SharedOptions, TableRangesRefuseBeforeAnyWorkInEveryTool) {
  struct Case {
    const char* tool;
    const char* flag;
    const char* message;
  };
  const Case cases[] = {
      {LPOE_PLAN_PATH, "--random_draws=0", "--random_draws must be in [1, 10000], got 0"},
      {LPOE_PLAN_PATH, "--acceptance_angle=91", "--acceptance_angle must be in (0, 90], got 91"},
      {LPOE_COMPENSATE_PATH, "--restarts=101", "--restarts must be in [0, 100], got 101"},
      {LPOE_COMPENSATE_PATH, "--position_tolerance=0", "--position_tolerance must be in (0, inf)"},
      {LPOE_SIMULATE_PATH, "--error_rotation=2", "--error_rotation must be in [0, 1], got 2"},
      {LPOE_COMPARE_PATH, "--tolerance_mm=-1", "--tolerance_mm must be in [0, 1000], got -1"},
      {LPOE_CALIBRATE_PATH, "--max_iterations=50000",
       "--max_iterations must be in [1, 10000], got 50000"},
  };
  for (const Case& c : cases) {
    // A missing model: the range is refused first (exit 1), not the file (exit 2).
    const ToolOutput o = Run(Tool(c.tool, std::string(c.flag) + " --model=missing.yaml "
                                  "--output=out.csv"));
    EXPECT_EQ(o.exit_code, 1) << c.flag << ": " << o.err;
    EXPECT_NE(o.err.find(c.message), std::string::npos) << c.flag << ": " << o.err;
    EXPECT_FALSE(testing::Exists(Path("out.csv")));
  }
  // --help prints the range and defaults as written.
  const ToolOutput help = Run(Tool(LPOE_CALIBRATE_PATH, "--help"));
  EXPECT_NE(help.out.find("default: 0.03  range: [1e-06, 100]"), std::string::npos) << help.out;
  EXPECT_EQ(help.out.find("0.0299999"), std::string::npos);
}

// The option table's defaults are the flags' defaults, in every tool that has the flag (the table
// gives the Python keyword arguments theirs: they must not drift apart).
TEST_F(SharedOptions, TableDefaultsAreTheFlagsDefaults) {
  const std::pair<const char*, const char*> tools[] = {
      {"lpoe_calibrate", LPOE_CALIBRATE_PATH}, {"lpoe_compare", LPOE_COMPARE_PATH},
      {"lpoe_simulate", LPOE_SIMULATE_PATH},   {"lpoe_predict", LPOE_PREDICT_PATH},
      {"lpoe_compensate", LPOE_COMPENSATE_PATH}, {"lpoe_plan", LPOE_PLAN_PATH}};
  int compared = 0;
  for (const auto& [name, path] : tools) {
    const std::string xml = Run(Tool(path, "--helpxml")).out;
    for (const OptionSpec& spec : Options()) {
      if (spec.scope[0] != '\0' && std::string(spec.scope) != name) continue;
      const std::string tag = "<name>" + std::string(spec.name) + "</name>";
      const size_t at = xml.find(tag);
      if (at == std::string::npos) {
        // Every tool has the shared options; a tool's own ones are its flags.
        ADD_FAILURE() << name << " has no --" << spec.name;
        continue;
      }
      const size_t open = xml.find("<default>", at) + 9;
      const std::string value = xml.substr(open, xml.find("</default>", open) - open);
      if (spec.has_range) {
        EXPECT_EQ(std::strtod(value.c_str(), nullptr), OptionDefault(name, spec.name))
            << name << " --" << spec.name;
      } else {
        EXPECT_EQ(value, spec.default_text) << name << " --" << spec.name;
      }
      ++compared;
    }
  }
  EXPECT_GT(compared, 6 * 8);
}

}  // namespace shared_options_test
}  // namespace
}  // namespace lpoe
