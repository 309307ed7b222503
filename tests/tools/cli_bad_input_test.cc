// End-to-end checks of lpoe_calibrate's failure behaviour: runs the built binary (its path comes
// from CMake as LPOE_CALIBRATE_PATH) as a child process.
//
//  - Every malformed file in tests/data/bad/ (MANIFEST) exits 2 with "<file>:<line>: <what>" on
//    stderr and writes nothing (no model, no report, no plots, no temporary files).
//  - A run that fails (bad input, exit 2; iteration limit, exit 4) leaves an existing output file
//    untouched.
//  - An output that names an input file is refused (exit 1) and the input is unchanged.
//  - The same input gives byte-identical --output and --report files.
//  - Bad or conflicting flags exit 1 with a message naming the flag.
#include <dirent.h>
#include <fcntl.h>
#include <sys/stat.h>
#include <sys/types.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "file_util.h"

namespace {
namespace cli_bad_input_test {

using ::lpoe::testing::Exists;
using ::lpoe::testing::ListDir;
using ::lpoe::testing::ReadAll;
using ::lpoe::testing::TempDir;
using ::lpoe::testing::WriteAll;

constexpr int kExitOk = 0;
constexpr int kExitUsage = 1;
constexpr int kExitInput = 2;
constexpr int kExitNotConverged = 4;

const std::string kTool = LPOE_CALIBRATE_PATH;
const std::string kBadDir = std::string(LPOE_TEST_DATA_DIR) + "/bad";
const std::string kGoodModel = std::string(LPOE_DATA_DIR) + "/cobot6.yaml";
const std::string kGoodMeasurements = std::string(LPOE_DATA_DIR) + "/section4/identification.csv";
const std::string kGoodVerification = std::string(LPOE_DATA_DIR) + "/section4/verification.csv";

struct RunResult {
  int exit_code = -1;  // -1: did not exit normally (signal, sanitizer abort)
  std::string out, err;
};

std::ostream& operator<<(std::ostream& os, const RunResult& r) {
  return os << "exit code " << r.exit_code << "\n--- stderr:\n" << r.err << "\n--- stdout:\n"
            << r.out;
}

// Runs lpoe_calibrate with `args` in the directory `cwd`; stdout and stderr go to files in
// `scratch` (which must not be a directory whose contents the test checks).
RunResult RunTool(const std::vector<std::string>& args, const std::string& cwd,
                  const std::string& scratch) {
  RunResult result;
  const std::string out_path = scratch + "/stdout.txt";
  const std::string err_path = scratch + "/stderr.txt";
  std::vector<std::string> argv_strings = {kTool};
  argv_strings.insert(argv_strings.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& a : argv_strings) argv.push_back(a.data());
  argv.push_back(nullptr);

  const pid_t pid = fork();
  if (pid == 0) {
    const int out = open(out_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    const int err = open(err_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (out < 0 || err < 0 || dup2(out, 1) < 0 || dup2(err, 2) < 0 || chdir(cwd.c_str()) != 0) {
      _exit(127);
    }
    execv(argv[0], argv.data());
    _exit(127);
  }
  if (pid < 0) return result;
  int status = 0;
  while (waitpid(pid, &status, 0) < 0) {
  }
  if (WIFEXITED(status)) result.exit_code = WEXITSTATUS(status);
  result.out = ReadAll(out_path);
  result.err = ReadAll(err_path);
  return result;
}

// The standard output arguments into `dir`.
std::vector<std::string> OutputArgs(const std::string& dir) {
  return {"--output=" + dir + "/out.yaml", "--report=" + dir + "/out.json",
          "--plots_dir=" + dir + "/plots"};
}

// ---- Every malformed file of tests/data/bad/.

struct BadFile {
  std::string file;      // name in tests/data/bad/
  std::string expected;  // MANIFEST substring: ":<line>: <what>"
};

std::vector<BadFile> ReadManifest() {
  std::vector<BadFile> files;
  std::ifstream in(kBadDir + "/MANIFEST");
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    const size_t tab = line.find('\t');
    if (tab == std::string::npos) continue;
    files.push_back({line.substr(0, tab), line.substr(tab + 1)});
  }
  return files;
}

// ctest shows a parameterized test by what PrintTo prints (gtest_discover_tests' pretty names).
void PrintTo(const BadFile& b, std::ostream* os) { *os << b.file; }

class CliBadInput : public ::testing::TestWithParam<BadFile> {};

TEST(CliBadInputManifest, ListsEveryFileInTheDirectory) {
  const std::vector<BadFile> manifest = ReadManifest();
  ASSERT_GE(manifest.size(), 40u) << "cannot read " << kBadDir << "/MANIFEST";
  for (const std::string& name : ListDir(kBadDir)) {
    if (name == "MANIFEST") continue;
    bool listed = false;
    for (const BadFile& b : manifest) listed = listed || b.file == name;
    EXPECT_TRUE(listed) << name << " is not in MANIFEST, so no test runs it";
  }
}

TEST_P(CliBadInput, ExitsTwoNamingFileAndLineAndWritesNothing) {
  const BadFile& bad = GetParam();
  const std::string path = kBadDir + "/" + bad.file;
  ASSERT_TRUE(Exists(path)) << path;
  const bool is_model = bad.file.size() > 5 && bad.file.substr(bad.file.size() - 5) == ".yaml";
  TempDir outputs, scratch;
  ASSERT_FALSE(outputs.path().empty());
  std::vector<std::string> args;
  if (is_model) {
    args = {"--model=" + path, "--measurements=" + kGoodMeasurements};
  } else {
    args = {"--model=" + kGoodModel, "--measurements=" + path};
  }
  for (const std::string& a : OutputArgs(outputs.path())) args.push_back(a);

  const RunResult r = RunTool(args, scratch.path(), scratch.path());
  EXPECT_EQ(r.exit_code, kExitInput) << r;
  // "<path>/<file>:<line>: <what>; expected ..." -- the MANIFEST substring starts with ":<line>:".
  EXPECT_NE(r.err.find(bad.file + bad.expected), std::string::npos)
      << "stderr should contain '" << bad.file + bad.expected << "'\n" << r;
  EXPECT_TRUE(std::regex_search(r.err, std::regex(":[0-9]+: "))) << r;
  EXPECT_NE(r.err.find("expected"), std::string::npos) << "no 'expected ...' part\n" << r;
  // Nothing at all in the output directory: no model, report, plots or temporary files.
  EXPECT_TRUE(ListDir(outputs.path()).empty())
      << "left behind: " << ::testing::PrintToString(ListDir(outputs.path()));
}

INSTANTIATE_TEST_SUITE_P(TestsDataBad, CliBadInput, ::testing::ValuesIn(ReadManifest()));

// ---- A failing run leaves previous outputs alone.

TEST(CliOutputs, FailedRunLeavesPreviousOutputsUntouched) {
  TempDir dir, scratch;
  ASSERT_FALSE(dir.path().empty());
  const std::string previous_model = "# a previous calibration, must survive\nname: old\n";
  const std::string previous_report = "{\"previous\": true}\n";
  ASSERT_TRUE(WriteAll(dir / "out.yaml", previous_model));
  ASSERT_TRUE(WriteAll(dir / "out.json", previous_report));

  // Bad input: exit 2 before anything is computed.
  RunResult r = RunTool({"--model=" + kGoodModel, "--measurements=" + kBadDir + "/nan_value.csv",
                         "--output=" + (dir / "out.yaml"), "--report=" + (dir / "out.json"),
                         "--plots_dir=" + (dir / "plots")},
                        scratch.path(), scratch.path());
  EXPECT_EQ(r.exit_code, kExitInput) << r;
  EXPECT_EQ(ReadAll(dir / "out.yaml"), previous_model);
  EXPECT_EQ(ReadAll(dir / "out.json"), previous_report);

  // Iteration limit: the solver ran and stopped half-way; exit 4, nothing written.
  r = RunTool({"--model=" + kGoodModel, "--measurements=" + kGoodMeasurements,
               "--max_iterations=1", "--output=" + (dir / "out.yaml"),
               "--report=" + (dir / "out.json"), "--plots_dir=" + (dir / "plots")},
              scratch.path(), scratch.path());
  EXPECT_EQ(r.exit_code, kExitNotConverged) << r;
  EXPECT_EQ(ReadAll(dir / "out.yaml"), previous_model);
  EXPECT_EQ(ReadAll(dir / "out.json"), previous_report);
  std::vector<std::string> left = ListDir(dir.path());
  std::sort(left.begin(), left.end());
  EXPECT_EQ(left, (std::vector<std::string>{"out.json", "out.yaml"}))
      << "a failed run should write no plots and leave no temporary files";
}

// ---- Inputs are never overwritten.

TEST(CliOutputs, OutputNamingAnInputIsRefused) {
  TempDir dir, scratch;
  ASSERT_FALSE(dir.path().empty());
  const std::string measurements = ReadAll(kGoodMeasurements);
  const std::string model = ReadAll(kGoodModel);
  ASSERT_FALSE(measurements.empty());
  ASSERT_TRUE(WriteAll(dir / "points.csv", measurements));
  ASSERT_TRUE(WriteAll(dir / "robot.yaml", model));
  const std::string base_args[] = {"--model=" + (dir / "robot.yaml"),
                                   "--measurements=" + (dir / "points.csv")};
  struct Case {
    std::string flag;
    std::string value;
  };
  const Case cases[] = {
      {"--output", dir / "points.csv"},
      {"--report", dir / "points.csv"},
      {"--output", dir / "robot.yaml"},
      // The same file through another spelling of its path.
      {"--output", dir.path() + "/./points.csv"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.flag + "=" + c.value);
    const RunResult r = RunTool({base_args[0], base_args[1], c.flag + "=" + c.value,
                                 "--plots_dir=" + (dir / "plots")},
                                scratch.path(), scratch.path());
    EXPECT_EQ(r.exit_code, kExitUsage) << r;
    EXPECT_EQ(ReadAll(dir / "points.csv"), measurements);
    EXPECT_EQ(ReadAll(dir / "robot.yaml"), model);
    EXPECT_FALSE(Exists(dir / "plots"));
  }
}

// ---- Determinism.

TEST(CliOutputs, SameInputGivesByteIdenticalOutputs) {
  // Two runs in two different directories with the same relative output names (the report lists
  // the output paths, so they must be spelled the same).
  TempDir a, b, scratch;
  ASSERT_FALSE(a.path().empty());
  ASSERT_FALSE(b.path().empty());
  const std::vector<std::string> args = {
      "--model=" + kGoodModel, "--measurements=" + kGoodMeasurements,
      "--verify=" + kGoodVerification, "--output=out.yaml", "--report=out.json",
      "--plots_dir=plots"};
  const RunResult ra = RunTool(args, a.path(), scratch.path());
  ASSERT_EQ(ra.exit_code, kExitOk) << ra;
  const RunResult rb = RunTool(args, b.path(), scratch.path());
  ASSERT_EQ(rb.exit_code, kExitOk) << rb;
  for (const char* name : {"out.yaml", "out.json"}) {
    SCOPED_TRACE(name);
    const std::string first = ReadAll(a / name);
    ASSERT_FALSE(first.empty());
    EXPECT_TRUE(first == ReadAll(b / name)) << "the two runs wrote different bytes";
  }
}

// ---- Flag errors.

struct FlagCase {
  std::string name;
  std::vector<std::string> args;
  std::vector<std::string> must_mention;
};

void PrintTo(const FlagCase& c, std::ostream* os) { *os << c.name; }

class CliBadFlags : public ::testing::TestWithParam<FlagCase> {};

TEST_P(CliBadFlags, ExitsOneNamingTheFlag) {
  const FlagCase& c = GetParam();
  TempDir dir, scratch;
  ASSERT_FALSE(dir.path().empty());
  std::vector<std::string> args = {"--model=" + kGoodModel,
                                   "--measurements=" + kGoodMeasurements};
  args.insert(args.end(), c.args.begin(), c.args.end());
  for (const std::string& a : OutputArgs(dir.path())) args.push_back(a);
  const RunResult r = RunTool(args, scratch.path(), scratch.path());
  EXPECT_EQ(r.exit_code, kExitUsage) << r;
  for (const std::string& m : c.must_mention) {
    EXPECT_NE(r.err.find(m), std::string::npos) << "stderr should mention " << m << "\n" << r;
  }
  EXPECT_TRUE(ListDir(dir.path()).empty())
      << "left behind: " << ::testing::PrintToString(ListDir(dir.path()));
}

INSTANTIATE_TEST_SUITE_P(
    Flags, CliBadFlags,
    ::testing::Values(
        FlagCase{"holdout_2", {"--holdout=2"}, {"--holdout"}},
        FlagCase{"holdout_negative", {"--holdout=-0.1"}, {"--holdout"}},
        FlagCase{"angle_unit_grad", {"--angle_unit=grad"}, {"--angle_unit", "grad"}},
        FlagCase{"length_unit_cm", {"--length_unit=cm"}, {"--length_unit", "cm"}},
        FlagCase{"kfold_1", {"--kfold=1"}, {"--kfold"}},
        FlagCase{"split_time", {"--holdout=0.3", "--split=time"}, {"--split", "time"}},
        FlagCase{"parameterization_foo", {"--parameterization=foo"}, {"--parameterization", "foo"}},
        FlagCase{"residual_model_kriging", {"--residual_model=kriging"},
                 {"--residual_model", "kriging", "none, gp or auto"}},
        FlagCase{"verify_and_holdout",
                 {"--verify=" + kGoodVerification, "--holdout=0.3"},
                 {"--verify", "--holdout"}},
        FlagCase{"tilt_without_compliance",
                 {"--joint_errors=harmonics,tilt"},
                 {"--joint_errors", "tilt", "needs it in the list, e.g. compliance,tilt"}},
        FlagCase{"unknown_flag", {"--no_such_flag=1"}, {"no_such_flag"}}));

// ---- Warnings about what the readers dropped or suspect (issues 13 and 14).

// Lost-beam rows and ignored columns of the verification file are reported like those of the
// identification file.
TEST(CliWarnings, VerificationFileLostBeamRowsAndExtraColumnsAreReported) {
  TempDir dir, scratch;
  ASSERT_FALSE(dir.path().empty());
  std::string text = ReadAll(kGoodVerification);
  ASSERT_FALSE(text.empty());
  // Add a status column and a lost-beam row at the end.
  std::string changed;
  size_t start = 0;
  bool header_done = false;
  int line = 0, lost_line = 0;
  while (start < text.size()) {
    size_t nl = text.find('\n', start);
    if (nl == std::string::npos) nl = text.size();
    std::string row = text.substr(start, nl - start);
    ++line;
    if (!row.empty() && row[0] != '#') {
      row += header_done ? ",ok" : ",status";
      header_done = true;
    }
    changed += row + "\n";
    start = nl + 1;
  }
  changed += "0.1,0.2,0.3,0.4,0.5,0.6,0,0,0,smr1,lost\n";
  lost_line = line + 1;
  const std::string verify = dir / "verify.csv";
  std::ofstream(verify) << changed;
  const RunResult r = RunTool({"--model=" + kGoodModel, "--measurements=" + kGoodMeasurements,
                               "--verify=" + verify, "--plots_dir=", "--output=" + (dir / "o.yaml")},
                              scratch.path(), scratch.path());
  EXPECT_EQ(r.exit_code, 0) << r;
  EXPECT_NE(r.err.find(verify + ": skipped 1 row(s) with no measurement (lost beam) at line(s) " +
                       std::to_string(lost_line)),
            std::string::npos)
      << r;
  EXPECT_NE(r.err.find(verify + ": ignored 1 column(s) the model does not use: 'status'"),
            std::string::npos)
      << r;
}

// Positions in metres read as millimetres are flagged; --length_unit=m reads them right.
TEST(CliWarnings, PositionsInMetresAreFlaggedAndReadWithLengthUnit) {
  TempDir dir, scratch;
  ASSERT_FALSE(dir.path().empty());
  const std::string text = ReadAll(kGoodMeasurements);
  // x, y, z (the 7th to 9th fields) divided by 1000.
  std::string metres;
  size_t start = 0;
  bool header_done = false;
  while (start < text.size()) {
    size_t nl = text.find('\n', start);
    if (nl == std::string::npos) nl = text.size();
    const std::string row = text.substr(start, nl - start);
    start = nl + 1;
    if (row.empty() || row[0] == '#' || !header_done) {
      header_done = header_done || (!row.empty() && row[0] != '#');
      metres += row + "\n";
      continue;
    }
    std::vector<std::string> fields;
    size_t a = 0;
    while (true) {
      const size_t comma = row.find(',', a);
      fields.push_back(row.substr(a, comma == std::string::npos ? std::string::npos : comma - a));
      if (comma == std::string::npos) break;
      a = comma + 1;
    }
    for (int k = 6; k < 9; ++k) {
      char buf[40];
      std::snprintf(buf, sizeof(buf), "%.17g", std::stod(fields[k]) / 1000.0);
      fields[k] = buf;
    }
    for (size_t k = 0; k < fields.size(); ++k) metres += (k ? "," : "") + fields[k];
    metres += "\n";
  }
  const std::string csv = dir / "metres.csv";
  std::ofstream(csv) << metres;
  const RunResult as_mm = RunTool({"--model=" + kGoodModel, "--measurements=" + csv,
                                   "--plots_dir=", "--output=" + (dir / "a.yaml")},
                                  scratch.path(), scratch.path());
  EXPECT_NE(as_mm.err.find("positions look like metres: use --length_unit=m"), std::string::npos)
      << as_mm;
  const RunResult as_m = RunTool({"--model=" + kGoodModel, "--measurements=" + csv,
                                  "--length_unit=m", "--plots_dir=",
                                  "--output=" + (dir / "b.yaml")},
                                 scratch.path(), scratch.path());
  EXPECT_EQ(as_m.exit_code, 0) << as_m;
  EXPECT_EQ(as_m.err.find("look like metres"), std::string::npos) << as_m;
}

}  // namespace cli_bad_input_test
}  // namespace
