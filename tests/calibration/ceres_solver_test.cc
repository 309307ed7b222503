#include "lpoe/ceres_solver.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "lpoe/analysis.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/linear_solver.h"
#include "lpoe/model/simulation.h"
#include "lpoe/model/statistics.h"
#include "loaded_cobot6.h"

namespace lpoe {
namespace {
namespace ceres_solver_test {

// Section 4 of the paper: 100 configurations, 70 identify, 30 verify.
constexpr int kRows = 100;
constexpr int kIdentificationRows = 70;
constexpr double kPaperSigma = 0.03;  // mm, docs/conventions.md
// The two solvers' predicted held-out positions agree to this (mm).
constexpr double kAgreementMm = 1e-6;
// Noise-free data are fitted to this (mm).
constexpr double kNoiseFreeFitMm = 1e-6;
// Gross errors: this fraction of the identification rows is off by kGrossMin..kGrossMax mm.
constexpr double kOutlierFraction = 0.05;
constexpr double kGrossMinMm = 3.0;
constexpr double kGrossMaxMm = 8.0;
constexpr double kRobustLossScaleMm = 0.1;
// A robust loss keeps the held-out error within this factor of the clean-data result...
constexpr double kRobustMaxRatio = 1.5;
// ...while plain least squares is at least this factor worse than clean.
constexpr double kLeastSquaresMinDegradation = 3.0;
// Covariance: predicted 1-sigma against the observed spread, over this many seeds.
constexpr int kCovarianceSeeds = 50;
constexpr double kCovarianceRatioMin = 0.7;
constexpr double kCovarianceRatioMax = 1.3;

struct DataSet {
  RobotModel nominal, actual;
  std::vector<double> joint_zero;
  MeasurementSet identification, verification;
};

DataSet Simulate(const RobotModel& nominal, const KinematicErrors& errors, double sigma,
                 uint64_t seed) {
  DataSet d;
  d.nominal = nominal;
  d.actual = ApplyErrors(nominal, errors);
  d.joint_zero = errors.joint_zero;
  SimulationOptions options;
  options.count = kRows;
  options.noise_sigma = sigma;
  options.seed = seed;
  const MeasurementSet all = SimulateMeasurements(d.actual, d.joint_zero, options);
  all.SplitAt(kIdentificationRows, &d.identification, &d.verification);
  return d;
}

DataSet SectionFour(double sigma, uint64_t seed = 1) {
  return Simulate(MakeCobot6(), PaperTable2Errors(), sigma, seed);
}

// The actual robot's (noise-free) position at a row's commanded configuration.
Eigen::Vector3d TruePosition(const DataSet& d, const MeasurementSet& data, int row) {
  std::vector<double> q(data.q(row), data.q(row) + data.num_joints());
  for (size_t i = 0; i < q.size(); ++i) q[i] += d.joint_zero[i];
  return ToolPosition(d.actual, q.data(), data.target(row));
}

double MaxPredictionDifference(const RobotModel& a, const RobotModel& b,
                               const MeasurementSet& data) {
  double worst = 0;
  for (int r = 0; r < data.size(); ++r) {
    worst = std::max(worst, (ToolPosition(a, data.q(r), data.target(r)) -
                             ToolPosition(b, data.q(r), data.target(r)))
                                .norm());
  }
  return worst;
}

double MaxTrueError(const DataSet& d, const RobotModel& model) {
  double worst = 0;
  for (int r = 0; r < d.verification.size(); ++r) {
    worst = std::max(worst, (ToolPosition(model, d.verification.q(r), d.verification.target(r)) -
                             TruePosition(d, d.verification, r))
                                .norm());
  }
  return worst;
}

CeresSolverOptions CeresOptions(ParameterizationKind kind = ParameterizationKind::kIdentifiable) {
  CeresSolverOptions o;
  o.parameterization = kind;
  o.num_threads = 1;
  // These tests compare the two solvers' minima to 1e-6 mm: stop on round-off, not on the
  // statistical rule (a step of 1 % of a standard deviation, convergence.h).
  o.convergence.sd_fraction = 0;
  return o;
}

LinearSolverOptions LinearOptions(ParameterizationKind kind = ParameterizationKind::kIdentifiable) {
  LinearSolverOptions o;
  o.parameterization = kind;
  o.convergence.sd_fraction = 0;
  return o;
}

void ExpectAgreement(const DataSet& d, ParameterizationKind kind) {
  const CalibrationResult lin = CalibrateLinear(d.nominal, d.identification, LinearOptions(kind));
  const CalibrationResult cer = CalibrateCeres(d.nominal, d.identification, CeresOptions(kind));
  ASSERT_TRUE(lin.converged()) << lin.message;
  ASSERT_TRUE(cer.converged()) << cer.message;
  const double difference = MaxPredictionDifference(lin.model, cer.model, d.verification);
  EXPECT_LT(difference, kAgreementMm);
  std::cout << "[ figures  ] " << d.nominal.name << " (" << ParameterizationName(kind)
            << "): held-out predictions differ by " << difference << " mm; linear "
            << lin.iterations << " it " << lin.wall_time_seconds * 1e3 << " ms, ceres "
            << cer.iterations << " it " << cer.wall_time_seconds * 1e3 << " ms\n";
  EXPECT_EQ(cer.rank, lin.rank);
  EXPECT_NEAR(cer.condition_number, lin.condition_number, 1e-6 * lin.condition_number);
  // The calibration did something: the nominal model is millimetres off.
  EXPECT_GT(MaxPredictionDifference(d.nominal, cer.model, d.verification), 0.1);
}

TEST(CeresSolver, AgreesWithLinearOnSectionFourNoiseFree) {
  const DataSet d = SectionFour(0.0);
  ExpectAgreement(d, ParameterizationKind::kIdentifiable);
  const CalibrationResult cer = CalibrateCeres(d.nominal, d.identification, CeresOptions());
  EXPECT_LT(PositionErrorStatistics(cer.model, d.identification).norm.max_abs, kNoiseFreeFitMm);
  EXPECT_LT(PositionErrorStatistics(cer.model, d.verification).norm.max_abs, kNoiseFreeFitMm);
}

TEST(CeresSolver, AgreesWithLinearOnSectionFourNoisy) {
  ExpectAgreement(SectionFour(kPaperSigma), ParameterizationKind::kIdentifiable);
}

TEST(CeresSolver, AgreesWithLinearWithFullParameterization) {
  ExpectAgreement(SectionFour(kPaperSigma), ParameterizationKind::kFull);
}

TEST(CeresSolver, AgreesWithLinearOnUr5Like) {
  const RobotModel nominal = MakeUr5Like();
  ExpectAgreement(Simulate(nominal, RandomErrors(nominal, 0.005, 2.0, 0.005, 0.005, 11),
                           kPaperSigma, 12),
                  ParameterizationKind::kIdentifiable);
}

TEST(CeresSolver, AgreesWithLinearOnSevenJointArm) {
  const RobotModel nominal = MakeSevenJointArm();
  ExpectAgreement(Simulate(nominal, RandomErrors(nominal, 0.005, 2.0, 0.005, 0.005, 21),
                           kPaperSigma, 22),
                  ParameterizationKind::kIdentifiable);
}

TEST(CeresSolver, AgreesWithLinearOnPoseData) {
  const RobotModel nominal = MakeCobot6();
  DataSet d;
  d.nominal = nominal;
  const KinematicErrors errors = PaperTable2Errors();
  d.actual = ApplyErrors(nominal, errors);
  d.joint_zero = errors.joint_zero;
  SimulationOptions sim;
  sim.count = kRows;
  sim.pose = true;
  sim.noise_sigma = kPaperSigma;
  sim.orientation_noise_sigma = 1e-5;
  sim.seed = 31;
  SimulateMeasurements(d.actual, d.joint_zero, sim)
      .SplitAt(kIdentificationRows, &d.identification, &d.verification);
  LinearSolverOptions lo = LinearOptions();
  lo.use_orientation = true;
  CeresSolverOptions co = CeresOptions();
  co.use_orientation = true;
  const CalibrationResult lin = CalibrateLinear(d.nominal, d.identification, lo);
  const CalibrationResult cer = CalibrateCeres(d.nominal, d.identification, co);
  ASSERT_TRUE(lin.converged()) << lin.message;
  ASSERT_TRUE(cer.converged()) << cer.message;
  EXPECT_EQ(cer.parameterization.num_parameters, lin.parameterization.num_parameters);
  EXPECT_LT(MaxPredictionDifference(lin.model, cer.model, d.verification), kAgreementMm);
}

TEST(CeresSolver, ResultCarriesHistoryAndCovariance) {
  const DataSet d = SectionFour(kPaperSigma);
  CeresSolverOptions o = CeresOptions();
  o.sigma = kPaperSigma;
  const CalibrationResult r = CalibrateCeres(d.nominal, d.identification, o);
  ASSERT_TRUE(r.converged()) << r.message;
  ASSERT_GE(r.history.size(), 2u);
  EXPECT_EQ(r.history.front().iteration, 0);
  EXPECT_GT(r.history.front().max_error, 1.0);               // nominal: mm off
  EXPECT_LT(r.history.back().max_error, 10 * kPaperSigma);  // calibrated: noise level
  EXPECT_NEAR(r.history.back().cost, r.final_cost, 1e-12 + 1e-9 * r.final_cost);
  EXPECT_GT(r.iterations, 0);
  ASSERT_EQ(r.covariance.rows(), r.parameterization.num_parameters);
  ASSERT_EQ(r.covariance.cols(), r.parameterization.num_parameters);
  EXPECT_TRUE(r.covariance.isApprox(r.covariance.transpose(), 1e-9));
  EXPECT_GT(r.covariance.diagonal().minCoeff(), 0.0);
  EXPECT_GT(r.wall_time_seconds, 0.0);
}

// The a-priori covariance (sigma given) and the a-posteriori one (sigma estimated from the
// residuals) agree when sigma is the true noise, up to the sampling spread of the variance factor.
TEST(CeresSolver, APosterioriCovarianceScalesByVarianceFactor) {
  const DataSet d = SectionFour(kPaperSigma);
  CeresSolverOptions o = CeresOptions();
  o.sigma = kPaperSigma;
  const CalibrationResult prior = CalibrateCeres(d.nominal, d.identification, o);
  o.a_posteriori_covariance = true;
  const CalibrationResult post = CalibrateCeres(d.nominal, d.identification, o);
  ASSERT_EQ(prior.covariance.rows(), post.covariance.rows());
  const double factor = post.covariance(0, 0) / prior.covariance(0, 0);
  EXPECT_TRUE(post.covariance.isApprox(factor * prior.covariance, 1e-9));
  const int dof = 3 * d.identification.size() - prior.parameterization.num_parameters;
  EXPECT_NEAR(factor, 2.0 * prior.final_cost / (kPaperSigma * kPaperSigma) / dof, 1e-9 * factor);
  EXPECT_GT(factor, 0.7);
  EXPECT_LT(factor, 1.3);
}

TEST(CeresSolver, RobustLossResistsGrossErrors) {
  const DataSet clean = SectionFour(kPaperSigma, 41);
  DataSet dirty = clean;
  // Gross errors on ceil(5%) of the rows, spread evenly, magnitudes across [kGrossMin, kGrossMax],
  // in varying directions.
  const int rows = dirty.identification.size();
  const int outliers = static_cast<int>(std::ceil(kOutlierFraction * rows));
  for (int k = 0; k < outliers; ++k) {
    const int r = (2 * k + 1) * rows / (2 * outliers);
    const double magnitude =
        kGrossMinMm + (kGrossMaxMm - kGrossMinMm) * k / std::max(1, outliers - 1);
    const Eigen::Vector3d direction =
        Eigen::Vector3d(std::cos(r), std::sin(r), 0.5 * std::cos(3.0 * r)).normalized();
    dirty.identification.mutable_position(r) += magnitude * direction;
  }
  ASSERT_EQ(outliers, 4);

  const CeresSolverOptions plain = CeresOptions();
  const double clean_error =
      MaxTrueError(clean, CalibrateCeres(clean.nominal, clean.identification, plain).model);
  const double ls_error =
      MaxTrueError(dirty, CalibrateCeres(dirty.nominal, dirty.identification, plain).model);
  EXPECT_GT(ls_error, kLeastSquaresMinDegradation * clean_error);
  for (const char* loss : {"cauchy", "huber"}) {
    CeresSolverOptions robust = CeresOptions();
    robust.loss = loss;
    robust.loss_scale = kRobustLossScaleMm;
    const CalibrationResult r = CalibrateCeres(dirty.nominal, dirty.identification, robust);
    ASSERT_TRUE(r.converged()) << loss << ": " << r.message;
    const double robust_error = MaxTrueError(dirty, r.model);
    std::cout << "[ figures  ] held-out max error vs truth: clean " << clean_error
              << " mm, least squares with outliers " << ls_error << " mm, " << loss << " "
              << robust_error << " mm\n";
    EXPECT_LT(robust_error, kRobustMaxRatio * clean_error)
        << loss << ": clean " << clean_error << " mm, least squares " << ls_error << " mm";
  }
}

// Over many noise draws, the covariance predicts the spread of predicted-versus-true held-out
// positions: sqrt(mean trace(J C J^T)) against the RMS of the actual errors.
TEST(CeresSolver, CovariancePredictsHeldOutErrorSpread) {
  double predicted_sq = 0, observed_sq = 0;
  int count = 0;
  for (int seed = 0; seed < kCovarianceSeeds; ++seed) {
    const DataSet d = SectionFour(kPaperSigma, 1000 + seed);
    CeresSolverOptions o = CeresOptions();
    o.sigma = kPaperSigma;
    const CalibrationResult r = CalibrateCeres(d.nominal, d.identification, o);
    ASSERT_TRUE(r.converged()) << r.message;
    ASSERT_EQ(r.covariance.rows(), r.parameterization.num_parameters);
    for (int row = 0; row < d.verification.size(); ++row) {
      const Eigen::Matrix3d C = PredictedPositionCovariance(r, d.verification.q(row), 0);
      predicted_sq += C.trace();
      observed_sq += (ToolPosition(r.model, d.verification.q(row), 0) -
                      TruePosition(d, d.verification, row))
                         .squaredNorm();
      ++count;
    }
  }
  const double ratio = std::sqrt(observed_sq / count) / std::sqrt(predicted_sq / count);
  EXPECT_GT(ratio, kCovarianceRatioMin);
  EXPECT_LT(ratio, kCovarianceRatioMax);
  RecordProperty("covariance_ratio", std::to_string(ratio));
  std::cout << "[ figures  ] observed / predicted held-out RMS over " << kCovarianceSeeds
            << " seeds: " << ratio << "\n";
}

TEST(CeresSolver, RefusesTooFewRows) {
  DataSet d = SectionFour(0.0);
  std::vector<int> rows = {0, 1, 2, 3, 4};
  const MeasurementSet few = d.identification.Subset(rows);
  const CalibrationResult lin = CalibrateLinear(d.nominal, few, LinearOptions());
  const CalibrationResult cer = CalibrateCeres(d.nominal, few, CeresOptions());
  EXPECT_EQ(cer.termination, Termination::kNotIdentifiable);
  EXPECT_EQ(cer.message, lin.message);
}

TEST(CeresSolver, RefusesDegeneratePoses) {
  // Only joint 1 moves: the other joints' frames cannot be told apart.
  const RobotModel nominal = MakeCobot6();
  MeasurementSet data(nominal.num_joints());
  for (int r = 0; r < 40; ++r) {
    const double q[6] = {-3.0 + 0.15 * r, 0.3, -0.2, 0.4, 0.1, 0.2};
    data.Add(q, ToolPosition(nominal, q, 0));
  }
  const CalibrationResult lin = CalibrateLinear(nominal, data, LinearOptions());
  const CalibrationResult cer = CalibrateCeres(nominal, data, CeresOptions());
  EXPECT_EQ(cer.termination, Termination::kNotIdentifiable);
  EXPECT_EQ(lin.termination, Termination::kNotIdentifiable);
  EXPECT_EQ(cer.rank, lin.rank);
  EXPECT_EQ(cer.message, lin.message);
}

TEST(CeresSolver, LeavesUnmeasuredToolsAlone) {
  RobotModel nominal = MakeCobot6();
  Tool spare;
  spare.name = "spare";
  spare.origin = SE3d(Eigen::Matrix3d::Identity(), Eigen::Vector3d(-50, 10, 70));
  nominal.tools.push_back(spare);
  KinematicErrors errors = PaperTable2Errors();
  errors.frame.push_back(Vector6d::Zero());
  const DataSet d = Simulate(nominal, errors, kPaperSigma, 51);  // measures tool 0 only
  CeresSolverOptions co = CeresOptions();
  co.a_posteriori_covariance = true;  // the linear solver's form, compared below
  const CalibrationResult r = CalibrateCeres(d.nominal, d.identification, co);
  ASSERT_TRUE(r.converged()) << r.message;
  EXPECT_EQ((r.model.tools[1].origin.t - spare.origin.t).norm(), 0.0);
  const Parameterization& p = r.parameterization;
  const int f = nominal.num_joints() + 1;
  ASSERT_EQ(r.covariance.rows(), p.num_parameters);
  EXPECT_EQ(r.covariance.middleRows(p.offset[f], p.basis[f].cols()).norm(), 0.0);
  EXPECT_GT(r.covariance.topRows(p.offset[f]).norm(), 0.0);
  // As the linear solver: the unmeasured tool is not among the solved parameters, its translations
  // are listed as not identifiable with the reason, and the covariance (solved numbering) equals
  // the linear solver's in size and, to the solvers' agreement, in value.
  const CalibrationResult lin = CalibrateLinear(d.nominal, d.identification, LinearSolverOptions());
  ASSERT_TRUE(lin.converged()) << lin.message;
  EXPECT_EQ(p.num_parameters, lin.parameterization.num_parameters);
  EXPECT_EQ(p.basis[f].cols(), 0);
  int listed = 0;
  for (const Direction& dir : p.unidentifiable) {
    if (dir.name.rfind("spare.t", 0) == 0) {
      ++listed;
      EXPECT_NE(dir.reason.find("never measured"), std::string::npos) << dir.reason;
    }
  }
  EXPECT_EQ(listed, 3);
  for (const Direction& dir : p.parameters) EXPECT_NE(dir.name.rfind("spare.", 0), 0u) << dir.name;
  ASSERT_EQ(lin.covariance.rows(), p.num_parameters);
  for (int k = 0; k < p.num_parameters; ++k) {
    EXPECT_EQ(p.parameters[k].name, lin.parameterization.parameters[k].name);
    EXPECT_NEAR(std::sqrt(r.covariance(k, k)), std::sqrt(lin.covariance(k, k)),
                0.02 * std::sqrt(lin.covariance(k, k)))
        << p.parameters[k].name;
  }
}

// linear_solver "auto" (the default) takes the normal equations only where they lose nothing that
// matters: identifiable parameterization, no robust loss, no gravity tilt, column-scaled condition
// number at most kNormalEquationsMaxCondition; a named solver is kept (dense_qr turns into the
// normal equations for batched rows only).
TEST(CeresSolver, AutoLinearSolverRule) {
  const double limit = CeresSolverOptions::kNormalEquationsMaxCondition;
  CeresSolverOptions o;
  EXPECT_EQ(o.linear_solver, "auto");
  EXPECT_TRUE(ValidateCeresSolverOptions(o).ok());
  EXPECT_EQ(CeresLinearSolverFor(o, 20.0, 1), "dense_normal_cholesky");
  EXPECT_EQ(CeresLinearSolverFor(o, limit, 1), "dense_normal_cholesky");
  EXPECT_EQ(CeresLinearSolverFor(o, 1.01 * limit, 1), "dense_qr");
  EXPECT_EQ(CeresLinearSolverFor(o, 1.01 * limit, 1024), "dense_normal_cholesky");  // batched
  o.parameterization = ParameterizationKind::kFull;
  EXPECT_EQ(CeresLinearSolverFor(o, 20.0, 1), "dense_qr");
  o = CeresSolverOptions();
  o.loss = "huber";
  EXPECT_EQ(CeresLinearSolverFor(o, 20.0, 1), "dense_qr");
  o = CeresSolverOptions();
  o.bilinear_effects = {std::make_shared<const GravityTiltModel>(MakeCobot6())};
  EXPECT_EQ(CeresLinearSolverFor(o, 20.0, 1), "dense_qr");
  o = CeresSolverOptions();
  o.linear_solver = "dense_qr";
  EXPECT_EQ(CeresLinearSolverFor(o, 20.0, 1), "dense_qr");
  EXPECT_EQ(CeresLinearSolverFor(o, 20.0, 1024), "dense_normal_cholesky");
  o.linear_solver = "sparse_normal_cholesky";
  EXPECT_EQ(CeresLinearSolverFor(o, 20.0, 1024), "sparse_normal_cholesky");
}

// "auto" (here the normal equations: condition numbers about 5 and 20) and dense_qr reach the
// same calibration, geometric and with compliance + harmonics (cobot6, 300 poses of an arm that
// deflects); the history's errors are those of PositionErrorStatistics at the effective joint
// values.
TEST(CeresSolver, AutoLinearSolverGivesTheQrSolution) {
  const testing::LoadedCobot6 loaded = testing::MakeLoadedCobot6(300, 0.01, 7);
  const RobotModel& nominal = loaded.nominal;
  const MeasurementSet& data = loaded.data;
  std::vector<std::shared_ptr<const JointTerm>> terms;
  for (const char* name : {"compliance", "harmonics"}) {
    std::shared_ptr<const JointTerm> term;
    ASSERT_TRUE(MakeJointTerm(name, nominal, &term).ok());
    terms.push_back(term);
  }
  for (bool with_terms : {false, true}) {
    CeresSolverOptions o = CeresOptions();
    o.sigma = 0.01;
    if (with_terms) o.joint_terms = terms;
    ASSERT_EQ(o.linear_solver, "auto");
    const CalibrationResult automatic = CalibrateCeres(nominal, data, o);
    o.linear_solver = "dense_qr";
    const CalibrationResult qr = CalibrateCeres(nominal, data, o);
    ASSERT_TRUE(automatic.converged()) << automatic.message;
    ASSERT_TRUE(qr.converged()) << qr.message;
    EXPECT_LT(automatic.condition_number, CeresSolverOptions::kNormalEquationsMaxCondition);
    const MeasurementSet q_auto =
        with_terms ? WithEffectiveJointValues(automatic.joint_terms, data) : data;
    const MeasurementSet q_qr = with_terms ? WithEffectiveJointValues(qr.joint_terms, data) : data;
    double worst = 0;
    for (int r = 0; r < data.size(); ++r) {
      const Eigen::Vector3d a = ToolPosition(automatic.model, q_auto.q(r), data.target(r));
      const Eigen::Vector3d b = ToolPosition(qr.model, q_qr.q(r), data.target(r));
      worst = std::max(worst, (a - b).norm());
    }
    EXPECT_LT(worst, kAgreementMm) << "with terms: " << with_terms;
    EXPECT_NEAR(automatic.final_cost, qr.final_cost, 1e-9 * qr.final_cost);
    ASSERT_EQ(automatic.covariance.rows(), qr.covariance.rows());
    EXPECT_LT((automatic.covariance - qr.covariance).norm(), 1e-6 * qr.covariance.norm());

    const ErrorStatistics last = PositionErrorStatistics(automatic.model, q_auto);
    EXPECT_NEAR(automatic.history.back().max_error, last.norm.max_abs, 1e-12);
    EXPECT_NEAR(automatic.history.back().mean_error, last.norm.mean_abs, 1e-12);
  }
}

TEST(CeresSolver, ValidatesOptions) {
  CeresSolverOptions o;
  EXPECT_TRUE(ValidateCeresSolverOptions(o).ok());
  for (const char* solver : {"dense_qr", "dense_normal_cholesky", "sparse_normal_cholesky",
                             "dense_schur"}) {
    o.linear_solver = solver;
    EXPECT_TRUE(ValidateCeresSolverOptions(o).ok()) << solver;
  }
  o.linear_solver = "magic";
  EXPECT_FALSE(ValidateCeresSolverOptions(o).ok());
  o = CeresSolverOptions();
  o.loss = "tukey";
  EXPECT_FALSE(ValidateCeresSolverOptions(o).ok());
  o = CeresSolverOptions();
  o.sigma = 0;
  EXPECT_FALSE(ValidateCeresSolverOptions(o).ok());
  o = CeresSolverOptions();
  o.loss_scale = -1;
  EXPECT_FALSE(ValidateCeresSolverOptions(o).ok());
}

}  // namespace ceres_solver_test
}  // namespace
}  // namespace lpoe
