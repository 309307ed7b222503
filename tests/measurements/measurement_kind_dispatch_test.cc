// The kind table is the solvers' dispatch (measurement_kind_dispatch.h): each line of the table
// names its kind's header (residuals, feature, left-out rule), and the contact solvers' rows (the
// linear solver's ContactLinearize, the Ceres path's templated Residual, ContactErrors) are the
// kind headers' functions reached through it, with Jacobians equal to finite differences.
#include <cmath>
#include <string>
#include <vector>

#include <Eigen/Dense>
#include <gtest/gtest.h>

#include "contact/contact_kinds.h"
#include "lpoe/contact_calibration.h"
#include "lpoe/measurements/contact_measurements.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/measurements/measurement_kind_dispatch.h"
#include "lpoe/measurements/measurement_kinds.h"
#include "lpoe/se3_manifold.h"
#include "lpoe/model/simulation.h"
#include "contact_arm.h"
#include "test_util.h"

namespace lpoe {
namespace {
namespace measurement_kind_dispatch_test {

struct KindFacts {
  MeasurementKindId id;
  int residuals;
  int feature_size;
  const char* left_out_reason;
};

TEST(MeasurementKindTable, EachLineIsItsKindsHeader) {
  ASSERT_EQ(MeasurementKinds().size(), 4u);
  for (const MeasurementKindInfo& kind : MeasurementKinds()) {
    const KindFacts f = VisitMeasurementKind(kind.id, [](auto tag) {
      using Kind = typename decltype(tag)::type;
      return KindFacts{Kind::kKind, Kind::kResiduals, Kind::kFeatureSize, Kind::kLeftOutReason};
    });
    EXPECT_EQ(f.id, kind.id) << kind.name;
    EXPECT_EQ(f.residuals, kind.residuals) << kind.name;
    EXPECT_EQ(f.feature_size, kind.feature_size) << kind.name;
    EXPECT_STREQ(f.left_out_reason, kind.left_out_reason) << kind.name;  // text, not address
    // A kind that does not see the base has a rule for what it leaves out, and only such a kind.
    EXPECT_EQ(kind.sees_base, kind.left_out_reason == nullptr) << kind.name;
    // A kind with a feature names it.
    EXPECT_EQ(kind.feature_size > 0, std::string(kind.feature_column) != "") << kind.name;
  }
  EXPECT_STREQ(MeasurementKind(MeasurementKindId::kDistance).left_out_reason,
               DistanceMeasurement::kLeftOutReason);
  EXPECT_STREQ(MeasurementKind(MeasurementKindId::kPlane).left_out_reason,
               PlaneMeasurement::kLeftOutReason);
}

using testing::ContactArm;
using testing::MakeContactArm;

// Ballbar distances, probe contacts and tracker positions (sigma 0.01 mm) of the true robot.
ContactMeasurementSet MixedRows(const RobotModel& truth) {
  ContactMeasurementSet data = testing::BallbarRows(truth, 24, 2, 5);
  data.Append(testing::CubeRows(truth, 24, 6));
  SimulationOptions so;
  so.count = 12;
  so.noise_sigma = 0.01;
  so.seed = 7;
  const MeasurementSet tracker =
      SimulateMeasurements(truth, std::vector<double>(truth.num_joints(), 0.0), so);
  data.Append(ContactSetFromPositions(tracker, 0.01, "tracker"));
  return data;
}

// The contact solvers' rows, kind by kind, are the headers': the linear solver's residuals equal
// the Ceres path's templated Residual on the model's frames (the same kind, reached through the
// table), ContactErrors the header's Error, and each row's Jacobian the central differences of the
// kind's own Residual along the solver's columns.
TEST(MeasurementKindTable, ContactRowsAreTheKindsHeaderFunctions) {
  const ContactArm t = MakeContactArm(45);
  const ContactMeasurementSet data = MixedRows(t.truth);
  ASSERT_GT(data.Count(MeasurementKindId::kDistance), 0);
  ASSERT_GT(data.Count(MeasurementKindId::kPlane), 0);
  ASSERT_GT(data.Count(MeasurementKindId::kPosition), 0);
  ContactFeatures f;
  ASSERT_TRUE(InitialContactFeatures(t.nominal, data, &f).ok());
  ContactCalibrationOptions o;
  ContactParameterization p;
  ASSERT_TRUE(MakeContactParameterization(t.nominal, f, data, o, &p).ok());
  Eigen::VectorXd r;
  Eigen::MatrixXd J;
  ContactLinearize(t.nominal, f, p, t.nominal, data, o, &r, &J);
  const std::vector<double> errors = ContactErrors(t.nominal, f, data);

  // Every frame's block of 7, as the Ceres path builds them; the residual of row i with its kind's
  // templated Residual, the feature's ambient values from `g`.
  const int n = t.nominal.num_joints();
  auto kind_residual = [&](const RobotModel& m, const ContactFeatures& g, int i) {
    const ContactRow& row = data.rows[i];
    std::vector<double> blocks(kSe3AmbientSize * (n + 1));
    for (int k = 0; k < n; ++k) Se3ToArray(m.joints[k].origin, blocks.data() + kSe3AmbientSize * k);
    Se3ToArray(m.tools[row.target].origin, blocks.data() + kSe3AmbientSize * n);
    std::vector<const double*> b;
    for (int k = 0; k <= n; ++k) b.push_back(blocks.data() + kSe3AmbientSize * k);
    const JointMotions<double> motions(m, data.joints(i));
    Eigen::VectorXd out;
    internal::VisitContactRowKind(row.kind, [&](auto tag) {
      using Kind = typename decltype(tag)::type;
      out.resize(Kind::kResiduals);
      const Kind kind{1.0 / row.sigma};
      if constexpr (Kind::kFeatureSize > 0) {
        b.push_back(internal::ContactFeatureData<Kind>(g, row.feature));
        kind.Residual(n, b.data(), motions, row.value, out.data());
      } else {
        kind.Residual(n, b.data(), motions, Eigen::Vector3d(row.position), out.data());
      }
    });
    return out;
  };

  const double h = 1e-6;
  std::vector<Eigen::VectorXd> plus(data.size()), minus(data.size());
  std::vector<Eigen::MatrixXd> fd(data.size());
  for (int i = 0; i < data.size(); ++i) {
    fd[i].resize(MeasurementKind(data.rows[i].kind).residuals, p.num_parameters);
  }
  for (int c = 0; c < p.num_parameters; ++c) {
    for (int sgn : {1, -1}) {
      const testing::MovedContactState s =
          testing::MoveAlongContactColumn(t.nominal, f, p, c, sgn * h);
      for (int i = 0; i < data.size(); ++i) {
        (sgn > 0 ? plus : minus)[i] = kind_residual(s.model, s.features, i);
      }
    }
    for (int i = 0; i < data.size(); ++i) fd[i].col(c) = (plus[i] - minus[i]) / (2 * h);
  }

  int at = 0;
  int checked[4] = {0, 0, 0, 0};
  for (int i = 0; i < data.size(); ++i) {
    const ContactRow& row = data.rows[i];
    const MeasurementKindInfo& kind = MeasurementKind(row.kind);
    const Eigen::VectorXd residual = kind_residual(t.nominal, f, i);
    ASSERT_EQ(residual.size(), kind.residuals);
    EXPECT_LT((r.segment(at, kind.residuals) - residual).norm(), 1e-9 * (1 + residual.norm()))
        << kind.name << " row " << i;
    // ContactErrors: mm, signed for a feature's kind, |e| for a tracker row.
    const double expected = kind.feature_size > 0 ? residual(0) * row.sigma
                                                  : residual.norm() * row.sigma;
    EXPECT_NEAR(errors[i], expected, 1e-9) << kind.name << " row " << i;
    const Eigen::MatrixXd rows = J.middleRows(at, kind.residuals);
    EXPECT_LT((rows - fd[i]).norm(), 1e-5 * std::max(1.0, fd[i].norm()))
        << kind.name << " row " << i;
    // The row has columns on its own feature only.
    const int features = p.num_parameters - p.pivot_offset;
    internal::VisitContactRowKind(row.kind, [&](auto tag) {
      using Kind = typename decltype(tag)::type;
      if constexpr (Kind::kFeatureSize > 0) {
        const int first = internal::ContactFeatureColumn<Kind>(p, row.feature);
        const double own = rows.middleCols(first, Kind::kFeatureTangent).norm();
        EXPECT_GT(own, 0) << kind.name << " row " << i;
        EXPECT_NEAR(rows.rightCols(features).norm(), own, 1e-12 * own)
            << kind.name << " row " << i;
      } else {
        EXPECT_EQ(rows.rightCols(features).norm(), 0) << kind.name << " row " << i;
      }
    });
    ++checked[static_cast<int>(row.kind)];
    at += kind.residuals;
  }
  EXPECT_GT(checked[static_cast<int>(MeasurementKindId::kDistance)], 0);
  EXPECT_GT(checked[static_cast<int>(MeasurementKindId::kPlane)], 0);
  EXPECT_GT(checked[static_cast<int>(MeasurementKindId::kPosition)], 0);
}

// The left-out rule comes from the table: a kind that does not see the base gives its own reason
// to the base's directions; both kinds together give the joint one.
TEST(MeasurementKindTable, LeftOutReasonIsTheKindsRule) {
  const ContactArm t = MakeContactArm(45);
  const ContactMeasurementSet bar = testing::BallbarRows(t.truth, 40, 3, 8);
  const ContactMeasurementSet cube = testing::CubeRows(t.truth, 40, 9);
  ContactMeasurementSet both = bar;
  both.Append(cube);
  auto base_reason = [&](const ContactMeasurementSet& data) {
    ContactFeatures f;
    EXPECT_TRUE(InitialContactFeatures(t.nominal, data, &f).ok());
    ContactParameterization p;
    const ContactCalibrationOptions o;
    EXPECT_TRUE(MakeContactParameterization(t.nominal, f, data, o, &p).ok());
    EXPECT_GT(p.num_base_directions, 0);
    return p.base_reason;
  };
  const std::string distance = MeasurementKind(MeasurementKindId::kDistance).left_out_reason;
  const std::string plane = MeasurementKind(MeasurementKindId::kPlane).left_out_reason;
  EXPECT_EQ(base_reason(bar).rfind(distance, 0), 0u) << base_reason(bar);
  EXPECT_EQ(base_reason(cube).rfind(plane, 0), 0u) << base_reason(cube);
  const std::string joint = base_reason(both);
  EXPECT_EQ(joint.rfind(distance, 0), std::string::npos) << joint;
  EXPECT_EQ(joint.rfind(plane, 0), std::string::npos) << joint;
  EXPECT_NE(joint.find("pivots and planes"), std::string::npos) << joint;
}

}  // namespace measurement_kind_dispatch_test
}  // namespace
}  // namespace lpoe
