// Tests of the file formats (docs/file_formats.md): YAML robot models and CSV measurements, their
// round trips, and the error messages on malformed input (tests/data/bad/, listed in MANIFEST).
#include "lpoe/io/io.h"

#include <gtest/gtest.h>
#include <stdlib.h>
#include <unistd.h>

#include <sys/stat.h>

#include <charconv>
#include <cstring>
#include <limits>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "lpoe/io/csv_rules.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/measurements/measurements.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/kinematics/se3.h"
#include "io/parse_util.h"

namespace lpoe {
namespace {
namespace io_test {

namespace fs = std::filesystem;

// docs/file_formats.md: a written model reproduces forward kinematics to this after a round trip.
constexpr double kRoundTripToleranceMm = 1e-9;
// Rotations go through a quaternion written exactly (shortest round-trip digits): a few ulps.
constexpr double kRotationRoundTripTolerance = 1e-14;
// rpy and quaternion spellings of one rotation, both written with 17 digits by the test.
constexpr double kRpyQuaternionTolerance = 1e-14;
constexpr int kRandomConfigurations = 200;
constexpr double kPrismaticRangeMm = 200.0;
constexpr int kMinBadFiles = 20;

const std::string kBadDir = std::string(LPOE_TEST_DATA_DIR) + "/bad";

std::vector<double> RandomQ(const RobotModel& model, std::mt19937* rng) {
  std::uniform_real_distribution<double> angle(-M_PI, M_PI);
  std::uniform_real_distribution<double> slide(-kPrismaticRangeMm, kPrismaticRangeMm);
  std::vector<double> q(model.num_joints());
  for (int j = 0; j < model.num_joints(); ++j) {
    q[j] = model.joints[j].type == JointType::kPrismatic ? slide(*rng) : angle(*rng);
  }
  return q;
}

// cobot6 with joint 3 made prismatic along a tilted direction, joint 1 turning about a tilted axis
// that does not pass through its frame origin, and a second, rotated tool whose name needs quoting.
RobotModel MakeModelWithPrismaticAndTiltedTwist() {
  RobotModel m = MakeCobot6();
  m.name = "cobot6 variant";
  m.joints[2].type = JointType::kPrismatic;
  m.joints[2].twist << 0, 0, 0, 0.6, 0, 0.8;
  const Eigen::Vector3d omega(0, std::sin(0.01), std::cos(0.01));
  const Eigen::Vector3d point(5, -3, 0);
  m.joints[0].twist.head<3>() = omega;
  m.joints[0].twist.tail<3>() = -omega.cross(point);
  m.tools.push_back(Tool{"smr #2: side", SE3d(RotationFromRpy(0.3, -1.2, 2.9),
                                              Eigen::Vector3d(10.5, -20.25, 30.125))});
  return m;
}

void ExpectSameKinematics(const RobotModel& expected, const RobotModel& actual, unsigned seed) {
  ASSERT_EQ(expected.num_joints(), actual.num_joints());
  ASSERT_EQ(expected.num_tools(), actual.num_tools());
  EXPECT_EQ(expected.name, actual.name);
  for (int j = 0; j < expected.num_joints(); ++j) {
    EXPECT_EQ(expected.joints[j].name, actual.joints[j].name);
    EXPECT_EQ(expected.joints[j].type, actual.joints[j].type);
    EXPECT_EQ(expected.joints[j].twist, actual.joints[j].twist) << "joint " << j;
    EXPECT_EQ(expected.joints[j].origin.t, actual.joints[j].origin.t) << "joint " << j;
    EXPECT_LE((expected.joints[j].origin.R - actual.joints[j].origin.R).norm(),
              kRotationRoundTripTolerance);
  }
  std::mt19937 rng(seed);
  double worst_mm = 0;
  for (int k = 0; k < kRandomConfigurations; ++k) {
    const std::vector<double> q = RandomQ(expected, &rng);
    for (int t = 0; t < expected.num_tools(); ++t) {
      EXPECT_EQ(expected.tools[t].name, actual.tools[t].name);
      const SE3d a = ToolPose(expected, q.data(), t);
      const SE3d b = ToolPose(actual, q.data(), t);
      worst_mm = std::max(worst_mm, (a.t - b.t).norm());
      EXPECT_LE((a.R - b.R).norm(), kRotationRoundTripTolerance);
    }
  }
  EXPECT_LE(worst_mm, kRoundTripToleranceMm);
}

// A scratch directory, removed at the end of the test.
class ScratchDir {
 public:
  ScratchDir() {
    std::string tmpl = (fs::temp_directory_path() / "lpoe_io_test.XXXXXX").string();
    if (::mkdtemp(&tmpl[0]) != nullptr) path_ = tmpl;
  }
  ~ScratchDir() {
    std::error_code ec;
    if (!path_.empty()) fs::remove_all(path_, ec);
  }
  const std::string& path() const { return path_; }
  std::vector<std::string> Entries() const {
    std::vector<std::string> names;
    for (const auto& e : fs::directory_iterator(path_))
      names.push_back(e.path().filename().string());
    std::sort(names.begin(), names.end());
    return names;
  }

