// The contract every tool keeps, checked on the tools that came after lpoe_calibrate:
// outputs checked before any work (collisions with inputs and each other through links and
// spellings, missing directories), committed together or not at all, symlinked outputs written
// through; names and paths of any bytes never abort a report writer; long joint names never crash
// the plots; one strict CSV reader (field counts, duplicate columns, ranges, short rows named);
// the refusals (zero redundancy, a nominal model of another robot).
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "file_util.h"
#include "lpoe/io/io.h"
#include "lpoe/model/residual_layer.h"
#include "lpoe/model/robot_model.h"

#ifndef LPOE_PLAN_PATH
#error "LPOE_PLAN_PATH must name the lpoe_plan binary"
#endif

namespace lpoe {
namespace {
namespace tool_contract_test {

using testing::Exists;
using testing::ListDir;
using testing::ReadAll;
using testing::RunInDir;
using testing::ShellQuote;
using testing::TempDir;
using testing::ToolOutput;
using testing::WriteAll;

constexpr int kExitOk = 0;
constexpr int kExitUsage = 1;
constexpr int kExitInput = 2;
constexpr int kExitNotIdentifiable = 3;

const std::string kData = LPOE_DATA_DIR;
const std::string kModel = kData + "/cobot6.yaml";
const std::string kIdentification = kData + "/section4/identification.csv";

std::string Q(const std::string& s) { return ShellQuote(s); }

ToolOutput Plan(const TempDir& d, const std::string& args) {
  return RunInDir(d.path(), std::string(LPOE_PLAN_PATH) + " --candidate_count=300 "
                                "--workspace_count=50 --random_draws=2 " + args);
}
ToolOutput Compensate(const TempDir& d, const std::string& args) {
  return RunInDir(d.path(), std::string(LPOE_COMPENSATE_PATH) + " --threads=1 " + args);
}
ToolOutput Predict(const TempDir& d, const std::string& args) {
  return RunInDir(d.path(), std::string(LPOE_PREDICT_PATH) + " " + args);
}
ToolOutput Calibrate(const TempDir& d, const std::string& args) {
  return RunInDir(d.path(), std::string(LPOE_CALIBRATE_PATH) + " --quiet " + args);
}

// Six joint values per row (rad), the header q1..q6, for the joint readers.
std::string JointsCsv(int rows) {
  std::string text = "q1,q2,q3,q4,q5,q6\n";
  for (int r = 0; r < rows; ++r) {
    const double a = 0.1 + 0.05 * r;
    for (int j = 0; j < 6; ++j) text += (j ? "," : "") + std::to_string(a * (j % 2 ? -1 : 1));
    text += "\n";
  }
  return text;
}

// Targets for lpoe_compensate: the shipped identification rows (q1..q6, x, y, z, target).
std::string TargetsCsv() { return ReadAll(kIdentification); }

bool IsSymlink(const std::string& path) {
  struct stat st;
  return ::lstat(path.c_str(), &st) == 0 && S_ISLNK(st.st_mode);
}

bool NoStagingLeft(const std::string& dir) {
  for (const std::string& name : ListDir(dir)) {
    if (name.rfind(".lpoe-staging-", 0) == 0) return false;
  }
  return true;
}

// ---- Data loss: outputs checked before any work.

TEST(ToolContract, PlanRefusesToOverwriteItsInputs) {
  TempDir d;
  ASSERT_TRUE(WriteAll(d / "model.yaml", ReadAll(kModel)));
  ASSERT_TRUE(WriteAll(d / "ws.csv", JointsCsv(5)));
  const std::string model_text = ReadAll(d / "model.yaml");
  const std::string ws_text = ReadAll(d / "ws.csv");
  struct Case {
    std::string args, why;
  } cases[] = {
      {"--model=model.yaml --count=12 --output=model.yaml", "--output = --model"},
      {"--model=model.yaml --count=12 --output=./sub/../model.yaml", "--output = --model, spelt"},
      {"--model=model.yaml --count=12 --output=p.csv --report=model.yaml", "--report = --model"},
      {"--model=model.yaml --count=12 --workspace=ws.csv --output=ws.csv", "--output = --workspace"},
      {"--model=model.yaml --count=12 --output=p.csv --report=p.csv", "--report = --output"},
  };
  ASSERT_EQ(::mkdir((d / "sub").c_str(), 0755), 0);
  for (const Case& c : cases) {
    const ToolOutput r = Plan(d, c.args);
    EXPECT_EQ(r.exit_code, kExitUsage) << c.why << "\n" << r.err;
    EXPECT_EQ(ReadAll(d / "model.yaml"), model_text) << c.why;
    EXPECT_EQ(ReadAll(d / "ws.csv"), ws_text) << c.why;
    EXPECT_FALSE(Exists(d / "p.csv")) << c.why;
  }
  // The default report name (<output>.json) naming the model: a model called plan.json.
  ASSERT_TRUE(WriteAll(d / "plan.json", ReadAll(kModel)));
  const ToolOutput r = Plan(d, "--model=plan.json --count=12 --output=plan.csv");
  EXPECT_EQ(r.exit_code, kExitUsage) << r.err;
  EXPECT_NE(r.err.find("would overwrite the input --model"), std::string::npos) << r.err;
  EXPECT_EQ(ReadAll(d / "plan.json"), ReadAll(kModel));
  EXPECT_FALSE(Exists(d / "plan.csv"));
  // A hard link to the model is the model.
  ASSERT_EQ(::link((d / "model.yaml").c_str(), (d / "hard.csv").c_str()), 0);
  EXPECT_EQ(Plan(d, "--model=model.yaml --count=12 --output=hard.csv").exit_code, kExitUsage);
  EXPECT_EQ(ReadAll(d / "model.yaml"), model_text);
}

TEST(ToolContract, CompensateOutputAndReportCollide) {
  TempDir d;
  ASSERT_TRUE(WriteAll(d / "t.csv", TargetsCsv()));
  ToolOutput r = Compensate(d, "--model=" + Q(kModel) + " --targets=t.csv --output=o.csv --report=o.csv");
  EXPECT_EQ(r.exit_code, kExitUsage) << r.err;
  EXPECT_NE(r.err.find("name the same file"), std::string::npos) << r.err;
  EXPECT_FALSE(Exists(d / "o.csv"));
  // Through a symlink to the targets file.
  ASSERT_EQ(::symlink("t.csv", (d / "link.csv").c_str()), 0);
  const std::string targets = ReadAll(d / "t.csv");
  r = Compensate(d, "--model=" + Q(kModel) + " --targets=t.csv --output=link.csv");
  EXPECT_EQ(r.exit_code, kExitUsage) << r.err;
  EXPECT_EQ(ReadAll(d / "t.csv"), targets);
}

TEST(ToolContract, PredictRefusesToOverwriteTheModelThroughALink) {
  TempDir d;
  ASSERT_TRUE(WriteAll(d / "m.yaml", ReadAll(kModel)));
  ASSERT_TRUE(WriteAll(d / "j.csv", JointsCsv(3)));
  ASSERT_EQ(::symlink((d / "m.yaml").c_str(), (d / "out.csv").c_str()), 0);
  const ToolOutput r = Predict(d, "--model=m.yaml --joints=j.csv --output=out.csv");
  EXPECT_EQ(r.exit_code, kExitUsage) << r.err;
  EXPECT_EQ(ReadAll(d / "m.yaml"), ReadAll(kModel));
}

// A missing directory of any output is found before a row is solved, and nothing is written.
TEST(ToolContract, MissingOutputDirectoryFoundFirst) {
  TempDir d;
  ASSERT_TRUE(WriteAll(d / "t.csv", TargetsCsv()));
  ToolOutput r = Compensate(d, "--model=" + Q(kModel) + " --targets=t.csv --output=o.csv "
                               "--report=missing/r.json");
  EXPECT_EQ(r.exit_code, kExitUsage) << r.err;
  EXPECT_NE(r.err.find("does not exist"), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("rows:"), std::string::npos) << "solved before the check:\n" << r.err;
  EXPECT_FALSE(Exists(d / "o.csv"));

  r = Plan(d, "--model=" + Q(kModel) + " --count=12 --output=p.csv --report=missing/r.json");
  EXPECT_EQ(r.exit_code, kExitUsage) << r.err;
  EXPECT_FALSE(Exists(d / "p.csv"));

  ASSERT_TRUE(WriteAll(d / "j.csv", JointsCsv(3)));
  r = Predict(d, "--model=" + Q(kModel) + " --joints=j.csv --output=missing/o.csv");
  EXPECT_EQ(r.exit_code, kExitUsage) << r.err;
  EXPECT_TRUE(NoStagingLeft(d.path()));
}

// A symlinked output stays a link; its target receives the text (as lpoe_calibrate does).
TEST(ToolContract, SymlinkedOutputsKeepTheLink) {
  TempDir d;
  ASSERT_TRUE(WriteAll(d / "t.csv", TargetsCsv()));
  ASSERT_TRUE(WriteAll(d / "j.csv", JointsCsv(3)));
  ASSERT_EQ(::mkdir((d / "real").c_str(), 0755), 0);
  for (const char* name : {"c.csv", "c.json", "p.csv", "p.json", "y.csv"}) {
    ASSERT_TRUE(WriteAll(d / (std::string("real/") + name), "old\n"));
    ASSERT_EQ(::symlink((d / (std::string("real/") + name)).c_str(), (d / name).c_str()), 0);
  }
  ToolOutput r = Compensate(d, "--model=" + Q(kModel) + " --targets=t.csv --output=c.csv --report=c.json");
  EXPECT_EQ(r.exit_code, kExitOk) << r.err;
  r = Plan(d, "--model=" + Q(kModel) + " --count=12 --output=p.csv");
  EXPECT_EQ(r.exit_code, kExitOk) << r.err;
  r = Predict(d, "--model=" + Q(kModel) + " --joints=j.csv --output=y.csv");
  EXPECT_EQ(r.exit_code, kExitOk) << r.err;
  for (const char* name : {"c.csv", "c.json", "p.csv", "p.json", "y.csv"}) {
    EXPECT_TRUE(IsSymlink(d / name)) << name << " was replaced by a regular file";
    const std::string text = ReadAll(d / (std::string("real/") + name));
    EXPECT_NE(text, "old\n") << name << ": the link's target was not written";
    EXPECT_GT(text.size(), 10u) << name;
  }
  EXPECT_NE(ReadAll(d / "real/y.csv").find("\nx,y,z\n"), std::string::npos);  // after the frame line
  nlohmann::json report;
  EXPECT_NO_THROW(report = nlohmann::json::parse(ReadAll(d / "real/c.json")));
  EXPECT_TRUE(report.contains("status_counts"));
  EXPECT_TRUE(NoStagingLeft(d.path()) && NoStagingLeft(d / "real"));
}

// ---- Names and paths of any bytes.

TEST(ToolContract, NonUtf8NamesAndPathsNeverAbortJson) {
  TempDir d;
  RobotModel model;
  ASSERT_TRUE(ReadRobotModel(kModel, &model).ok());
  model.name = "robot\xff\xfe\xc3";
  model.joints[1].name = "j\x80\xbf" "2";
  const std::string bad = "m\xff.yaml";  // the model's path too
  ASSERT_TRUE(WriteRobotModel(d / bad, model).ok());
  ASSERT_TRUE(WriteAll(d / "t\xfe.csv", TargetsCsv()));

  ToolOutput r = Plan(d, "--model=" + Q(bad) + " --count=12 --output=p.csv");
  ASSERT_EQ(r.exit_code, kExitOk) << r.err;
  nlohmann::json j;
  ASSERT_NO_THROW(j = nlohmann::json::parse(ReadAll(d / "p.json")));
  EXPECT_EQ(j["model"].get<std::string>(), "robot\xef\xbf\xbd\xef\xbf\xbd\xef\xbf\xbd");

  r = Compensate(d, "--model=" + Q(bad) + " --targets=" + Q("t\xfe.csv") +
                        " --output=o.csv --report=o.json");
  ASSERT_EQ(r.exit_code, kExitOk) << r.err;
  ASSERT_NO_THROW(j = nlohmann::json::parse(ReadAll(d / "o.json")));
  EXPECT_EQ(j["input"].get<std::string>(), "t\xef\xbf\xbd.csv");

  r = Calibrate(d, "--model=" + Q(bad) + " --measurements=" + Q(kIdentification) +
                       " --report=r.json --html_report=r.html");
  ASSERT_EQ(r.exit_code, kExitOk) << r.err;
  ASSERT_NO_THROW(j = nlohmann::json::parse(ReadAll(d / "r.json")));
  const std::string html = ReadAll(d / "r.html");
  EXPECT_EQ(html.find("\xff"), std::string::npos);
  EXPECT_NE(html.find("robot\xef\xbf\xbd"), std::string::npos);
  EXPECT_TRUE(NoStagingLeft(d.path()));
}

TEST(ToolContract, LongJointNamesDoNotCrashThePlots) {
  TempDir d;
  RobotModel model;
  ASSERT_TRUE(ReadRobotModel(kModel, &model).ok());
  for (int j = 0; j < model.num_joints(); ++j) {
    model.joints[j].name = std::string(2000, 'a' + j) + "#u";
  }
  model.name = std::string(3000, 'n');
  ASSERT_TRUE(WriteRobotModel(d / "long.yaml", model).ok());
  const ToolOutput r = Calibrate(d, "--model=long.yaml --measurements=" + Q(kIdentification) +
                                        " --html_report=r.html --plots_dir=plots --report=r.json");
  ASSERT_EQ(r.exit_code, kExitOk) << r.err;
  EXPECT_GT(ReadAll(d / "r.html").size(), 1000u);
  EXPECT_FALSE(ListDir(d / "plots").empty());
  EXPECT_TRUE(NoStagingLeft(d.path()));
  // lpoe_compare's HTML report draws the same plots.
  const ToolOutput c = RunInDir(d.path(), std::string(LPOE_COMPARE_PATH) +
                                              " --model=long.yaml --measurements=" +
                                              Q(kIdentification) + " --html_report=c.html");
  EXPECT_TRUE(c.exit_code == 0 || c.exit_code == 7) << c.err;  // 7: the solvers disagree
  EXPECT_GT(ReadAll(d / "c.html").size(), 1000u) << c.err;
  EXPECT_TRUE(NoStagingLeft(d.path()));
}

// ---- One strict CSV reader.

TEST(ToolContract, CompensateAndPredictRefuseExtraFieldsAndDuplicateColumns) {
  TempDir d;
  // Decimal commas: 0,1,0,2,... reads as more fields than the header.
  ASSERT_TRUE(WriteAll(d / "comma.csv", "q1,q2,q3,q4,q5,q6,x,y,z\n"
                                        "0,1,0,2,0,3,0,4,0,5,0,6,500,0,300\n"));
  ASSERT_TRUE(WriteAll(d / "dup.csv", "q1,q2,q3,q4,q5,q6,x,y,z,q1\n"
                                      "0.1,0.2,0.3,0.4,0.5,0.6,500,0,300,9\n"));
  for (const char* f : {"comma.csv", "dup.csv"}) {
    ToolOutput r = Compensate(d, "--model=" + Q(kModel) + " --targets=" + f + " --output=o.csv");
    EXPECT_EQ(r.exit_code, kExitInput) << f << "\n" << r.err;
    EXPECT_NE(r.err.find(std::string(f) + ":"), std::string::npos) << r.err;
    r = Predict(d, "--model=" + Q(kModel) + " --joints=" + f + " --output=o.csv");
    EXPECT_EQ(r.exit_code, kExitInput) << f << "\n" << r.err;
    EXPECT_FALSE(Exists(d / "o.csv"));
  }
  ToolOutput r = Compensate(d, "--model=" + Q(kModel) + " --targets=comma.csv --output=o.csv");
  EXPECT_NE(r.err.find("comma.csv:2: the row has 15 fields, the header 9"), std::string::npos)
      << r.err;
  r = Predict(d, "--model=" + Q(kModel) + " --joints=dup.csv --output=o.csv");
  EXPECT_NE(r.err.find("appears twice"), std::string::npos) << r.err;
}

TEST(ToolContract, ShortRowsNameTheMissingColumn) {
  TempDir d;
  ASSERT_TRUE(WriteAll(d / "short.csv", "q1,q2,q3,q4,q5,q6,x,y,z\n"
                                        "0.1,0.2,0.3,0.4,0.5,0.6,500,0,300\n"
                                        "0.1,0.2,0.3,0.4,0.5\n"));
  for (bool compensate : {true, false}) {
    const ToolOutput r =
        compensate ? Compensate(d, "--model=" + Q(kModel) + " --targets=short.csv --output=o.csv")
                   : Predict(d, "--model=" + Q(kModel) + " --joints=short.csv --output=o.csv");
    EXPECT_EQ(r.exit_code, kExitInput) << r.err;
    EXPECT_NE(r.err.find("short.csv:3: the row has 5 fields, no 'q6'"), std::string::npos)
        << r.err;
  }
  ASSERT_TRUE(WriteAll(d / "short2.csv", "q1,q2,q3,q4,q5,q6,x,y,z\n0.1,0.2,0.3,0.4,0.5,0.6,500,0\n"));
  const ToolOutput r = Compensate(d, "--model=" + Q(kModel) + " --targets=short2.csv --output=o.csv");
  EXPECT_NE(r.err.find("short2.csv:2: the row has 8 fields, no 'z'"), std::string::npos) << r.err;
}

TEST(ToolContract, CompensateRangeLimitsAndUnitHint) {
  TempDir d;
  ASSERT_TRUE(WriteAll(d / "seed.csv", "q1,q2,q3,q4,q5,q6,x,y,z\n1e300,0,0,0,0,0,500,0,300\n"));
  ASSERT_TRUE(WriteAll(d / "far.csv", "q1,q2,q3,q4,q5,q6,x,y,z\n0,0,0,0,0,0,1e300,0,300\n"));
  for (const char* f : {"seed.csv", "far.csv"}) {
    const ToolOutput r = Compensate(d, "--model=" + Q(kModel) + " --targets=" + f + " --output=o.csv");
    EXPECT_EQ(r.exit_code, kExitInput) << f << "\n" << r.err;
    EXPECT_NE(r.err.find("magnitude at most"), std::string::npos) << r.err;
    EXPECT_FALSE(Exists(d / "o.csv"));
  }
  // Degrees read as radians: a warning naming --angle_unit=deg.
  ASSERT_TRUE(WriteAll(d / "deg.csv", "q1,q2,q3,q4,q5,q6,x,y,z\n10,-45,90,30,60,-120,500,0,300\n"));
  ToolOutput r = Compensate(d, "--model=" + Q(kModel) + " --targets=deg.csv --output=o.csv");
  EXPECT_EQ(r.exit_code, kExitOk) << r.err;
  EXPECT_NE(r.err.find("--angle_unit=deg"), std::string::npos) << r.err;
  r = Compensate(d, "--model=" + Q(kModel) + " --targets=deg.csv --output=o.csv --angle_unit=deg");
  EXPECT_EQ(r.exit_code, kExitOk) << r.err;
  EXPECT_EQ(r.err.find("--angle_unit=deg"), std::string::npos) << r.err;
  // lpoe_predict gives the same hint.
  r = Predict(d, "--model=" + Q(kModel) + " --joints=deg.csv --output=p.csv");
  EXPECT_EQ(r.exit_code, kExitOk) << r.err;
  EXPECT_NE(r.err.find("--angle_unit=deg"), std::string::npos) << r.err;
  r = Predict(d, "--model=" + Q(kModel) + " --joints=deg.csv --output=p.csv --angle_unit=deg");
  EXPECT_EQ(r.err.find("--angle_unit=deg"), std::string::npos) << r.err;
}

TEST(ToolContract, CompensateRefusesANominalModelOfAnotherRobot) {
  TempDir d;
  RobotModel other;
  ASSERT_TRUE(ReadRobotModel(kModel, &other).ok());
  other.joints[1].type = JointType::kPrismatic;
  other.joints[1].twist = DefaultTwist(JointType::kPrismatic);
  ASSERT_TRUE(WriteRobotModel(d / "prismatic.yaml", other).ok());
  ASSERT_TRUE(WriteAll(d / "t.csv", TargetsCsv()));
  const ToolOutput r = Compensate(d, "--model=" + Q(kModel) + " --targets=t.csv --output=o.csv "
                                      "--nominal=prismatic.yaml");
  EXPECT_EQ(r.exit_code, kExitInput) << r.err;
  EXPECT_NE(r.err.find("joint 2 is prismatic in the nominal model but revolute"), std::string::npos)
      << r.err;
  EXPECT_FALSE(Exists(d / "o.csv"));
}

// ---- Refusals.

TEST(ToolContract, PlanWithoutRedundancyIsRefused) {
  TempDir d;
  // cobot6 with one SMR: 27 parameters, 3 rows per pose. 9 poses: 27 rows, no redundancy.
  ToolOutput r = Plan(d, "--model=" + Q(kModel) + " --count=9 --output=p.csv");
  EXPECT_EQ(r.exit_code, kExitNotIdentifiable) << r.out << r.err;
  EXPECT_NE(r.err.find("cannot check itself"), std::string::npos) << r.err;
  EXPECT_FALSE(Exists(d / "p.csv"));
  EXPECT_FALSE(Exists(d / "p.json"));
  r = Plan(d, "--model=" + Q(kModel) + " --count=10 --output=p.csv");
  EXPECT_EQ(r.exit_code, kExitOk) << r.err;
  // --count=auto on 9 candidates (27 rows at most): refused, not an endless search.
  std::string nine = "q1,q2,q3,q4,q5,q6\n";
  for (int k = 0; k < 9; ++k) {
    for (int j = 0; j < 6; ++j) {
      nine += (j ? "," : "") + std::to_string(0.3 * std::sin(1.7 * k + 2.3 * j + 0.4 * k * j));
    }
    nine += "\n";
  }
  ASSERT_TRUE(WriteAll(d / "nine.csv", nine));
  r = RunInDir(d.path(), "timeout 60 " + std::string(LPOE_PLAN_PATH) +
                             " --model=" + Q(kModel) + " --count=auto --target_accuracy=100 "
                             "--noise_sigma=0.01 --candidates=nine.csv --min_singularity=0 "
                             "--workspace_count=50 --random_draws=2 --output=a.csv");
  EXPECT_EQ(r.exit_code, kExitNotIdentifiable) << r.out << r.err;
  EXPECT_FALSE(Exists(d / "a.csv"));
}

// The same refusal for a data set: 9 points of cobot6 (27 rows for 27 parameters) fit exactly and
// used to pass the verdict with a residual of 1e-13 mm and no standard deviation.
TEST(ToolContract, CalibrationWithoutRedundancyIsRefused) {
  TempDir d;
  const std::string all = ReadAll(kIdentification);
  std::string nine, ten;
  int data_rows = 0;
  size_t start = 0;
  while (start < all.size()) {
    const size_t end = all.find('\n', start);
    const std::string line = all.substr(start, end == std::string::npos ? std::string::npos : end - start + 1);
    start = end == std::string::npos ? all.size() : end + 1;
    const bool data = !line.empty() && line[0] != '#' && line.rfind("q1,", 0) != 0;
    if (data) ++data_rows;
    if (!data || data_rows <= 9) nine += line;
    if (!data || data_rows <= 10) ten += line;
  }
  ASSERT_TRUE(WriteAll(d / "nine.csv", nine));
  ASSERT_TRUE(WriteAll(d / "ten.csv", ten));
  ToolOutput r = Calibrate(d, "--model=" + Q(kModel) + " --measurements=nine.csv --output=cal.yaml");
  EXPECT_EQ(r.exit_code, kExitNotIdentifiable) << r.out << r.err;
  EXPECT_NE((r.out + r.err).find("cannot check itself"), std::string::npos) << r.out << r.err;
  EXPECT_FALSE(Exists(d / "cal.yaml"));
  r = Calibrate(d, "--model=" + Q(kModel) + " --measurements=ten.csv --output=cal.yaml");
  EXPECT_NE(r.exit_code, kExitNotIdentifiable) << r.out << r.err;
  EXPECT_EQ((r.out + r.err).find("cannot check itself"), std::string::npos) << r.out << r.err;
}

// ---- Crashes, lost outputs and silent wrong results.

constexpr int kExitOutput = 6;

// A joint program for cobot6 (its only tool is the flange of program mode).
const char kUrJoints[] =
    "def p():\n  movej([0.1, -1.2, 1.0, 0.3, 0.5, 0.2], a=1.2, v=0.25)\n"
    "  movej([0.2, -1.1, 0.9, 0.2, 0.6, 0.1], a=1.2, v=0.25)\nend\n";
const char kRapidJoints[] =
    "MODULE M\n  CONST jointtarget j1:=[[10,-60,50,20,30,10],[9E9,9E9,9E9,9E9,9E9,9E9]];\n"
    "  PROC main()\n    MoveAbsJ j1, v100, fine, tool0;\n  ENDPROC\nENDMODULE\n";

std::string Models() { return "--model=" + Q(kModel) + " --nominal=" + Q(kModel) + " "; }

// cobot6 with a residual layer of one inducing input (as lpoe_calibrate --residual_model=gp writes
// one, small).
RobotModel WithResidualLayer() {
  RobotModel m;
  EXPECT_TRUE(ReadRobotModel(kModel, &m).ok());
  auto layer = std::make_shared<ResidualLayer>();
  layer->num_joints = m.num_joints();
  layer->num_tools = m.num_tools();
  layer->length_scales = Eigen::VectorXd::Constant(m.num_joints(), 1.0);
  layer->signal_std = 0.02;
  layer->noise_std = 0.01;
  layer->inducing_q = Eigen::MatrixXd::Constant(1, m.num_joints(), 0.2);
  layer->inducing_tool = {0};
  layer->weights = Eigen::MatrixXd::Constant(1, 3, 10.0);
  layer->variance = Eigen::MatrixXd::Constant(1, 1, 100.0);
  layer->fitted_rows = 10;
  EXPECT_TRUE(layer->Validate(m.num_joints(), m.num_tools()).ok());
  m.residual_layer = layer;
  return m;
}

// --output=keep.* --report=/dev/full: exit 6 and keep.* as it was (lpoe_compensate in program and
// targets mode, lpoe_calibrate with its report and HTML page).
TEST(ToolContract, AFailingOutputLeavesEveryOtherOutputAsItWas) {
  if (!Exists("/dev/full")) GTEST_SKIP() << "no /dev/full";
  TempDir d;
  ASSERT_TRUE(WriteAll(d / "in.script", kUrJoints));
  ASSERT_TRUE(WriteAll(d / "keep.script", "keep\n"));
  ToolOutput r = Compensate(d, Models() + "--program=in.script --output=keep.script "
                                          "--report=/dev/full");
  EXPECT_EQ(r.exit_code, kExitOutput) << r.err;
  EXPECT_EQ(ReadAll(d / "keep.script"), "keep\n");
  ASSERT_TRUE(WriteAll(d / "t.csv", TargetsCsv()));
  ASSERT_TRUE(WriteAll(d / "keep.csv", "keep\n"));
  r = Compensate(d, "--model=" + Q(kModel) + " --targets=t.csv --output=keep.csv "
                    "--report=/dev/full");
  EXPECT_EQ(r.exit_code, kExitOutput) << r.err;
  EXPECT_EQ(ReadAll(d / "keep.csv"), "keep\n");
  for (const char* flag : {"--report", "--html_report"}) {
    ASSERT_TRUE(WriteAll(d / "keep.yaml", "keep\n"));
    r = Calibrate(d, "--model=" + Q(kModel) + " --measurements=" + Q(kIdentification) +
                         " --output=keep.yaml --plots_dir= " + flag + "=/dev/full");
    EXPECT_EQ(r.exit_code, kExitOutput) << flag << "\n" << r.out << r.err;
    EXPECT_EQ(ReadAll(d / "keep.yaml"), "keep\n") << flag;
  }
  EXPECT_TRUE(NoStagingLeft(d.path()));
}

// A model with a residual layer and a TCP given by its offset: refused with the reason (the layer
// corrects the measured tools only), never an abort; a measured tool by name works.
TEST(ToolContract, ResidualLayerWithAnOffsetTcpIsRefusedNotAborted) {
  TempDir d;
  ASSERT_TRUE(WriteRobotModel(d / "layer.yaml", WithResidualLayer()).ok());
  ASSERT_TRUE(WriteAll(d / "t.csv", TargetsCsv()));
  ToolOutput r = Compensate(d, "--model=layer.yaml --targets=t.csv --output=o.csv --tcp=0,0,100");
  EXPECT_EQ(r.exit_code, kExitUsage) << r.err;
  EXPECT_NE(r.err.find("residual layer corrects only the tools it was measured with (smr1)"),
            std::string::npos)
      << r.err;
  EXPECT_FALSE(Exists(d / "o.csv"));
  r = Compensate(d, "--model=layer.yaml --targets=t.csv --output=o.csv --tcp=smr1");
  EXPECT_EQ(r.exit_code, kExitOk) << r.err;
}

// inducing_tools with 100,000 entries: an error at that key's line, before any allocation.
TEST(ToolContract, HugeInducingCountIsRefusedAtItsLine) {
  TempDir d;
  ASSERT_TRUE(WriteRobotModel(d / "layer.yaml", WithResidualLayer()).ok());
  std::string text = ReadAll(d / "layer.yaml");
  const size_t at = text.find("  inducing_tools: [");
  ASSERT_NE(at, std::string::npos) << text;
  const size_t end = text.find('\n', at);
  std::string many = "  inducing_tools: [0";
  for (int k = 1; k < 100000; ++k) many += ", 0";
  text.replace(at, end - at, many + "]");
  const int line = 1 + static_cast<int>(std::count(text.begin(), text.begin() + at, '\n'));
  ASSERT_TRUE(WriteAll(d / "many.yaml", text));
  ASSERT_TRUE(WriteAll(d / "j.csv", JointsCsv(2)));
  const ToolOutput r = Predict(d, "--model=many.yaml --joints=j.csv --output=p.csv");
  EXPECT_EQ(r.exit_code, kExitInput) << r.err;
  EXPECT_NE(r.err.find("many.yaml:" + std::to_string(line) +
                       ": 'inducing_tools' has 100000 entries"),
            std::string::npos)
      << r.err;
  EXPECT_FALSE(Exists(d / "p.csv"));
}

// Program mode refuses what targets mode refuses, and says which flag is wrong.
TEST(ToolContract, ProgramModeRefusals) {
  TempDir d;
  ASSERT_TRUE(WriteAll(d / "in.script", kUrJoints));
  ASSERT_TRUE(WriteAll(d / "in.mod", kRapidJoints));
  // A nominal model of another robot (joint 2 prismatic): as --targets refuses it.
  RobotModel other;
  ASSERT_TRUE(ReadRobotModel(kModel, &other).ok());
  other.joints[1].type = JointType::kPrismatic;
  other.joints[1].twist = DefaultTwist(JointType::kPrismatic);
  ASSERT_TRUE(WriteRobotModel(d / "prismatic.yaml", other).ok());
  ToolOutput r = Compensate(d, "--model=" + Q(kModel) +
                                   " --nominal=prismatic.yaml --program=in.script --output=o.script");
  EXPECT_EQ(r.exit_code, kExitInput) << r.err;
  EXPECT_NE(r.err.find("joint 2 is prismatic in the nominal model but revolute"), std::string::npos)
      << r.err;
  EXPECT_FALSE(Exists(d / "o.script"));
  // --language that does not fit the text.
  r = Compensate(d, Models() + "--program=in.script --language=rapid --strict --output=o.mod");
  EXPECT_EQ(r.exit_code, kExitInput) << r.err;
  EXPECT_NE(r.err.find("reads as a urscript program"), std::string::npos) << r.err;
  r = Compensate(d, Models() + "--program=in.mod --language=urscript --output=o.script");
  EXPECT_EQ(r.exit_code, kExitInput) << r.err;
  EXPECT_NE(r.err.find("reads as a rapid program"), std::string::npos) << r.err;
  EXPECT_FALSE(Exists(d / "o.mod") || Exists(d / "o.script"));
  // A robtarget declared twice: an error naming both lines.
  ASSERT_TRUE(WriteAll(d / "twice.mod",
                       "MODULE M\n"
                       "  CONST robtarget p1:=[[400,0,500],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n"
                       "  CONST robtarget p1:=[[400,0,600],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]];\n"
                       "  PROC main()\n    MoveL p1, v100, fine, tool0;\n  ENDPROC\nENDMODULE\n"));
  r = Compensate(d, Models() + "--program=twice.mod --output=o.mod");
  EXPECT_EQ(r.exit_code, kExitInput) << r.err;
  EXPECT_NE(r.err.find("line 3: robtarget p1 is declared twice (first on line 2)"),
            std::string::npos)
      << r.err;
  EXPECT_FALSE(Exists(d / "o.mod"));
  // --quiet: nothing on stderr or stdout in program mode.
  r = Compensate(d, Models() + "--quiet --program=in.script --output=o.script");
  EXPECT_EQ(r.exit_code, kExitOk) << r.err;
  EXPECT_EQ(r.err, "");
  EXPECT_EQ(r.out, "");
  EXPECT_TRUE(Exists(d / "o.script"));
}

// A TCP or length unit that puts the targets out of reach is blamed on --tcp / --length_unit, not
// on --frame.
TEST(ToolContract, CompensateBlamesTheRightFlag) {
  TempDir d;
  ASSERT_TRUE(WriteAll(d / "t.csv", TargetsCsv()));
  ToolOutput r = Compensate(d, "--model=" + Q(kModel) + " --targets=t.csv --output=o.csv "
                                "--tcp=0,0,1e300");
  EXPECT_EQ(r.exit_code, kExitUsage) << r.err;
  EXPECT_NE(r.err.find("--tcp=0,0,1e300"), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("--frame"), std::string::npos) << r.err;
  // Millimetres read as metres: beyond the reader's 1e6 mm (z of 1061 mm) ...
  r = Compensate(d, "--model=" + Q(kModel) + " --targets=t.csv --output=o.csv --length_unit=m");
  EXPECT_EQ(r.exit_code, kExitInput) << r.err;
  EXPECT_NE(r.err.find("--length_unit"), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("--frame"), std::string::npos) << r.err;
  // ... and within it (targets of 300-400 mm read as 300-400 m): hundreds of reaches away.
  ASSERT_TRUE(WriteAll(d / "mm.csv", "q1,q2,q3,q4,q5,q6,x,y,z\n0.1,0.2,0.3,0.4,0.5,0.6,400,100,300\n"
                                     "0.2,0.3,0.4,0.5,0.6,0.7,380,120,320\n"
                                     "0.3,0.4,0.5,0.6,0.7,0.8,360,140,340\n"));
  r = Compensate(d, "--model=" + Q(kModel) + " --targets=mm.csv --output=o.csv --length_unit=m");
  EXPECT_EQ(r.exit_code, kExitInput) << r.err;
  EXPECT_NE(r.err.find("times its reach): their lengths are in another unit"), std::string::npos)
      << r.err;
  EXPECT_NE(r.err.find("--length_unit"), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("--frame"), std::string::npos) << r.err;
  EXPECT_FALSE(Exists(d / "o.csv"));
}

// `fixed: true` on a tool the data never measure identifies nothing: the calibrated model does not
// record it as fixed, and program mode does not report the flange's rotation as identified.
TEST(ToolContract, UnmeasuredFixedToolIsNotReportedAsIdentifyingTheFlange) {
  TempDir d;
  RobotModel nominal;
  ASSERT_TRUE(ReadRobotModel(kModel, &nominal).ok());
  Tool nest;
  nest.name = "nest2";
  nest.origin.t = Eigen::Vector3d(-40, 0, 60);
  nest.fixed = true;
  nominal.tools.push_back(nest);
  ASSERT_TRUE(WriteRobotModel(d / "nominal.yaml", nominal).ok());
  ToolOutput r = RunInDir(d.path(), std::string(LPOE_CALIBRATE_PATH) +
                                        " --model=nominal.yaml --measurements=" +
                                        Q(kIdentification) + " --output=cal.yaml --plots_dir=");
  ASSERT_EQ(r.exit_code, kExitOk) << r.out << r.err;
  EXPECT_NE((r.out + r.err).find("nest2 not measured in these data (recorded as not fixed"),
            std::string::npos)
      << r.out << r.err;
  RobotModel cal;
  ASSERT_TRUE(ReadRobotModel(d / "cal.yaml", &cal).ok());
  ASSERT_EQ(cal.num_tools(), 2);
  EXPECT_FALSE(cal.tools[1].fixed);
  EXPECT_FALSE(cal.HasFixedTool());
  ASSERT_TRUE(WriteAll(d / "in.script", kUrJoints));
  r = Compensate(d, "--model=cal.yaml --nominal=nominal.yaml --flange=smr1 --program=in.script "
                    "--output=o.script --report=o.json");
  ASSERT_EQ(r.exit_code, kExitOk) << r.err;
  nlohmann::json report = nlohmann::json::parse(ReadAll(d / "o.json"), nullptr, false);
  ASSERT_FALSE(report.is_discarded());
  EXPECT_EQ(report["flange_rotation_identified"], false);
}

// --targets_only on a name of 100,000 characters (std::regex recursed per character and
// crashed), and a pattern that backtracks exponentially in std::regex: RE2 is linear in both.
TEST(ToolContract, TargetsOnlyOnLongNamesAndPathologicalPatterns) {
  TempDir d;
  const std::string name = "Waypoint_" + std::string(100000, 'a');
  ASSERT_TRUE(WriteAll(d / "long.script",
                       "def p():\n  global " + name + "=[0.1, -1.2, 1.0, 0.3, 0.5, 0.2]\n  movej(" +
                           name + ")\nend\n"));
  ToolOutput r = Compensate(d, Models() + "--program=long.script --output=o.script "
                                          "--report=o.json --targets_only='Waypoint_.*'");
  EXPECT_EQ(r.exit_code, kExitOk) << r.err.substr(0, 2000);
  nlohmann::json report = nlohmann::json::parse(ReadAll(d / "o.json"), nullptr, false);
  ASSERT_FALSE(report.is_discarded());
  EXPECT_EQ(report["rows"][0]["status"], "compensated");
  r = Compensate(d, Models() + "--program=long.script --output=o.script --report=o.json "
                               "--targets_only='(a|a)*b'");
  EXPECT_EQ(r.exit_code, kExitOk) << r.err.substr(0, 2000);
  report = nlohmann::json::parse(ReadAll(d / "o.json"), nullptr, false);
  EXPECT_EQ(report["rows"][0]["status"], "not_selected");
  // What RE2 cannot run (a backreference) is refused as a bad flag, naming it.
  r = Compensate(d, Models() + "--program=long.script --output=x.script --targets_only='(a)\\1'");
  EXPECT_EQ(r.exit_code, kExitUsage) << r.err;
  EXPECT_NE(r.err.find("--targets_only"), std::string::npos) << r.err;
  EXPECT_FALSE(Exists(d / "x.script"));
}

}  // namespace tool_contract_test
}  // namespace
}  // namespace lpoe
