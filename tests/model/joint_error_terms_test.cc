// Issue 11 phase 2: the compliance and harmonics joint terms identified with the geometry by the
// calibration pipeline, on data simulated with the simulator's joint-error truth.
#include <algorithm>
#include <cmath>
#include <iostream>
#include <memory>
#include <numeric>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "lpoe/io/io.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/parallel.h"
#include "lpoe/pipeline.h"
#include "lpoe/model/simulation.h"
#include "lpoe/model/statistics.h"

namespace lpoe {
namespace {
namespace joint_error_terms_test {

TEST(JointErrorTerms, RegisteredAndSized) {
  const RobotModel m = MakeCobot6();
  for (const std::string& kind : JointTermNames()) {
    std::shared_ptr<const JointTerm> term;
    ASSERT_TRUE(MakeJointTerm(kind, m, &term).ok());
    EXPECT_EQ(term->name(), kind);
    EXPECT_EQ(term->num_joints(), m.num_joints());
    EXPECT_EQ(term->num_parameters(), NumJointErrorParameters(m, kind));
    const std::vector<double> q = {0.1, -0.4, 0.7, 0.2, -1.1, 0.5};
    Eigen::MatrixXd Y(m.num_joints(), term->num_parameters()), ref;
    term->Regressor(q.data(), Y.data());
    JointErrorRegressor(m, kind, q.data(), &ref);
    EXPECT_LE((Y - ref).cwiseAbs().maxCoeff(), 1e-10 * ref.cwiseAbs().maxCoeff());
  }
}

// RegressorValues (what the solvers and the effective joint values read) are exactly the
// regressor's entries at each parameter's joint, every other entry of Y is zero, and the
// effective joint values from them equal Y theta.
TEST(JointErrorTerms, RegressorValuesAreTheRegressorsEntriesAtTheirJoints) {
  RobotModel m = MakeCobot6();
  m.payload.mass = 1.5;
  m.payload.com = Eigen::Vector3d(10, -5, 40);
  m.gravity = Eigen::Vector3d(0.3, -0.2, -9.8);  // tilted: every joint feels a torque
  const int n = m.num_joints();
  const std::vector<std::vector<double>> configurations = {
      {0.1, -0.4, 0.7, 0.2, -1.1, 0.5}, {0, 0, 0, 0, 0, 0}, {-2.9, 1.3, -2.2, 3.0, 0.01, -1.7}};
  for (const std::string kind : {"compliance", "harmonics"}) {
    std::shared_ptr<const JointTerm> term;
    ASSERT_TRUE(MakeJointTerm(kind, m, &term).ok());
    const int P = term->num_parameters();
    Eigen::VectorXd theta(P);
    for (int k = 0; k < P; ++k) theta(k) = 1e-5 * std::sin(1.0 + 0.7 * k);
    for (const std::vector<double>& q : configurations) {
      Eigen::MatrixXd Y(n, P);
      term->Regressor(q.data(), Y.data());
      Eigen::VectorXd y(P);
      ASSERT_TRUE(term->RegressorValues(q.data(), y.data()));
      int nonzero = 0;
      for (int k = 0; k < P; ++k) {
        const int j = term->ParameterJoint(k);
        ASSERT_GE(j, 0);
        EXPECT_EQ(y(k), Y(j, k)) << term->ParameterName(k);
        nonzero += y(k) != 0;
        for (int i = 0; i < n; ++i) {
          if (i != j) {
            EXPECT_EQ(Y(i, k), 0.0) << term->ParameterName(k) << " row " << i;
          }
        }
      }
      EXPECT_GE(nonzero, P / 2);  // not a vacuous comparison (sin q = 0 at q = 0)
      JointTermValues values;
      values.term = term;
      values.theta = theta;
      std::vector<double> q_eff(n);
      EffectiveJointValues({values}, n, q.data(), q_eff.data());
      const Eigen::VectorXd expected = Eigen::Map<const Eigen::VectorXd>(q.data(), n) + Y * theta;
      for (int j = 0; j < n; ++j) EXPECT_NEAR(q_eff[j], expected(j), 1e-15) << "joint " << j;
    }
  }
}

struct Fixture {
  RobotModel nominal = MakeCobot6();
  MeasurementSet identification, verification;
  double noise = 0.01;
  Fixture() {
    nominal.payload.mass = 1.0;
    nominal.payload.com = Eigen::Vector3d(0, 0, 50);
    const KinematicErrors errors = RandomErrors(nominal, 2e-3, 0.5, 1e-3, 2e-3, 5);
    RobotModel actual = ApplyErrors(nominal, errors);
    SmallArmOptions small_arm;
    ApplyJointErrorPhysics(SmallArmJointErrors(nominal, small_arm), {"compliance", "harmonics"}, &actual);
    SimulationOptions options;
    options.count = 300;
    options.noise_sigma = noise;
    options.seed = 3;
    const MeasurementSet data = SimulateMeasurements(actual, errors.joint_zero, options);
    std::vector<int> id(200), ver(100);
    std::iota(id.begin(), id.end(), 0);
    std::iota(ver.begin(), ver.end(), 200);
    identification = data.Subset(id);
    verification = data.Subset(ver);
  }
};

PipelineResult RunPipeline(const Fixture& f, SolverKind solver, const std::vector<std::string>& terms) {
  PipelineOptions o;
  o.solver = solver;
  o.register_frames = false;
  o.joint_errors = terms;
  return RunCalibrationPipeline(f.nominal, f.identification, f.verification, o);
}

TEST(JointErrorTerms, PipelineRecoversComplianceAndHarmonics) {
  const Fixture f;
  const std::vector<std::string> both = {"compliance", "harmonics"};
  const PipelineResult without = RunPipeline(f, SolverKind::kLinear, {});
  const PipelineResult with = RunPipeline(f, SolverKind::kLinear, both);
  const PipelineResult ceres = RunPipeline(f, SolverKind::kCeres, both);
  ASSERT_TRUE(without.result.converged()) << without.result.message;
  ASSERT_TRUE(with.result.converged()) << with.result.message;
  ASSERT_TRUE(ceres.result.converged()) << ceres.result.message;
  ASSERT_EQ(with.result.joint_terms.size(), 2u);

  // Held-out RMS of the error norm; pure noise gives sqrt(3) sigma.
  const double noise_only = std::sqrt(3.0) * f.noise;
  const double rms_without = without.verification_after.norm.rms;
  const double rms_with = with.verification_after.norm.rms;
  std::cout << "held-out RMS: geometry only " << rms_without << " mm, with terms " << rms_with
            << " mm, noise only " << noise_only << " mm\n";
  EXPECT_LT(rms_with, 0.2 * rms_without);
  EXPECT_LT(rms_with, 1.5 * noise_only);

  // The identified values are stored in the calibrated model: its own prediction (EffectiveJoints
  // on its geometry) stays at the noise level
  // although its regressor is evaluated on the calibrated geometry, not the start model.
  EXPECT_EQ(with.result.model.joint_errors.Values("compliance").size(),
            static_cast<size_t>(NumComplianceParameters(6)));
  EXPECT_EQ(with.result.model.joint_errors.Values("harmonics").size(),
            static_cast<size_t>(NumHarmonicsParameters(6)));
  std::vector<Eigen::Vector3d> own;
  for (int r = 0; r < f.verification.size(); ++r) {
    own.push_back(f.verification.position(r) -
                  PredictToolPosition(with.result.model, f.verification.q(r),
                                      f.verification.target(r)));
  }
  EXPECT_LT(ComputeStatistics(own).norm.rms, 1.5 * noise_only);

  // Linear and Ceres agree on the predictions.
  double max_diff = 0;
  for (int r = 0; r < f.verification.size(); ++r) {
    const Eigen::Vector3d a =
        PredictToolPosition(with.result.model, f.verification.q(r), f.verification.target(r));
    const Eigen::Vector3d b =
        PredictToolPosition(ceres.result.model, f.verification.q(r), f.verification.target(r));
    max_diff = std::max(max_diff, (a - b).norm());
  }
  EXPECT_LT(max_diff, 1e-6);
}

// Simulated identification and verification sets of cobot6 with random geometric errors; the
// actual robot carries the simulator's small-arm compliance and harmonics when `joint_errors`.
// Identical geometry, configurations and noise otherwise. `tracker`: the measurements are in a
// tracker frame (so the calibration registers and moves the base).
struct AutoFixture {
  RobotModel nominal = MakeCobot6();
  RobotModel truth;  // the actual robot with its joint zeros folded into the frames
  MeasurementSet identification, verification;
  double noise = 0.01;
  AutoFixture(bool joint_errors, int identification_rows, int verification_rows,
              bool tracker = false) {
    nominal.payload.mass = 1.0;
    nominal.payload.com = Eigen::Vector3d(0, 0, 50);
    const KinematicErrors errors = RandomErrors(nominal, 2e-3, 0.5, 1e-3, 2e-3, 11);
    RobotModel actual = ApplyErrors(nominal, errors);
    if (joint_errors) {
      ApplyJointErrorPhysics(SmallArmJointErrors(nominal, SmallArmOptions()), {"compliance", "harmonics"}, &actual);
    }
    truth = FoldJointZeros(actual, errors.joint_zero);
    SimulationOptions options;
    options.count = identification_rows + verification_rows;
    options.noise_sigma = noise;
    options.seed = 7;
    MeasurementSet data = SimulateMeasurements(actual, errors.joint_zero, options);
    if (tracker) {
      const SE3d T(ExpSO3(Eigen::Vector3d(0.3, -0.2, 1.1)), Eigen::Vector3d(2500, -800, 300));
      for (int r = 0; r < data.size(); ++r) data.mutable_position(r) = T * data.position(r);
    }
    std::vector<int> id(identification_rows), ver(verification_rows);
    std::iota(id.begin(), id.end(), 0);
    std::iota(ver.begin(), ver.end(), identification_rows);
    identification = data.Subset(id);
    verification = data.Subset(ver);
  }
};

PipelineResult RunAuto(const AutoFixture& f, SolverKind solver, bool automatic,
                       const std::vector<std::string>& terms = {}) {
  PipelineOptions o;
  o.solver = solver;
  o.register_frames = false;
  o.joint_errors = terms;
  o.joint_errors_auto = automatic;
  return RunCalibrationPipeline(f.nominal, f.identification, f.verification, o);
}

std::string Chosen(const PipelineResult& r) {
  const JointErrorSelection& s = r.joint_error_selection;
  return s.chosen < 0 ? "(none ran)" : s.candidates[s.chosen].label;
}

void PrintSelection(const std::string& what, const PipelineResult& r) {
  std::cout << what << ":\n";
  for (const JointErrorCandidate& c : r.joint_error_selection.candidates) {
    std::cout << "  " << c.label << ": " << c.parameters << " combinations, CV rms " << c.cv_rms
              << " mm, mse " << c.cv_mse << " +- " << c.cv_mse_se << (c.ok ? "" : " FAILED")
              << "\n";
  }
  std::cout << "  chosen " << Chosen(r) << " (" << r.joint_error_selection.reason << ")\n";
}

// The tool displacement the joint-error terms of `model` cause at q (mm).
Eigen::Vector3d Deflection(const RobotModel& model, const double* q, int tool) {
  return PredictToolPosition(model, q, tool) - ToolPosition(model, q, tool);
}

// Acceptance of with compliance and harmonics in the actual robot (sigma 0.01 mm, 300
// poses), auto reaches within 1.5x the held-out RMS of the same data without such terms, and the
// identified deflection matches the true one within 5% RMS.
TEST(JointErrorAuto, ChoosesTheTermsAndRecoversTheDeflection) {
  const AutoFixture with(true, 300, 200);
  const AutoFixture without(false, 300, 200);
  const PipelineResult automatic = RunAuto(with, SolverKind::kLinear, true);
  const PipelineResult geometric = RunAuto(with, SolverKind::kLinear, false);
  const PipelineResult clean = RunAuto(without, SolverKind::kLinear, false);
  ASSERT_TRUE(automatic.result.converged()) << automatic.result.message;
  ASSERT_TRUE(geometric.result.converged()) << geometric.result.message;
  ASSERT_TRUE(clean.result.converged()) << clean.result.message;
  PrintSelection("with joint errors", automatic);
  EXPECT_EQ(Chosen(automatic), "compliance,harmonics");
  // Every subset of the registry's T terms (2^T), and the 2^(T-1) with compliance once more with
  // the gravity tilt when the data determine it (they do here: the compliance torques are large;
  // the level base keeps the simpler set chosen above).
  ASSERT_TRUE(automatic.joint_error_selection.Bilinear(kGravityTiltName).candidates)
      << automatic.joint_error_selection.Bilinear(kGravityTiltName).message;
  const size_t T = JointTermNames().size();
  ASSERT_EQ(automatic.joint_error_selection.candidates.size(),
            (size_t{1} << T) + (size_t{1} << (T - 1)));
  for (const JointErrorCandidate& c : automatic.joint_error_selection.candidates) {
    EXPECT_TRUE(c.ok) << c.label << ": " << c.failure;
  }
  EXPECT_EQ(automatic.joint_error_selection.candidates[0].label, "none");

  // Held-out RMS of the error norm: auto, geometric, the same data without joint errors.
  const double rms[3] = {automatic.verification_after.norm.rms,
                         geometric.verification_after.norm.rms,
                         clean.verification_after.norm.rms};
  std::cout << "held-out RMS: auto " << rms[0] << " mm, geometric " << rms[1]
            << " mm, same data without joint errors " << rms[2] << " mm\n";
  EXPECT_LE(rms[0], 1.5 * rms[2]);
  EXPECT_LT(rms[0], 0.2 * rms[1]);

  // Deflection at each verification pose: identified model vs the truth.
  double diff2 = 0, true2 = 0;
  for (int r = 0; r < with.verification.size(); ++r) {
    const double* q = with.verification.q(r);
    const int t = with.verification.target(r);
    const Eigen::Vector3d d_true = Deflection(with.truth, q, t);
    const Eigen::Vector3d d_id = Deflection(automatic.result.model, q, t);
    diff2 += (d_id - d_true).squaredNorm();
    true2 += d_true.squaredNorm();
  }
  const double relative = std::sqrt(diff2 / true2);
  std::cout << "deflection: true RMS " << std::sqrt(true2 / with.verification.size())
            << " mm, identified - true RMS " << std::sqrt(diff2 / with.verification.size())
            << " mm (" << 100 * relative << "%)\n";
  EXPECT_GT(true2, 0);
  EXPECT_LT(relative, 0.05);
}

// The (candidate, fold) calibrations run side by side: the selection is the same, bit for bit,
// on one thread and on four.
TEST(JointErrorAuto, SelectionDoesNotDependOnTheThreads) {
  const AutoFixture with(true, 150, 50);
  PipelineOptions o;
  o.register_frames = false;
  o.joint_error_folds = 4;
  ThreadCountOverride() = 1;
  const JointErrorSelection one = SelectJointErrors(with.nominal, with.identification, o);
  ThreadCountOverride() = 4;
  const JointErrorSelection four = SelectJointErrors(with.nominal, with.identification, o);
  ThreadCountOverride() = 0;
  ASSERT_EQ(one.candidates.size(), four.candidates.size());
  ASSERT_GT(one.candidates.size(), 4u);
  for (size_t k = 0; k < one.candidates.size(); ++k) {
    EXPECT_EQ(one.candidates[k].label, four.candidates[k].label);
    EXPECT_EQ(one.candidates[k].cv_mse, four.candidates[k].cv_mse) << one.candidates[k].label;
    EXPECT_EQ(one.candidates[k].fold_rms, four.candidates[k].fold_rms);
    EXPECT_EQ(one.candidates[k].parameters, four.candidates[k].parameters);
  }
  EXPECT_EQ(one.chosen, four.chosen);
}

// Without non-geometric effects auto keeps the geometric model, or costs at most 2% of held-out RMS.
TEST(JointErrorAuto, KeepsTheGeometryWithoutJointErrors) {
  const AutoFixture without(false, 300, 200);
  const PipelineResult automatic = RunAuto(without, SolverKind::kLinear, true);
  const PipelineResult geometric = RunAuto(without, SolverKind::kLinear, false);
  ASSERT_TRUE(automatic.result.converged()) << automatic.result.message;
  ASSERT_TRUE(geometric.result.converged()) << geometric.result.message;
  PrintSelection("without joint errors", automatic);
  const double rms_auto = automatic.verification_after.norm.rms;
  const double rms_geometric = geometric.verification_after.norm.rms;
  std::cout << "held-out RMS: auto " << rms_auto << " mm, geometric " << rms_geometric << " mm\n";
  EXPECT_TRUE(Chosen(automatic) == "none" || rms_auto <= 1.02 * rms_geometric) << Chosen(automatic);
  EXPECT_EQ(automatic.result.joint_terms.empty(), Chosen(automatic) == "none");
}

// The Ceres solver runs the same selection (same folds) and agrees with the linear solver.
TEST(JointErrorAuto, CeresAgreesWithLinear) {
  const AutoFixture with(true, 200, 50);
  PipelineOptions o;
  o.register_frames = false;
  o.joint_errors_auto = true;
  o.joint_error_folds = 3;
  o.solver = SolverKind::kLinear;
  const PipelineResult linear = RunCalibrationPipeline(with.nominal, with.identification,
                                                       with.verification, o);
  o.solver = SolverKind::kCeres;
  const PipelineResult ceres = RunCalibrationPipeline(with.nominal, with.identification,
                                                      with.verification, o);
  ASSERT_TRUE(linear.result.converged()) << linear.result.message;
  ASSERT_TRUE(ceres.result.converged()) << ceres.result.message;
  EXPECT_EQ(Chosen(ceres), Chosen(linear));
  EXPECT_EQ(Chosen(ceres), "compliance,harmonics");
  for (size_t k = 0; k < linear.joint_error_selection.candidates.size(); ++k) {
    EXPECT_NEAR(ceres.joint_error_selection.candidates[k].cv_rms,
                linear.joint_error_selection.candidates[k].cv_rms, 1e-6);
  }
  double max_diff = 0;
  for (int r = 0; r < with.verification.size(); ++r) {
    const double* q = with.verification.q(r);
    max_diff = std::max(max_diff, (PredictToolPosition(linear.result.model, q, 0) -
                                   PredictToolPosition(ceres.result.model, q, 0))
                                      .norm());
  }
  EXPECT_LT(max_diff, 1e-6);
}

// Predicting with the calibrated model (its own geometry, the stored regressor origins) reproduces
// the solver's final residuals, for both solvers and a registered (moved) base; the YAML round trip
// reproduces the predictions.
TEST(JointErrorAuto, PredictionReproducesTheSolversResiduals) {
  const AutoFixture tracker(true, 200, 0, true);
  for (SolverKind solver : {SolverKind::kLinear, SolverKind::kCeres}) {
    PipelineOptions o;
    o.solver = solver;
    o.joint_errors = {"compliance", "harmonics"};
    const PipelineResult run =
        RunCalibrationPipeline(tracker.nominal, tracker.identification, MeasurementSet(6), o);
    ASSERT_TRUE(run.result.converged()) << run.result.message;
    ASSERT_TRUE(run.registration.moved);
    const RobotModel& model = run.result.model;
    ASSERT_EQ(model.joint_errors.regressor_origins.size(), 6u);
    // The solver's residuals: the geometry at the effective joints of its terms (built on the
    // registered start model).
    RobotModel geometric = model;
    geometric.joint_errors = JointErrorTerms();
    const std::vector<Eigen::Vector3d> solver_errors = PositionErrors(
        geometric, WithEffectiveJointValues(run.result.joint_terms, tracker.identification));
    RobotModel reread;
    ASSERT_TRUE(ParseRobotModelYaml(RobotModelToYaml(model), "calibrated.yaml", &reread).ok());
    double max_diff = 0, max_round_trip = 0, cost = 0;
    for (int r = 0; r < tracker.identification.size(); ++r) {
      const double* q = tracker.identification.q(r);
      const Eigen::Vector3d p = PredictToolPosition(model, q, 0);
      const Eigen::Vector3d e = tracker.identification.position(r) - p;
      max_diff = std::max(max_diff, (e - solver_errors[r]).norm());
      max_round_trip = std::max(max_round_trip, (PredictToolPosition(reread, q, 0) - p).norm());
      cost += 0.5 * e.squaredNorm();
    }
    EXPECT_LT(max_diff, 1e-9);
    EXPECT_LT(max_round_trip, 1e-9);
    if (solver == SolverKind::kLinear) {
      EXPECT_NEAR(cost, run.result.final_cost, 1e-9 * cost);
    }
    // Without the stored origins (the model's own geometry) the difference is far larger: the test
    // can fail.
    RobotModel own = model;
    own.joint_errors.regressor_origins.clear();
    double own_diff = 0;
    for (int r = 0; r < tracker.identification.size(); ++r) {
      const double* q = tracker.identification.q(r);
      own_diff = std::max(own_diff, (PredictToolPosition(own, q, 0) -
                                     PredictToolPosition(model, q, 0)).norm());
    }
    std::cout << "own geometry instead of the stored origins: up to " << own_diff << " mm\n";
    EXPECT_GT(own_diff, 1e-7);
  }
}

TEST(JointErrorTerms, UnknownNameFails) {
  const Fixture f;
  const PipelineResult r = RunPipeline(f, SolverKind::kLinear, {"backlash"});
  EXPECT_EQ(r.result.termination, Termination::kNotIdentifiable);
}

}  // namespace joint_error_terms_test
}  // namespace
}  // namespace lpoe
