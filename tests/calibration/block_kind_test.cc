// Issue 42, the gravity tilt as a parameter-block kind (solvers/src/calibration/block_kind.h): the
// registry's entry, its columns against finite differences of the core's own prediction of the
// joint offsets, and both solvers' tilt on simulated data with compliance and a known tilt against
// a plain least-squares reference (Gauss-Newton on finite-difference Jacobians of the predicted
// positions).
#include <algorithm>
#include <cmath>
#include <memory>
#include <numeric>
#include <string>
#include <vector>

#include <Eigen/Dense>
#include <gtest/gtest.h>

#include "calibration/block_kind.h"
#include "calibration/problem_setup.h"
#include "lpoe/ceres_solver.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/linear_solver.h"
#include "lpoe/measurements/measurement_model.h"
#include "lpoe/problem_builder.h"
#include "lpoe/model/simulation.h"

namespace lpoe {
namespace {
namespace block_kind_test {

constexpr double kDeg = M_PI / 180.0;

std::shared_ptr<const JointTerm> Compliance(const RobotModel& model) {
  std::shared_ptr<const JointTerm> term;
  const Status s = MakeJointTerm("compliance", model, &term);
  EXPECT_TRUE(s.ok()) << s.message();
  return term;
}

RobotModel LoadedCobot() {
  RobotModel model = MakeCobot6();
  model.payload.mass = 1.0;
  model.payload.com = Eigen::Vector3d(0, 0, 50);
  return model;
}

// The registry holds the tilt, with the term it is bilinear with; asked for without that term it
// is refused with the kind's message, by the check both solvers' validation uses.
TEST(BlockKind, RegistryHoldsTheTiltAndRefusesItWithoutItsPartner) {
  const internal::BilinearBlockKind* kind = internal::FindBilinearBlockKind(kGravityTiltName);
  ASSERT_NE(kind, nullptr);
  EXPECT_EQ(internal::FindBlockKind(kGravityTiltName), kind);
  EXPECT_EQ(std::string(kind->name()), "tilt");
  EXPECT_EQ(std::string(kind->partner_term()), "compliance");
  EXPECT_EQ(internal::FindBlockKind("compliance"), nullptr);
  // The frames' and the terms' kinds are not bilinear.
  EXPECT_EQ(internal::FrameBlockKind().bilinear(), nullptr);
  EXPECT_EQ(internal::JointTermBlockKind().bilinear(), nullptr);
  const RobotModel model = LoadedCobot();
  internal::ProblemSetupRequest request;
  const auto tilt = std::make_shared<const GravityTiltModel>(model);
  request.bilinear_effects = {tilt};
  EXPECT_TRUE(kind->Requested(request));
  std::shared_ptr<const JointTerm> harmonics;
  ASSERT_TRUE(MakeJointTerm("harmonics", model, &harmonics).ok());
  const Status refused = internal::CheckBlockKindPartners({harmonics}, request);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.message(), kind->needs_partner_message());
  EXPECT_NE(refused.message().find("compliance"), std::string::npos);
  EXPECT_TRUE(internal::CheckBlockKindPartners({harmonics, Compliance(model)}, request).ok());
  // Through the Ceres problem's validation as well.
  CalibrationProblemOptions o;
  o.joint_terms = {harmonics};
  o.bilinear_effects = request.bilinear_effects;
  const Status s = ValidateCalibrationProblemOptions(o);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.message(), kind->needs_partner_message());
  // Without a compliance block in the parameterization, Add names the reason too.
  Parameterization p =
      MakeParameterization(model, ParameterizationKind::kIdentifiable, DataKind::kPosition);
  EXPECT_FALSE(kind->Add(request, &p).ok());
  EXPECT_FALSE(kind->In(p));
  EXPECT_FALSE(internal::HasNonlinearBlocks(p));
  // An effect given twice, or a null one, is refused by the same check.
  o.joint_terms = {Compliance(model)};
  ASSERT_TRUE(ValidateCalibrationProblemOptions(o).ok());
  o.bilinear_effects = {tilt, std::make_shared<const GravityTiltModel>(model)};
  const Status twice = ValidateCalibrationProblemOptions(o);
  ASSERT_FALSE(twice.ok());
  EXPECT_NE(twice.message().find("'tilt' is given twice"), std::string::npos) << twice.message();
  o.bilinear_effects = {nullptr};
  EXPECT_FALSE(ValidateCalibrationProblemOptions(o).ok());
}

// The kind's columns of a row at a tilt of (0.4, -0.3) deg and the small arm's compliance: every
// joint-space column (the compliance block's, taken at the tilt, and the tilt's) equals central
// differences of q + JointErrorOffsets of the model carrying those values and the tilted gravity;
// q_eff equals that prediction.
TEST(BlockKind, TiltColumnsMatchFiniteDifferencesOfThePredictedOffsets) {
  const RobotModel model = LoadedCobot();
  const std::vector<double> theta =
      CompliancePhysicsParameters(SmallArmJointErrors(model, SmallArmOptions()));
  auto term = Compliance(model);
  Parameterization p =
      MakeParameterization(model, ParameterizationKind::kIdentifiable, DataKind::kPosition);
  AddJointBlock(term, &p);
  internal::ProblemSetupRequest request;
  const auto tilt = std::make_shared<const GravityTiltModel>(model);
  request.bilinear_effects = {tilt};
  const internal::BilinearBlockKind* kind = internal::FindBilinearBlockKind(kGravityTiltName);
  ASSERT_TRUE(kind->Add(request, &p).ok());
  ASSERT_TRUE(kind->In(p));
  ASSERT_TRUE(internal::HasNonlinearBlocks(p));
  const int n = model.num_joints();
  const int P = term->num_parameters();
  const int K = p.num_joint_parameters();
  ASSERT_EQ(K, P + 2);
  Eigen::VectorXd state(K);
  state.head(P) = Eigen::Map<const Eigen::VectorXd>(theta.data(), P);
  state(P) = 0.4 * kDeg;
  state(P + 1) = -0.3 * kDeg;
  // The core's prediction: the model carrying the values, its gravity tilted.
  auto predicted = [&](const Eigen::VectorXd& s, const double* q) {
    RobotModel m = model;
    m.gravity = tilt->Tilted(s.data() + P);
    *m.joint_errors.MutableValues("compliance") = std::vector<double>(s.data(), s.data() + P);
    Eigen::VectorXd dq = Eigen::VectorXd::Zero(n);
    JointErrorOffsets(m, q, dq.data());
    return Eigen::VectorXd(Eigen::Map<const Eigen::VectorXd>(q, n) + dq);
  };
  const double configurations[3][6] = {{0.3, -1.1, 1.4, 0.2, -0.7, 2.0},
                                       {-2.1, 0.4, -0.9, 1.3, 0.8, -0.4},
                                       {1.2, -0.3, 2.2, -1.7, 1.1, 0.6}};
  for (const auto& config : configurations) {
    const double* q = config;
    Eigen::MatrixXd R = Eigen::MatrixXd::Zero(n, K);
    Eigen::MatrixXd Y(n, P);
    term->Regressor(q, Y.data());
    R.leftCols(P) = Y;
    Eigen::VectorXd q_eff = Eigen::Map<const Eigen::VectorXd>(q, n) + R * state;
    internal::AddNonlinearRowColumns(p, q, state, R, &q_eff);
    const Eigen::VectorXd expected = predicted(state, q);
    EXPECT_LT((q_eff - expected).cwiseAbs().maxCoeff(), 1e-12) << "q_eff";
    int checked = 0;
    // The prediction sets a regressor's rounding noise (below kJointErrorRoundingCutoff of its
    // largest entry) to zero: columns of that size are compared to zero.
    const double largest = R.leftCols(P).cwiseAbs().maxCoeff();
    for (int c = 0; c < K; ++c) {
      // Steps: 1e-6 rad of tilt; a compliance coordinate moving the offsets by about 1e-6 rad.
      const double column = R.col(c).cwiseAbs().maxCoeff();
      if (c < P && column <= kJointErrorRoundingCutoff * largest) {
        EXPECT_EQ((predicted(state + 1e-3 * Eigen::VectorXd::Unit(K, c), q) - expected).norm(), 0)
            << "column " << c;
        continue;
      }
      const double h = c < P ? 1e-6 / column : 1e-6;
      Eigen::VectorXd sp = state, sm = state;
      sp(c) += h;
      sm(c) -= h;
      const Eigen::VectorXd fd = (predicted(sp, q) - predicted(sm, q)) / (2 * h);
      const double scale = std::max(fd.cwiseAbs().maxCoeff(), column);
      ASSERT_GT(scale, 0) << "column " << c;
      EXPECT_LT((R.col(c) - fd).cwiseAbs().maxCoeff(), 1e-6 * scale) << "column " << c;
      ++checked;
    }
    EXPECT_GT(checked, 2);
    // The tilt moves the offsets (a vertical joint 1 gains a gravity torque).
    EXPECT_GT(R.rightCols(2).norm(), 0);
    // The Ceres residual's data of the same row: its Z_a give the same compliance columns.
    const auto row = internal::BilinearRowOf(p, 0, q, 0);
    ASSERT_NE(row, nullptr);
    ASSERT_EQ(row->Z.size(), 3u);
    const Eigen::Vector3d dg = tilt->Tilted(state.data() + P) - model.gravity;
    const Eigen::MatrixXd compliance =
        Y + dg(0) * row->Z[0] + dg(1) * row->Z[1] + dg(2) * row->Z[2];
    EXPECT_LT((compliance - R.leftCols(P)).cwiseAbs().maxCoeff(),
              1e-12 * R.leftCols(P).cwiseAbs().maxCoeff());
  }
}

// Simulated data: cobot6 with geometric errors and the small arm's compliance, its base tilted by
// (0.3, -0.2) deg, noise 0.01 mm, 150 poses.
struct Simulated {
  RobotModel nominal = LoadedCobot();
  MeasurementSet data;
  Eigen::Vector2d true_tilt;
  Simulated() {
    const KinematicErrors errors = RandomErrors(nominal, 2e-3, 0.5, 1e-3, 2e-3, 5);
    RobotModel actual = ApplyErrors(nominal, errors);
    const double t[2] = {0.3 * kDeg, -0.2 * kDeg};
    actual.gravity = TiltedGravity<double>(nominal.gravity, t);
    // What the calibration can find: gravity relative to the actual base (joint 1's frame carries
    // a geometric error), seen in the nominal model's.
    true_tilt = GravityTiltBetween(nominal.gravity, nominal.joints[0].origin.R *
                                                        actual.joints[0].origin.R.transpose() *
                                                        actual.gravity);
    ApplyJointErrorPhysics(SmallArmJointErrors(nominal, SmallArmOptions()), {"compliance"},
                           &actual);
    SimulationOptions options;
    options.count = 150;
    options.noise_sigma = 0.01;
    options.seed = 3;
    data = SimulateMeasurements(actual, errors.joint_zero, options);
  }
};

// The model of parameterization p's coordinates x about `nominal`: frames moved by x, compliance
// values from x's compliance coordinates, gravity tilted by x's tilt (the calibrated model's form).
RobotModel ModelAt(const RobotModel& nominal, const Parameterization& p,
                   const Eigen::VectorXd& x) {
  RobotModel m = nominal;
  ApplyUpdate(p, x, &m);
  for (const JointBlock& block : p.joint_blocks) {
    const Eigen::VectorXd theta = block.basis * x.segment(block.offset, block.basis.cols());
    *m.joint_errors.MutableValues(block.term->name()) =
        std::vector<double>(theta.data(), theta.data() + theta.size());
  }
  m.joint_errors.regressor_origins.clear();
  for (const Joint& j : nominal.joints) m.joint_errors.regressor_origins.push_back(j.origin);
  const Eigen::VectorXd t = BilinearValuesOf(p, 0, x);
  m.gravity = static_cast<const GravityTiltModel&>(*p.bilinear_blocks[0].effect).Tilted(t.data());
  return m;
}

Eigen::VectorXd Residuals(const RobotModel& model, const MeasurementSet& data) {
  Eigen::VectorXd r(3 * data.size());
  for (int i = 0; i < data.size(); ++i) {
    r.segment<3>(3 * i) = data.position(i) - PredictToolPosition(model, data.q(i), data.target(i));
  }
  return r;
}

// Both solvers, asked for compliance and the tilt from a compliance solution, estimate the tilt a
// plain Gauss-Newton on finite-difference Jacobians of the predicted positions finds (in the same
// parameterization, from the same start) to 1% of its standard deviation, and recover the true
// tilt within 4 standard deviations. (At the minimum the residuals are noise, so this checks the
// solvers' cost and convergence; their columns are checked against differences above.)
TEST(BlockKind, BothSolversEstimateTheTiltOfAPlainLeastSquaresReference) {
  const Simulated s;
  LinearSolverOptions first;
  first.joint_terms = {Compliance(s.nominal)};
  const CalibrationResult without = CalibrateLinear(s.nominal, s.data, first);
  ASSERT_TRUE(without.converged()) << without.message;
  const auto tilt_model = std::make_shared<const GravityTiltModel>(s.nominal);
  LinearSolverOptions lo = first;
  lo.bilinear_effects = {tilt_model};
  lo.initial_joint_terms = without.joint_terms;
  const CalibrationResult linear = CalibrateLinear(s.nominal, s.data, lo);
  ASSERT_TRUE(linear.converged()) << linear.message;
  CeresSolverOptions co;
  co.joint_terms = lo.joint_terms;
  co.bilinear_effects = {tilt_model};
  co.initial_joint_terms = without.joint_terms;
  const CalibrationResult ceres = CalibrateCeres(s.nominal, s.data, co);
  ASSERT_TRUE(ceres.converged()) << ceres.message;
  ASSERT_TRUE(linear.gravity_tilt.identified);
  ASSERT_TRUE(ceres.gravity_tilt.identified);

  // The reference: the linear solver's parameterization, started where the solvers start.
  const Parameterization& p = linear.parameterization;
  ASSERT_EQ(p.bilinear_blocks.size(), 1u);
  Eigen::VectorXd x = Eigen::VectorXd::Zero(p.num_parameters);
  for (const JointBlock& block : p.joint_blocks) {
    for (const JointTermValues& v : without.joint_terms) {
      if (v.term->name() == block.term->name()) {
        x.segment(block.offset, block.basis.cols()) = block.basis.transpose() * v.theta;
      }
    }
  }
  const int P = p.num_parameters;
  for (int iteration = 0; iteration < 12; ++iteration) {
    const Eigen::VectorXd r = Residuals(ModelAt(s.nominal, p, x), s.data);
    Eigen::MatrixXd J(r.size(), P);  // d(predicted)/dx = -d(r)/dx
    for (int c = 0; c < P; ++c) {
      // Central differences; a step of about 1e-4 mm of the predictions' largest motion.
      Eigen::VectorXd e = Eigen::VectorXd::Zero(P);
      e(c) = 1e-6;
      const Eigen::VectorXd probe = Residuals(ModelAt(s.nominal, p, x + e), s.data) - r;
      const double motion = probe.cwiseAbs().maxCoeff();
      const double h = motion > 0 ? 1e-6 * 1e-4 / motion : 1e-6;
      e(c) = h;
      J.col(c) = (Residuals(ModelAt(s.nominal, p, x - e), s.data) -
                  Residuals(ModelAt(s.nominal, p, x + e), s.data)) /
                 (2 * h);
    }
    const Eigen::VectorXd step = J.colPivHouseholderQr().solve(r);
    x += step;
    if (step.cwiseAbs().maxCoeff() < 1e-14) break;
  }
  const Eigen::VectorXd reference = BilinearValuesOf(p, 0, x);
  for (int a = 0; a < 2; ++a) {
    const double sd = linear.gravity_tilt.standard_deviation(a);
    ASSERT_GT(sd, 0);
    EXPECT_LT(sd, 0.1 * kDeg);
    EXPECT_LT(std::abs(linear.gravity_tilt.tilt(a) - reference(a)), 0.01 * sd)
        << "linear, tilt " << a << ": " << linear.gravity_tilt.tilt(a) << " vs " << reference(a);
    EXPECT_LT(std::abs(ceres.gravity_tilt.tilt(a) - reference(a)), 0.01 * sd)
        << "ceres, tilt " << a << ": " << ceres.gravity_tilt.tilt(a) << " vs " << reference(a);
    EXPECT_LT(std::abs(reference(a) - s.true_tilt(a)), 4 * sd)
        << "tilt " << a << ": " << reference(a) / kDeg << " deg, true " << s.true_tilt(a) / kDeg;
  }
  // And the same cost: the reference's residuals are not smaller than the solvers'.
  const double reference_cost = 0.5 * Residuals(ModelAt(s.nominal, p, x), s.data).squaredNorm();
  EXPECT_NEAR(linear.final_cost, reference_cost, 1e-6 * reference_cost);
}

// A problem with every kind: cobot6 loaded, a second tool no row measures, compliance and
// harmonics starting from realistic values (the small arm's compliance, 0.1 mrad harmonics), and
// the gravity tilt; position (or pose) data of 40 poses of tool 0.
struct EveryKind {
  RobotModel nominal = LoadedCobot();
  MeasurementSet data;
  std::vector<JointTermValues> initial;
  explicit EveryKind(bool pose) {
    Tool second = nominal.tools[0];
    second.name = "smr2";
    second.origin.t = Eigen::Vector3d(-30.0, 20.0, 70.0);
    nominal.tools.push_back(second);
    const KinematicErrors errors = RandomErrors(nominal, 2e-3, 0.5, 1e-3, 2e-3, 7);
    RobotModel actual = ApplyErrors(nominal, errors);
    ApplyJointErrorPhysics(SmallArmJointErrors(nominal, SmallArmOptions()), {"compliance"},
                           &actual);
    SimulationOptions options;
    options.count = 40;
    options.noise_sigma = 0.01;
    options.pose = pose;
    options.orientation_noise_sigma = pose ? 1e-5 : 0.0;
    options.seed = 11;
    data = SimulateMeasurements(actual, errors.joint_zero, options);
    std::shared_ptr<const JointTerm> harmonics;
    EXPECT_TRUE(MakeJointTerm("harmonics", nominal, &harmonics).ok());
    const std::vector<double> theta =
        CompliancePhysicsParameters(SmallArmJointErrors(nominal, SmallArmOptions()));
    auto compliance = Compliance(nominal);
    initial.push_back({compliance, Eigen::Map<const Eigen::VectorXd>(theta.data(), theta.size())});
    Eigen::VectorXd h(harmonics->num_parameters());
    for (int k = 0; k < h.size(); ++k) h(k) = 1e-4 * std::sin(1.7 * k + 0.3);
    initial.push_back({harmonics, h});
  }
  CalibrationProblemOptions Options(bool pose) const {
    CalibrationProblemOptions o;
    o.use_orientation = pose;
    o.joint_terms = {initial[0].term, initial[1].term};
    o.initial_joint_terms = initial;
    o.bilinear_effects = {std::make_shared<const GravityTiltModel>(nominal)};
    return o;
  }
};

// Moves every block of `problem` off its start: frames by 1e-3 (rad, mm) per direction,
// joint-space coordinates by 1e-5, the tilt by (0.4, -0.3) deg.
void MoveEveryBlock(CalibrationProblem* problem) {
  Eigen::VectorXd x(problem->SolvedParameterization().num_parameters);
  for (int k = 0; k < x.size(); ++k) x(k) = std::cos(2.3 * k + 0.1);
  for (const ProblemBlock& b : problem->blocks()) {
    auto seg = x.segment(b.solved_offset, b.tangent_size);
    if (b.kind == &internal::FrameBlockKind()) seg *= 1e-3;
    if (b.kind == &internal::JointTermBlockKind()) seg *= 1e-5;
    if (b.kind == internal::FindBlockKind(kGravityTiltName)) seg << 0.4 * kDeg, -0.3 * kDeg;
  }
  problem->Update(x);
}

internal::BlockColumnsContext ColumnsContext(const CalibrationProblem& problem,
                                             const RobotModel& model,
                                             const Eigen::VectorXd& joint_state) {
  internal::BlockColumnsContext ctx;
  ctx.model = &model;
  ctx.p = &problem.parameterization();
  ctx.joint_state = &joint_state;
  ctx.use_orientation = problem.options().use_orientation;
  ctx.orientation_weight = problem.options().orientation_weight;
  return ctx;
}

// The problem's blocks are one list from the registry: the solved frames (the unmeasured tool
// left out), a block per joint-space term, the tilt, in that order; each block's offset and
// tangent size are the parameterization's numbering, its solved offset the solved one's (the
// numbering of NormalEquations and Update), and parameter_blocks / tangent_sizes /
// tangent_offsets / Update / JointState follow the list.
TEST(BlockKind, ProblemBlocksAreOneListInTheParameterizationsNumbering) {
  const EveryKind s(false);
  const CalibrationProblemOptions options = s.Options(false);
  ASSERT_TRUE(ValidateCalibrationProblem(s.nominal, s.data, options).ok());
  CalibrationProblem problem(s.nominal, s.data, options);
  ASSERT_TRUE(problem.block_status().ok()) << problem.block_status().message();
  const Parameterization& p = problem.parameterization();
  const Parameterization& solved = problem.SolvedParameterization();
  const int n = s.nominal.num_joints();
  const std::vector<ProblemBlock>& blocks = problem.blocks();
  ASSERT_EQ(p.joint_blocks.size(), 2u);
  ASSERT_GT(p.joint_blocks[0].basis.cols(), 0);
  ASSERT_GT(p.joint_blocks[1].basis.cols(), 0);
  // n joints + the measured tool, two joint-space blocks, the tilt.
  ASSERT_EQ(blocks.size(), static_cast<size_t>(n + 1 + 2 + 1));
  EXPECT_TRUE(problem.frame_solved(n));
  EXPECT_FALSE(problem.frame_solved(n + 1));
  EXPECT_EQ(problem.frame_block(n + 1), nullptr);
  EXPECT_GT(p.basis[n + 1].cols(), 0);  // the unmeasured tool keeps its basis in p, but no block
  const std::vector<double*> pointers = problem.parameter_blocks();
  const std::vector<int> sizes = problem.tangent_sizes();
  const std::vector<int> offsets = problem.tangent_offsets();
  int solved_offset = 0;
  for (size_t i = 0; i < blocks.size(); ++i) {
    const ProblemBlock& b = blocks[i];
    SCOPED_TRACE("block " + std::to_string(i) + " (" + b.kind->name() + ")");
    if (i <= static_cast<size_t>(n)) {
      ASSERT_EQ(b.kind, &internal::FrameBlockKind());
      EXPECT_EQ(b.index, static_cast<int>(i));
      EXPECT_EQ(b.offset, p.offset[i]);
      EXPECT_EQ(b.tangent_size, p.basis[i].cols());
      EXPECT_EQ(b.solved_offset, solved.offset[i]);
      EXPECT_EQ(b.values.size(), static_cast<size_t>(kSe3AmbientSize));
      EXPECT_EQ(problem.frame_block(static_cast<int>(i)), b.values.data());
    } else if (i < static_cast<size_t>(n + 3)) {
      const int jb = static_cast<int>(i) - n - 1;
      ASSERT_EQ(b.kind, &internal::JointTermBlockKind());
      EXPECT_EQ(b.index, jb);
      EXPECT_EQ(b.offset, p.joint_blocks[jb].offset);
      EXPECT_EQ(b.tangent_size, p.joint_blocks[jb].basis.cols());
      EXPECT_EQ(b.solved_offset, solved.joint_blocks[jb].offset);
      EXPECT_EQ(problem.joint_block(jb), b.values.data());
    } else {
      ASSERT_EQ(b.kind, internal::FindBlockKind(kGravityTiltName));
      EXPECT_EQ(b.index, 0);
      EXPECT_EQ(b.offset, p.bilinear_blocks[0].offset);
      EXPECT_EQ(b.tangent_size, 2);
      EXPECT_EQ(b.solved_offset, solved.bilinear_blocks[0].offset);
      EXPECT_EQ(problem.bilinear_block(), b.values.data());
    }
    EXPECT_EQ(b.solved_offset, solved_offset);
    solved_offset += b.tangent_size;
    EXPECT_EQ(pointers[i], b.values.data());
    EXPECT_EQ(sizes[i], b.tangent_size);
    EXPECT_EQ(offsets[i], b.offset);
  }
  EXPECT_EQ(solved_offset, solved.num_parameters);
  // The joint-space blocks start at the initial values: JointState is their coordinates.
  const Eigen::VectorXd start = problem.JointState();
  ASSERT_EQ(start.size(), p.num_joint_parameters());
  const Eigen::VectorXd x0 =
      p.joint_blocks[0].basis.transpose() * s.initial[0].theta;
  EXPECT_LT((start.head(x0.size()) - x0).cwiseAbs().maxCoeff(), 1e-12 * x0.cwiseAbs().maxCoeff());
  // Update moves each joint-space block by its segment of the step, and the model's frames.
  Eigen::VectorXd x = Eigen::VectorXd::Zero(solved.num_parameters);
  for (int k = 0; k < x.size(); ++k) x(k) = 1e-4 * (k + 1);
  problem.Update(x);
  const Eigen::VectorXd moved = problem.JointState();
  const int F = solved.num_frame_parameters();
  EXPECT_LT((moved - start - x.tail(solved.num_joint_parameters())).cwiseAbs().maxCoeff(), 1e-15);
  RobotModel expected = s.nominal;
  ApplyUpdate(solved, x, &expected);
  const RobotModel model = problem.Model();
  for (int f = 0; f <= n; ++f) {
    const SE3d& a = f < n ? model.joints[f].origin : model.tools[0].origin;
    const SE3d& e = f < n ? expected.joints[f].origin : expected.tools[0].origin;
    EXPECT_LT(LogSE3(a.Inverse() * e).norm(), 1e-12) << "frame " << f;
  }
  EXPECT_EQ((model.tools[1].origin.t - s.nominal.tools[1].origin.t).norm(), 0);  // not solved
  EXPECT_EQ(F, p.num_frame_parameters() - static_cast<int>(p.basis[n + 1].cols()));
}

// Each kind's columns of a row, at a state off the start (every block moved, the tilt 0.4 deg),
// equal central differences of the predicted tool position: a frame's along its manifold's
// directions (T_f exp((B_f e_k h)^)), a joint-space block's and the tilt's along its coordinates.
TEST(BlockKind, EachKindsColumnsAreCentralDifferencesOfThePrediction) {
  const EveryKind s(false);
  CalibrationProblem problem(s.nominal, s.data, s.Options(false));
  ASSERT_TRUE(problem.block_status().ok());
  MoveEveryBlock(&problem);
  const Parameterization& p = problem.parameterization();
  const RobotModel model = problem.Model();
  const Eigen::VectorXd joint_state = problem.JointState();
  const internal::BlockColumnsContext ctx = ColumnsContext(problem, model, joint_state);
  const int F = p.num_frame_parameters();
  // The prediction at a perturbation dx of every coordinate (p's numbering) about the state.
  Eigen::VectorXd coordinates = Eigen::VectorXd::Zero(p.num_parameters);
  coordinates.tail(p.num_joint_parameters()) = joint_state;
  auto predicted = [&](const Eigen::VectorXd& dx, int r) {
    RobotModel m = model;
    ApplyUpdate(p, dx, &m);
    return PredictPosition(m, JointValuesOf(p, coordinates + dx), s.data.q(r), s.data.target(r));
  };
  std::vector<int> checked(3, 0);
  for (int r : {0, 17, 33}) {
    for (const ProblemBlock& b : problem.blocks()) {
      Eigen::MatrixXd J;
      b.kind->Columns(ctx, b, s.data, r, &J);
      ASSERT_EQ(J.rows(), 3);
      ASSERT_EQ(J.cols(), b.tangent_size);
      const int kind = b.kind == &internal::FrameBlockKind()       ? 0
                       : b.kind == &internal::JointTermBlockKind() ? 1
                                                                    : 2;
      for (int c = 0; c < b.tangent_size; ++c) {
        // Steps: 1e-6 rad or mm of a frame, of the tilt; a joint-space coordinate moving the
        // position by about 1e-6 mm.
        const double column = J.col(c).norm();
        double h = 1e-6;
        if (kind == 1) {
          if (column == 0) continue;  // a combination this row does not move
          h = 1e-6 / column;
        }
        Eigen::VectorXd dx = Eigen::VectorXd::Zero(p.num_parameters);
        dx(b.offset + c) = h;
        const Eigen::Vector3d fd = (predicted(dx, r) - predicted(-dx, r)) / (2 * h);
        const double scale = std::max(fd.norm(), column);
        ASSERT_GT(scale, 0) << b.kind->name() << " column " << c;
        EXPECT_LT((J.col(c) - fd).norm(), 1e-5 * scale)
            << b.kind->name() << " block at " << b.offset << " column " << c << " row " << r;
        ++checked[kind];
      }
    }
  }
  EXPECT_GT(checked[0], 30);
  EXPECT_GT(checked[1], 10);
  EXPECT_EQ(checked[2], 6);
  (void)F;
}

// The kinds' columns, stacked over every row in the blocks' solved numbering, are the problem's
// normal equations: sum_r J_r^T J_r / sigma^2 = NormalEquations().H (the bulk assembly), for
// position and for pose data, at a state off the start.
TEST(BlockKind, KindsColumnsStackToTheProblemsNormalEquations) {
  for (bool pose : {false, true}) {
    SCOPED_TRACE(pose ? "pose" : "position");
    const EveryKind s(pose);
    CalibrationProblemOptions options = s.Options(pose);
    options.sigma = 0.02;
    CalibrationProblem problem(s.nominal, s.data, options);
    ASSERT_TRUE(problem.block_status().ok());
    MoveEveryBlock(&problem);
    const RobotModel model = problem.Model();
    const Eigen::VectorXd joint_state = problem.JointState();
    const internal::BlockColumnsContext ctx = ColumnsContext(problem, model, joint_state);
    const int P = problem.SolvedParameterization().num_parameters;
    const int m = pose ? 6 : 3;
    Eigen::MatrixXd H = Eigen::MatrixXd::Zero(P, P);
    for (int r = 0; r < s.data.size(); ++r) {
      Eigen::MatrixXd Jr = Eigen::MatrixXd::Zero(m, P);
      for (const ProblemBlock& b : problem.blocks()) {
        Eigen::MatrixXd J;
        b.kind->Columns(ctx, b, s.data, r, &J);
        Jr.middleCols(b.solved_offset, b.tangent_size) = J;
      }
      H.noalias() += Jr.transpose() * Jr;
    }
    H /= options.sigma * options.sigma;
    const ProblemNormalEquations ne = problem.NormalEquations();
    ASSERT_EQ(ne.H.rows(), P);
    ASSERT_TRUE(ne.finite);
    // Relative to each entry's scale sqrt(H_aa H_bb).
    double worst = 0;
    for (int a = 0; a < P; ++a) {
      for (int c = 0; c < P; ++c) {
        const double scale = std::sqrt(ne.H(a, a) * ne.H(c, c));
        if (scale > 0) worst = std::max(worst, std::abs(H(a, c) - ne.H(a, c)) / scale);
      }
    }
    EXPECT_LT(worst, 1e-9);
    EXPECT_GT(H.rightCols(2).norm(), 0);  // the tilt's columns are not zero
  }
}

}  // namespace block_kind_test
}  // namespace
}  // namespace lpoe
