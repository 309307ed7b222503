// End-to-end regression tests on the built tools (paths from CMake): implausible
// results are refused (exit 8) unless --force, flags outside their ranges exit 1 naming the flag,
// and outputs are safe (symlinks resolved, devices written straight, collisions by identity,
// nested plot directories, concurrent runs into one plots directory).
#include <dirent.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "file_util.h"

namespace {
namespace safety_test {

using ::lpoe::testing::Exists;
using ::lpoe::testing::ListDir;
using ::lpoe::testing::ReadAll;
using ::lpoe::testing::RunInDir;
using ::lpoe::testing::WriteAll;
using Result = ::lpoe::testing::ToolOutput;

constexpr int kExitOk = 0;
constexpr int kExitUsage = 1;
constexpr int kExitImplausible = 8;
constexpr int kRows = 150;
constexpr int kConcurrentRuns = 8;

const std::string kCalibrate = LPOE_CALIBRATE_PATH;
const std::string kSimulate = LPOE_SIMULATE_PATH;

class Safety : public ::testing::Test {
 protected:
  std::string Path(const std::string& name) const { return dir_ + "/" + name; }

  Result Run(const std::string& tool, const std::string& args) const {
    return RunInDir(dir_, tool + " " + args);
  }

  // Simulated section-4-like data (cobot6, Table 2 errors) in `name`.
  void Simulate(const std::string& name, const std::string& extra = "") const {
    const Result r = Run(kSimulate, "--count=" + std::to_string(kRows) +
                                        " --noise_sigma=0.03 --output=" + Path(name) + " " + extra);
    ASSERT_EQ(r.exit_code, kExitOk) << r.err;
  }

  // Rewrites the x, y, z columns of a simulated CSV (header q1..q6,x,y,z,target).
  template <typename F>
  void Transform(const std::string& from, const std::string& to, F f) const {
    std::istringstream in(ReadAll(Path(from)));
    std::ostringstream out;
    std::string line;
    while (std::getline(in, line)) {
      if (line.empty() || line[0] == '#' || line[0] == 'q') {
        out << line << "\n";
        continue;
      }
      std::vector<std::string> fields;
      std::stringstream ss(line);
      std::string field;
      while (std::getline(ss, field, ',')) fields.push_back(field);
      double p[3] = {std::stod(fields[6]), std::stod(fields[7]), std::stod(fields[8])};
      f(p);
      char buf[200];
      std::snprintf(buf, sizeof(buf), "%.17g,%.17g,%.17g", p[0], p[1], p[2]);
      for (int k = 0; k < 6; ++k) out << fields[k] << ",";
      out << buf << "," << fields[9] << "\n";
    }
    ASSERT_TRUE(WriteAll(Path(to), out.str()));
  }

  // Calibrating `csv` must be refused as implausible, write nothing, and say `hint` on stderr.
  void ExpectImplausible(const std::string& csv, const std::string& hint,
                         const std::string& extra = "") const {
    const Result r = Run(kCalibrate, "--measurements=" + Path(csv) +
                                         " --max_iterations=1000 --plots_dir=plots --output=" +
                                         Path("out.yaml") + " " + extra);
    EXPECT_EQ(r.exit_code, kExitImplausible) << r.err;
    EXPECT_NE(r.err.find(hint), std::string::npos) << r.err;
    EXPECT_FALSE(Exists(Path("out.yaml")));
    EXPECT_FALSE(Exists(Path("plots")));
  }

