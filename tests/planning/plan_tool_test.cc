// End-to-end tests of lpoe_plan: exit codes of bad flags and inputs, the plan CSV (sampled and from a
// candidate file, with its candidate_row column), the JSON report, --count=auto, and that
// lpoe_simulate --joints measures at the planned poses.
#include <sys/wait.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "file_util.h"
#include "lpoe/io/io.h"
#include "lpoe/kinematics/kinematics.h"

#ifndef LPOE_PLAN_PATH
#error "LPOE_PLAN_PATH must name the lpoe_plan binary"
#endif
#ifndef LPOE_SIMULATE_PATH
#error "LPOE_SIMULATE_PATH must name the lpoe_simulate binary"
#endif

namespace {
namespace plan_tool_test {

namespace fs = std::filesystem;

constexpr int kExitOk = 0;
constexpr int kExitUsage = 1;
constexpr int kExitInput = 2;
constexpr int kExitNoPlan = 3;

using Output = lpoe::testing::ToolOutput;
using lpoe::testing::ReadAll;
using lpoe::testing::RunInDir;
using lpoe::testing::ShellQuote;

std::vector<std::string> DataLines(const std::string& text) {
  std::vector<std::string> lines;
  std::stringstream ss(text);
  std::string line;
  while (std::getline(ss, line)) {
    if (!line.empty() && line[0] != '#') lines.push_back(line);
  }
  return lines;
}

// Three SMRs on cobot6 (the frames of docs/conventions.md); joint 2 limited.
constexpr char kModel[] = R"(name: cobot6_3smr
joints:
  - {name: joint1, type: revolute, origin: {xyz: [0, 0, 96], rpy: [0, 0, 0]}}
  - {name: joint2, type: revolute, origin: {xyz: [0, 138, 0], rpy: [-1.5707963267948966, 0, 0]}}
  - {name: joint3, type: revolute, origin: {xyz: [0, -418, -114], rpy: [0, 0, 0]}}
  - {name: joint4, type: revolute, origin: {xyz: [0, -398, 98], rpy: [0, 0, 0]}}
  - {name: joint5, type: revolute, origin: {xyz: [0, -98, 0], rpy: [1.5707963267948966, 0, 0]}}
  - {name: joint6, type: revolute, origin: {xyz: [0, 89, 0], rpy: [-1.5707963267948966, 0, 0]}}
tools:
  - {name: smr1, origin: {xyz: [40, 0, 60], rpy: [0, 0, 0]}}
  - {name: smr2, origin: {xyz: [-30, 35, 55], rpy: [0, 0, 0]}}
  - {name: smr3, origin: {xyz: [-25, -45, 50], rpy: [0, 0, 0]}}
)";

class PlanTool : public ::testing::Test {
 protected:
  void SetUp() override { std::ofstream(dir_ / "m.yaml") << kModel; }
  Output Run(const std::string& binary, const std::string& args) {
    return RunInDir(dir_.string(), ShellQuote(binary) + " " + args);
  }
  Output Plan(const std::string& args) {
    return Run(LPOE_PLAN_PATH, "--model=m.yaml --candidate_count=800 --workspace_count=200 " + args);
  }
  lpoe::testing::TempDir temp_{"lpoe_plan_test"};
  fs::path dir_ = temp_.path();
};

TEST_F(PlanTool, BadFlagsAreUsageErrors) {
  for (const char* args :
       {"--count=0 --output=p.csv", "--count=x --output=p.csv", "--count=10",
        "--count=10 --output=p.csv --criterion=Z", "--count=10 --output=p.csv --angle_unit=grad",
        "--count=auto --output=p.csv", "--count=auto --output=p.csv --target_accuracy=0.01",
        "--count=10 --output=p.csv --tracker=1,2", "--count=10 --output=p.csv --max_range=5000",
        "--count=10 --output=p.csv --tracker=0,2000,500 --acceptance_angle=120",
        "--count=10 --output=p.csv --tracker=0,2000,500 --smr_facing='0,0,1;0,0,1'",
        "--count=10 --output=p.csv --min_singularity=-1",
        "--count=10 --output=p.csv --joint_errors=backlash",
        "--count=10 --output=p.csv --joint_errors=compliance,compliance"}) {
    const Output o = Plan(args);
    EXPECT_EQ(o.exit_code, kExitUsage) << args << "\n" << o.err;
    EXPECT_NE(o.err.find("error:"), std::string::npos) << args;
    EXPECT_FALSE(fs::exists(dir_ / "p.csv")) << args;
  }
}

TEST_F(PlanTool, HelpListsTheFlagsAndExitCodes) {
  const Output o = Run(LPOE_PLAN_PATH, "--help");
  EXPECT_EQ(o.exit_code, kExitOk);
  for (const char* flag : {"--count", "--candidates", "--criterion", "--tracker", "--smr_facing",
                           "--min_singularity", "--target_accuracy", "--joint_errors",
                           "Exit codes"}) {
    EXPECT_NE(o.out.find(flag), std::string::npos) << flag;
  }
}

TEST_F(PlanTool, BadInputsAreInputErrors) {
  Output o = Plan("--count=10 --output=p.csv --model=missing.yaml");
  EXPECT_EQ(o.exit_code, kExitInput) << o.err;
  std::ofstream(dir_ / "c.csv") << "q1,q2,q3,q4,q5\n0,0,0,0,0\n";
  o = Plan("--count=10 --output=p.csv --candidates=c.csv");
  EXPECT_EQ(o.exit_code, kExitInput) << o.err;
  EXPECT_NE(o.err.find("c.csv:1: missing column 'q6'"), std::string::npos) << o.err;
  std::ofstream(dir_ / "c.csv") << "q1,q2,q3,q4,q5,q6\n0,0,0,zero,0,0\n";
  o = Plan("--count=10 --output=p.csv --candidates=c.csv");
  EXPECT_EQ(o.exit_code, kExitInput) << o.err;
  EXPECT_NE(o.err.find("c.csv:2: column 'q4'"), std::string::npos) << o.err;
  // A prismatic joint without limits cannot be sampled.
  std::string model = kModel;
  model.replace(model.find("type: revolute"), 14, "type: prismatic");
  std::ofstream(dir_ / "m.yaml") << model;
  o = Plan("--count=10 --output=p.csv");
  EXPECT_EQ(o.exit_code, kExitInput) << o.err;
  EXPECT_NE(o.err.find("prismatic joint 'joint1' has no limits"), std::string::npos) << o.err;
}

TEST_F(PlanTool, SampledPlanIsReadBySimulateAndBeatsTheRandomPlan) {
  const Output o = Plan("--count=20 --output=p.csv --angle_unit=deg --noise_sigma=0.02");
  ASSERT_EQ(o.exit_code, kExitOk) << o.err;
  const std::vector<std::string> lines = DataLines(ReadAll(dir_ / "p.csv"));
  ASSERT_EQ(lines.size(), 21u);
  EXPECT_EQ(lines[0], "q1,q2,q3,q4,q5,q6");
  const nlohmann::json report = nlohmann::json::parse(ReadAll(dir_ / "p.json"));
  EXPECT_EQ(report["count"], 20);
  EXPECT_EQ(report["criterion"], "D");
  EXPECT_EQ(report["plan"]["rank"], 33);
  const double plan = report["plan"]["predicted_rms_per_unit_noise"];
  const double random = report["random_plan"]["predicted_rms_per_unit_noise"];
  EXPECT_LT(plan, random);
  EXPECT_NEAR(report["plan"]["predicted_rms_mm"].get<double>(), 0.02 * plan, 1e-12);
  EXPECT_GT(report["plan"]["condition_number"].get<double>(), 1.0);
  // lpoe_simulate measures every SMR at each planned pose (degrees read back as degrees).
  const Output s = Run(LPOE_SIMULATE_PATH,
                       "--model=m.yaml --errors=random --joints=p.csv --angle_unit=deg --all_tools "
                       "--output=sim.csv");
  ASSERT_EQ(s.exit_code, kExitOk) << s.err;
  const std::vector<std::string> sim = DataLines(ReadAll(dir_ / "sim.csv"));
  ASSERT_EQ(sim.size(), 1u + 20 * 3);
  // Same joint values (written with 17 digits by the simulator, shortest form by the planner).
  std::stringstream a(lines[1]), b(sim[1]);
  for (int j = 0; j < 6; ++j) {
    std::string fa, fb;
    std::getline(a, fa, ',');
    std::getline(b, fb, ',');
    EXPECT_DOUBLE_EQ(std::stod(fa), std::stod(fb)) << j;
  }
}

TEST_F(PlanTool, CandidateRowsAreCopiedWithTheirIndex) {
  // 300 candidate rows with an extra column that must survive, angles in degrees.
  std::ofstream c(dir_ / "cand.csv");
  c << "# reachable poses\nlabel,q1,q2,q3,q4,q5,q6\n";
  unsigned state = 7;
  auto next = [&state]() {
    state = state * 1103515245u + 12345u;
    return static_cast<int>((state >> 8) % 340) - 170;
  };
  for (int r = 0; r < 300; ++r) {
    c << "pose" << r;
    for (int j = 0; j < 6; ++j) c << "," << next();
    c << "\n";
  }
  c.close();
  const Output o = Plan("--count=12 --output=p.csv --candidates=cand.csv --angle_unit=deg");
  ASSERT_EQ(o.exit_code, kExitOk) << o.err;
  const std::string cand = ReadAll(dir_ / "cand.csv");
  const std::vector<std::string> cand_lines = DataLines(cand);
  const std::vector<std::string> lines = DataLines(ReadAll(dir_ / "p.csv"));
  ASSERT_EQ(lines.size(), 13u);
  EXPECT_EQ(lines[0], "label,q1,q2,q3,q4,q5,q6,candidate_row");
  for (size_t k = 1; k < lines.size(); ++k) {
    const size_t comma = lines[k].find_last_of(',');
    const int row = std::stoi(lines[k].substr(comma + 1));
    ASSERT_GE(row, 0);
    ASSERT_LT(row, 300);
    EXPECT_EQ(lines[k].substr(0, comma), cand_lines[1 + row]);
    EXPECT_EQ(lines[k].substr(0, lines[k].find(',')), "pose" + std::to_string(row));
  }
  // Planning again from the plan is refused (it already has candidate_row).
  const Output again = Plan("--count=5 --output=q.csv --candidates=p.csv --angle_unit=deg");
  EXPECT_EQ(again.exit_code, kExitInput) << again.err;
}

TEST_F(PlanTool, CountAutoReturnsTheSmallestPlanReachingTheTarget) {
  // Per unit noise a random-pose plan of ~40 poses reaches ~0.55; aim at 0.011 mm with 0.02 mm noise.
  const Output o =
      Plan("--count=auto --target_accuracy=0.011 --noise_sigma=0.02 --output=p.csv --report=r.json");
  ASSERT_EQ(o.exit_code, kExitOk) << o.err;
  const nlohmann::json report = nlohmann::json::parse(ReadAll(dir_ / "r.json"));
  const int n = report["count"];
  EXPECT_LE(report["plan"]["predicted_rms_mm"].get<double>(), 0.011);
  // One pose fewer of the same criterion does not reach it (--count=auto makes no exchange on the
  // unmodelled error's prediction, so neither does the comparison: --unmodelled_error=0).
  const Output fewer = Plan("--count=" + std::to_string(n - 1) +
                            " --noise_sigma=0.02 --unmodelled_error=0 --output=f.csv");
  ASSERT_EQ(fewer.exit_code, kExitOk) << fewer.err;
  const nlohmann::json f = nlohmann::json::parse(ReadAll(dir_ / "f.json"));
  EXPECT_GT(f["plan"]["predicted_rms_mm"].get<double>(), 0.011);
  // Out of reach.
  const Output never = Plan("--count=auto --target_accuracy=0.0001 --noise_sigma=0.02 --output=n.csv");
  EXPECT_EQ(never.exit_code, kExitNoPlan) << never.err;
  EXPECT_FALSE(fs::exists(dir_ / "n.csv"));
}

// With joint-space error terms the plan must determine their identifiable combinations too: more
// parameters, and a prediction that includes their uncertainty (larger than the geometric one for
// the same number of poses). 'auto' plans for every term.
TEST_F(PlanTool, JointErrorTermsJoinThePlannedParameters) {
  // The parameters and the criterion are what this test is about, not the exchange on an
  // unmodelled error (PlanningStandIn, PlanningUnmodelled): --unmodelled_error=0 throughout.
  const Output o =
      Plan("--count=30 --output=p.csv --joint_errors=harmonics,compliance --unmodelled_error=0");
  ASSERT_EQ(o.exit_code, kExitOk) << o.err;
  const nlohmann::json report = nlohmann::json::parse(ReadAll(dir_ / "p.json"));
  ASSERT_EQ(report["joint_errors"].size(), 2u);
  EXPECT_EQ(report["joint_errors"][0]["term"], "compliance");  // compliance first, as calibrated
  EXPECT_EQ(report["joint_errors"][1]["term"], "harmonics");
  int combinations = 0;
  for (const auto& t : report["joint_errors"]) {
    EXPECT_GT(t["identifiable_combinations"].get<int>(), 0);
    EXPECT_LT(t["identifiable_combinations"].get<int>(), t["parameters"].get<int>());
    combinations += t["identifiable_combinations"].get<int>();
  }
  EXPECT_EQ(report["parameters"].get<int>(), 33 + combinations);
  EXPECT_EQ(report["plan"]["rank"], report["parameters"]);
  const double with_terms = report["plan"]["predicted_rms_per_unit_noise"];
  EXPECT_LT(with_terms, report["random_plan"]["predicted_rms_per_unit_noise"].get<double>());
  EXPECT_NE(ReadAll(dir_ / "p.csv").find("joint errors compliance,harmonics"), std::string::npos);

  const Output g = Plan("--count=30 --output=g.csv --unmodelled_error=0");
  ASSERT_EQ(g.exit_code, kExitOk) << g.err;
  const nlohmann::json geometric = nlohmann::json::parse(ReadAll(dir_ / "g.json"));
  EXPECT_TRUE(geometric["joint_errors"].empty());
  EXPECT_GT(with_terms, geometric["plan"]["predicted_rms_per_unit_noise"].get<double>());

  const Output a = Plan("--count=30 --output=a.csv --joint_errors=auto --unmodelled_error=0");
  ASSERT_EQ(a.exit_code, kExitOk) << a.err;
  const nlohmann::json automatic = nlohmann::json::parse(ReadAll(dir_ / "a.json"));
  // auto plans for every registry term (compliance and harmonics first, then the others), each
  // adding its identifiable combinations.
  ASSERT_GE(automatic["joint_errors"].size(), 2u);
  EXPECT_EQ(automatic["joint_errors"][0], report["joint_errors"][0]);
  EXPECT_EQ(automatic["joint_errors"][1], report["joint_errors"][1]);
  int all_combinations = 0;
  for (const auto& t : automatic["joint_errors"]) {
    all_combinations += t["identifiable_combinations"].get<int>();
  }
  EXPECT_EQ(automatic["parameters"].get<int>(), 33 + all_combinations);
  EXPECT_GE(automatic["parameters"].get<int>(), report["parameters"].get<int>());
  // Too few poses for the 80-odd parameters: refused.
  const Output few = Plan("--count=8 --output=f.csv --joint_errors=compliance,harmonics");
  EXPECT_EQ(few.exit_code, kExitNoPlan) << few.err;
  EXPECT_NE(few.err.find("identifies only"), std::string::npos) << few.err;
}

// --joint_errors with the gravity tilt: refused with the reason for a nominal model (no compliance
// values: the tilt's information is zero) and without compliance in the list; accepted for a model
// that carries compliance values (lpoe_simulate's actual robot here; a calibrated model's YAML in
// practice), with the tilt's two parameters and its predicted standard deviations in the report.
TEST_F(PlanTool, GravityTiltNeedsAModelWithComplianceValues) {
  const Output nominal = Plan("--count=40 --output=t.csv --joint_errors=compliance,tilt");
  EXPECT_EQ(nominal.exit_code, kExitUsage) << nominal.err;
  EXPECT_NE(nominal.err.find("--joint_errors=compliance,tilt"), std::string::npos) << nominal.err;
  EXPECT_NE(nominal.err.find("carries no compliance values"), std::string::npos) << nominal.err;
  EXPECT_FALSE(fs::exists(dir_ / "t.csv"));
  const Output alone = Plan("--count=40 --output=t.csv --joint_errors=harmonics,tilt");
  EXPECT_EQ(alone.exit_code, kExitUsage) << alone.err;
  EXPECT_NE(alone.err.find("needs it in the list"), std::string::npos) << alone.err;

  const Output sim = Run(LPOE_SIMULATE_PATH, "--model=m.yaml --errors=none --joint_errors=compliance "
                                             "--payload_mass=1 --count=10 --output=s.csv "
                                             "--actual_out=actual.yaml");
  ASSERT_EQ(sim.exit_code, kExitOk) << sim.err;
  // The tilt's columns are what this test is about, not the exchange on an unmodelled error
  // (planning_test's PlanningStandIn): without it the plan is the criterion's.
  const std::string common = "--model=actual.yaml --candidate_count=800 --workspace_count=200 "
                             "--count=60 --noise_sigma=0.01 --unmodelled_error=0 ";
  const Output without = Run(LPOE_PLAN_PATH, common + "--output=c.csv --joint_errors=compliance");
  ASSERT_EQ(without.exit_code, kExitOk) << without.err;
  const Output with = Run(LPOE_PLAN_PATH, common + "--output=t.csv --joint_errors=compliance,tilt");
  ASSERT_EQ(with.exit_code, kExitOk) << with.err;
  EXPECT_NE(with.out.find("gravity tilt 2"), std::string::npos) << with.out;
  const nlohmann::json c = nlohmann::json::parse(ReadAll(dir_ / "c.json"));
  const nlohmann::json t = nlohmann::json::parse(ReadAll(dir_ / "t.json"));
  EXPECT_EQ(t["parameters"].get<int>(), c["parameters"].get<int>() + 2);
  EXPECT_EQ(t["plan"]["rank"], t["parameters"]);
  ASSERT_EQ(t["joint_errors"].size(), 2u);
  EXPECT_EQ(t["joint_errors"][1]["term"], "tilt");
  EXPECT_EQ(t["joint_errors"][1]["parameters"], 2);
  ASSERT_TRUE(t["gravity_tilt"]["planned"].get<bool>()) << t.dump();
  EXPECT_FALSE(c["gravity_tilt"]["planned"].get<bool>());
  for (int a = 0; a < 2; ++a) {
    const double sd = t["gravity_tilt"]["predicted_std_dev_deg"][a].get<double>();
    EXPECT_GT(sd, 0);
    EXPECT_LT(sd, 10);  // degrees: determined, if loosely with 60 poses of light links
    EXPECT_NEAR(sd, 0.01 * t["gravity_tilt"]["predicted_std_dev_deg_per_unit_noise"][a].get<double>(),
                1e-12 * sd);
  }
  EXPECT_NE(ReadAll(dir_ / "t.csv").find("joint errors compliance,tilt"), std::string::npos);
  // auto plans for the tilt too when the model carries compliance values, and says why not when not.
  const Output a = Run(LPOE_PLAN_PATH, common + "--output=a.csv --joint_errors=auto");
  ASSERT_EQ(a.exit_code, kExitOk) << a.err;
  EXPECT_TRUE(nlohmann::json::parse(ReadAll(dir_ / "a.json"))["gravity_tilt"]["planned"].get<bool>());
  const Output an = Plan("--count=40 --output=an.csv --joint_errors=auto --unmodelled_error=0");
  ASSERT_EQ(an.exit_code, kExitOk) << an.err;
  const nlohmann::json jn = nlohmann::json::parse(ReadAll(dir_ / "an.json"));
  EXPECT_FALSE(jn["gravity_tilt"]["planned"].get<bool>());
  EXPECT_NE(jn["gravity_tilt"]["note"].get<std::string>().find("no compliance values"),
            std::string::npos);
}

TEST_F(PlanTool, TrackerConstraintKeepsOnlyVisiblePoses) {
  const Output o = Plan("--count=15 --output=p.csv --tracker=0,2500,600 --max_range=4000");
  ASSERT_EQ(o.exit_code, kExitOk) << o.err;
  const nlohmann::json report = nlohmann::json::parse(ReadAll(dir_ / "p.json"));
  EXPECT_GT(report["candidates"]["nothing_visible"].get<int>(), 100);
  EXPECT_LT(report["plan"]["rows"].get<int>(), 15 * 9 + 1);
  EXPECT_EQ(report["plan"]["rank"], 33);
}

// The planned poses as joint vectors (the first n fields of each data line).
std::vector<std::vector<double>> PlannedPoses(const std::string& csv, int n) {
  std::vector<std::vector<double>> out;
  for (const std::string& line : DataLines(csv)) {
    if (line.rfind("q1", 0) == 0) continue;  // the header
    std::stringstream ss(line);
    std::vector<double> q;
    std::string field;
    for (int j = 0; j < n && std::getline(ss, field, ','); ++j) q.push_back(std::stod(field));
    out.push_back(q);
  }
  return out;
}

// Joint i's origin in the base frame at q: the model cut after joint i - 1 with a tool there.
Eigen::Vector3d JointOrigin(const lpoe::RobotModel& model, const std::vector<double>& q, int i) {
  lpoe::RobotModel cut = model;
  cut.joints.resize(i);
  cut.tools = {lpoe::Tool{"origin", model.joints[i].origin}};
  return lpoe::ToolPosition(cut, q.data(), 0);
}

// --prior (docs/recalibration.md): a calibrated model with its covariance block; the plan starts
// from its information, so 2 poses (18 rows for 33 parameters) plan where the model alone is
// refused; --prior_free names frames of the prior's model; the report records the prior.
TEST_F(PlanTool, PriorPlansWhatItLeavesOpen) {
  std::string block = "covariance:\n  models: 1\n  data_sigma: 0.02\n  frames:\n";
  for (const char* frame : {"joint2", "joint3", "joint4", "joint5", "joint6", "smr1", "smr2",
                            "smr3"}) {
    // 0.05 mrad and 0.01 mm (standard deviations) in every direction.
    std::string m;
    for (int i = 0; i < 6; ++i) {
      for (int j = 0; j < 6; ++j) {
        m += (m.empty() ? "" : ", ") + std::string(i != j ? "0" : i < 3 ? "2.5e-9" : "1e-4");
      }
    }
    block += std::string("    - {name: ") + frame + ", matrix: [" + m + "]}\n";
  }
  std::ofstream(dir_ / "prior.yaml") << kModel << block;
  Output o = Run(LPOE_PLAN_PATH, "--prior=prior.yaml --count=2 --output=p.csv "
                                 "--candidate_count=400 --workspace_count=100 --prior_free=joint5");
  ASSERT_EQ(o.exit_code, kExitOk) << o.err;
  EXPECT_NE(o.out.find("prior: prior.yaml"), std::string::npos) << o.out;
  EXPECT_NE(o.out.find("freed: joint5"), std::string::npos) << o.out;
  EXPECT_EQ(DataLines(ReadAll((dir_ / "p.csv").string())).size(), 3u);  // header and 2 poses
  const nlohmann::json report = nlohmann::json::parse(ReadAll((dir_ / "p.json").string()));
  EXPECT_EQ(report["prior"]["file"], "prior.yaml");
  EXPECT_EQ(report["prior"]["freed"][0], "joint5");
  // Without the prior the same 2 poses cannot identify the model: refused.
  o = Plan("--count=2 --output=q.csv --candidate_count=400 --workspace_count=100");
  EXPECT_EQ(o.exit_code, kExitNoPlan) << o.err;
  // A frame the prior's model does not have, and --prior_free without --prior: usage errors.
  o = Run(LPOE_PLAN_PATH, "--prior=prior.yaml --count=2 --output=r.csv --prior_free=joint9");
  EXPECT_EQ(o.exit_code, kExitUsage) << o.err;
  EXPECT_NE(o.err.find("'joint9' is no joint or tool"), std::string::npos) << o.err;
  o = Plan("--count=2 --output=r.csv --prior_free=joint5");
  EXPECT_EQ(o.exit_code, kExitUsage) << o.err;
  EXPECT_FALSE(fs::exists(dir_ / "r.csv"));
  // A model file without the block is not a prior: an input error naming it.
  o = Run(LPOE_PLAN_PATH, "--prior=m.yaml --count=2 --output=r.csv");
  EXPECT_EQ(o.exit_code, kExitInput) << o.err;
  EXPECT_NE(o.err.find("no covariance block"), std::string::npos) << o.err;
}

TEST_F(PlanTool, CellConstraintsKeepEveryPlannedPoseInTheCell) {
  std::ofstream(dir_ / "keep_out.csv") << "# the controller cabinet\n"
                                       << "300, -800, -200, 1200, -300, 900\n";
  const Output o = Plan("--count=30 --output=p.csv --min_z=50 "
                        "--box=-1100,-1100,-500,1100,1100,1400 --keep_out=keep_out.csv "
                        "--joint_ranges=,-2.5:-0.5,,,,");
  ASSERT_EQ(o.exit_code, kExitOk) << o.err;
  const nlohmann::json report = nlohmann::json::parse(ReadAll(dir_ / "p.json"));
  EXPECT_GT(report["candidates"]["outside_cell"].get<int>(), 50);  // not vacuous
  lpoe::RobotModel model;
  ASSERT_TRUE(lpoe::ReadRobotModel((dir_ / "m.yaml").string(), &model).ok());
  const auto poses = PlannedPoses(ReadAll(dir_ / "p.csv"), model.num_joints());
  ASSERT_EQ(poses.size(), 30u);
  const Eigen::AlignedBox3d box(Eigen::Vector3d(-1100, -1100, -500),
                                Eigen::Vector3d(1100, 1100, 1400));
  const Eigen::AlignedBox3d cabinet(Eigen::Vector3d(300, -800, -200),
                                    Eigen::Vector3d(1200, -300, 900));
  for (const auto& q : poses) {
    EXPECT_GE(q[1], -2.5 - 1e-9);
    EXPECT_LE(q[1], -0.5 + 1e-9);
    for (int i = 1; i < model.num_joints(); ++i) {
      const Eigen::Vector3d p = JointOrigin(model, q, i);
      EXPECT_GE(p.z(), 50 - 1e-6) << "joint " << i + 1;
      EXPECT_FALSE(cabinet.contains(p)) << "joint " << i + 1;
    }
    for (int t = 0; t < model.num_tools(); ++t) {
      const Eigen::Vector3d p = lpoe::ToolPosition(model, q.data(), t);
      EXPECT_GE(p.z(), 50 - 1e-6);
      EXPECT_TRUE(box.contains(p));
      EXPECT_FALSE(cabinet.contains(p));
    }
  }
}

TEST_F(PlanTool, CellFlagsAreCheckedBeforeAnyWork) {
  std::ofstream(dir_ / "bad.csv") << "0,0,0,1,1,1\n0,0,0,1,1\n";
  for (const char* args : {"--count=10 --output=p.csv --box=1,2,3",
                           "--count=10 --output=p.csv --box=0,0,0,-1,1,1",
                           "--count=10 --output=p.csv --joint_ranges=0:1",
                           "--count=10 --output=p.csv --joint_ranges=,1:0,,,,"}) {
    const Output o = Plan(args);
    EXPECT_EQ(o.exit_code, kExitUsage) << args << "\n" << o.err;
    EXPECT_FALSE(fs::exists(dir_ / "p.csv")) << args;
  }
  const Output o = Plan("--count=10 --output=p.csv --keep_out=bad.csv");
  EXPECT_EQ(o.exit_code, kExitInput) << o.err;
  EXPECT_NE(o.err.find("bad.csv:2:"), std::string::npos) << o.err;
}

TEST_F(PlanTool, TrackerPlanListsTheVisibleSmrsOfEachPose) {
  const Output o = Plan("--count=15 --output=p.csv --tracker=0,2500,600 --max_range=4000");
  ASSERT_EQ(o.exit_code, kExitOk) << o.err;
  const std::string csv = ReadAll(dir_ / "p.csv");
  EXPECT_NE(csv.find("# measure the SMRs of the visible column"), std::string::npos);
  const std::vector<std::string> lines = DataLines(csv);
  ASSERT_EQ(lines.size(), 16u);
  EXPECT_EQ(lines[0], "q1,q2,q3,q4,q5,q6,visible");
  int listed = 0;
  for (size_t k = 1; k < lines.size(); ++k) {
    const std::string names = lines[k].substr(lines[k].rfind(',') + 1);
    EXPECT_FALSE(names.empty()) << lines[k];
    std::stringstream ss(names);
    for (std::string name; std::getline(ss, name, ';');) {
      EXPECT_TRUE(name == "smr1" || name == "smr2" || name == "smr3") << name;
      ++listed;
    }
  }
  // The rows the report counts are the SMRs listed.
  const nlohmann::json report = nlohmann::json::parse(ReadAll(dir_ / "p.json"));
  EXPECT_EQ(3 * listed, report["plan"]["rows"].get<int>());
}

}  // namespace plan_tool_test
}  // namespace