 private:
  std::string path_;
};

std::string ReadAll(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

MeasurementSet SimulatedMeasurements(const RobotModel& model, int rows, bool pose, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0, 0.02);
  MeasurementSet data(model.num_joints());
  for (int r = 0; r < rows; ++r) {
    const std::vector<double> q = RandomQ(model, &rng);
    const int tool = r % model.num_tools();
    SE3d X = ToolPose(model, q.data(), tool);
    X.t += Eigen::Vector3d{noise(rng), noise(rng), noise(rng)};
    if (pose) {
      data.AddPose(q.data(), X, tool);
    } else {
      data.Add(q.data(), X.t, tool);
    }
  }
  return data;
}

TEST(Io, YamlRoundTripCobot6) {
  const RobotModel model = MakeCobot6();
  const std::string yaml = RobotModelToYaml(model);
  RobotModel back;
  const Status s = ParseRobotModelYaml(yaml, "cobot6.yaml", &back);
  ASSERT_TRUE(s.ok()) << s.message() << "\n" << yaml;
  ExpectSameKinematics(model, back, 1);
}

TEST(Io, YamlRoundTripPrismaticAndTiltedTwist) {
  const RobotModel model = MakeModelWithPrismaticAndTiltedTwist();
  ASSERT_TRUE(model.Validate().ok()) << model.Validate().message();
  const std::string yaml = RobotModelToYaml(model);
  RobotModel back;
  const Status s = ParseRobotModelYaml(yaml, "variant.yaml", &back);
  ASSERT_TRUE(s.ok()) << s.message() << "\n" << yaml;
  ExpectSameKinematics(model, back, 2);
}

TEST(Io, YamlRoundTripShippedTestRobots) {
  for (const RobotModel& model : {MakeUr5Like(), MakeSevenJointArm(), MakeArmWithPrismatic()}) {
    RobotModel back;
    const Status s = ParseRobotModelYaml(RobotModelToYaml(model), model.name + ".yaml", &back);
    ASSERT_TRUE(s.ok()) << s.message();
    ExpectSameKinematics(model, back, 3);
  }
}

TEST(Io, YamlFileRoundTrip) {
  ScratchDir dir;
  ASSERT_FALSE(dir.path().empty());
  const std::string path = dir.path() + "/model.yaml";
  const RobotModel model = MakeModelWithPrismaticAndTiltedTwist();
  ASSERT_TRUE(WriteRobotModel(path, model).ok());
  RobotModel back;
  const Status s = ReadRobotModel(path, &back);
  ASSERT_TRUE(s.ok()) << s.message();
  ExpectSameKinematics(model, back, 4);
  EXPECT_EQ(dir.Entries(), std::vector<std::string>{"model.yaml"});
}

TEST(Io, RpyAndQuaternionAgree) {
  const double roll = 0.3, pitch = -1.2, yaw = 2.9;
  const Eigen::Vector4d q = RotationToQuaternion<double>(RotationFromRpy(roll, pitch, yaw));
  char quat[200];
  std::snprintf(quat, sizeof(quat), "[%.17g, %.17g, %.17g, %.17g]", q(0), q(1), q(2), q(3));
  const std::string head =
      "name: one_joint\n"
      "joints:\n"
      "  - name: joint1\n"
      "    type: revolute\n"
      "    origin: {xyz: [1, 2, 3], ";
  const std::string tail =
      "}\n"
      "tools:\n"
      "  - name: smr1\n"
      "    origin: {xyz: [40, 0, 60], rpy: [0, 0, 0]}\n";
  RobotModel from_rpy, from_quat;
  Status s = ParseRobotModelYaml(head + "rpy: [0.3, -1.2, 2.9]" + tail, "rpy.yaml", &from_rpy);
  ASSERT_TRUE(s.ok()) << s.message();
  s = ParseRobotModelYaml(head + "quaternion: " + quat + tail, "quat.yaml", &from_quat);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_LE((from_rpy.joints[0].origin.R - from_quat.joints[0].origin.R).norm(),
            kRpyQuaternionTolerance);
  EXPECT_LE((from_rpy.joints[0].origin.R - RotationFromRpy(roll, pitch, yaw)).norm(),
            kRpyQuaternionTolerance);
  // Omitted twist: the default of the joint type.
  EXPECT_EQ(from_rpy.joints[0].twist, DefaultTwist(JointType::kRevolute));
  for (double angle : {-2.0, 0.0, 1.0}) {
    const SE3d a = ToolPose(from_rpy, &angle);
    const SE3d b = ToolPose(from_quat, &angle);
    EXPECT_LE((a.t - b.t).norm(), kRoundTripToleranceMm);
  }
}

TEST(Io, YamlNearUnitQuaternionIsNormalized) {
  // Norm 1 + 1e-5: a rounding artefact, accepted and normalized. (Far from unit: see bad/.)
  const std::string yaml =
      "name: one_joint\n"
      "joints:\n"
      "  - {name: slide, type: prismatic, origin: {xyz: [0, 0, 0], quaternion: [0, 0, 0, "
      "1.00001]}}\n"
      "tools:\n"
      "  - {name: smr1, origin: {xyz: [0, 0, 10], rpy: [0, 0, 0]}}\n";
  RobotModel model;
  const Status s = ParseRobotModelYaml(yaml, "near_unit.yaml", &model);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_LE((model.joints[0].origin.R - Eigen::Matrix3d::Identity()).norm(), 1e-15);
  EXPECT_EQ(model.joints[0].twist, DefaultTwist(JointType::kPrismatic));
}

TEST(Io, ModelErrorLeavesOutputUntouched) {
  RobotModel model = MakeCobot6();
  const Status s = ParseRobotModelYaml("name: x\njoints: []\ntools: []\n", "empty.yaml", &model);
  EXPECT_FALSE(s.ok());
  EXPECT_EQ(model.num_joints(), 6);
}

void ExpectSameMeasurements(const MeasurementSet& a, const MeasurementSet& b) {
  ASSERT_EQ(a.size(), b.size());
  ASSERT_EQ(a.num_joints(), b.num_joints());
  ASSERT_EQ(a.has_orientation(), b.has_orientation());
  for (int r = 0; r < a.size(); ++r) {
    for (int j = 0; j < a.num_joints(); ++j) EXPECT_EQ(a.q(r)[j], b.q(r)[j]) << "row " << r;
    EXPECT_EQ(a.position(r), b.position(r)) << "row " << r;
    EXPECT_EQ(a.target(r), b.target(r)) << "row " << r;
    if (a.has_orientation()) {
      EXPECT_LE((a.orientation(r) - b.orientation(r)).norm(), kRotationRoundTripTolerance);
    }
  }
}

// The CSV readers' fast path (std::from_chars up to the comma) gives the correctly rounded value,
// checked against glibc's strtod bit for bit, and stops where the number ends; spellings that
// ParseNumber treats specially ('+', inf, nan, out of range) are declined.
TEST(Io, NumberFastPathIsCorrectlyRoundedOrDeclines) {
  auto reference = [](const std::string& text) { return std::strtod(text.c_str(), nullptr); };
  auto same_bits = [](double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; };
  std::mt19937_64 rng(17);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  std::uniform_int_distribution<int> exponent(-8, 6);
  for (int k = 0; k < 50000; ++k) {
    const double mantissa = unit(rng);  // drawn in this order on every compiler
    const double x = mantissa * std::pow(10.0, exponent(rng));
    char buf[64];
    std::string texts[5];
    texts[0] = std::string(buf, std::to_chars(buf, buf + sizeof buf, x,
                                              std::chars_format::fixed).ptr);  // shortest
    std::snprintf(buf, sizeof buf, "%.17f", x);
    texts[1] = buf;
    std::snprintf(buf, sizeof buf, "%.9f", x);
    texts[2] = buf;
    std::snprintf(buf, sizeof buf, "%.3f", x);
    texts[3] = buf;
    std::snprintf(buf, sizeof buf, "%.20e", x);  // more digits than a double holds
    texts[4] = buf;
    for (const std::string& text : texts) {
      double v = 0;
      const char* end = text.data() + text.size();
      const char* after = internal::ParsePlainDecimal(text.data(), end, &v);
      ASSERT_EQ(after, end) << text;
      ASSERT_TRUE(same_bits(v, reference(text))) << text;
      const std::string line = text + ",smr1,12345678";
      double w = 0;
      const char* stop = internal::ParsePlainDecimal(line.data(), line.data() + line.size(), &w);
      ASSERT_EQ(stop, line.data() + text.size()) << line;
      ASSERT_TRUE(same_bits(w, v)) << line;
    }
  }
  // Exactly halfway between two doubles (round to even), and one unit either side; signed zero.
  for (const std::string text : {"9007199254740993", "9007199254740992", "9007199254740995",
                                 "0.5", "-0.0", "0", "123456789012345678901234567890",
                                 "2.2250738585072011e-308", "4.9e-324", "1.7976931348623157e308"}) {
    double v = 1;
    const char* after = internal::ParsePlainDecimal(text.data(), text.data() + text.size(), &v);
    ASSERT_EQ(after, text.data() + text.size()) << text;
    EXPECT_TRUE(same_bits(v, reference(text))) << text;
  }
  // Declined: ParseNumber decides (and words its error).
  for (const std::string text : {"", "-", ".5", "+12.25", "abc", "+-1", " 1", "inf", "-nan",
                                 "1e999", "-1e999"}) {
    double v = 0;
    EXPECT_EQ(internal::ParsePlainDecimal(text.data(), text.data() + text.size(), &v), nullptr)
        << text;
  }
  const std::string exp = "1.5e3,2";
  double v = 0;
  const char* after = internal::ParsePlainDecimal(exp.data(), exp.data() + exp.size(), &v);
  ASSERT_NE(after, nullptr);
  EXPECT_EQ(*after, ',');
  EXPECT_EQ(v, 1500.0);
}

// Numbers in other spellings than the fast path's go the general way, to the same values.
TEST(Io, CsvNumberSpellingsReadTheSameValues) {
  const RobotModel model = MakeCobot6();
  const std::string header = "q1,q2,q3,q4,q5,q6,x,y,z\n";
  const std::string a = header + "0.25,-1.5,2,0.125,-0.5,3,100.5,-200.25,300\n";
  const std::string b =
      header + "2.5e-1, -1.50 ,+2.0,1.25E-1,-.5,3.,1005e-1,-200.250000000000000000001,3e2\n";
  MeasurementSet da, db;
  ASSERT_TRUE(ParseMeasurementsCsv(a, "a.csv", model, AngleUnit::kRadians, &da).ok());
  ASSERT_TRUE(ParseMeasurementsCsv(b, "b.csv", model, AngleUnit::kRadians, &db).ok());
  ASSERT_EQ(da.size(), 1);
  ASSERT_EQ(db.size(), 1);
  for (int j = 0; j < 6; ++j) EXPECT_EQ(da.q(0)[j], db.q(0)[j]) << j;
  EXPECT_EQ(da.position(0), db.position(0));
  // A value out of range is reported with its text either way.
  MeasurementSet dc;
  const Status s =
      ParseMeasurementsCsv(header + "0,0,0,0,0,0,1,2,3000000\n", "c.csv", model,
                           AngleUnit::kRadians, &dc);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("c.csv:2: column 'z': value '3000000' is out of range"),
            std::string::npos)
      << s.message();
}

TEST(Io, CsvRoundTripExact) {
  const RobotModel model = MakeModelWithPrismaticAndTiltedTwist();
  const MeasurementSet data = SimulatedMeasurements(model, 100, /*pose=*/false, 5);
  const std::string csv = MeasurementsToCsv(model, data, "simulated\nsecond line");
  EXPECT_EQ(csv.rfind("# simulated\n# second line\nq1,q2,q3,q4,q5,q6,x,y,z,target\n", 0), 0u)
      << csv;
  MeasurementSet back;
  const Status s = ParseMeasurementsCsv(csv, "sim.csv", model, AngleUnit::kRadians, &back);
  ASSERT_TRUE(s.ok()) << s.message();
  ExpectSameMeasurements(data, back);
  // Two comment lines and the header come first: data row r is on line r + 4.
  EXPECT_EQ(back.source_line(0), 4);
  EXPECT_EQ(back.source_line(99), 103);
}

TEST(Io, CsvPoseRoundTrip) {
  const RobotModel model = MakeModelWithPrismaticAndTiltedTwist();
  const MeasurementSet data = SimulatedMeasurements(model, 50, /*pose=*/true, 6);
  ScratchDir dir;
  ASSERT_FALSE(dir.path().empty());
  const std::string path = dir.path() + "/pose.csv";
  ASSERT_TRUE(WriteMeasurements(path, model, data).ok());
  EXPECT_NE(ReadAll(path).find(",target,quat_x,quat_y,quat_z,quat_w\n"), std::string::npos);
  MeasurementSet back;
  const Status s = ReadMeasurements(path, model, AngleUnit::kRadians, &back);
  ASSERT_TRUE(s.ok()) << s.message();
  ExpectSameMeasurements(data, back);
}

TEST(Io, CsvColumnOrderTargetsAndSpaces) {
  const RobotModel model = MakeModelWithPrismaticAndTiltedTwist();
  const std::string csv =
      "target, z, y, x, q6, q5, q4, q3, q2, q1\n"
      "smr1, 3, 2, 1, 0.6, 0.5, 0.4, 0.3, 0.2, 0.1\n"
      "1, 6, 5, 4, 0, 0, 0, 0, 0, +1.5e-1\n"
      "smr #2: side, 9, 8, 7, 0, 0, 0, 0, 0, 0\n";
  MeasurementSet data;
  const Status s = ParseMeasurementsCsv(csv, "order.csv", model, AngleUnit::kRadians, &data);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(data.size(), 3);
  EXPECT_EQ(data.position(0), Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(data.q(0)[0], 0.1);
  EXPECT_EQ(data.q(0)[5], 0.6);
  EXPECT_EQ(data.target(0), 0);
  EXPECT_EQ(data.target(1), 1);
  EXPECT_EQ(data.q(1)[0], 0.15);
  EXPECT_EQ(data.target(2), 1);
  EXPECT_FALSE(data.has_orientation());
}

TEST(Io, CsvDegreesConvertRevoluteJointsOnly) {
  const RobotModel model = MakeModelWithPrismaticAndTiltedTwist();  // joint 3 is prismatic
  const std::string csv =
      "q1,q2,q3,q4,q5,q6,x,y,z\n"
      "90,-45,12.5,180,0,1,100,200,300\n";
  MeasurementSet deg;
  const Status s = ParseMeasurementsCsv(csv, "deg.csv", model, AngleUnit::kDegrees, &deg);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(deg.size(), 1);
  EXPECT_DOUBLE_EQ(deg.q(0)[0], M_PI / 2);
  EXPECT_DOUBLE_EQ(deg.q(0)[1], -M_PI / 4);
  EXPECT_EQ(deg.q(0)[2], 12.5);  // mm, untouched
  EXPECT_DOUBLE_EQ(deg.q(0)[3], M_PI);
  EXPECT_DOUBLE_EQ(deg.q(0)[5], M_PI / 180);
  EXPECT_EQ(deg.position(0), Eigen::Vector3d(100, 200, 300));  // positions are never converted
  MeasurementSet rad;
  ASSERT_TRUE(ParseMeasurementsCsv(csv, "deg.csv", model, AngleUnit::kRadians, &rad).ok());
  EXPECT_EQ(rad.q(0)[0], 90.0);
}

TEST(Io, CsvAcceptsCrlfAndBom) {
  const RobotModel model = MakeCobot6();
  const std::string csv =
      "\xEF\xBB\xBF# exported on Windows\r\n"
      "q1,q2,q3,q4,q5,q6,x,y,z,target\r\n"
      "\r\n"
      "0.1,0.2,0.3,0.4,0.5,0.6,1,2,3,smr1\r\n"
      "  # indented comment\r\n"
      "0.1,0.2,0.3,0.4,0.5,0.6,4,5,6,0\r\n";
  MeasurementSet data;
  const Status s = ParseMeasurementsCsv(csv, "windows.csv", model, AngleUnit::kRadians, &data);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(data.size(), 2);
  EXPECT_EQ(data.position(0), Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(data.position(1), Eigen::Vector3d(4, 5, 6));
  EXPECT_EQ(data.source_line(0), 4);
  EXPECT_EQ(data.source_line(1), 6);
  EXPECT_EQ(data.target(0), 0);
  EXPECT_EQ(data.target(1), 0);
}

TEST(Io, CsvSkipsZeroRowsAndReportsThem) {
  const RobotModel model = MakeCobot6();
  const std::string csv =
      "q1,q2,q3,q4,q5,q6,x,y,z\n"
      "0.1,0.2,0.3,0.4,0.5,0.6,1,2,3\n"
      "0.1,0.2,0.3,0.4,0.5,0.6,0,0,0\n"
      "# beam lost again\n"
      "0.1,0.2,0.3,0.4,0.5,0.6,0,-0,0.0\n"
      "0.1,0.2,0.3,0.4,0.5,0.6,0,0,7\n"
      "0.1,0.2,0.3,0.4,0.5,0.6,NaN,2,3\n"
      "0.1,0.2,0.3,0.4,0.5,0.6,1,inf,3\n";
  MeasurementSet data;
  CsvReadReport report;
  Status s = ParseMeasurementsCsv(csv, "dirty.csv", model, AngleUnit::kRadians, &data, &report);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_EQ(data.size(), 2);
  EXPECT_EQ(data.source_line(1), 6);
  EXPECT_EQ(report.skipped_zero_rows, 4);
  EXPECT_EQ(report.skipped_lines, (std::vector<int64_t>{3, 5, 7, 8}));
  // Without a report the rows are skipped all the same.
  MeasurementSet again;
  s = ParseMeasurementsCsv(csv, "dirty.csv", model, AngleUnit::kRadians, &again);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_EQ(again.size(), 2);
}

TEST(Io, CsvErrorLeavesOutputUntouched) {
  const RobotModel model = MakeCobot6();
  MeasurementSet data = SimulatedMeasurements(model, 3, false, 7);
  CsvReadReport report;
  report.skipped_zero_rows = 42;
  const Status s = ParseMeasurementsCsv("q1,q2,q3,q4,q5,q6,x,y,z\n0,0,0,0,0,0,0,0,0\n1,2\n",
                                        "short.csv", model, AngleUnit::kRadians, &data, &report);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("short.csv:3: the row has 2 fields, no 'q3'; expected 9 fields"), std::string::npos)
      << s.message();
  EXPECT_EQ(data.size(), 3);
  EXPECT_EQ(report.skipped_zero_rows, 42);
}

std::map<std::string, std::string> ReadManifest() {
  std::map<std::string, std::string> manifest;
  std::ifstream in(kBadDir + "/MANIFEST");
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    const size_t tab = line.find('\t');
    if (tab == std::string::npos) {
      ADD_FAILURE() << "MANIFEST line without a tab: " << line;
      continue;
    }
    manifest[line.substr(0, tab)] = line.substr(tab + 1);
  }
  return manifest;
}

// True when `message` holds "<name>:<digits>: ".
bool NamesFileAndLine(const std::string& message, const std::string& name) {
  for (size_t at = message.find(name + ":"); at != std::string::npos;
       at = message.find(name + ":", at + 1)) {
    size_t i = at + name.size() + 1;
    const size_t digits_begin = i;
    while (i < message.size() && std::isdigit(static_cast<unsigned char>(message[i]))) ++i;
    if (i > digits_begin && message.compare(i, 2, ": ") == 0) return true;
  }
  return false;
}

TEST(Io, BadFilesAreRejectedWithFileLineAndReason) {
  const std::map<std::string, std::string> manifest = ReadManifest();
  const RobotModel cobot6 = MakeCobot6();
  int checked = 0;
  for (const auto& entry : fs::directory_iterator(kBadDir)) {
    const std::string name = entry.path().filename().string();
    const std::string ext = entry.path().extension().string();
    if (ext != ".yaml" && ext != ".csv") continue;
    SCOPED_TRACE(name);
    const auto it = manifest.find(name);
    ASSERT_NE(it, manifest.end()) << name << " is not listed in MANIFEST";
    Status s;
    if (ext == ".yaml") {
      RobotModel model;
      s = ReadRobotModel(entry.path().string(), &model);
    } else {
      MeasurementSet data;
      CsvReadReport report;
      s = ReadMeasurements(entry.path().string(), cobot6, AngleUnit::kRadians, &data, &report);
    }
    ASSERT_FALSE(s.ok()) << name << " was accepted";
    EXPECT_TRUE(NamesFileAndLine(s.message(), name)) << s.message();
    EXPECT_NE(s.message().find("; expected "), std::string::npos) << s.message();
    EXPECT_NE(s.message().find(it->second), std::string::npos)
        << "message: " << s.message() << "\nwanted: " << it->second;
    ++checked;
  }
  EXPECT_GE(checked, kMinBadFiles);
  for (const auto& [name, substring] : manifest) {
    EXPECT_TRUE(fs::exists(kBadDir + "/" + name)) << "MANIFEST lists a missing file " << name;
  }
  EXPECT_EQ(static_cast<size_t>(checked), manifest.size());
}

TEST(Io, MissingFileNamesPathAndReason) {
  const std::string path = kBadDir + "/does_not_exist.yaml";
  RobotModel model;
  Status s = ReadRobotModel(path, &model);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find(path), std::string::npos) << s.message();
  EXPECT_NE(s.message().find("No such file or directory"), std::string::npos) << s.message();
  MeasurementSet data;
  s = ReadMeasurements(kBadDir + "/does_not_exist.csv", MakeCobot6(), AngleUnit::kRadians, &data);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("does_not_exist.csv"), std::string::npos) << s.message();
  std::string text;
  s = ReadFile(kBadDir, &text);  // a directory
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find(kBadDir), std::string::npos) << s.message();
}

