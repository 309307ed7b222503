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

#include "lpoe/joint_errors.h"
#include "lpoe/joint_term.h"
#include "lpoe/pipeline.h"
#include "lpoe/simulation.h"
#include "lpoe/statistics.h"

namespace lpoe {
namespace {

TEST(JointErrorTerms, RegisteredAndSized) {
  const RobotModel m = MakeCobot6();
  for (JointErrorKind kind : {JointErrorKind::kCompliance, JointErrorKind::kHarmonics}) {
    std::shared_ptr<const JointTerm> term;
    ASSERT_TRUE(MakeJointTerm(JointErrorKindName(kind), m, &term).ok());
    EXPECT_EQ(term->name(), JointErrorKindName(kind));
    EXPECT_EQ(term->num_joints(), m.num_joints());
    EXPECT_EQ(term->num_parameters(), NumJointErrorParameters(m.num_joints(), kind));
    const std::vector<double> q = {0.1, -0.4, 0.7, 0.2, -1.1, 0.5};
    Eigen::MatrixXd Y(m.num_joints(), term->num_parameters()), ref;
    term->Regressor(q.data(), Y.data());
    JointErrorRegressor(m, kind, q.data(), &ref);
    EXPECT_LE((Y - ref).cwiseAbs().maxCoeff(), 1e-10 * ref.cwiseAbs().maxCoeff());
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
    ApplyJointErrorPhysics(SmallArmJointErrors(nominal, small_arm), true, true, &actual);
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
  EXPECT_EQ(JointErrorParameters(with.result.model, JointErrorKind::kCompliance).size(),
            static_cast<size_t>(NumComplianceParameters(6)));
  EXPECT_EQ(JointErrorParameters(with.result.model, JointErrorKind::kHarmonics).size(),
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

TEST(JointErrorTerms, UnknownNameFails) {
  const Fixture f;
  const PipelineResult r = RunPipeline(f, SolverKind::kLinear, {"backlash"});
  EXPECT_EQ(r.result.termination, Termination::kNotIdentifiable);
}

}  // namespace
}  // namespace lpoe
