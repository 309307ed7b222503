// Ballbar distances and touch-probe plane contacts: the kinds' readers, their analytic
// rows against finite differences, and calibrations of a simulated 6R arm from (a) ballbar
// distances, (b) probe contacts on a cube, (c) both, against a plain least-squares reference.
#include <cmath>
#include <fstream>
#include <string>
#include <vector>

#include <Eigen/Dense>
#include <gtest/gtest.h>

#include "lpoe/contact_calibration.h"
#include "lpoe/measurements/contact_measurements.h"
#include "lpoe/measurements/distance_measurement.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/measurements/measurement_kinds.h"
#include "lpoe/measurements/plane_measurement.h"
#include "lpoe/model/simulation.h"
#include "contact_arm.h"
#include "measurements/contact_reference.h"
#include "test_util.h"

namespace lpoe {
namespace {
namespace contact_measurements_test {

using testing::PlainLeastSquares;
using testing::Reference;
using testing::ReferenceRows;

// ---------------------------------------------------------------------------------------------
// Readers.

TEST(ContactCsv, DetectsTheKindFromTheColumns) {
  EXPECT_EQ(DetectMeasurementKind({"q1", "distance", "pivot"})->id, MeasurementKindId::kDistance);
  EXPECT_EQ(DetectMeasurementKind({"q1", "PLANE", "offset"})->id, MeasurementKindId::kPlane);
  EXPECT_EQ(DetectMeasurementKind({"q1", "x", "y", "z"})->id, MeasurementKindId::kPosition);
  EXPECT_EQ(DetectMeasurementKind({"q1", "x", "y", "z", "quat_x", "quat_y", "quat_z", "quat_w"})->id,
            MeasurementKindId::kPose);
  std::string why;
  EXPECT_EQ(DetectMeasurementKind({"q1", "x", "y", "z", "distance"}, &why), nullptr);
  EXPECT_NE(why.find("one kind per file"), std::string::npos) << why;
  EXPECT_EQ(DetectMeasurementKind({"q1", "time"}), nullptr);
  EXPECT_EQ(FindMeasurementKind("ballbar")->id, MeasurementKindId::kDistance);
  EXPECT_EQ(FindMeasurementKind("plane")->id, MeasurementKindId::kPlane);
  EXPECT_EQ(FindMeasurementKind("laser"), nullptr);
}

// A file's kind from its header line: comments and blank lines before it, a header without a final
// newline, a header beyond the first read piece (64 KiB of comments), and a file without one.
TEST(ContactCsv, DetectsAFilesKindFromItsHeaderLine) {
  const std::string dir = ::testing::TempDir();
  const auto kind_of = [&](const std::string& name, const std::string& text,
                           const MeasurementKindInfo** kind) {
    const std::string path = dir + "/" + name;
    std::ofstream(path, std::ios::binary) << text;
    return DetectMeasurementFileKind(path, kind);
  };
  const MeasurementKindInfo* kind = nullptr;
  ASSERT_TRUE(kind_of("a.csv", "# ballbar\n\n  \nq1,q2,distance,pivot\n1,2,150,a\n", &kind).ok());
  EXPECT_EQ(kind->id, MeasurementKindId::kDistance);
  ASSERT_TRUE(kind_of("b.csv", "q1,plane", &kind).ok());
  EXPECT_EQ(kind->id, MeasurementKindId::kPlane);
  std::string long_comments;
  while (long_comments.size() < 200000) long_comments += "# a comment line of the cell's log\n";
  ASSERT_TRUE(kind_of("c.csv", long_comments + "q1,x,y,z\n0,1,2,3\n", &kind).ok());
  EXPECT_EQ(kind->id, MeasurementKindId::kPosition);
  const Status none = kind_of("d.csv", "# only a comment\n\n", &kind);
  ASSERT_FALSE(none.ok());
  EXPECT_NE(none.message().find("d.csv:1"), std::string::npos) << none.message();
  EXPECT_NE(none.message().find("no header"), std::string::npos) << none.message();
  const Status bad = kind_of("e.csv", "# log\nq1,time\n", &kind);
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.message().find("e.csv:2"), std::string::npos) << bad.message();
}

TEST(ContactCsv, ReadsDistancesAndPlanes) {
  const RobotModel model = MakeCobot6();
  ContactCsvOptions o;
  o.sigma = 0.002;
  ContactMeasurementSet d;
  ASSERT_TRUE(ParseContactMeasurementsCsv(
                  "# ballbar\nq1,q2,q3,q4,q5,q6,distance,pivot,temp\n"
                  "0.1,0.2,0.3,0.4,0.5,0.6,150.001,A,21.5\n"
                  "0.1,0.2,0.3,0.4,0.5,0.7,149.5,B,21.5\r\n",
                  "bar.csv", model, o, &d)
                  .ok());
  ASSERT_EQ(d.size(), 2);
  EXPECT_EQ(d.rows[0].kind, MeasurementKindId::kDistance);
  EXPECT_DOUBLE_EQ(d.rows[0].value, 150.001);
  EXPECT_DOUBLE_EQ(d.rows[1].sigma, 0.002);
  EXPECT_EQ(d.pivots, (std::vector<std::string>{"A", "B"}));
  EXPECT_EQ(d.rows[1].feature, 1);
  EXPECT_EQ(d.rows[1].line, 4);
  EXPECT_DOUBLE_EQ(d.joints(1)[5], 0.7);

  ContactMeasurementSet p;
  o.sigma = 0;  // a sigma column instead
  ASSERT_TRUE(ParseContactMeasurementsCsv("q1,q2,q3,q4,q5,q6,plane,offset,sigma,target\n"
                                          "0,0,0,0,0,0,top,3,0.003,0\n",
                                          "probe.csv", model, o, &p)
                  .ok());
  EXPECT_EQ(p.rows[0].kind, MeasurementKindId::kPlane);
  EXPECT_DOUBLE_EQ(p.rows[0].value, 3.0);
  EXPECT_DOUBLE_EQ(p.rows[0].sigma, 0.003);
  EXPECT_EQ(p.planes, (std::vector<std::string>{"top"}));

  // Written and read back.
  ContactMeasurementSet back;
  ASSERT_TRUE(ParseContactMeasurementsCsv(ContactMeasurementsCsv(model, d, MeasurementKindId::kDistance),
                                          "w.csv", model, o, &back)
                  .ok());
  ASSERT_EQ(back.size(), 2);
  EXPECT_EQ(back.rows[1].value, d.rows[1].value);
  EXPECT_EQ(back.pivots, d.pivots);
}

TEST(ContactCsv, RefusesBadInputNamingFileAndLine) {
  const RobotModel model = MakeCobot6();
  ContactCsvOptions o;
  o.sigma = 0.002;
  const std::string head = "q1,q2,q3,q4,q5,q6,distance\n";
  struct Case {
    std::string text;
    std::string message;
  };
  const std::vector<Case> cases = {
      {head + "0,0,0,0,0,0,-1\n", "f.csv:2: column 'distance'"},
      {head + "0,0,0,0,0,0,nan\n", "f.csv:2: column 'distance': 'nan' is not finite"},
      {head + "0,0,0,0,0,0\n", "f.csv:2: the row has 6 fields"},
      {head + "0,0,0,0,0,1e5,150\n", "f.csv:2: column 'q6'"},
      {"q1,q2,q3,q4,q5,q6,distance,target\n0,0,0,0,0,0,150,smr9\n", "f.csv:2: column 'target': unknown tool"},
      {"q1,q2,q3,q4,q5,q6,distance,pivot\n0,0,0,0,0,0,150,\n", "f.csv:2: column 'pivot'"},
      {"q1,q2,q3,q4,q5,q6,distance,x,y,z\n", "f.csv:1: the header has the columns of"},
      {"q1,q2,q3,q4,q5,distance\n", "f.csv:1: no column for joint 6"},
      {head, "f.csv:1: no data rows"},
      {"# nothing\n", "f.csv:1: no header"},
      {"q1,q2,q3,q4,q5,q6,x,y,z\n", "f.csv:1: no 'distance' or 'plane' column (a position file)"},
      {"q1,q2,q3,q4,q5,q6,plane,sigma\n0,0,0,0,0,0,top,0\n", "f.csv:2: column 'sigma'"},
  };
  for (const Case& c : cases) {
    ContactMeasurementSet out;
    const Status s = ParseContactMeasurementsCsv(c.text, "f.csv", model, o, &out);
    ASSERT_FALSE(s.ok()) << c.text;
    EXPECT_NE(s.message().find(c.message), std::string::npos) << s.message();
  }
  ContactCsvOptions no_sigma;
  ContactMeasurementSet out;
  const Status s = ParseContactMeasurementsCsv(head + "0,0,0,0,0,0,150\n", "f.csv", model, no_sigma, &out);
  ASSERT_FALSE(s.ok());
  EXPECT_NE(s.message().find("f.csv:1: no 'sigma' column and no noise given"), std::string::npos)
      << s.message();
  // --data_kind=plane on a distance file.
  ContactCsvOptions plane = o;
  plane.kind = FindMeasurementKind("plane");
  const Status k = ParseContactMeasurementsCsv(head + "0,0,0,0,0,0,150\n", "f.csv", model, plane, &out);
  ASSERT_FALSE(k.ok());
  EXPECT_NE(k.message().find("f.csv:1: --data_kind=plane but the columns are a distance file's"),
            std::string::npos)
      << k.message();
}

// ---------------------------------------------------------------------------------------------
// A simulated arm.

// The arm of these tests (contact_arm.h, seed 44) and its rows.
using testing::BallbarRows;
using testing::ContactArm;
using testing::CubeRows;
using testing::MakeContactArm;

TEST(ContactSimulation, RowsSitWhereTheyMust) {
  const ContactArm t = MakeContactArm(44);
  std::vector<Eigen::Vector3d> pivots;
  BallbarSimulationOptions o;
  o.count = 30;
  o.noise = 0;
  ContactMeasurementSet bar;
  ASSERT_TRUE(SimulateBallbar(t.truth, o, &bar, &pivots).ok());
  ASSERT_EQ(pivots.size(), 3u);
  for (int r = 0; r < bar.size(); ++r) {
    const Eigen::Vector3d P = ToolPosition(t.truth, bar.joints(r));
    EXPECT_NEAR((P - pivots[bar.rows[r].feature]).norm(), bar.rows[r].value, 1e-8);
    EXPECT_NEAR(bar.rows[r].value, 150.0, 1.0 + 1e-9);
  }
  std::vector<Eigen::Vector4d> planes;
  PlaneSimulationOptions po;
  po.count = 30;
  po.noise = 0;
  ContactMeasurementSet cube;
  ASSERT_TRUE(SimulatePlaneContacts(t.truth, po, &cube, &planes).ok());
  for (int r = 0; r < cube.size(); ++r) {
    const Eigen::Vector3d P = ToolPosition(t.truth, cube.joints(r));
    EXPECT_NEAR(PlaneMeasurement::Simulate(P, planes[cube.rows[r].feature]), 3.0, 1e-8);
  }
}

// The analytic rows (ContactLinearize) against central differences of the residuals through the
// same steps (ApplyUpdate, ApplyFeatureStep).
TEST(ContactLinearize, MatchesFiniteDifferences) {
  const ContactArm t = MakeContactArm(44);
  ContactMeasurementSet data = BallbarRows(t.truth, 24, 3, 3);
  data.Append(CubeRows(t.truth, 24, 4));
  ContactFeatures f;
  ASSERT_TRUE(InitialContactFeatures(t.nominal, data, &f).ok());
  ContactCalibrationOptions o;
  o.hold_scale = ScaleHold::kOn;
  ContactParameterization p;
  ASSERT_TRUE(MakeContactParameterization(t.nominal, f, data, o, &p).ok());
  Eigen::VectorXd r;
  Eigen::MatrixXd J;
  ContactLinearize(t.nominal, f, p, t.nominal, data, o, &r, &J);
  ASSERT_EQ(J.cols(), p.num_parameters);
  const double h = 1e-6;
  for (int c = 0; c < p.num_parameters; ++c) {
    Eigen::VectorXd rp, rm;
    for (int sgn : {1, -1}) {
      const testing::MovedContactState s =
          testing::MoveAlongContactColumn(t.nominal, f, p, c, sgn * h);
      ContactLinearize(s.model, s.features, p, t.nominal, data, o, sgn > 0 ? &rp : &rm, nullptr);
    }
    const Eigen::VectorXd fd = (rp - rm) / (2 * h);
    EXPECT_LT((fd - J.col(c)).norm(), 1e-5 * std::max(1.0, fd.norm())) << "column " << c;
  }
}

// RMS distance (mm) of predicted from true tool positions after the best rigid (or similarity)
// alignment; the similarity's scale goes to `scale`.
double AlignedRms(const std::vector<Eigen::Vector3d>& predicted,
                  const std::vector<Eigen::Vector3d>& truth, bool similarity, double* scale) {
  const int m = static_cast<int>(predicted.size());
  Eigen::Matrix3Xd A(3, m), B(3, m);
  for (int i = 0; i < m; ++i) {
    A.col(i) = predicted[i];
    B.col(i) = truth[i];
  }
  const Eigen::Matrix4d T = Eigen::umeyama(A, B, similarity);
  if (scale != nullptr) *scale = T.topLeftCorner<3, 3>().determinant() > 0
                                     ? std::cbrt(T.topLeftCorner<3, 3>().determinant())
                                     : 0;
  const Eigen::Matrix3Xd moved = (T.topLeftCorner<3, 3>() * A).colwise() + T.topRightCorner<3, 1>();
  return std::sqrt((moved - B).colwise().squaredNorm().mean());
}

std::vector<Eigen::Vector3d> Positions(const RobotModel& m, const ContactMeasurementSet& at) {
  std::vector<Eigen::Vector3d> out;
  for (int r = 0; r < at.size(); ++r) out.push_back(ToolPosition(m, at.joints(r)));
  return out;
}

int NullDimension(const Eigen::MatrixXd& J, double tolerance) {
  Eigen::MatrixXd Js = J;
  for (int c = 0; c < Js.cols(); ++c) {
    const double norm = Js.col(c).norm();
    if (norm > 0) Js.col(c) /= norm;
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(Js);
  const Eigen::VectorXd& s = svd.singularValues();
  int rank = 0;
  while (rank < s.size() && s(rank) > tolerance * s(0)) ++rank;
  return static_cast<int>(Js.cols()) - rank;
}

void CalibrateAndCompare(const ContactMeasurementSet& data, bool planes_only,
                         int expected_left_out) {
  const ContactArm t = MakeContactArm(44);
  // Held-out configurations of the same kinds, never used by the calibrations.
  ContactMeasurementSet held = BallbarRows(t.truth, 60, 3, 901);
  held.Append(CubeRows(t.truth, 60, 902));
  const std::vector<Eigen::Vector3d> truth = Positions(t.truth, held);

  ContactCalibrationOptions o;  // defaults
  const ContactCalibrationResult linear = CalibrateContactsLinear(t.nominal, data, o);
  ASSERT_TRUE(linear.ok) << linear.message;
  const ContactCalibrationResult ceres = CalibrateContactsCeres(t.nominal, data, o);
  ASSERT_TRUE(ceres.ok) << ceres.message;

  // The reference from the same start.
  ContactFeatures start;
  ASSERT_TRUE(InitialContactFeatures(t.nominal, data, &start).ok());
  Eigen::MatrixXd J_reference;
  const Reference ref = PlainLeastSquares(t.nominal, start, data, planes_only, &J_reference);

  double s_lin = 1, s_ref = 1, s_nom = 1;
  const double e_nominal = AlignedRms(Positions(t.nominal, held), truth, planes_only, &s_nom);
  const double e_linear = AlignedRms(Positions(linear.model, held), truth, planes_only, &s_lin);
  const double e_ceres = AlignedRms(Positions(ceres.model, held), truth, planes_only, nullptr);
  const double e_ref = AlignedRms(Positions(ref.model, held), truth, planes_only, &s_ref);
  ::testing::Test::RecordProperty("held_out_rms_nm", static_cast<int>(1e6 * e_linear));
  ::testing::Test::RecordProperty("reference_rms_nm", static_cast<int>(1e6 * e_ref));
  ::testing::Test::RecordProperty("nominal_rms_um", static_cast<int>(1e3 * e_nominal));
  ::testing::Test::RecordProperty("similarity_scale_ppm", static_cast<int>(1e6 * (s_lin - 1)));
  EXPECT_LE(e_linear, 1.3 * e_ref) << "linear " << e_linear << " reference " << e_ref;
  EXPECT_LE(e_ceres, 1.3 * e_ref) << "ceres " << e_ceres << " reference " << e_ref;
  // A calibration, not a copy of the nominal model: the errors of about 1 mm are gone.
  EXPECT_LT(e_linear, 0.02 * e_nominal) << "nominal " << e_nominal;
  if (planes_only) {
    EXPECT_TRUE(linear.parameterization.scale_held);
    EXPECT_NEAR(s_lin, 1.0, 0.03);
    EXPECT_NEAR(linear.scale, 1.0, 1e-5);  // held at the nominal's
  } else {
    EXPECT_FALSE(linear.parameterization.scale_held);
  }
  // Both solvers agree.
  double largest = 0;
  const std::vector<Eigen::Vector3d> a = Positions(linear.model, held), b = Positions(ceres.model, held);
  for (size_t i = 0; i < a.size(); ++i) largest = std::max(largest, (a[i] - b[i]).norm());
  EXPECT_LT(largest, 1e-4) << "mm between the two solvers' predictions";
  EXPECT_NEAR(linear.cost, ceres.cost, 1e-6 * std::max(1.0, linear.cost));
  // What is left out (or held) is what the reference finds unobservable: the reference's null
  // space (every frame's six directions) is the one of the identifiable parameterization plus the
  // directions it drops by construction (per revolute joint 2, per position tool 3), and the
  // parameterization's decision removes exactly that null space (6: the base), no more.
  const ContactParameterization& p = linear.parameterization;
  ContactParameterization unreduced;
  unreduced.frames =
      MakeParameterization(t.nominal, ParameterizationKind::kIdentifiable, DataKind::kPosition);
  unreduced.num_pivots = static_cast<int>(start.pivots.size());
  unreduced.num_planes = static_cast<int>(start.planes.size());
  unreduced.pivot_offset = unreduced.frames.num_parameters;
  unreduced.plane_offset = unreduced.pivot_offset + 3 * unreduced.num_pivots;
  unreduced.num_parameters = unreduced.plane_offset + 3 * unreduced.num_planes;
  Eigen::VectorXd r;
  Eigen::MatrixXd J_unreduced, J_ours;
  ContactLinearize(t.nominal, start, unreduced, t.nominal, data, o, &r, &J_unreduced);
  ContactParameterization free_scale = p;
  free_scale.scale_held = false;
  ContactLinearize(t.nominal, start, free_scale, t.nominal, data, o, &r, &J_ours);
  // (and the reference's plane normals are not normalized: their length is one more each).
  const int by_construction =
      2 * t.nominal.num_joints() + 3 * t.nominal.num_tools() + static_cast<int>(start.planes.size());
  EXPECT_EQ(NullDimension(J_reference, 1e-8) - by_construction, NullDimension(J_unreduced, 1e-8));
  EXPECT_EQ(NullDimension(J_unreduced, 1e-8), expected_left_out);
  EXPECT_EQ(p.num_base_directions, expected_left_out);
  EXPECT_EQ(NullDimension(J_ours, 1e-8), 0);
  int base = 0;
  for (const Direction& d : p.frames.unidentifiable) {
    if (d.reason.find("do not see the robot's base") != std::string::npos) ++base;
  }
  EXPECT_EQ(base + p.num_gauge_rows(), expected_left_out);
  EXPECT_NE(p.base_reason.find("do not see the robot's base"), std::string::npos);
  if (planes_only) {
    // The scale is not an exact null direction: in the reference's coordinates, scaling every
    // translation, pivot and plane (d -> s d + (s - 1) offset) changes the whitened residuals by
    // exactly r per unit of s - 1, which vanishes only where the fit is exact: no rank test sees
    // it, and the noise leaves it determined to a few per cent only (hence the hold).
    Eigen::VectorXd r_ref;
    Eigen::MatrixXd J_ref;
    Reference at_start{t.nominal, start.pivots, start.planes};
    ReferenceRows(at_start, data, &r_ref, &J_ref);
    Eigen::VectorXd v = Eigen::VectorXd::Zero(J_ref.cols());
    const int n = t.nominal.num_joints();
    for (int f = 0; f < t.nominal.num_frames(); ++f) {
      const SE3d& T = f < n ? t.nominal.joints[f].origin : t.nominal.tools[f - n].origin;
      v.segment<3>(6 * f + 3) = T.R.transpose() * T.t;
    }
    const int planes_at = 6 * t.nominal.num_frames() + 3 * static_cast<int>(start.pivots.size());
    for (size_t k = 0; k < start.planes.size(); ++k) v(planes_at + 4 * k + 3) = start.planes[k](3) + 3.0;
    EXPECT_LT((J_ref * v - r_ref).norm(), 1e-6 * r_ref.norm());
  }
}

// The warning, shown: plain least squares on planes alone, with nothing holding the
// scale, shrinks the robot (the residuals shrink with it), however small the noise.
TEST(ContactCalibration, ReferenceWithoutScaleShrinksOnPlanes) {
  const ContactArm t = MakeContactArm(44);
  const ContactMeasurementSet data = CubeRows(t.truth, 120, 2);  // fewer rows: only the trend matters here
  ContactFeatures start;
  ASSERT_TRUE(InitialContactFeatures(t.nominal, data, &start).ok());
  Eigen::MatrixXd J;
  const Reference free = PlainLeastSquares(t.nominal, start, data, false, &J);
  const Reference held = PlainLeastSquares(t.nominal, start, data, true, &J);
  // The size of the predicted points relative to the nominal's (contact_calibration.h, ScaleOf).
  auto size = [&](const RobotModel& m) { return ScaleOf(m, t.nominal, data); };
  EXPECT_LT(size(free.model), 0.9);
  EXPECT_NEAR(size(held.model), 1.0, 0.01);
}

TEST(ContactCalibration, BallbarThreePivots) {
  const ContactArm t = MakeContactArm(44);
  CalibrateAndCompare(BallbarRows(t.truth, 300, 3, 1), false, 6);
}

TEST(ContactCalibration, ProbeOnThreeFacesOfACube) {
  const ContactArm t = MakeContactArm(44);
  CalibrateAndCompare(CubeRows(t.truth, 300, 2), true, 6);
}

TEST(ContactCalibration, BallbarAndProbeTogether) {
  const ContactArm t = MakeContactArm(44);
  ContactMeasurementSet data = BallbarRows(t.truth, 300, 3, 1);
  data.Append(CubeRows(t.truth, 300, 2));
  CalibrateAndCompare(data, false, 6);
}

// Fewer rows than unknowns: refused before solving, with the counts and what to do (it was an
// Eigen assertion when the null space was split among the frames and features).
TEST(ContactCalibration, FewerRowsThanUnknownsRefusedWithTheCounts) {
  const ContactArm t = MakeContactArm(44);
  const ContactMeasurementSet data = BallbarRows(t.truth, 20, 3, 5);
  for (const ContactCalibrationResult& r :
       {CalibrateContactsLinear(t.nominal, data, ContactCalibrationOptions()),
        CalibrateContactsCeres(t.nominal, data, ContactCalibrationOptions())}) {
    EXPECT_FALSE(r.ok);
    EXPECT_EQ(r.iterations, 0);
    EXPECT_NE(r.message.find("20 rows (20 residuals) cannot determine the"), std::string::npos)
        << r.message;
    EXPECT_NE(r.message.find("give more rows"), std::string::npos) << r.message;
  }
}

}  // namespace contact_measurements_test
}  // namespace
}  // namespace lpoe