TEST(Io, WriteFileAtomically) {
  ScratchDir dir;
  ASSERT_FALSE(dir.path().empty());
  const std::string path = dir.path() + "/out.txt";
  ASSERT_TRUE(WriteFileAtomically(path, "first\n").ok());
  EXPECT_EQ(ReadAll(path), "first\n");
  ASSERT_TRUE(WriteFileAtomically(path, "second\n").ok());
  EXPECT_EQ(ReadAll(path), "second\n");
  std::string text;
  ASSERT_TRUE(ReadFile(path, &text).ok());
  EXPECT_EQ(text, "second\n");
  EXPECT_EQ(dir.Entries(), std::vector<std::string>{"out.txt"});

  // A missing directory: an error naming the path, nothing created.
  Status s = WriteFileAtomically(dir.path() + "/no/such/dir/out.txt", "x");
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("no/such/dir/out.txt"), std::string::npos) << s.message();

  // The rename fails (the target is a non-empty directory): the temporary file is removed.
  fs::create_directory(dir.path() + "/sub");
  std::ofstream(dir.path() + "/sub/keep") << "keep";
  s = WriteFileAtomically(dir.path() + "/sub", "x");
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(dir.Entries(), (std::vector<std::string>{"out.txt", "sub"}));
  EXPECT_EQ(ReadAll(dir.path() + "/sub/keep"), "keep");
}

