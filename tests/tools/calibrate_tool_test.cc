// End-to-end tests of the lpoe_calibrate program (and lpoe_simulate, which makes its input): exit
// codes, what is printed, and that a written model reads back and predicts like the in-process
// calibration. Each test runs the built binaries in its own temporary directory.
#include <sys/wait.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "file_util.h"
#include "lpoe/io/io.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/linear_solver.h"
#include "lpoe/pipeline.h"
#include "lpoe/model/statistics.h"

#ifndef LPOE_CALIBRATE_PATH
#error "LPOE_CALIBRATE_PATH must name the lpoe_calibrate binary"
#endif
#ifndef LPOE_SIMULATE_PATH
#error "LPOE_SIMULATE_PATH must name the lpoe_simulate binary"
#endif

namespace lpoe {
namespace {
namespace calibrate_tool_test {

namespace fs = std::filesystem;

constexpr int kExitOk = 0;
constexpr int kExitUsage = 1;
constexpr int kExitInput = 2;
constexpr int kExitNotIdentifiable = 3;
constexpr int kExitNotConverged = 4;
// The tool's model must predict like the in-process calibration of the same data (mm) ...
constexpr double kSameCalibrationTolerance = 1e-6;
// ... and like the simulated actual robot, to within the noise, per axis (mm).
constexpr double kHeldOutPerAxisMax = 0.15;
constexpr double kNoiseSigma = 0.03;

using Output = testing::ToolOutput;
using testing::RunInDir;
using testing::ShellQuote;
using testing::ReadAll;

// A temporary directory that every test works in (the tools may write default outputs, e.g. plots,
// to the working directory).
class CalibrateTool : public ::testing::Test {
 protected:
  Output Run(const std::string& binary, const std::string& args) {
    return RunInDir(dir_.string(), ShellQuote(binary) + " " + args);
  }
  Output Calibrate(const std::string& args) { return Run(LPOE_CALIBRATE_PATH, args); }

  // Section-4-like data: cobot6, Table 2 errors, 70 + 30 rows with noise, and the nominal and actual
  // models.
  void Simulate(double sigma = kNoiseSigma, int count = 100, int verify_count = 30) {
    std::ostringstream args;
    args << "--count=" << count << " --noise_sigma=" << sigma << " --seed=11 --output=" << Path("id.csv")
         << " --model_out=" << Path("nominal.yaml") << " --actual_out=" << Path("actual.yaml");
    if (verify_count > 0) {
      args << " --verify_count=" << verify_count << " --verify_out=" << Path("ver.csv");
    }
    const Output o = Run(LPOE_SIMULATE_PATH, args.str());
    ASSERT_EQ(o.exit_code, kExitOk) << o.err;
  }

  std::string Path(const std::string& name) const { return ShellQuote((dir_ / name).string()); }
  std::string RawPath(const std::string& name) const { return (dir_ / name).string(); }
  bool Exists(const std::string& name) const { return fs::exists(dir_ / name); }

