// Issue 11, "offer to identify the gravity direction's tilt": the tilt's joint-space columns against
// finite differences and autodiff, both solvers' Jacobians, and the pipeline on simulated data of a
// small arm whose base is not level (docs/joint_errors.md, "Gravity tilt").
#include <algorithm>
#include <cmath>
#include <iostream>
#include <memory>
#include <numeric>
#include <string>
#include <vector>

#include <ceres/ceres.h>
#include <ceres/jet.h>
#include <gtest/gtest.h>

#include "calibration/block_kind.h"
#include "lpoe/joint_error_list.h"
#include "lpoe/io/io.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/pipeline.h"
#include "lpoe/problem_builder.h"
#include "lpoe/model/simulation.h"
#include "lpoe/model/statistics.h"
#include "linearization/normal_equations.h"

namespace lpoe {
namespace {
namespace gravity_tilt_test {

constexpr double kDeg = M_PI / 180.0;

// cobot6 with a payload, its physical compliance products (SmallArmJointErrors), and a position
// parameterization with the compliance block and the gravity tilt on it.
struct Loaded {
  RobotModel model = MakeCobot6();
  std::vector<double> theta;
  std::shared_ptr<const JointTerm> term;
  std::shared_ptr<const GravityTiltModel> tilt_model;
  Parameterization p;
  Loaded() {
    model.payload.mass = 1.0;
    model.payload.com = Eigen::Vector3d(0, 0, 50);
    theta = CompliancePhysicsParameters(SmallArmJointErrors(model, SmallArmOptions()));
    p = MakeParameterization(model, ParameterizationKind::kIdentifiable, DataKind::kPosition);
    EXPECT_TRUE(MakeJointTerm("compliance", model, &term).ok());
    AddJointBlock(term, &p);
    tilt_model = std::make_shared<const GravityTiltModel>(model);
    AddBilinearBlock(tilt_model, 0, &p);
  }
};

std::vector<double> Configuration(uint64_t seed) {
  std::vector<double> q(6);
  uint64_t s = seed * 2654435761u + 12345;
  for (double& v : q) {
    s = s * 6364136223846793005ull + 1442695040888963407ull;
    v = -M_PI + 2 * M_PI * static_cast<double>(s >> 11) / 9007199254740992.0;
  }
  return q;
}

TEST(GravityTilt, AxesArePerpendicularAndTheJacobianIsExact) {
  for (const Eigen::Vector3d& g : {Eigen::Vector3d(0, 0, -9.81), Eigen::Vector3d(9.81, 0, 0),
                                   Eigen::Vector3d(1, -2, -9)}) {
    const Eigen::Matrix<double, 3, 2> U = GravityTiltAxes(g);
    EXPECT_NEAR(U.col(0).dot(g), 0, 1e-12);
    EXPECT_NEAR(U.col(1).dot(g), 0, 1e-12);
    EXPECT_NEAR(U.col(0).dot(U.col(1)), 0, 1e-12);
    EXPECT_NEAR(U.col(0).norm(), 1, 1e-12);
    EXPECT_NEAR(U.col(1).norm(), 1, 1e-12);
    const double t[2] = {0.004, -0.007};
    const Eigen::Matrix<double, 3, 2> J = TiltedGravityJacobian(g, U, t);
    const double h = 1e-6;
    for (int a = 0; a < 2; ++a) {
      double tp[2] = {t[0], t[1]}, tm[2] = {t[0], t[1]};
      tp[a] += h;
      tm[a] -= h;
      const Eigen::Vector3d fd =
          (TiltedGravity<double>(g, U, tp) - TiltedGravity<double>(g, U, tm)) / (2 * h);
      EXPECT_LT((fd - J.col(a)).norm(), 1e-8 * g.norm());
    }
    // GravityTiltBetween inverts TiltedGravity.
    const Eigen::Vector2d back = GravityTiltBetween(g, TiltedGravity<double>(g, U, t));
    EXPECT_NEAR(back(0), t[0], 1e-12);
    EXPECT_NEAR(back(1), t[1], 1e-12);
  }
  // For gravity along -z the axes are the base's x and y.
  const Eigen::Matrix<double, 3, 2> U = GravityTiltAxes(Eigen::Vector3d(0, 0, -9.81));
  EXPECT_LT((U.col(0) - Eigen::Vector3d::UnitX()).norm(), 1e-15);
  EXPECT_LT((U.col(1) - Eigen::Vector3d::UnitY()).norm(), 1e-15);
}

// GravityTiltModel::RowRegressors forms Z_a = Y_a(q) B from Y_a's entries at their joints only
// (ComplianceValuesGravityAxes): equal to the dense product of ComplianceRegressorGravityAxes'
// matrices with a general (not selecting) basis, and the values are those matrices' entries.
TEST(GravityTilt, RowRegressorsEqualTheDenseProducts) {
  const Loaded l;
  const int n = 6;
  Parameterization p = l.p;
  const JointTerm* term = l.term.get();
  const int P = term->num_parameters();
  ASSERT_EQ(P, NumComplianceParameters(n));
  // A dense basis of 11 combinations (only the rows' product is under test here).
  Eigen::MatrixXd B(P, 11);
  for (int c = 0; c < B.cols(); ++c) {
    for (int r = 0; r < P; ++r) B(r, c) = std::sin(0.7 * r + 1.3 * c + 0.1 * r * c);
  }
  p.joint_blocks[0].basis = B;
  std::vector<double> values(3 * P);
  double* const y[3] = {values.data(), values.data() + P, values.data() + 2 * P};
  for (uint64_t trial = 0; trial < 5; ++trial) {
    const std::vector<double> q = Configuration(trial + 11);
    Eigen::MatrixXd Y[3];
    std::vector<Eigen::MatrixXd> Z;
    ComplianceRegressorGravityAxes(l.model, q.data(), Y);
    l.tilt_model->RowRegressors(p.joint_blocks[0].basis, q.data(), &Z);
    ASSERT_EQ(Z.size(), 3u);
    ComplianceValuesGravityAxes(l.model, q.data(), y);
    for (int a = 0; a < 3; ++a) {
      const Eigen::MatrixXd expected = Y[a] * B;
      ASSERT_EQ(Z[a].rows(), n);
      ASSERT_EQ(Z[a].cols(), B.cols());
      const double scale = expected.cwiseAbs().maxCoeff();
      ASSERT_GT(scale, 0);
      EXPECT_LT((Z[a] - expected).cwiseAbs().maxCoeff(), 1e-13 * scale) << "axis " << a;
      for (int c = 0; c < P; ++c) {
        EXPECT_EQ(y[a][c], Y[a](term->ParameterJoint(c), c)) << "axis " << a << " c " << c;
      }
      // Every other entry of Y_a is zero.
      int nonzero = 0;
      for (int j = 0; j < n; ++j) {
        for (int c = 0; c < P; ++c) nonzero += Y[a](j, c) != 0 && term->ParameterJoint(c) != j;
      }
      EXPECT_EQ(nonzero, 0) << "axis " << a;
    }
  }
}

// The extra joint-space columns of the linear solver (AddNonlinearRowColumns): d(dq)/dt and the
// compliance columns at the tilt, against central differences of the offsets and against Jets
// through the templated TiltedGravity / ComplianceOffsets (what the Ceres residual uses); the
// offsets themselves are those of the model with the tilted gravity.
TEST(GravityTilt, JointColumnsMatchFiniteDifferencesAndAutodiff) {
  const Loaded l;
  const int n = 6;
  const Parameterization& p = l.p;
  const JointTerm* term = l.term.get();
  const GravityTiltModel* tilt_model = l.tilt_model.get();
  const int K = p.num_joint_parameters();
  const int P = term->num_parameters();
  ASSERT_EQ(K, P + 2);
  Eigen::VectorXd state(K);
  state.head(P) = Eigen::Map<const Eigen::VectorXd>(l.theta.data(), P);
  state(P) = 0.3 * kDeg;
  state(P + 1) = -0.2 * kDeg;
  for (uint64_t trial = 0; trial < 5; ++trial) {
    const std::vector<double> q = Configuration(trial + 1);
    auto offsets = [&](const Eigen::VectorXd& s, Eigen::MatrixXd* columns) {
      Eigen::MatrixXd R = Eigen::MatrixXd::Zero(n, K);
      Eigen::MatrixXd Y(n, P);
      term->Regressor(q.data(), Y.data());
      R.leftCols(P) = Y;
      Eigen::VectorXd q_eff = Eigen::Map<const Eigen::VectorXd>(q.data(), n) + R * s;
      internal::AddNonlinearRowColumns(p, q.data(), s, R, &q_eff);
      if (columns != nullptr) *columns = R;
      return Eigen::VectorXd(q_eff - Eigen::Map<const Eigen::VectorXd>(q.data(), n));
    };
    Eigen::MatrixXd R;
    const Eigen::VectorXd dq = offsets(state, &R);
    // The offsets are the compliance of the model with the tilted gravity.
    RobotModel tilted = l.model;
    tilted.gravity = tilt_model->Tilted(state.data() + P);
    *tilted.joint_errors.MutableValues("compliance") = l.theta;
    std::vector<double> expected(n);
    JointErrorOffsets(tilted, q.data(), expected.data());
    for (int j = 0; j < n; ++j) {
      EXPECT_NEAR(dq(j), expected[j], 1e-9 * std::abs(expected[j]) + 1e-15) << "joint " << j + 1;
    }
    // Tilt columns: finite differences (1e-6 rad) and Jets.
    using Jet = ceres::Jet<double, 2>;
    Eigen::MatrixXd Y_axes[3];
    tilt_model->AxisRegressors(q.data(), Y_axes);
    const Jet t[2] = {Jet(state(P), 0), Jet(state(P + 1), 1)};
    const std::vector<Jet> theta_jet(l.theta.begin(), l.theta.end());
    std::vector<Jet> dq_jet(n);
    ComplianceOffsets<Jet>(Y_axes, TiltedGravity<Jet>(l.model.gravity, tilt_model->axes(), t),
                           theta_jet.data(), dq_jet.data());
    for (int a = 0; a < 2; ++a) {
      const double h = 1e-6;
      Eigen::VectorXd sp = state, sm = state;
      sp(P + a) += h;
      sm(P + a) -= h;
      const Eigen::VectorXd fd = (offsets(sp, nullptr) - offsets(sm, nullptr)) / (2 * h);
      const double scale = fd.cwiseAbs().maxCoeff();
      ASSERT_GT(scale, 0);
      for (int j = 0; j < n; ++j) {
        EXPECT_NEAR(R(j, P + a), fd(j), 1e-6 * scale) << "joint " << j + 1 << " tilt " << a;
        EXPECT_NEAR(R(j, P + a), dq_jet[j].v(a), 1e-12 * scale) << "joint " << j + 1;
      }
    }
    // A tilt loads the vertical joint 1 (gravity no longer along its axis).
    EXPECT_GT(R.row(0).tail(2).norm(), 1e-3 * R.rightCols(2).norm());
    // Compliance columns at the tilt: differences in the products (the offsets are linear in them).
    for (int c = 0; c < P; c += 7) {
      const double scale = R.col(c).cwiseAbs().maxCoeff();
      if (scale == 0) continue;
      const double h = 1e-3 / scale;
      Eigen::VectorXd sp = state, sm = state;
      sp(c) += h;
      sm(c) -= h;
      const Eigen::VectorXd fd = (offsets(sp, nullptr) - offsets(sm, nullptr)) / (2 * h);
      EXPECT_LT((fd - R.col(c)).cwiseAbs().maxCoeff(), 1e-7 * scale) << "column " << c;
    }
  }
}

// Simulated data: cobot6 with geometric errors, the simulator's small-arm compliance and harmonics,
// a base tilted by `tilt_deg` (t1, t2), noise 0.01 mm, `rows` identification and 200 verification
// poses.
struct TiltFixture {
  RobotModel nominal = MakeCobot6();
  RobotModel actual;
  MeasurementSet identification, verification;
  Eigen::Vector2d true_tilt;
  double noise = 0.01;
  TiltFixture(double t1_deg, double t2_deg, bool joint_errors = true, int rows = 300,
              uint64_t seed = 7) {
    nominal.payload.mass = 1.0;
    nominal.payload.com = Eigen::Vector3d(0, 0, 50);
    const KinematicErrors errors = RandomErrors(nominal, 2e-3, 0.5, 1e-3, 2e-3, 11);
    actual = ApplyErrors(nominal, errors);
    const double t[2] = {t1_deg * kDeg, t2_deg * kDeg};
    actual.gravity = TiltedGravity<double>(nominal.gravity, t);
    // What the calibration can find: gravity relative to the actual robot's base (joint 1's frame,
    // which carries a geometric error of about 0.1 deg here), seen in the nominal model's.
    true_tilt = GravityTiltBetween(nominal.gravity, nominal.joints[0].origin.R *
                                                        actual.joints[0].origin.R.transpose() *
                                                        actual.gravity);
    if (joint_errors) {
      ApplyJointErrorPhysics(SmallArmJointErrors(nominal, SmallArmOptions()), {"compliance", "harmonics"}, &actual);
    }
    SimulationOptions options;
    options.count = rows + 200;
    options.noise_sigma = noise;
    options.seed = seed;
    const MeasurementSet data = SimulateMeasurements(actual, errors.joint_zero, options);
    std::vector<int> id(rows), ver(200);
    std::iota(id.begin(), id.end(), 0);
    std::iota(ver.begin(), ver.end(), rows);
    identification = data.Subset(id);
    verification = data.Subset(ver);
  }
};

PipelineResult RunTilt(const TiltFixture& f, SolverKind solver, const std::vector<std::string>& terms,
                   bool register_frames = false) {
  PipelineOptions o;
  o.solver = solver;
  o.register_frames = register_frames;
  o.joint_errors = terms;
  return RunCalibrationPipeline(f.nominal, f.identification, f.verification, o);
}

const std::vector<std::string> kWithTilt = {"compliance", "harmonics", "tilt"};
const std::vector<std::string> kWithoutTilt = {"compliance", "harmonics"};

void Print(const std::string& what, const PipelineResult& r) {
  const GravityTiltResult& t = r.result.gravity_tilt;
  std::cout << what << ": held-out RMS " << r.verification_after.norm.rms << " mm";
  if (t.identified) {
    std::cout << ", tilt " << t.tilt(0) / kDeg << " +- " << t.standard_deviation(0) / kDeg
              << ", " << t.tilt(1) / kDeg << " +- " << t.standard_deviation(1) / kDeg
              << " deg (predicted sd " << t.predicted_standard_deviation(0) / kDeg << ", "
              << t.predicted_standard_deviation(1) / kDeg << "; kept fraction "
              << t.kept_fraction << ")";
  } else if (t.requested) {
    std::cout << ", " << t.message;
  }
  std::cout << "\n";
}

// Both solvers' Jacobians with the tilt at a compliance solution: the linear solver's normal
// equations (analytic tilt columns) equal J^T J and J^T r of Ceres's autodiff Jacobian, whose tilt
// columns match central differences of Ceres's own residuals.
TEST(GravityTilt, SolverJacobiansAgreeWithFiniteDifferences) {
  const TiltFixture f(0.3, -0.2, true, 120);
  const PipelineResult first = RunTilt(f, SolverKind::kLinear, kWithoutTilt);
  ASSERT_TRUE(first.result.converged()) << first.result.message;
  CalibrationProblemOptions o;
  for (const std::string& name : kWithoutTilt) {
    std::shared_ptr<const JointTerm> term;
    ASSERT_TRUE(MakeJointTerm(name, f.nominal, &term).ok());
    o.joint_terms.push_back(term);
  }
  o.bilinear_effects = {std::make_shared<const GravityTiltModel>(f.nominal)};
  o.initial_joint_terms = first.result.joint_terms;
  CalibrationProblem builder(f.nominal, f.identification, o);
  ASSERT_TRUE(builder.block_status().ok()) << builder.block_status().message();
  builder.bilinear_block()[0] = 0.2 * kDeg;
  builder.bilinear_block()[1] = -0.1 * kDeg;
  ceres::Problem problem;
  builder.AddTo(&problem);
  std::vector<double*> blocks = builder.parameter_blocks();
  ceres::Problem::EvaluateOptions eval;
  eval.parameter_blocks = blocks;
  double cost = 0;
  std::vector<double> residuals;
  ceres::CRSMatrix crs;
  ASSERT_TRUE(problem.Evaluate(eval, &cost, &residuals, nullptr, &crs));
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(crs.num_rows, crs.num_cols);
  for (int r = 0; r < crs.num_rows; ++r) {
    for (int k = crs.rows[r]; k < crs.rows[r + 1]; ++k) J(r, crs.cols[k]) = crs.values[k];
  }
  const Eigen::Map<const Eigen::VectorXd> res(residuals.data(), residuals.size());
  // Tilt columns (the last two) against differences of the residuals.
  const int T = crs.num_cols - 2;
  for (int a = 0; a < 2; ++a) {
    const double h = 1e-6, saved = builder.bilinear_block()[a];
    std::vector<double> plus, minus;
    builder.bilinear_block()[a] = saved + h;
    ASSERT_TRUE(problem.Evaluate(eval, nullptr, &plus, nullptr, nullptr));
    builder.bilinear_block()[a] = saved - h;
    ASSERT_TRUE(problem.Evaluate(eval, nullptr, &minus, nullptr, nullptr));
    builder.bilinear_block()[a] = saved;
    const Eigen::VectorXd fd = (Eigen::Map<const Eigen::VectorXd>(plus.data(), plus.size()) -
                                Eigen::Map<const Eigen::VectorXd>(minus.data(), minus.size())) /
                               (2 * h);
    ASSERT_GT(fd.norm(), 1e-3);
    EXPECT_LT((J.col(T + a) - fd).norm(), 1e-6 * fd.norm()) << "tilt " << a;
  }
  // The linear solver's normal equations at the same values.
  const ProblemNormalEquations ne = builder.NormalEquations();
  ASSERT_EQ(ne.H.rows(), J.cols());
  const Eigen::MatrixXd H = J.transpose() * J;
  const Eigen::VectorXd g = -J.transpose() * res;  // y = measured - predicted = -r
  for (int a = 0; a < 2; ++a) {
    const double scale = std::sqrt(H(T + a, T + a));
    for (int c = 0; c < H.cols(); ++c) {
      EXPECT_NEAR(ne.H(T + a, c), H(T + a, c), 1e-8 * scale * std::sqrt(H(c, c)) + 1e-12)
          << "tilt " << a << " column " << c;
    }
    EXPECT_NEAR(ne.g(T + a), g(T + a), 1e-8 * scale * res.norm());
  }
  EXPECT_NEAR(ne.cost, cost, 1e-10 * cost);
}

// Acceptance: a base tilted by 0.3 deg (about x) and -0.2 deg (about y), small-arm compliance and
// harmonics, 300 poses, noise 0.01 mm. The tilt is recovered within 4 of its standard deviations
// (the linear solver's a-posteriori ones, about 0.05 deg here and required below the 0.1 deg of the
// identifiability check, so a recovery error above ~0.2 deg fails), the held-out RMS is not worse
// than without the tilt, the two solvers agree (tilt within 1e-7 rad, predictions within 1e-6 mm),
// and the calibrated model carries the tilted gravity.
TEST(GravityTilt, RecoveredFromSimulationAndSolversAgree) {
  const TiltFixture f(0.3, -0.2);
  const PipelineResult without = RunTilt(f, SolverKind::kLinear, kWithoutTilt);
  const PipelineResult with = RunTilt(f, SolverKind::kLinear, kWithTilt);
  const PipelineResult ceres = RunTilt(f, SolverKind::kCeres, kWithTilt);
  ASSERT_TRUE(without.result.converged()) << without.result.message;
  ASSERT_TRUE(with.result.converged()) << with.result.message;
  ASSERT_TRUE(ceres.result.converged()) << ceres.result.message;
  std::cout << "true tilt relative to the actual base: " << f.true_tilt(0) / kDeg << ", "
            << f.true_tilt(1) / kDeg << " deg\n";
  Print("0.3/-0.2 deg, no tilt identified", without);
  Print("0.3/-0.2 deg, linear with tilt", with);
  Print("0.3/-0.2 deg, ceres with tilt", ceres);
  const GravityTiltResult& t = with.result.gravity_tilt;
  ASSERT_TRUE(t.requested);
  ASSERT_TRUE(t.identified) << t.message;
  for (int a = 0; a < 2; ++a) {
    EXPECT_GT(t.standard_deviation(a), 0);
    EXPECT_LT(t.standard_deviation(a), 0.1 * kDeg);
    EXPECT_LT(std::abs(t.tilt(a) - f.true_tilt(a)), 4 * t.standard_deviation(a))
        << "tilt " << a << ": " << t.tilt(a) / kDeg << " deg, true " << f.true_tilt(a) / kDeg;
    // The check before solving predicted this standard deviation (same data, same noise level).
    EXPECT_NEAR(t.predicted_standard_deviation(a), t.standard_deviation(a),
                0.25 * t.standard_deviation(a));
  }
  EXPECT_LE(with.verification_after.norm.rms, 1.01 * without.verification_after.norm.rms);
  // The calibrated model carries the tilted gravity (its predictions use it).
  EXPECT_LT((with.result.model.gravity - t.gravity_after).norm(), 1e-15);
  EXPECT_GT((with.result.model.gravity - f.nominal.gravity).norm(), 1e-3);
  // Both solvers: same tilt, same predictions.
  const GravityTiltResult& tc = ceres.result.gravity_tilt;
  ASSERT_TRUE(tc.identified) << tc.message;
  EXPECT_LT((tc.tilt - t.tilt).cwiseAbs().maxCoeff(), 1e-7);
  double max_diff = 0;
  for (int r = 0; r < f.verification.size(); ++r) {
    const double* q = f.verification.q(r);
    max_diff = std::max(max_diff, (PredictToolPosition(with.result.model, q, 0) -
                                   PredictToolPosition(ceres.result.model, q, 0))
                                      .norm());
  }
  std::cout << "linear vs ceres, held-out predictions: up to " << max_diff << " mm\n";
  EXPECT_LT(max_diff, 1e-6);
}

// The tilt's standard deviation is reported in one form, a posteriori, by both solvers: the linear
// solver's, Ceres's with its covariance a posteriori (lpoe_calibrate without --sigma) and Ceres's
// with an a-priori covariance from a sigma 5x the true noise agree to 1% on the same data; the last
// also keeps the a-priori form, about 5x larger (sigma / the noise the residuals show).
TEST(GravityTilt, SolversReportTheSameStandardDeviation) {
  const TiltFixture f(0.3, -0.2);
  const PipelineResult lin = RunTilt(f, SolverKind::kLinear, kWithTilt);
  ASSERT_TRUE(lin.result.converged()) << lin.result.message;
  const GravityTiltResult& tl = lin.result.gravity_tilt;
  ASSERT_TRUE(tl.identified) << tl.message;
  EXPECT_EQ(tl.a_priori_standard_deviation.maxCoeff(), 0.0);  // the linear solver has no a priori
  for (const bool a_posteriori : {true, false}) {
    PipelineOptions o;
    o.solver = SolverKind::kCeres;
    o.joint_errors = kWithTilt;
    o.ceres.a_posteriori_covariance = a_posteriori;
    o.ceres.sigma = 5 * f.noise;
    const PipelineResult cer =
        RunCalibrationPipeline(f.nominal, f.identification, f.verification, o);
    ASSERT_TRUE(cer.result.converged()) << cer.result.message;
    const GravityTiltResult& tc = cer.result.gravity_tilt;
    ASSERT_TRUE(tc.identified) << tc.message;
    Print(a_posteriori ? "ceres, a-posteriori covariance" : "ceres, a-priori covariance", cer);
    for (int a = 0; a < 2; ++a) {
      ASSERT_GT(tl.standard_deviation(a), 0);
      EXPECT_NEAR(tc.standard_deviation(a), tl.standard_deviation(a),
                  0.01 * tl.standard_deviation(a))
          << "tilt " << a << (a_posteriori ? ", a posteriori" : ", a priori");
      if (a_posteriori) {
        EXPECT_EQ(tc.a_priori_standard_deviation(a), 0.0);
      } else {
        // sigma / s with s the residuals' noise estimate (about the simulated 0.01 mm).
        const double ratio = tc.a_priori_standard_deviation(a) / tc.standard_deviation(a);
        EXPECT_GT(ratio, 4.0) << ratio;
        EXPECT_LT(ratio, 6.0) << ratio;
      }
    }
  }
}

// With a tilt of 1 deg, identifying it beats keeping the model's gravity on held-out data.
TEST(GravityTilt, LargeTiltImprovesTheHeldOutError) {
  const TiltFixture f(1.0, 0.5);
  const PipelineResult without = RunTilt(f, SolverKind::kLinear, kWithoutTilt);
  const PipelineResult with = RunTilt(f, SolverKind::kLinear, kWithTilt);
  ASSERT_TRUE(without.result.converged()) << without.result.message;
  ASSERT_TRUE(with.result.converged()) << with.result.message;
  Print("1/0.5 deg, no tilt identified", without);
  Print("1/0.5 deg, with tilt", with);
  ASSERT_TRUE(with.result.gravity_tilt.identified) << with.result.gravity_tilt.message;
  EXPECT_LT(with.verification_after.norm.rms, 0.95 * without.verification_after.norm.rms);
}

// Without a tilt of gravity in the data the identified tilt is consistent with the actual base's own
// (geometric) tilt, i.e. with zero gravity tilt (within 3 standard deviations).
TEST(GravityTilt, ConsistentWithZeroWithoutTilt) {
  const TiltFixture f(0, 0);
  const PipelineResult with = RunTilt(f, SolverKind::kLinear, kWithTilt);
  ASSERT_TRUE(with.result.converged()) << with.result.message;
  std::cout << "true tilt relative to the actual base: " << f.true_tilt(0) / kDeg << ", "
            << f.true_tilt(1) / kDeg << " deg\n";
  Print("level base, with tilt", with);
  const GravityTiltResult& t = with.result.gravity_tilt;
  ASSERT_TRUE(t.identified) << t.message;
  for (int a = 0; a < 2; ++a) {
    EXPECT_GT(t.standard_deviation(a), 0);
    EXPECT_LT(std::abs(t.tilt(a) - f.true_tilt(a)), 3 * t.standard_deviation(a)) << "tilt " << a;
  }
}

// Without compliance in the data the tilt cannot be located: it is not identified, the message says
// so, and the model keeps its gravity.
TEST(GravityTilt, NotIdentifiableWithoutComplianceTorques) {
  const TiltFixture f(0.3, 0, false);
  const PipelineResult r = RunTilt(f, SolverKind::kLinear, {"compliance", "tilt"});
  ASSERT_TRUE(r.result.converged()) << r.result.message;
  const GravityTiltResult& t = r.result.gravity_tilt;
  EXPECT_TRUE(t.requested);
  EXPECT_FALSE(t.identified);
  EXPECT_NE(t.message.find("gravity tilt not identifiable from these data; kept at the model's "
                           "gravity"),
            std::string::npos)
      << t.message;
  std::cout << t.message << "\n";
  EXPECT_EQ(r.result.model.gravity, f.nominal.gravity);
}

// The calibrated YAML stores the tilted gravity: predictions of the re-read model (what lpoe_predict
// evaluates) equal the calibrated model's and the solver's residuals to 1e-9 mm, also when the data
// are in a tracker frame (registration turns gravity with the base, the tilt is on top).
TEST(GravityTilt, YamlRoundTripReproducesPredictions) {
  TiltFixture f(0.3, -0.2, true, 200);
  const SE3d T(ExpSO3(Eigen::Vector3d(0.3, -0.2, 1.1)), Eigen::Vector3d(2500, -800, 300));
  for (int r = 0; r < f.identification.size(); ++r) {
    f.identification.mutable_position(r) = T * f.identification.position(r);
  }
  for (SolverKind solver : {SolverKind::kLinear, SolverKind::kCeres}) {
    PipelineOptions o;
    o.solver = solver;
    o.joint_errors = kWithTilt;
    const PipelineResult run =
        RunCalibrationPipeline(f.nominal, f.identification, MeasurementSet(6), o);
    ASSERT_TRUE(run.result.converged()) << run.result.message;
    ASSERT_TRUE(run.registration.moved);
    ASSERT_TRUE(run.result.gravity_tilt.identified) << run.result.gravity_tilt.message;
    const RobotModel& model = run.result.model;
    RobotModel geometric = model;
    geometric.joint_errors = JointErrorTerms();
    const std::vector<Eigen::Vector3d> solver_errors = PositionErrors(
        geometric, WithEffectiveJointValues(run.result.joint_terms, f.identification));
    RobotModel reread;
    ASSERT_TRUE(ParseRobotModelYaml(RobotModelToYaml(model), "calibrated.yaml", &reread).ok());
    EXPECT_EQ(reread.gravity, model.gravity);
    double max_diff = 0, max_round_trip = 0;
    for (int r = 0; r < f.identification.size(); ++r) {
      const double* q = f.identification.q(r);
      const Eigen::Vector3d p = PredictToolPosition(model, q, 0);
      max_diff = std::max(max_diff, (f.identification.position(r) - p - solver_errors[r]).norm());
      max_round_trip = std::max(max_round_trip, (PredictToolPosition(reread, q, 0) - p).norm());
    }
    EXPECT_LT(max_diff, 1e-9);
    EXPECT_LT(max_round_trip, 1e-9);
    // The tilt is that of the simulated base (registration rotates the frame, not the tilt's
    // meaning): the calibrated gravity, taken back to the base by the registered joint 1, is the
    // actual robot's within 4 standard deviations of the larger angle.
    const Eigen::Vector3d in_base = f.nominal.joints[0].origin.R *
                                    run.start.joints[0].origin.R.transpose() * model.gravity;
    const double angle = std::acos(std::clamp(
        in_base.normalized().dot(f.actual.gravity.normalized()), -1.0, 1.0));
    EXPECT_LT(angle, 4 * run.result.gravity_tilt.standard_deviation.maxCoeff() + 2e-3 * kDeg)
        << angle / kDeg << " deg";
  }
}

// auto: the tilt joins the compliance candidates when the identification rows determine it (a base
// tilted by 1 deg), and not without compliance torques in the data, which the selection says.
TEST(GravityTilt, AutoAddsTiltCandidatesOnlyWhenIdentifiable) {
  auto labels = [](const PipelineResult& r) {
    std::vector<std::string> out;
    for (const JointErrorCandidate& c : r.joint_error_selection.candidates) out.push_back(c.label);
    return out;
  };
  PipelineOptions o;
  o.register_frames = false;
  o.joint_errors_auto = true;
  const TiltFixture tilted(1.0, 0.5);
  const PipelineResult a =
      RunCalibrationPipeline(tilted.nominal, tilted.identification, tilted.verification, o);
  ASSERT_TRUE(a.result.converged()) << a.result.message;
  const std::vector<std::string> with = labels(a);
  ASSERT_EQ(a.joint_error_selection.bilinear.size(), 1u);
  EXPECT_EQ(a.joint_error_selection.bilinear[0].name, kGravityTiltName);
  EXPECT_TRUE(a.joint_error_selection.bilinear[0].candidates)
      << a.joint_error_selection.bilinear[0].message;
  EXPECT_NE(std::find(with.begin(), with.end(), "compliance,tilt"), with.end());
  EXPECT_NE(std::find(with.begin(), with.end(), "compliance,harmonics,tilt"), with.end());
  const JointErrorSelection& sel = a.joint_error_selection;
  for (const JointErrorCandidate& c : sel.candidates) {
    const bool with_tilt = c.label.find("tilt") != std::string::npos;
    const int tilt_folds = c.IdentifiedFolds(kGravityTiltName);
    EXPECT_TRUE(tilt_folds >= 0 && tilt_folds <= (with_tilt ? sel.folds : 0)) << c.label;
    EXPECT_EQ(c.identified_folds.size(), with_tilt && tilt_folds > 0 ? 1u : 0u) << c.label;
    // The tilt identified on all rows (the check above, with every registry term): on each fold's
    // too with compliance and harmonics.
    if (c.label == "compliance,harmonics,tilt") {
      EXPECT_EQ(tilt_folds, sel.folds);
    }
  }
  std::cout << "auto on a 1 deg tilt chose " << sel.candidates[sel.chosen].label << " ("
            << sel.reason << ")\n";
  const TiltFixture level(0.3, 0, false);
  const PipelineResult b =
      RunCalibrationPipeline(level.nominal, level.identification, level.verification, o);
  ASSERT_TRUE(b.result.converged()) << b.result.message;
  const std::vector<std::string> without = labels(b);
  EXPECT_FALSE(b.joint_error_selection.Bilinear(kGravityTiltName).candidates);
  EXPECT_EQ(without.size(), size_t{1} << JointTermNames().size());  // every registry subset
  EXPECT_NE(b.joint_error_selection.Bilinear(kGravityTiltName).message.find(
                "gravity tilt not identifiable from these data; kept at the model's gravity"),
            std::string::npos)
      << b.joint_error_selection.Bilinear(kGravityTiltName).message;
}

// Bad use: the tilt without compliance.
TEST(GravityTilt, RejectedWithoutCompliance) {
  std::vector<std::string> kinds, effects;
  std::string error;
  const std::vector<std::string> tilt = {kGravityTiltName};
  ASSERT_TRUE(ParseJointErrorList("compliance,tilt", &kinds, &effects, &error)) << error;
  EXPECT_EQ(effects, tilt);
  ASSERT_EQ(kinds.size(), 1u);
  ASSERT_TRUE(ParseJointErrorList("tilt,harmonics,compliance", &kinds, &effects, &error)) << error;
  EXPECT_EQ(effects, tilt);
  EXPECT_EQ(kinds.size(), 2u);
  ASSERT_TRUE(ParseJointErrorList("compliance,harmonics", &kinds, &effects, &error)) << error;
  EXPECT_TRUE(effects.empty());
  ASSERT_TRUE(ParseJointErrorList("none", &kinds, &effects, &error)) << error;
  EXPECT_TRUE(kinds.empty() && effects.empty());
  for (const char* bad : {"tilt", "harmonics,tilt", "none,tilt"}) {
    EXPECT_FALSE(ParseJointErrorList(bad, &kinds, &effects, &error)) << bad;
    EXPECT_EQ(error, kGravityTiltNeedsCompliance) << bad;
  }
  EXPECT_FALSE(ParseJointErrorList("compliance,tilt,tilt", &kinds, &effects, &error));
  EXPECT_EQ(error, "'tilt' is listed more than once");
  // A comma at either end, an empty item, a misspelt name.
  for (const char* bad : {"compliance,tilt,", "compliance,", ",compliance", "compliance,,tilt",
                          "compliance,tlit"}) {
    EXPECT_FALSE(ParseJointErrorList(bad, &kinds, &effects, &error)) << bad;
    EXPECT_EQ(error.rfind("not a comma-separated list of", 0), 0u) << bad << ": " << error;
  }
  // The list's vocabulary comes from the block kinds: the tilt, bilinear with compliance.
  const BilinearEffectName* name = FindBilinearEffectName(kGravityTiltName);
  ASSERT_NE(name, nullptr);
  EXPECT_EQ(name->partner, "compliance");
  EXPECT_EQ(BilinearEffectsHelp(true), "with tilt in a list with compliance (compliance,tilt)");
  EXPECT_NE(MakeBilinearEffect(kGravityTiltName, MakeCobot6()), nullptr);
  EXPECT_EQ(MakeBilinearEffect("compliance", MakeCobot6()), nullptr);

  const TiltFixture f(0.3, 0, true, 60);
  const PipelineResult r = RunTilt(f, SolverKind::kLinear, {"harmonics", "tilt"});
  EXPECT_EQ(r.result.termination, Termination::kNotIdentifiable);
  EXPECT_EQ(r.result.message, kGravityTiltNeedsCompliance);
  // The library's list (no parser in between): one bilinear effect per calibration.
  const PipelineResult twice = RunTilt(f, SolverKind::kLinear, {"compliance", "tilt", "tilt"});
  EXPECT_EQ(twice.result.termination, Termination::kNotIdentifiable);
  EXPECT_NE(twice.result.message.find("one bilinear effect per calibration"), std::string::npos)
      << twice.result.message;
}

}  // namespace gravity_tilt_test
}  // namespace
}  // namespace lpoe