  ::lpoe::testing::TempDir temp_{"lpoe_safety"};
  std::string dir_ = temp_.path();
};

// ---- Issue 13 item 1: silent wrong success.

TEST_F(Safety, CleanDataPass) {
  Simulate("clean.csv");
  const Result r = Run(kCalibrate, "--measurements=clean.csv --plots_dir= --report=r.json");
  ASSERT_EQ(r.exit_code, kExitOk) << r.err;
  const std::string report = ReadAll(Path("r.json"));
  EXPECT_NE(report.find("\"verdict\""), std::string::npos);
  EXPECT_NE(report.find("\"level\": \"pass\""), std::string::npos) << report;
}

TEST_F(Safety, PositionsInMetresAreRefusedWithAUnitHint) {
  Simulate("clean.csv");
  Transform("clean.csv", "metres.csv", [](double* p) {
    for (int a = 0; a < 3; ++a) p[a] /= 1000;
  });
  ExpectImplausible("metres.csv", "look like metres");
}

TEST_F(Safety, PositionsScaledByTwoAreRefused) {
  Simulate("clean.csv");
  Transform("clean.csv", "scaled.csv", [](double* p) {
    for (int a = 0; a < 3; ++a) p[a] *= 2;
  });
  ExpectImplausible("scaled.csv", "spread");
}

TEST_F(Safety, DegreesReadAsRadiansAreRefusedWithAUnitHint) {
  Simulate("deg.csv", "--angle_unit=deg");
  ExpectImplausible("deg.csv", "--angle_unit=deg");
}

TEST_F(Safety, SwappedColumnsAreRefused) {
  Simulate("clean.csv");
  Transform("clean.csv", "swapped.csv", [](double* p) { std::swap(p[0], p[1]); });
  ExpectImplausible("swapped.csv", "not plausible");
}

TEST_F(Safety, RandomPositionsAreRefused) {
  Simulate("clean.csv");
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> u(-1000, 1000);
  Transform("clean.csv", "random.csv", [&](double* p) {
    for (int a = 0; a < 3; ++a) p[a] = u(rng);
  });
  ExpectImplausible("random.csv", "not plausible");
}

TEST_F(Safety, MetreNoiseIsRefused) {
  const Result s = Run(kSimulate, "--count=150 --noise_sigma=1000 --output=noisy.csv");
  ASSERT_EQ(s.exit_code, kExitOk) << s.err;
  ExpectImplausible("noisy.csv", "not plausible");
}

// Radians read as degrees: every joint moves a few "degrees", the calibration cannot converge or
// identify anything, and the tool says why: a unit hint at the start and with the error.
TEST_F(Safety, RadiansReadAsDegreesGetAUnitHint) {
  Simulate("clean.csv");
  const Result r = Run(kCalibrate, "--measurements=clean.csv --angle_unit=deg --plots_dir= "
                                   "--output=out.yaml");
  EXPECT_NE(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("warning:"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("they look like radians: use --angle_unit=rad"), std::string::npos) << r.err;
  EXPECT_FALSE(Exists(Path("out.yaml")));
  // Read as radians (what they are): no hint.
  const Result d = Run(kCalibrate, "--measurements=clean.csv --plots_dir=");
  EXPECT_EQ(d.err.find("look like radians"), std::string::npos) << d.err;
}

// lpoe_simulate's old --out still works for one release, with a warning; both at once is an error.
TEST_F(Safety, SimulateOldOutFlagStillWorksWithAWarning) {
  Result r = Run(kSimulate, "--count=5 --out=old.csv");
  ASSERT_EQ(r.exit_code, kExitOk) << r.err;
  EXPECT_TRUE(Exists(Path("old.csv")));
  EXPECT_NE(r.err.find("--out is now --output"), std::string::npos) << r.err;
  r = Run(kSimulate, "--count=5 --out=a.csv --output=b.csv");
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_FALSE(Exists(Path("a.csv")));
  EXPECT_FALSE(Exists(Path("b.csv")));
}

TEST_F(Safety, ForceWritesAnImplausibleResult) {
  Simulate("clean.csv");
  Transform("clean.csv", "metres.csv", [](double* p) {
    for (int a = 0; a < 3; ++a) p[a] /= 1000;
  });
  const Result r = Run(kCalibrate, "--measurements=metres.csv --max_iterations=1000 --plots_dir= "
                                   "--force --output=out.yaml --html_report=page.html");
  // Written, and still exit 8: a script can tell a forced result from a plausible one.
  EXPECT_EQ(r.exit_code, 8) << r.err;
  EXPECT_TRUE(Exists(Path("out.yaml")));
  // The page ends with what was written and what to do: not deploy.
  const std::string page = ReadAll(Path("page.html"));
  EXPECT_NE(page.find("<h2>Outputs and next steps</h2>"), std::string::npos);
  EXPECT_NE(page.find("<code>out.yaml</code>"), std::string::npos);
  EXPECT_NE(page.find("Do not deploy this model"), std::string::npos);
  EXPECT_NE(page.find("only because of --force"), std::string::npos);
  EXPECT_NE(r.err.find("outputs written because of --force"), std::string::npos) << r.err;
}

TEST_F(Safety, FlagsOutsideTheirRangesExitOneNamingTheFlag) {
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"--solver=ceres --sigma=1e-200", "--sigma"},
      {"--solver=ceres --sigma=1e200", "--sigma"},
      {"--solver=ceres --loss=huber --loss_scale=1e-300", "--loss_scale"},
      {"--solver=ceres --loss=cauchy --loss_scale=1e-300", "--loss_scale"},
      {"--step_tolerance=inf", "--step_tolerance"},
      {"--step_tolerance=nan", "--step_tolerance"},
      {"--threads=2147483647", "--threads"},
      {"--threads=-1", "--threads"},
      {"--kfold=1", "--kfold"},
      {"--kfold=60 --holdout=0.5", "--kfold"},  // 35 identification rows: folds would be empty
      {"--holdout=0.99999", "--holdout"},
      {"--holdout=1e-6", "--holdout"},
      {"--holdout=0.9", "--holdout"},  // 7 identification rows
      {"--noise_sigma=0", "--noise_sigma"},
      {"--max_iterations=0", "--max_iterations"},
      {"--sd_fraction=1", "--sd_fraction"},
  };
  for (const auto& [args, flag] : cases) {
    SCOPED_TRACE(args);
    const Result r = Run(kCalibrate, args + " --plots_dir=plots --output=out.yaml");
    EXPECT_EQ(r.exit_code, kExitUsage) << r.err;
    EXPECT_NE(r.err.find(flag), std::string::npos) << r.err;
    EXPECT_FALSE(Exists(Path("out.yaml")));
    EXPECT_FALSE(Exists(Path("plots")));
  }
}

TEST_F(Safety, SimulateBoundsItsFlags) {
  for (const std::string args : {"--count=2147483647", "--count=0", "--noise_sigma=inf",
                                 "--noise_sigma=nan", "--orientation_noise_sigma=inf"}) {
    SCOPED_TRACE(args);
    const Result r = Run(kSimulate, args + " --output=x.csv");
    EXPECT_EQ(r.exit_code, kExitUsage) << r.err;
    EXPECT_FALSE(Exists(Path("x.csv")));
  }
}

// ---- Items 2-3: outputs.

TEST_F(Safety, SymlinkedOutputReplacesItsTargetAndKeepsTheLink) {
  ASSERT_TRUE(WriteAll(Path("target.yaml"), "old\n"));
  ASSERT_EQ(symlink("target.yaml", Path("link.yaml").c_str()), 0);
  const Result r = Run(kCalibrate, "--plots_dir= --output=link.yaml");
  ASSERT_EQ(r.exit_code, kExitOk) << r.err;
  struct stat st;
  ASSERT_EQ(lstat(Path("link.yaml").c_str(), &st), 0);
  EXPECT_TRUE(S_ISLNK(st.st_mode));
  EXPECT_NE(ReadAll(Path("target.yaml")).find("joints:"), std::string::npos);
}

TEST_F(Safety, DeviceOutputIsWrittenStraightNotReplaced) {
  // Two outputs may share a device (nothing is renamed over it).
  const Result ok = Run(kCalibrate, "--plots_dir= --report=/dev/null --output=/dev/null");
  EXPECT_EQ(ok.exit_code, kExitOk) << ok.err;
  struct stat st;
  ASSERT_EQ(lstat("/dev/null", &st), 0);
  EXPECT_TRUE(S_ISCHR(st.st_mode));
  EXPECT_TRUE(ListDir(dir_).empty());
  // /dev/stdout is a link into /proc: written straight, after the tool's own text.
  const Result out = Run(kCalibrate, "--plots_dir= --report=/dev/stdout");
  EXPECT_EQ(out.exit_code, kExitOk) << out.err;
  const size_t schema = out.out.find("\"schema\"");
  EXPECT_NE(schema, std::string::npos);
  EXPECT_GT(schema, out.out.find("verdict:"));
  EXPECT_TRUE(ListDir(dir_).empty());
}

TEST_F(Safety, CollisionsAreFoundByIdentityNotBySpelling) {
  ASSERT_EQ(mkdir(Path("d").c_str(), 0755), 0);
  ASSERT_EQ(symlink("d", Path("linked").c_str()), 0);
  const Result s = Run(kSimulate, "--count=100 --output=sim.csv --model_out=model.yaml");
  ASSERT_EQ(s.exit_code, kExitOk) << s.err;
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"--output=d/x.yaml --urdf_output=d/./x.yaml", "name the same file"},
      {"--urdf_output=d/y --report=linked/y", "name the same file"},
      {"--output=d/../d/z --report=d/z", "name the same file"},
      {"--plots_dir=p --output=p/convergence.png", "name the same file"},
      {"--plots_dir=p --report=./p/../p/histogram.png --output=p/./axis_errors.png",
       "name the same file"},
      {"--model=model.yaml --output=./d/../model.yaml", "would overwrite the input"},
      {"--measurements=sim.csv --report=linked/../sim.csv", "would overwrite the input"},
  };
  for (const auto& [args, message] : cases) {
    SCOPED_TRACE(args);
    const Result r = Run(kCalibrate, args);
    EXPECT_EQ(r.exit_code, kExitUsage) << r.err;
    EXPECT_NE(r.err.find(message), std::string::npos) << r.err;
  }
  const Result sim = Run(kSimulate, "--model=model.yaml --output=./d/../model.yaml");
  EXPECT_EQ(sim.exit_code, kExitUsage) << sim.err;
  EXPECT_NE(ReadAll(Path("model.yaml")).find("joints:"), std::string::npos);
}