  testing::TempDir temp_{"lpoe_calibrate_test"};
  fs::path dir_ = temp_.path();
};

TEST_F(CalibrateTool, DefaultRunPrintsTheTableAndTheVerificationSet) {
  const Output o = Calibrate("");
  ASSERT_EQ(o.exit_code, kExitOk) << o.out << o.err;
  EXPECT_NE(o.out.find("iteration"), std::string::npos) << o.out;
  EXPECT_NE(o.out.find("max error [mm]"), std::string::npos) << o.out;
  EXPECT_NE(o.out.find("identification set"), std::string::npos) << o.out;
  EXPECT_NE(o.out.find("verification set"), std::string::npos) << o.out;
  EXPECT_NE(o.out.find("converged"), std::string::npos) << o.out;
}

// The identifiability block is read by a person in a terminal: the joint-space terms leave out
// dozens of combinations, which come wrapped under their reason, every one of them listed; the
// largest standard deviations are the frames' (rad or mm).
TEST_F(CalibrateTool, IdentifiabilityListsWrapEveryLeftOutCombination) {
  const Output sim = Run(LPOE_SIMULATE_PATH,
                         "--count=150 --noise_sigma=0.01 --seed=3 --joint_errors=compliance,harmonics "
                         "--output=" + Path("id.csv") + " --model_out=" + Path("nominal.yaml"));
  ASSERT_EQ(sim.exit_code, kExitOk) << sim.err;
  const Output o = Calibrate("--model=" + Path("nominal.yaml") + " --measurements=" + Path("id.csv") +
                             " --joint_errors=compliance,harmonics --plots_dir= --output=" +
                             Path("out.yaml"));
  ASSERT_EQ(o.exit_code, kExitOk) << o.out << o.err;
  std::istringstream lines(o.out);
  std::string line;
  bool in_block = false, in_left_out = false, in_sd = false;
  int listed = 0, announced = 0;
  while (std::getline(lines, line)) {
    if (line.rfind("identifiability:", 0) == 0) in_block = true;
    if (!in_block) continue;
    if (line.empty()) break;
    EXPECT_LE(line.size(), 100u) << line;
    if (line.find("not identifiable from this data kind") != std::string::npos) in_left_out = true;
    if (line.rfind("  largest standard deviations", 0) == 0) {
      in_left_out = false;
      in_sd = true;
      // The joint-space combinations have their terms' scaled units: not ranked with rad and mm.
      EXPECT_NE(line.find("of the frames (rad or mm;"), std::string::npos) << line;
    }
    if (line.rfind("  most correlated pairs", 0) == 0) in_sd = false;
    if (in_sd) {
      EXPECT_EQ(line.find("compliance."), std::string::npos) << line;
      EXPECT_EQ(line.find("harmonics."), std::string::npos) << line;
    }
    if (in_left_out && line.rfind("      ", 0) == 0) {  // a line of names under its reason
      for (size_t at = line.find("compliance."); at != std::string::npos;
           at = line.find("compliance.", at + 1)) {
        ++listed;
      }
    }
    const size_t term = line.find("joint-space term compliance: ");
    if (term != std::string::npos) {
      const size_t comb = line.find("combinations, ");
      ASSERT_NE(comb, std::string::npos) << line;
      announced = std::stoi(line.substr(comb + 14));
    }
  }
  EXPECT_GT(announced, 10) << o.out;  // light links: most gravity products are not separable
  EXPECT_EQ(listed, announced) << o.out;
}

TEST_F(CalibrateTool, OutputReadsBackAndPredictsLikeTheLibrary) {
  Simulate();
  const Output o = Calibrate("--model=" + Path("nominal.yaml") + " --measurements=" + Path("id.csv") +
                             " --verify=" + Path("ver.csv") + " --output=" + Path("calibrated.yaml"));
  ASSERT_EQ(o.exit_code, kExitOk) << o.out << o.err;
  EXPECT_NE(o.out.find("verification set"), std::string::npos);

  RobotModel nominal, calibrated, actual;
  ASSERT_TRUE(ReadRobotModel(RawPath("nominal.yaml"), &nominal).ok());
  const Status read = ReadRobotModel(RawPath("calibrated.yaml"), &calibrated);
  ASSERT_TRUE(read.ok()) << read.message();
  ASSERT_TRUE(ReadRobotModel(RawPath("actual.yaml"), &actual).ok());
  MeasurementSet identification, verification;
  ASSERT_TRUE(ReadMeasurements(RawPath("id.csv"), nominal, AngleUnit::kRadians, &identification).ok());
  ASSERT_TRUE(ReadMeasurements(RawPath("ver.csv"), nominal, AngleUnit::kRadians, &verification).ok());
  ASSERT_EQ(identification.size(), 70);
  ASSERT_EQ(verification.size(), 30);

  // The same calibration in process (the pipeline the tool runs, its prior included) converges to
  // the same predictions.
  const CalibrationResult result =
      RunCalibrationPipeline(nominal, identification, verification, PipelineOptions()).result;
  ASSERT_TRUE(result.converged()) << result.message;
  double worst_same = 0;
  for (const MeasurementSet* set : {&identification, &verification}) {
    for (int r = 0; r < set->size(); ++r) {
      worst_same = std::max(worst_same, (ToolPosition(calibrated, set->q(r)) -
                                         ToolPosition(result.model, set->q(r)))
                                            .norm());
    }
  }
  EXPECT_LE(worst_same, kSameCalibrationTolerance);

  // And it predicts the held-out measurements to within the noise.
  const ErrorStatistics after = PositionErrorStatistics(calibrated, verification);
  for (int a = 0; a < 3; ++a) EXPECT_LE(after.axis[a].max_abs, kHeldOutPerAxisMax) << "axis " << a;
  const ErrorStatistics before = PositionErrorStatistics(nominal, verification);
  EXPECT_GT(before.norm.max_abs, 10 * after.norm.max_abs);
  // Against the noise-free actual robot, the error is the estimation error only.
  double worst_actual = 0;
  for (int r = 0; r < verification.size(); ++r) {
    worst_actual = std::max(worst_actual, (ToolPosition(calibrated, verification.q(r)) -
                                           ToolPosition(actual, verification.q(r)))
                                              .norm());
  }
  EXPECT_LE(worst_actual, 3 * kNoiseSigma);
}

// A registry term end to end through the tools: lpoe_simulate puts the gear ratios into the truth
// robot (and its YAML), lpoe_calibrate identifies them with compliance and writes them to the
// calibrated model, which predicts the held-out data to the noise; an unknown term is refused
// naming the registry.
TEST_F(CalibrateTool, GearRatioFromSimulationToCalibratedModel) {
  const Output sim = Run(LPOE_SIMULATE_PATH,
                         "--joint_errors=gear_ratio --errors=random --count=200 --noise_sigma=0.005 "
                         "--seed=3 --output=" + Path("id.csv") + " --verify_count=60 --verify_out=" +
                             Path("ver.csv") + " --model_out=" + Path("nominal.yaml") +
                             " --actual_out=" + Path("actual.yaml"));
  ASSERT_EQ(sim.exit_code, kExitOk) << sim.err;
  RobotModel actual, nominal, calibrated;
  ASSERT_TRUE(ReadRobotModel(RawPath("actual.yaml"), &actual).ok());
  ASSERT_TRUE(ReadRobotModel(RawPath("nominal.yaml"), &nominal).ok());
  const std::vector<double>& truth = actual.joint_errors.Values("gear_ratio");
  ASSERT_EQ(truth.size(), 6u);
  for (double s : truth) EXPECT_TRUE(std::abs(s) >= 1e-4 && std::abs(s) <= 1e-3) << s;

  const Output o = Calibrate("--quiet --model=" + Path("nominal.yaml") + " --measurements=" +
                             Path("id.csv") + " --verify=" + Path("ver.csv") +
                             " --joint_errors=gear_ratio,compliance --output=" +
                             Path("calibrated.yaml"));
  ASSERT_EQ(o.exit_code, kExitOk) << o.out << o.err;
  const Status read = ReadRobotModel(RawPath("calibrated.yaml"), &calibrated);
  ASSERT_TRUE(read.ok()) << read.message();
  const std::vector<double>& found = calibrated.joint_errors.Values("gear_ratio");
  ASSERT_EQ(found.size(), 6u);
  for (int j = 0; j < 6; ++j) EXPECT_NEAR(found[j], truth[j], 1e-5) << "joint " << j + 1;
  EXPECT_FALSE(calibrated.joint_errors.Values("compliance").empty());
  MeasurementSet verification;
  ASSERT_TRUE(ReadMeasurements(RawPath("ver.csv"), nominal, AngleUnit::kRadians, &verification).ok());
  std::vector<Eigen::Vector3d> residuals;
  for (int r = 0; r < verification.size(); ++r) {
    residuals.push_back(verification.position(r) -
                        PredictToolPosition(calibrated, verification.q(r), verification.target(r)));
  }
  EXPECT_LT(ComputeStatistics(residuals).norm.rms, 1.5 * std::sqrt(3.0) * 0.005);

  const Output bad = Calibrate("--model=" + Path("nominal.yaml") + " --measurements=" +
                               Path("id.csv") + " --joint_errors=compliance,gear_ration");
  EXPECT_EQ(bad.exit_code, kExitUsage);
  EXPECT_NE(bad.err.find("unknown joint error term 'gear_ration'"), std::string::npos) << bad.err;
  EXPECT_NE(bad.err.find("gear_ratio"), std::string::npos) << bad.err;
}

TEST_F(CalibrateTool, TooFewRowsExitsNotIdentifiableWithoutOutput) {
  Simulate(kNoiseSigma, /*count=*/8, /*verify_count=*/0);
  const Output o = Calibrate("--model=" + Path("nominal.yaml") + " --measurements=" +
                             Path("id.csv") + " --output=" + Path("out.yaml"));
  EXPECT_EQ(o.exit_code, kExitNotIdentifiable) << o.out << o.err;
  EXPECT_FALSE(Exists("out.yaml"));
  EXPECT_FALSE(o.err.empty());
}

TEST_F(CalibrateTool, IdenticalPosesExitNotIdentifiableWithoutOutput) {
  Simulate(0.0, /*count=*/10, /*verify_count=*/0);
  // Keep the header and repeat the first row 40 times.
  std::istringstream in(ReadAll(RawPath("id.csv")));
  std::string line, header, row;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    if (header.empty()) {
      header = line;
    } else {
      row = line;
      break;
    }
  }
  ASSERT_FALSE(row.empty());
  {
    std::ofstream out(RawPath("same.csv"));
    out << header << "\n";
    for (int k = 0; k < 40; ++k) out << row << "\n";
  }
  const Output o = Calibrate("--model=" + Path("nominal.yaml") + " --measurements=" +
                             Path("same.csv") + " --output=" + Path("out.yaml"));
  EXPECT_EQ(o.exit_code, kExitNotIdentifiable) << o.out << o.err;
  EXPECT_FALSE(Exists("out.yaml"));
  EXPECT_FALSE(o.err.empty());
}

TEST_F(CalibrateTool, MissingFileExitsWithInputErrorNamingIt) {
  Simulate();
  const std::string missing = RawPath("no_such_measurements.csv");
  Output o = Calibrate("--model=" + Path("nominal.yaml") + " --measurements=" + ShellQuote(missing) +
                       " --output=" + Path("out.yaml"));
  EXPECT_EQ(o.exit_code, kExitInput) << o.out << o.err;
  EXPECT_NE(o.err.find("no_such_measurements.csv"), std::string::npos) << o.err;
  EXPECT_FALSE(Exists("out.yaml"));

  o = Calibrate("--model=" + Path("no_such_model.yaml") + " --measurements=" + Path("id.csv"));
  EXPECT_EQ(o.exit_code, kExitInput) << o.out << o.err;
  EXPECT_NE(o.err.find("no_such_model.yaml"), std::string::npos) << o.err;
}

TEST_F(CalibrateTool, BadFlagValuesExitWithUsageError) {
  for (const std::string flag : {"--angle_unit=gradians", "--parameterization=bogus",
                                 "--max_iterations=0", "--holdout=1.5", "--data_kind=both"}) {
    const Output o = Calibrate(flag + " --output=" + Path("out.yaml"));
    EXPECT_EQ(o.exit_code, kExitUsage) << flag << "\n" << o.out << o.err;
    EXPECT_FALSE(o.err.empty()) << flag;
    EXPECT_FALSE(Exists("out.yaml")) << flag;
  }
}

TEST_F(CalibrateTool, IterationLimitExitsNotConvergedWithoutOutput) {
  Simulate();
  const Output o = Calibrate("--model=" + Path("nominal.yaml") + " --measurements=" +
                             Path("id.csv") + " --max_iterations=1 --output=" + Path("out.yaml"));
  EXPECT_EQ(o.exit_code, kExitNotConverged) << o.out << o.err;
  EXPECT_FALSE(Exists("out.yaml"));
}

// Regression: a UR-like arm whose tool lies exactly on joint 6's axis (the actual one too: no
// errors), calibrated by Ceres on the full parameterization, ran Levenberg-Marquardt along the lost
// axis tilt until the iteration limit and exited 4. It now converges and exits 0 like the linear
// solver, with the tilt reported as not identifiable and the model written.
TEST_F(CalibrateTool, CeresFullParameterizationWithTheToolOnTheLastAxisConverges) {
  std::ofstream(dir_ / "ur.yaml") << R"(name: ur_tool_on_axis
joints:
  - {name: joint1, type: revolute, origin: {xyz: [0, 0, 0], rpy: [0, 0, 0]}}
  - {name: joint2, type: revolute, origin: {xyz: [0, 0, 89.159], rpy: [1.5707963267948966, 0, 0]}}
  - {name: joint3, type: revolute, origin: {xyz: [-425, 0, 0], rpy: [0, 0, 0]}}
  - {name: joint4, type: revolute, origin: {xyz: [-392.25, 0, 0], rpy: [0, 0, 0]}}
  - {name: joint5, type: revolute, origin: {xyz: [0, 0, 109.15], rpy: [1.5707963267948966, 0, 0]}}
  - {name: joint6, type: revolute, origin: {xyz: [0, 0, 94.65], rpy: [-1.5707963267948966, 0, 0]}}
tools:
  - {name: tool0, origin: {xyz: [0, 0, 82.3], rpy: [0, 0, 0]}}
)";
  const Output sim = Run(LPOE_SIMULATE_PATH, "--model=" + Path("ur.yaml") +
                                                 " --errors=none --count=200 --noise_sigma=0.01 "
                                                 "--output=" + Path("id.csv"));
  ASSERT_EQ(sim.exit_code, kExitOk) << sim.err;
  for (const char* solver : {"ceres", "linear"}) {
    const std::string out = std::string("cal_") + solver + ".yaml";
    const Output o = Calibrate("--model=" + Path("ur.yaml") + " --measurements=" + Path("id.csv") +
                               " --solver=" + solver + " --parameterization=full --plots_dir= " +
                               "--output=" + Path(out));
    EXPECT_EQ(o.exit_code, kExitOk) << solver << "\n" << o.out << o.err;
    EXPECT_TRUE(Exists(out)) << solver;
    EXPECT_NE(o.out.find("joint6.rx: no configuration separates it"), std::string::npos) << o.out;
    EXPECT_NE(o.out.find("result: converged"), std::string::npos) << o.out;
  }
}

TEST_F(CalibrateTool, OutputEqualToAnInputIsRefused) {
  Simulate();
  const std::string model_before = ReadAll(RawPath("nominal.yaml"));
  const std::string csv_before = ReadAll(RawPath("id.csv"));
  for (const std::string& target : {std::string("nominal.yaml"), std::string("id.csv")}) {
    const Output o = Calibrate("--model=" + Path("nominal.yaml") + " --measurements=" +
                               Path("id.csv") + " --output=" + Path(target));
    EXPECT_EQ(o.exit_code, kExitUsage) << target << "\n" << o.out << o.err;
    EXPECT_NE(o.err.find(target), std::string::npos) << o.err;
  }
  EXPECT_EQ(ReadAll(RawPath("nominal.yaml")), model_before);
  EXPECT_EQ(ReadAll(RawPath("id.csv")), csv_before);
}

}  // namespace calibrate_tool_test
}  // namespace
}  // namespace lpoe