// Readers never throw or abort, whatever the bytes: corrupt valid files at random and parse them.
TEST(Io, CorruptedInputNeverThrows) {
  const RobotModel model = MakeModelWithPrismaticAndTiltedTwist();
  const std::string yaml = RobotModelToYaml(model);
  const std::string csv =
      MeasurementsToCsv(model, SimulatedMeasurements(model, 5, /*pose=*/true, 9), "corrupt me");
  constexpr int kTrials = 3000;
  const std::string alphabet = "0123456789.,:-+[]{}#'\"\n\r\t eE_xyzqnaif\xEF\xBB\xBF";
  std::mt19937 rng(10);
  int accepted_yaml = 0, accepted_csv = 0;
  for (int trial = 0; trial < kTrials; ++trial) {
    for (const std::string* original : {&yaml, &csv}) {
      std::string text = *original;
      const int edits = 1 + static_cast<int>(rng() % 4);
      for (int e = 0; e < edits && !text.empty(); ++e) {
        const size_t at = rng() % text.size();
        switch (rng() % 4) {
          case 0:
            text[at] = alphabet[rng() % alphabet.size()];
            break;
          case 1:
            text.erase(at, 1 + rng() % 8);
            break;
          case 2:
            text.insert(at, 1, alphabet[rng() % alphabet.size()]);
            break;
          default:
            text.resize(at);
            break;
        }
      }
      if (original == &yaml) {
        RobotModel parsed;
        Status s;
        EXPECT_NO_THROW(s = ParseRobotModelYaml(text, "fuzz.yaml", &parsed));
        if (s.ok()) {
          ++accepted_yaml;
          EXPECT_TRUE(parsed.Validate().ok());
        } else {
          EXPECT_TRUE(NamesFileAndLine(s.message(), "fuzz.yaml")) << s.message();
        }
      } else {
        MeasurementSet parsed;
        Status s;
        EXPECT_NO_THROW(
            s = ParseMeasurementsCsv(text, "fuzz.csv", model, AngleUnit::kRadians, &parsed));
        if (s.ok()) {
          ++accepted_csv;
        } else {
          EXPECT_TRUE(NamesFileAndLine(s.message(), "fuzz.csv")) << s.message();
        }
      }
    }
  }
  RecordProperty("accepted_yaml", accepted_yaml);
  RecordProperty("accepted_csv", accepted_csv);
}

