// What is identifiable is decided from the data at the estimate, never from the nominal model's
// tool points (docs/identifiability.md). A URDF's tool0 lies on the last axis; the SMR that the
// tracker measures usually does not. Each case below simulates a UR5-like arm with realistic errors
// (1 mm, 0.1 degree, joint zeros), measured by a tracker 2.5 m away, and compares the calibrated
// model's held-out error (fresh configurations, the actual robot against the model) with a plain
// least-squares reference of the same data: a rigid fit, then Gauss-Newton on every coordinate of
// every local frame with minimum-norm (pseudo-inverse) steps and a numerical Jacobian, which makes
// no identifiability decision at all.
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <map>
#include <random>
#include <sstream>
#include <set>
#include <string>
#include <vector>

#include "lpoe/analysis.h"
#include "lpoe/kinematics/eigen_decompositions.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/pipeline.h"
#include "lpoe/registration.h"
#include "lpoe/model/simulation.h"
#include "lpoe/model/statistics.h"
#include "identifiability/structural_identifiability.h"

namespace lpoe {
namespace {
namespace identifiability_at_estimate_test {

constexpr int kPoses = 200;
constexpr double kTcpHeight = 82.3;  // tool0 on joint 6's axis, mm from its frame

// The nominal model: tools that all sit at tool0 (on the last axis), as a URDF tip gives them.
RobotModel NominalWithToolsOnTheAxis(int tools, double height = kTcpHeight) {
  RobotModel m = MakeUr5Like();
  m.tools.resize(tools);
  for (int t = 0; t < tools; ++t) {
    m.tools[t].name = tools == 1 ? "tool0" : "smr" + std::to_string(t + 1);
    m.tools[t].origin = SE3d(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0, 0, height));
  }
  return m;
}

struct Case {
  std::string name;
  int tools = 1;
  double height = kTcpHeight;
  // Where the actual points are, in the flange frame, relative to the nominal tool0.
  std::vector<Eigen::Vector3d> offsets;
  double axis_tilt = 0;       // rad: the actual last axis tilted about x
  bool on_axis = false;       // the actual point exactly on the actual last axis
  double noise = 0.02;        // mm per axis
  bool pose = false;          // pose data (orientation noise 1e-5 rad)
};

struct Simulated {
  RobotModel actual;  // in the data's (tracker) frame, joint zeros folded in
  MeasurementSet data;
};

// `count` random configurations (joints in [-pi, pi]), every tool measured at each.
SimulationOptions EveryToolAt(const RobotModel& model, int count, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> angle(-3.14159265358979323846, 3.14159265358979323846);
  SimulationOptions o;
  o.all_tools = true;
  for (int c = 0; c < count * model.num_joints(); ++c) o.configurations.push_back(angle(rng));
  return o;
}

const SE3d& TrackerFromBase() {
  static const SE3d T = [] {
    Vector6d xi;
    xi << 0.3, -0.2, 1.1, 2000, -1500, 600;  // 2.5 m away, turned
    return ExpSE3(xi);
  }();
  return T;
}

Simulated Simulate(const RobotModel& nominal, const Case& c, bool tracker_frame) {
  const int n = nominal.num_joints();
  KinematicErrors errors = RandomErrors(nominal, 0.002, 1.0, 0.002, 0.002, 31);
  if (c.on_axis || c.axis_tilt != 0) {
    // The actual tool point on the nominal flange axis (no error across it) ...
    for (int t = 0; t < nominal.num_tools(); ++t) {
      errors.frame[n + t].tail<3>().head<2>().setZero();
    }
    // ... and the actual axis either exactly the frame's z or tilted by axis_tilt.
    errors.twist[n - 1].setZero();
    errors.twist[n - 1](0) = c.axis_tilt;
  }
  RobotModel with_errors = ApplyErrors(nominal, errors);
  for (int t = 0; t < nominal.num_tools() && t < static_cast<int>(c.offsets.size()); ++t) {
    with_errors.tools[t].origin.t += c.offsets[t];
  }
  SimulationOptions o = EveryToolAt(nominal, kPoses, 5);
  o.noise_sigma = c.noise;
  o.pose = c.pose;
  o.orientation_noise_sigma = c.pose ? 1e-5 : 0.0;
  o.seed = 5;
  Simulated s;
  s.data = SimulateMeasurements(with_errors, errors.joint_zero, o);
  s.actual = FoldJointZeros(with_errors, errors.joint_zero);
  if (tracker_frame) {
    const SE3d& T = TrackerFromBase();
    MeasurementSet moved(s.data.num_joints());
    for (int r = 0; r < s.data.size(); ++r) {
      if (c.pose) {
        moved.AddPose(s.data.q(r), T * s.data.pose(r), s.data.target(r));
      } else {
        moved.Add(s.data.q(r), T * s.data.position(r), s.data.target(r));
      }
    }
    s.data = moved;
    s.actual.joints[0].origin = T * s.actual.joints[0].origin;
  }
  return s;
}

// RMS over fresh configurations (every tool) of the distance between the two models' points.
double HeldOutRms(const RobotModel& actual, const RobotModel& model) {
  const SimulationOptions o = EveryToolAt(actual, 300, 1234);
  const MeasurementSet fresh =
      SimulateMeasurements(actual, std::vector<double>(actual.num_joints(), 0.0), o);
  double sum = 0;
  for (int r = 0; r < fresh.size(); ++r) {
    sum += (ToolPosition(model, fresh.q(r), fresh.target(r)) - fresh.position(r)).squaredNorm();
  }
  return std::sqrt(sum / fresh.size());
}

// The least-squares reference: every frame coordinate, minimum-norm Gauss-Newton steps.
RobotModel LeastSquaresReference(const RobotModel& nominal, const MeasurementSet& data) {
  RobotModel m = nominal;
  std::vector<Eigen::Vector3d> predicted(data.size()), measured(data.size());
  for (int r = 0; r < data.size(); ++r) {
    predicted[r] = ToolPosition(m, data.q(r), data.target(r));
    measured[r] = data.position(r);
  }
  SE3d T;
  EXPECT_TRUE(FitRigidTransform(predicted, measured, &T).ok());
  m.joints[0].origin = T * m.joints[0].origin;
  const int n = m.num_joints();
  const int frames = n + m.num_tools();
  auto frame = [&](RobotModel* model, int f) -> SE3d& {
    return f < model->num_joints() ? model->joints[f].origin
                                   : model->tools[f - model->num_joints()].origin;
  };
  // The residuals of the rows of `tool` (all rows: -1), zero elsewhere. A tool's frame moves only
  // its own rows, so its Jacobian columns need only those.
  auto residuals = [&](const RobotModel& model, int tool = -1) {
    Eigen::VectorXd y = Eigen::VectorXd::Zero(3 * data.size());
    for (int r = 0; r < data.size(); ++r) {
      if (tool >= 0 && data.target(r) != tool) continue;
      y.segment<3>(3 * r) = data.position(r) - ToolPosition(model, data.q(r), data.target(r));
    }
    return y;
  };
  for (int iteration = 0; iteration < 40; ++iteration) {
    const Eigen::VectorXd y = residuals(m);
    Eigen::MatrixXd J(y.size(), 6 * frames);
    constexpr double h = 1e-6;
    for (int f = 0; f < frames; ++f) {
      const int tool = f < n ? -1 : f - n;
      for (int k = 0; k < 6; ++k) {
        RobotModel plus = m, minus = m;
        Vector6d d = Vector6d::Zero();
        d(k) = h;
        frame(&plus, f) = frame(&plus, f) * ExpSE3(d);
        frame(&minus, f) = frame(&minus, f) * ExpSE3(Vector6d(-d));
        J.col(6 * f + k) = (residuals(minus, tool) - residuals(plus, tool)) / (2 * h);
      }
    }
    Eigen::JacobiSVD<Eigen::MatrixXd> svd(J, Eigen::ComputeThinU | Eigen::ComputeThinV);
    // Singular values below 1e-6 of the largest are zero: the central differences' round-off
    // alone gives J singular values of 1e-11 to 1e-10 of the largest, and with the point on the
    // axis the tilt's directions sit at 1e-9 to 2.3e-8, steps along them are round-off's (with 1e-9
    // those cases never converged: steps of 0.1 to 10^4 for all 40 iterations). The smallest
    // direction the data do determine, in any case here, is at 1.5e-5 (the tilted axis).
    svd.setThreshold(1e-6);
    const Eigen::VectorXd x = svd.solve(y);
    for (int f = 0; f < frames; ++f) {
      frame(&m, f) = frame(&m, f) * ExpSE3(Vector6d(x.segment<6>(6 * f)));
    }
    // Converged: the central differences' round-off leaves steps of 1e-9 (mm, rad) at the
    // minimum, which a bound of 1e-10 never saw (every case ran all 40 iterations).
    if (x.norm() < 1e-7) break;
  }
  return m;
}

// The reference depends on the nominal model and the data only, and several solvers and
// parameterizations of a test are checked against the same case: it is computed once per input.
RobotModel MemoizedLeastSquaresReference(const RobotModel& nominal, const MeasurementSet& data) {
  std::string key;
  auto append = [&key](const void* p, size_t bytes) {
    key.append(static_cast<const char*>(p), bytes);
  };
  for (const Joint& j : nominal.joints) {
    append(j.origin.R.data(), 9 * sizeof(double));
    append(j.origin.t.data(), 3 * sizeof(double));
    append(j.twist.data(), 6 * sizeof(double));
  }
  for (const Tool& t : nominal.tools) {
    append(t.origin.R.data(), 9 * sizeof(double));
    append(t.origin.t.data(), 3 * sizeof(double));
  }
  for (int r = 0; r < data.size(); ++r) {
    append(data.q(r), data.num_joints() * sizeof(double));
    append(data.position(r).data(), 3 * sizeof(double));
    const int target = data.target(r);
    append(&target, sizeof(target));
  }
  static std::map<std::string, RobotModel> cache;
  auto it = cache.find(key);
  if (it == cache.end()) it = cache.emplace(key, LeastSquaresReference(nominal, data)).first;
  return it->second;
}

bool Reported(const PipelineResult& r, const std::string& name) {
  for (const Direction& d : r.identifiability.unidentifiable) {
    if (d.name == name) return true;
  }
  return false;
}

// The structural directions the solution was solved with (not the unmeasured tools' or the joint
// blocks').
std::vector<Direction> SolvedWithLeftOut(const PipelineResult& r) {
  std::vector<Direction> out;
  for (const Direction& d : r.result.parameterization.unidentifiable) {
    if (IsStructurallyLost(d)) {
      out.push_back(d);
    }
  }
  return out;
}

// The decision at the solution is the one the solution was solved with.
void ExpectDecisionStableAtTheSolution(const PipelineResult& r, const MeasurementSet& data,
                                       bool use_orientation, double orientation_weight) {
  const RobotModel at = internal::StructureReference(
      r.geometric, data, internal::RmsPerAxisOfCost(r.result.final_cost, data, use_orientation));
  const std::vector<Direction> lost =
      internal::StructurallyUnidentifiable(at, data, use_orientation, orientation_weight);
  EXPECT_TRUE(internal::SameDirections(lost, SolvedWithLeftOut(r)))
      << lost.size() << " left out at the solution, " << SolvedWithLeftOut(r).size()
      << " in the solve";
}

struct CalibrationSetup {
  SolverKind solver = SolverKind::kLinear;
  ParameterizationKind kind = ParameterizationKind::kIdentifiable;
  bool register_frames = true;
  std::vector<std::string> joint_errors;
};

std::string Describe(const Case& c, const CalibrationSetup& run) {
  std::ostringstream os;
  os << c.name << ", solver " << (run.solver == SolverKind::kCeres ? "ceres" : "linear") << ", "
     << ParameterizationName(run.kind) << ", register " << run.register_frames;
  for (const std::string& t : run.joint_errors) os << ", " << t;
  return os.str();
}

// Calibrates the case and checks the held-out error against the reference's (3x, plus the noise
// floor's share that the reference, fitting every direction, may take from the noise).
PipelineResult ExpectNearReference(const Case& c, const CalibrationSetup& run) {
  SCOPED_TRACE(Describe(c, run));
  const RobotModel nominal = NominalWithToolsOnTheAxis(c.tools, c.height);
  const Simulated s = Simulate(nominal, c, run.register_frames);
  PipelineOptions o;
  o.solver = run.solver;
  o.parameterization = run.kind;
  o.register_frames = run.register_frames;
  o.joint_errors = run.joint_errors;
  o.use_orientation = c.pose;
  o.ceres.num_threads = 1;
  PipelineResult r = RunCalibrationPipeline(nominal, s.data, MeasurementSet(), o);
  EXPECT_EQ(r.result.termination, Termination::kConverged) << r.result.message;
  const double ours = HeldOutRms(s.actual, r.geometric);
  const double reference =
      HeldOutRms(s.actual, MemoizedLeastSquaresReference(nominal, s.data));
  EXPECT_LE(ours, 3 * reference) << "ours " << ours << " mm, reference " << reference << " mm";
  std::cout << Describe(c, run) << ": held-out RMS " << ours << " mm, least-squares reference "
            << reference << " mm\n";
  EXPECT_GT(HeldOutRms(s.actual, r.before), 20 * ours);  // not vacuous: the errors were large
  ExpectDecisionStableAtTheSolution(r, s.data, c.pose,
                                    run.solver == SolverKind::kCeres
                                        ? o.ceres.orientation_weight
                                        : o.linear.orientation_weight);
  return r;
}

Case SmrOffTheAxis(double offset_mm, double noise = 0.02) {
  Case c;
  c.name = "SMR " + std::to_string(offset_mm) + " mm off the nominal axis";
  c.offsets = {Eigen::Vector3d(offset_mm, 0, 0)};
  c.noise = noise;
  return c;
}

TEST(IdentifiabilityAtTheEstimate, SmrFortyMillimetresOffTool0BothSolversBothParameterizations) {
  for (SolverKind solver : {SolverKind::kLinear, SolverKind::kCeres}) {
    for (ParameterizationKind kind :
         {ParameterizationKind::kIdentifiable, ParameterizationKind::kFull}) {
      CalibrationSetup run;
      run.solver = solver;
      run.kind = kind;
      const PipelineResult r = ExpectNearReference(SmrOffTheAxis(40), run);
      EXPECT_FALSE(Reported(r, "joint6.rx"));  // the data determine the last axis' tilt
      EXPECT_FALSE(Reported(r, "joint6.ry"));
    }
  }
}

TEST(IdentifiabilityAtTheEstimate, PoseDataIdentifyTheTiltWhereverThePointIs) {
  for (const bool on_axis : {false, true}) {
    Case c = SmrOffTheAxis(on_axis ? 0.0 : 40.0);
    c.on_axis = on_axis;
    c.pose = true;
    for (SolverKind solver : {SolverKind::kLinear, SolverKind::kCeres}) {
      CalibrationSetup run;
      run.solver = solver;
      const PipelineResult r = ExpectNearReference(c, run);
      EXPECT_FALSE(Reported(r, "joint6.rx"));
    }
  }
}

TEST(IdentifiabilityAtTheEstimate, WithoutRegistrationAndWithJointSpaceTerms) {
  CalibrationSetup base_frame;
  base_frame.register_frames = false;
  ExpectNearReference(SmrOffTheAxis(40), base_frame);
  base_frame.solver = SolverKind::kCeres;
  ExpectNearReference(SmrOffTheAxis(40), base_frame);
  CalibrationSetup terms;
  terms.joint_errors = {"compliance"};
  for (SolverKind solver : {SolverKind::kLinear, SolverKind::kCeres}) {
    terms.solver = solver;
    const PipelineResult r = ExpectNearReference(SmrOffTheAxis(40), terms);
    EXPECT_FALSE(Reported(r, "joint6.rx"));
  }
}

TEST(IdentifiabilityAtTheEstimate, ThreeSmrsOnAPlateWhoseNominalPointsAreTheFlangeCentre) {
  Case c;
  c.name = "three SMRs on a plate";
  c.tools = 3;
  c.height = 20.0;
  c.offsets = {Eigen::Vector3d(50, 0, 15), Eigen::Vector3d(-35, 50, 15),
               Eigen::Vector3d(-30, -62, 15)};
  for (SolverKind solver : {SolverKind::kLinear, SolverKind::kCeres}) {
    CalibrationSetup run;
    run.solver = solver;
    const PipelineResult r = ExpectNearReference(c, run);
    EXPECT_FALSE(Reported(r, "joint6.rx"));
  }
}

TEST(IdentifiabilityAtTheEstimate, PointOnTheNominalAxisOfATiltedActualAxis) {
  Case c;
  c.name = "last axis tilted 0.015 rad";
  c.height = 120.0;  // the point circles with 1.8 mm radius
  c.axis_tilt = 0.015;
  for (SolverKind solver : {SolverKind::kLinear, SolverKind::kCeres}) {
    CalibrationSetup run;
    run.solver = solver;
    ExpectNearReference(c, run);
  }
}

TEST(IdentifiabilityAtTheEstimate, SmallOffsetsAreWeakDirectionsNotStructuralZeros) {
  for (double offset : {2.0, 5.0, 8.0}) {
    for (SolverKind solver : {SolverKind::kLinear, SolverKind::kCeres}) {
      CalibrationSetup run;
      run.solver = solver;
      const PipelineResult r = ExpectNearReference(SmrOffTheAxis(offset, 0.0175), run);
      EXPECT_FALSE(Reported(r, "joint6.rx")) << offset << " mm";
    }
  }
}

TEST(IdentifiabilityAtTheEstimate, PointReallyOnTheAxisStillCalibratesWithTheTiltReported) {
  Case c;
  c.name = "point on the actual axis";
  c.on_axis = true;
  for (SolverKind solver : {SolverKind::kLinear, SolverKind::kCeres}) {
    for (ParameterizationKind kind :
         {ParameterizationKind::kIdentifiable, ParameterizationKind::kFull}) {
      CalibrationSetup run;
      run.solver = solver;
      run.kind = kind;
      const PipelineResult r = ExpectNearReference(c, run);
      EXPECT_TRUE(Reported(r, "joint6.rx"));
      EXPECT_TRUE(Reported(r, "joint6.ry"));
      EXPECT_EQ(r.verdict.level, VerdictLevel::kPass) << r.verdict.reason;
    }
  }
}

// The structural decision at the reference: a point within the noise of the axis is put on it, one
// a few millimetres off stays off.
TEST(IdentifiabilityAtTheEstimate, StructureReferenceSnapsOnlyInsignificantOffsets) {
  const RobotModel nominal = NominalWithToolsOnTheAxis(2);
  MeasurementSet data(nominal.num_joints());
  std::vector<double> q(nominal.num_joints(), 0.1);
  for (int r = 0; r < 100; ++r) {
    data.Add(q.data(), Eigen::Vector3d::Zero(), 0);
    data.Add(q.data(), Eigen::Vector3d::Zero(), 1);
  }
  RobotModel estimate = nominal;
  estimate.tools[0].origin.t += Eigen::Vector3d(0.003, -0.002, 0.5);  // 0.0036 mm off
  estimate.tools[1].origin.t += Eigen::Vector3d(2.0, 0, 0);
  // rms 0.02 mm, 100 rows: 5 sigma = 5 * 0.02 * sqrt(2 / 100) = 0.014 mm.
  const RobotModel ref = internal::StructureReference(estimate, data, 0.02);
  EXPECT_NEAR(ref.tools[0].origin.t.head<2>().norm(), 0.0, 1e-12);
  EXPECT_NEAR(ref.tools[0].origin.t.z(), kTcpHeight + 0.5, 1e-12);  // along the axis: kept
  EXPECT_EQ(ref.tools[1].origin.t, estimate.tools[1].origin.t);
  // Without an estimate of the noise (0): nothing moves.
  const RobotModel exact = internal::StructureReference(estimate, data, 0.0);
  EXPECT_EQ(exact.tools[0].origin.t, estimate.tools[0].origin.t);
}

// ---- Held-out figures split by configuration: the SMRs of one pose stay together.

MeasurementSet ThreeSmrsPerPose(int poses) {
  const RobotModel model = NominalWithToolsOnTheAxis(3);
  const SimulationOptions o = EveryToolAt(model, poses, 8);
  return SimulateMeasurements(model, std::vector<double>(model.num_joints(), 0.0), o);
}

std::set<std::vector<double>> Configurations(const MeasurementSet& data,
                                             const std::vector<int>& rows) {
  std::set<std::vector<double>> out;
  for (int r : rows) out.insert(std::vector<double>(data.q(r), data.q(r) + data.num_joints()));
  return out;
}

TEST(ConfigurationSplit, NoConfigurationIsOnBothSidesOfAHoldoutOrAFold) {
  const MeasurementSet data = ThreeSmrsPerPose(103);
  std::vector<int> group;
  ASSERT_EQ(ConfigurationGroups(data, &group), 103);
  ASSERT_EQ(data.size(), 309);
  for (SplitKind kind : {SplitKind::kRandom, SplitKind::kSequential}) {
    std::vector<int> id, ver;
    HoldoutSplit(data, 0.3, 7, &id, &ver, kind);
    EXPECT_EQ(id.size() + ver.size(), 309u);
    EXPECT_EQ(ver.size(), 3u * 31u);  // 30 % of the 103 configurations, each with its 3 rows
    const auto a = Configurations(data, id), b = Configurations(data, ver);
    for (const auto& c : b) EXPECT_EQ(a.count(c), 0u);
    const auto folds = KFolds(data, 5, 3, kind);
    size_t rows = 0;
    for (size_t f = 0; f < folds.size(); ++f) {
      rows += folds[f].size();
      EXPECT_EQ(folds[f].size() % 3, 0u);
      const auto held = Configurations(data, folds[f]);
      std::vector<int> rest = Complement(data.size(), folds[f]);
      const auto kept = Configurations(data, rest);
      for (const auto& c : held) EXPECT_EQ(kept.count(c), 0u) << "fold " << f;
    }
    EXPECT_EQ(rows, 309u);
  }
}

TEST(ConfigurationSplit, OneRowPerConfigurationSplitsAsTheRowSplit) {
  const RobotModel model = MakeUr5Like();
  SimulationOptions o;
  o.count = 50;
  const MeasurementSet data =
      SimulateMeasurements(model, std::vector<double>(model.num_joints(), 0.0), o);
  std::vector<int> id, ver, id2, ver2;
  HoldoutSplit(data, 0.3, 9, &id, &ver);
  HoldoutSplit(data.size(), 0.3, 9, &id2, &ver2);
  EXPECT_EQ(ver, ver2);
  EXPECT_EQ(KFolds(data, 5, 3), KFolds(data.size(), 5, 3));
}

// ---- Geometry-only outputs (URDF, UR kinematics) after a calibration with joint-space terms get
// a geometry-only re-fit of the same data: the geometry identified with the terms predicts worse
// without them.

TEST(GeometryOnlyOutputs, RefitPredictsBetterThanTheGeometryIdentifiedWithTheTerms) {
  const RobotModel nominal = MakeCobot6();
  KinematicErrors errors = RandomErrors(nominal, 0.002, 1.0, 0.002, 0.002, 12);
  RobotModel actual = ApplyErrors(nominal, errors);
  ApplyJointErrorPhysics(SmallArmJointErrors(nominal, SmallArmOptions()), {"compliance"}, &actual);
  SimulationOptions o;
  o.count = 300;
  o.noise_sigma = 0.02;
  o.seed = 3;
  MeasurementSet identification = SimulateMeasurements(actual, errors.joint_zero, o);
  o.count = 150;
  o.seed = 4;
  const MeasurementSet verification = SimulateMeasurements(actual, errors.joint_zero, o);
  PipelineOptions po;
  po.joint_errors = {"compliance"};
  po.refit_geometry = true;
  const PipelineResult r = RunCalibrationPipeline(nominal, identification, verification, po);
  ASSERT_EQ(r.result.termination, Termination::kConverged) << r.result.message;
  ASSERT_TRUE(r.has_geometry_only);
  EXPECT_TRUE(r.geometry_only.model.joint_errors.empty());
  // The re-fit minimizes exactly the geometry-only cost: never worse on its own data, and here
  // clearly better on held-out data than the terms' geometry without the terms.
  const double refit_id = r.geometry_only_identification.norm.rms;
  const double with_terms_geometry_id = PositionErrorStatistics(r.geometric, identification).norm.rms;
  EXPECT_LE(refit_id, with_terms_geometry_id * (1 + 1e-9));
  const double refit_ver = r.geometry_only_verification.norm.rms;
  const double with_terms_geometry_ver =
      PositionErrorStatistics(r.geometric, verification).norm.rms;
  EXPECT_LT(refit_ver, 0.95 * with_terms_geometry_ver)
      << refit_ver << " mm against " << with_terms_geometry_ver << " mm";
  // ... and the model with the terms stays the best of the three.
  EXPECT_LT(r.verification_after.norm.rms, refit_ver);
  // Without terms nothing is re-fitted.
  po.joint_errors.clear();
  EXPECT_FALSE(RunCalibrationPipeline(nominal, identification, verification, po).has_geometry_only);
}

}  // namespace identifiability_at_estimate_test
}  // namespace
}  // namespace lpoe