TEST_F(Safety, NestedPlotsDirectoryIsCreated) {
  const Result r = Run(kCalibrate, "--plots_dir=a/b/c");
  ASSERT_EQ(r.exit_code, kExitOk) << r.err;
  EXPECT_TRUE(Exists(Path("a/b/c/convergence.png")));
}

TEST_F(Safety, PlantedLinkAtAnOldTemporaryNameIsNotFollowed) {
  ASSERT_EQ(mkdir(Path("plots").c_str(), 0755), 0);
  ASSERT_TRUE(WriteAll(Path("victim"), "precious\n"));
  ASSERT_EQ(symlink(Path("victim").c_str(), Path("plots/convergence.png.tmp").c_str()), 0);
  const Result r = Run(kCalibrate, "--plots_dir=plots");
  ASSERT_EQ(r.exit_code, kExitOk) << r.err;
  EXPECT_EQ(ReadAll(Path("victim")), "precious\n");
}

bool ValidPng(const std::string& bytes) {
  static const char kSignature[] = "\x89PNG\r\n\x1a\n";
  static const char kIend[] = "IEND\xae\x42\x60\x82";
  return bytes.size() > 20 && bytes.compare(0, 8, kSignature, 8) == 0 &&
         bytes.compare(bytes.size() - 8, 8, kIend, 8) == 0;
}

TEST_F(Safety, ConcurrentRunsIntoOnePlotsDirectory) {
  std::vector<pid_t> children;
  for (int k = 0; k < kConcurrentRuns; ++k) {
    const pid_t pid = fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) {
      const std::string log = dir_ + "/run" + std::to_string(k) + ".log";
      const std::string cmd = "cd " + dir_ + " && " + kCalibrate +
                              " --plots_dir=shared/plots >" + log + " 2>&1";
      _exit(WEXITSTATUS(std::system(cmd.c_str())));
    }
    children.push_back(pid);
  }
  for (pid_t pid : children) {
    int status = 0;
    ASSERT_EQ(waitpid(pid, &status, 0), pid);
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == kExitOk);
  }
  std::vector<std::string> names = ListDir(Path("shared/plots"));
  std::sort(names.begin(), names.end());
  EXPECT_EQ(names, (std::vector<std::string>{"axis_errors.png", "convergence.png",
                                             "error_histogram.png"}));
  for (const std::string& name : names) {
    EXPECT_TRUE(ValidPng(ReadAll(Path("shared/plots/" + name)))) << name;
  }
}

}  // namespace safety_test
}  // namespace