// Columns by name: joint names instead of q1..q6, upper-case X/Y/Z, extra columns ignored and
// listed once, positions in metres converted, the lost-beam row reported.
TEST(Io, CsvColumnsByNameExtraColumnsAndMetres) {
  const RobotModel model = MakeCobot6();
  const std::string path = std::string(LPOE_TEST_DATA_DIR) + "/extra_columns.csv";
  CsvOptions options;
  options.length_unit = LengthUnit::kMetres;
  MeasurementSet data;
  CsvReadReport report;
  const Status s = ReadMeasurements(path, model, options, &data, &report);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(data.size(), 2);
  EXPECT_NEAR(data.position(0).x(), 400.5, 1e-9);
  EXPECT_NEAR(data.position(1).z(), 899.875, 1e-9);
  EXPECT_EQ(data.q(1)[0], -0.1);
  EXPECT_EQ(data.q(1)[5], 0.65);
  EXPECT_EQ(data.source_line(0), 4);
  EXPECT_EQ(report.ignored_columns,
            (std::vector<std::string>{"timestamp", "temperature_C", "status"}));
  EXPECT_EQ(report.skipped_lines, (std::vector<int64_t>{6}));
  const std::string warnings = CsvReadWarnings(path, report);
  EXPECT_NE(warnings.find("ignored 3 column(s) the model does not use: 'timestamp' "
                          "'temperature_C' 'status'"),
            std::string::npos)
      << warnings;
  EXPECT_NE(warnings.find("skipped 1 row(s) with no measurement (lost beam) at line(s) 6"),
            std::string::npos)
      << warnings;
  // Read as millimetres, the same file is refused by nothing but looks like metres.
  MeasurementSet as_mm;
  ASSERT_TRUE(ReadMeasurements(path, model, CsvOptions(), &as_mm, nullptr).ok());
  EXPECT_NEAR(as_mm.position(0).x(), 0.4005, 1e-15);
  EXPECT_EQ(CsvReadWarnings(path, CsvReadReport()), "");
}

TEST(Io, LengthUnitHintComparesExtentWithReach) {
  const RobotModel model = MakeCobot6();
  EXPECT_GT(ModelReach(model), 1000.0);  // 96 + 138 + ... : about 1.2 m for this arm
  EXPECT_LT(ModelReach(model), 2000.0);
  MeasurementSet mm = SimulatedMeasurements(model, 200, /*pose=*/false, 3);
  EXPECT_EQ(LengthUnitHint(model, mm), "");
  MeasurementSet metres = mm, micrometres = mm;
  // In a tracker frame far from the base: the offset must not matter, only the spread.
  const Eigen::Vector3d far(3500, -2000, 400);
  for (int r = 0; r < mm.size(); ++r) {
    metres.mutable_position(r) = (mm.position(r) + far) / 1000.0;
    micrometres.mutable_position(r) = (mm.position(r) + far) * 1000.0;
    mm.mutable_position(r) += far;
  }
  EXPECT_EQ(LengthUnitHint(model, mm), "");
  EXPECT_NE(LengthUnitHint(model, metres).find("use --length_unit=m"), std::string::npos);
  EXPECT_NE(LengthUnitHint(model, micrometres).find("too large"), std::string::npos);
}

TEST(Io, ParseLengthUnit) {
  LengthUnit unit = LengthUnit::kMillimetres;
  EXPECT_TRUE(ParseLengthUnit("m", &unit));
  EXPECT_EQ(unit, LengthUnit::kMetres);
  EXPECT_TRUE(ParseLengthUnit("mm", &unit));
  EXPECT_EQ(unit, LengthUnit::kMillimetres);
  EXPECT_FALSE(ParseLengthUnit("cm", &unit));
  EXPECT_FALSE(ParseLengthUnit("", &unit));
}

// The streaming reader (1 MiB chunks, lines split across them) gives exactly what the in-memory
// parser gives, source lines and targets included.
TEST(Io, StreamedFileEqualsInMemoryText) {
  RobotModel model = MakeCobot6();
  model.tools.push_back({"smr2", SE3d(Eigen::Matrix3d::Identity(), Eigen::Vector3d(-40, 30, 60))});
  constexpr int kRows = 30000;  // about 5 MiB: several chunks
  const MeasurementSet rows = SimulatedMeasurements(model, kRows, /*pose=*/false, 5);
  std::string csv = MeasurementsToCsv(model, rows, "streamed");
  // Comments and blank lines between rows break the runs of consecutive source lines.
  std::string text;
  size_t start = 0;
  for (int line = 0; start < csv.size(); ++line) {
    const size_t nl = csv.find('\n', start);
    text.append(csv, start, nl + 1 - start);
    if (line % 997 == 5) text += "# a comment\n\n";
    start = nl + 1;
  }
  ScratchDir dir;
  const std::string path = dir.path() + "/streamed.csv";
  std::ofstream(path, std::ios::binary) << text;
  MeasurementSet streamed, parsed;
  ASSERT_TRUE(ReadMeasurements(path, model, AngleUnit::kRadians, &streamed).ok());
  ASSERT_TRUE(ParseMeasurementsCsv(text, path, model, AngleUnit::kRadians, &parsed).ok());
  ASSERT_EQ(streamed.size(), kRows);
  ASSERT_EQ(parsed.size(), kRows);
  int64_t previous_line = 0;
  for (int r = 0; r < kRows; ++r) {
    for (int j = 0; j < 6; ++j) ASSERT_EQ(streamed.q(r)[j], rows.q(r)[j]) << r;
    ASSERT_EQ(streamed.position(r), rows.position(r)) << r;
    ASSERT_EQ(streamed.target(r), rows.target(r)) << r;
    ASSERT_EQ(streamed.source_line(r), parsed.source_line(r)) << r;
    ASSERT_GT(streamed.source_line(r), previous_line) << r;
    previous_line = streamed.source_line(r);
  }
  // Lines counted through the inserted lines: a comment, the header, then the rows, with 2 extra
  // lines after the 4th row (file line 6).
  EXPECT_EQ(streamed.source_line(0), 3);
  EXPECT_EQ(streamed.source_line(3), 6);
  EXPECT_EQ(streamed.source_line(4), 9);
}

// Lines after the header are parsed in blocks split between two threads: a bad row or a lost-beam
// row in the second half of a block is reported at its own line, the first error in the file wins,
// and the first row may measure another tool than the first.
TEST(Io, CsvBlocksOnTwoThreadsKeepLinesAndFirstError) {
  RobotModel model = MakeCobot6();
  model.tools.push_back({"smr2", SE3d(Eigen::Matrix3d::Identity(), Eigen::Vector3d(-40, 30, 60))});
  constexpr int kRows = 20000;  // about 800 kB: one block, its halves on two threads
  std::string text = "q1,q2,q3,q4,q5,q6,x,y,z,target\n";
  for (int r = 0; r < kRows; ++r) {
    text += r == 15000 ? "0.1,0.2,0.3,0.4,0.5,0.6,0,0,0," : "0.1,0.2,0.3,0.4,0.5,0.6,500,20,900,";
    text += r % 3 == 0 ? "smr2\n" : "0\n";
  }
  MeasurementSet data;
  CsvReadReport report;
  Status s = ParseMeasurementsCsv(text, "blocks.csv", model, CsvOptions(), &data, &report);
  ASSERT_TRUE(s.ok()) << s.message();
  ASSERT_EQ(data.size(), kRows - 1);
  EXPECT_EQ(data.target(0), 1);
  EXPECT_EQ(data.target(1), 0);
  EXPECT_EQ(report.skipped_zero_rows, 1);
  EXPECT_EQ(report.skipped_lines, (std::vector<int64_t>{15002}));
  for (int r = 0; r < data.size(); ++r) {
    const int row = r < 15000 ? r : r + 1;  // file row of data row r
    ASSERT_EQ(data.source_line(r), row + 2) << r;
    ASSERT_EQ(data.target(r), row % 3 == 0 ? 1 : 0) << r;
  }
  // Two bad rows, one in each half of the block: the earlier one is reported.
  std::string bad = text;
  const auto replace_row = [&bad](int line, const std::string& with) {
    size_t start = 0;
    for (int l = 1; l < line; ++l) start = bad.find('\n', start) + 1;
    bad.replace(start, bad.find('\n', start) - start, with);
  };
  replace_row(19000, "0.1,0.2,0.3,0.4,0.5,0.6,500,oops,900,0");
  s = ParseMeasurementsCsv(bad, "blocks.csv", model, CsvOptions(), &data, nullptr);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("blocks.csv:19000: column 'y': 'oops' is not a number"),
            std::string::npos)
      << s.message();
  replace_row(3000, "0.1,0.2,0.3,0.4,0.5,0.6,500,20");
  s = ParseMeasurementsCsv(bad, "blocks.csv", model, CsvOptions(), &data, nullptr);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("blocks.csv:3000: the row has 8 fields, no 'z'"), std::string::npos)
      << s.message();
}

// A file that is one huge line (no '\n', or a wrong line end) fails at the line-length bound instead
// of being held whole in memory.
TEST(Io, OverlongLineIsRefused) {
  const RobotModel model = MakeCobot6();
  ScratchDir dir;
  const std::string path = dir.path() + "/one_line.csv";
  {
    std::ofstream out(path, std::ios::binary);
    out << "q1,q2,q3,q4,q5,q6,x,y,z\n";
    const std::string row = "0.1,0.2,0.3,0.4,0.5,0.6,400.5,120.25,900.125\r";  // CR line ends
    for (int k = 0; k < 60000; ++k) out << row;  // about 2.7 MB
  }
  MeasurementSet data;
  Status s = ReadMeasurements(path, model, AngleUnit::kRadians, &data);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("one_line.csv:2: a line longer than 1048576 bytes"),
            std::string::npos)
      << s.message();
  const std::string text = "q1" + std::string(3 << 20, ' ');
  s = ParseMeasurementsCsv(text, "text.csv", model, AngleUnit::kRadians, &data);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("text.csv:1: a line longer than"), std::string::npos) << s.message();
}

// Directories are refused, devices and FIFOs read with a bound and never block.
TEST(Io, NonRegularInputsAreRefusedOrBounded) {
  RobotModel model;
  Status s = ReadRobotModel(kBadDir, &model);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("is a directory"), std::string::npos) << s.message();
  MeasurementSet data;
  s = ReadMeasurements(kBadDir, MakeCobot6(), AngleUnit::kRadians, &data);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("is a directory"), std::string::npos) << s.message();
  if (fs::exists("/dev/zero")) {
    s = ReadRobotModel("/dev/zero", &model);
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.message().find("more than the limit of " + std::to_string(kMaxModelFileBytes)),
              std::string::npos)
        << s.message();
    s = ReadMeasurements("/dev/zero", MakeCobot6(), AngleUnit::kRadians, &data);
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.message().find("/dev/zero:1: a line longer than"), std::string::npos)
        << s.message();
  }
  ScratchDir dir;
  const std::string fifo = dir.path() + "/fifo";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  s = ReadRobotModel(fifo, &model);  // no writer: empty, at once
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("the document is empty"), std::string::npos) << s.message();
  s = ReadMeasurements(fifo, MakeCobot6(), AngleUnit::kRadians, &data);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("no header line"), std::string::npos) << s.message();
  // A model file above the bound is refused from its size, before reading.
  std::string text;
  const std::string big = dir.path() + "/big.yaml";
  std::ofstream(big) << std::string(1000, '#');
  s = ReadFile(big, 999, &text);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("more than the limit of 999"), std::string::npos) << s.message();
  EXPECT_TRUE(ReadFile(big, 1000, &text).ok());
  EXPECT_EQ(text.size(), 1000u);
}

TEST(Io, UrdfRecognisedInAnyLetterCase) {
  EXPECT_TRUE(IsUrdfPath("robot.urdf"));
  EXPECT_TRUE(IsUrdfPath("dir/ROBOT.URDF"));
  EXPECT_TRUE(IsUrdfPath("r.Urdf"));
  EXPECT_FALSE(IsUrdfPath("robot.yaml"));
  EXPECT_FALSE(IsUrdfPath("urdf"));
  EXPECT_FALSE(IsUrdfPath("robot.urdf.yaml"));
  ScratchDir dir;
  const std::string upper = dir.path() + "/UR_LIKE.URDF";
  fs::copy_file(std::string(LPOE_TEST_DATA_DIR) + "/urdf/ur_like.urdf", upper);
  RobotModel model;
  const Status s = ReadRobotModelFile(upper, &model);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_EQ(model.num_joints(), 6);
}

// Joint limits: read (rad / mm, an open side as .inf), written back, lower <= upper enforced.
TEST(Io, YamlJointLimitsRoundTrip) {
  RobotModel model = MakeModelWithPrismaticAndTiltedTwist();
  model.joints[0].lower = -3.0;
  model.joints[0].upper = 2.5;
  model.joints[2].lower = -150.0;  // prismatic, mm
  model.joints[2].upper = 250.0;
  model.joints[4].lower = -std::numeric_limits<double>::infinity();
  model.joints[4].upper = 1.25;
  const std::string yaml = RobotModelToYaml(model);
  EXPECT_NE(yaml.find("limits: [-3, 2.5]"), std::string::npos) << yaml;
  EXPECT_NE(yaml.find("limits: [-.inf, 1.25]"), std::string::npos) << yaml;
  RobotModel back;
  const Status s = ParseRobotModelYaml(yaml, "limits.yaml", &back);
  ASSERT_TRUE(s.ok()) << s.message();
  for (int j = 0; j < model.num_joints(); ++j) {
    EXPECT_EQ(back.joints[j].lower, model.joints[j].lower) << j;
    EXPECT_EQ(back.joints[j].upper, model.joints[j].upper) << j;
  }
  EXPECT_FALSE(back.joints[1].has_limits());
  ExpectSameKinematics(model, back, 4);
  // An open side may only be open outwards.
  const std::string wrong = std::string(yaml).replace(yaml.find("-.inf"), 5, ".inf");
  const Status bad = ParseRobotModelYaml(wrong, "limits.yaml", &back);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.message().find("'limits' lower value is +infinity"), std::string::npos)
      << bad.message();
  // The same rule in Validate(), for models built in code.
  RobotModel open_wrong_way = model;
  open_wrong_way.joints[1].lower = std::numeric_limits<double>::infinity();
  open_wrong_way.joints[1].upper = std::numeric_limits<double>::infinity();
  EXPECT_FALSE(open_wrong_way.Validate().ok());
  EXPECT_FALSE(ValidateLimits(1.0, -std::numeric_limits<double>::infinity()).ok());
  EXPECT_FALSE(ValidateLimits(2.0, 1.0).ok());
  EXPECT_TRUE(ValidateLimits(-std::numeric_limits<double>::infinity(), 1.0).ok());
}

// Duplicate names are found by hashing: many joints, the duplicate named with its first line.
TEST(Io, DuplicateJointNameAmongManyJoints) {
  constexpr int kJoints = 3000;
  std::string yaml = "name: long\njoints:\n";
  for (int j = 0; j < kJoints; ++j) {
    const int id = j == kJoints - 1 ? 17 : j;  // the last repeats joint 17 (line 3 + 2 * 17)
    yaml += "  - {name: j" + std::to_string(id) +
            ", type: revolute, origin: {xyz: [0, 0, 1], rpy: [0, 0, 0]}}\n";
  }
  yaml += "tools:\n  - {name: t, origin: {xyz: [0, 0, 1], rpy: [0, 0, 0]}}\n";
  RobotModel model;
  const Status s = ParseRobotModelYaml(yaml, "long.yaml", &model);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("long.yaml:" + std::to_string(kJoints + 2) +
                             ": duplicate joint name 'j17' (first on line 20)"),
            std::string::npos)
      << s.message();
}

// Source lines are 64-bit and survive subsets and the in-place hold-out split.
TEST(Io, SourceLinesAre64BitAndSurviveSplits) {
  constexpr int64_t kFarLine = int64_t{5} << 30;  // beyond 2^31
  MeasurementSet data(2);
  const double q[2] = {0.1, 0.2};
  for (int r = 0; r < 10; ++r) {
    data.Add(q, Eigen::Vector3d(r, 0, 1), r % 3, kFarLine + r + (r >= 5 ? 7 : 0));
  }
  EXPECT_EQ(data.source_line(0), kFarLine);
  EXPECT_EQ(data.source_line(9), kFarLine + 16);
  const std::vector<int> rows = {1, 2, 5, 8};
  const MeasurementSet subset = data.Subset(rows);
  std::vector<bool> out(10, false);
  for (int r : rows) out[r] = true;
  MeasurementSet kept = data, moved;
  kept.MoveRowsOut(out, &moved);
  ASSERT_EQ(moved.size(), 4);
  ASSERT_EQ(kept.size(), 6);
  for (int k = 0; k < 4; ++k) {
    EXPECT_EQ(moved.source_line(k), subset.source_line(k));
    EXPECT_EQ(moved.target(k), subset.target(k));
    EXPECT_EQ(moved.position(k), subset.position(k));
  }
  const std::vector<int> rest = {0, 3, 4, 6, 7, 9};
  for (int k = 0; k < 6; ++k) {
    EXPECT_EQ(kept.source_line(k), data.source_line(rest[k]));
    EXPECT_EQ(kept.target(k), data.target(rest[k]));
    EXPECT_EQ(kept.position(k), data.position(rest[k]));
  }
  // Generated rows (line 0) stay 0.
  MeasurementSet generated(2);
  generated.Add(q, Eigen::Vector3d(1, 2, 3));
  generated.Add(q, Eigen::Vector3d(1, 2, 3));
  EXPECT_EQ(generated.source_line(1), 0);
}

// A measured quaternion slightly off unit length (a tracker's rounding) is normalized.
TEST(Io, CsvNearUnitMeasuredQuaternionIsNormalized) {
  const std::string csv =
      "q1,q2,q3,q4,q5,q6,x,y,z,quat_x,quat_y,quat_z,quat_w\n"
      "0.1,0.2,0.3,0.4,0.5,0.6,400.5,120.25,900.125,0,0,0.6,0.8004\n";
  MeasurementSet data;
  const Status s = ParseMeasurementsCsv(csv, "q.csv", MakeCobot6(), AngleUnit::kRadians, &data);
  ASSERT_TRUE(s.ok()) << s.message();
  EXPECT_NEAR((data.orientation(0).transpose() * data.orientation(0) -
               Eigen::Matrix3d::Identity()).norm(), 0.0, 1e-14);
}

}  // namespace io_test
}  // namespace
// yaml-cpp's LoadAll loops forever on this input (found by fuzz_yaml); the reader must return.
TEST(Io, MalformedFlowAfterCommentDoesNotHang) {
  const std::string text = "# lpoe-calib robot model (docs/file_format {xyz: [0], rpy: [0, 0, 0]}\n, type: prismatic, : \xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""\xa0""[0, 0), 0, ~]}}]\n";
  RobotModel model;
  const Status s = ParseRobotModelYaml(text, "hang.yaml", &model);
  EXPECT_FALSE(s.ok());
  EXPECT_NE(s.message().find("hang.yaml:"), std::string::npos) << s.message();
}

// The rules every CSV reader shares (lpoe/io/csv_rules.h).
TEST(CsvRules, HeaderAndRowFieldCounts) {
  CsvHeader header;
  EXPECT_TRUE(ParseCsvHeader({"q1", "q2", "x"}, "f.csv", 1, &header).ok());
  EXPECT_EQ(header.Find("Q2"), 1);
  EXPECT_EQ(header.Find("z"), -1);
  const Status twice = ParseCsvHeader({"q1", "x", "Q1"}, "f.csv", 4, &header);
  ASSERT_FALSE(twice.ok());
  EXPECT_NE(twice.message().find("f.csv:4: column 'Q1' appears twice (columns 1 and 3)"),
            std::string::npos)
      << twice.message();
  ASSERT_TRUE(ParseCsvHeader({"q1", "q2", "x"}, "f.csv", 2, &header).ok());
  EXPECT_TRUE(CheckCsvRowFields(3, header, "f.csv", 5).ok());
  EXPECT_NE(CheckCsvRowFields(1, header, "f.csv", 5).message().find(
                "f.csv:5: the row has 1 field, no 'q2'"),
            std::string::npos);
  EXPECT_NE(CheckCsvRowFields(6, header, "f.csv", 7).message().find(
                "f.csv:7: the row has 6 fields, the header 3"),
            std::string::npos);
}

TEST(CsvRules, JointUnitHint) {
  RobotModel model = MakeCobot6();
  EXPECT_EQ(JointUnitHint(model, {1, 2, 3, 3, 2, 1}), "");
  EXPECT_NE(JointUnitHint(model, {1, 45, 3, 3, 2, 1}).find("q2"), std::string::npos);
  // Limits of two turns: 10 rad may be meant.
  model.joints[1].lower = -4 * M_PI;
  model.joints[1].upper = 4 * M_PI;
  EXPECT_EQ(JointUnitHint(model, {1, 10, 3, 3, 2, 1}), "");
  EXPECT_NE(JointUnitHint(model, {1, 30, 3, 3, 2, 1}), "");
}

}  // namespace lpoe
