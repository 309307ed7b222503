// Position and pose as measurement kinds (measurement_kind_dispatch.h, docs/measurements.md): each
// line of the kind table gives the CSV columns its reader accepts, and the tracker solvers' rows
// reached through VisitTrackerKind are the kind headers' functions: the linear solver's normal
// equations (NormalEquationsOf) equal J^T J and -J^T r of the kind's templated Residual with J by
// central differences, the Ceres problem's residuals (CalibrationProblem::AddTo) are that Residual,
// and the simulation draws the kind's Simulate.
#include <algorithm>
#include <cmath>
#include <iterator>
#include <string>
#include <vector>

#include <ceres/ceres.h>
#include <Eigen/Dense>
#include <gtest/gtest.h>

#include "linearization/normal_equations.h"
#include "lpoe/measurements/contact_measurements.h"
#include "lpoe/io/io.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/measurements/measurement_kind_dispatch.h"
#include "lpoe/measurements/measurement_kinds.h"
#include "lpoe/model/parameterization.h"
#include "lpoe/problem_builder.h"
#include "lpoe/se3_manifold.h"
#include "lpoe/model/simulation.h"
#include "test_util.h"

namespace lpoe {
namespace {
namespace tracker_kind_test {

// A table line's columns ("q1..qN,x,y,z[,target]"): the required ones after the joint values and
// the optional ones.
struct TableColumns {
  std::vector<std::string> required, optional;
};

TableColumns SplitTableColumns(const std::string& text) {
  TableColumns out;
  std::string token;
  bool optional = false;
  auto flush = [&]() {
    if (!token.empty() && token != "q1..qN") (optional ? out.optional : out.required).push_back(token);
    token.clear();
  };
  for (char c : text) {
    if (c == '[') {
      flush();
      optional = true;
    } else if (c == ']') {
      flush();
      optional = false;
    } else if (c == ',') {
      flush();
    } else {
      token += c;
    }
  }
  flush();
  return out;
}

// A value each column accepts.
std::string ValueOf(const std::string& column) {
  if (column == "quat_x" || column == "quat_y" || column == "quat_z") return "0";
  if (column == "quat_w") return "1";
  if (column == "target") return "0";
  if (column == "pivot") return "p1";
  if (column == "plane") return "top";
  if (column == "offset" || column == "x") return "0.5";
  if (column == "sigma") return "0.002";
  return "150";  // distance, y, z
}

// A one-row file with the joint values and `columns`: its kind as the reader takes it (null when
// the reader refuses it; *message says why).
const MeasurementKindInfo* ReadAs(const RobotModel& model, const std::vector<std::string>& columns,
                                  std::string* message) {
  std::string header, row;
  for (int j = 0; j < model.num_joints(); ++j) {
    header += "q" + std::to_string(j + 1) + ",";
    row += "0.1,";
  }
  for (size_t k = 0; k < columns.size(); ++k) {
    header += (k > 0 ? "," : "") + columns[k];
    row += (k > 0 ? "," : "") + ValueOf(columns[k]);
  }
  const std::string text = header + "\n" + row + "\n";
  std::vector<std::string> names;
  for (int j = 0; j < model.num_joints(); ++j) names.push_back("q" + std::to_string(j + 1));
  names.insert(names.end(), columns.begin(), columns.end());
  const MeasurementKindInfo* kind = DetectMeasurementKind(names);
  if (kind == nullptr) {
    *message = "no kind detected";
    return nullptr;
  }
  if (IsTrackerKind(kind->id)) {
    MeasurementSet data(model.num_joints());
    const Status s = ParseMeasurementsCsv(text, "t.csv", model, AngleUnit::kRadians, &data);
    *message = s.message();
    if (!s.ok() || data.size() != 1) return nullptr;
    return &MeasurementKind(TrackerKindId(data.has_orientation()));
  }
  ContactMeasurementSet data;
  ContactCsvOptions options;
  options.sigma = 0.002;
  const Status s = ParseContactMeasurementsCsv(text, "t.csv", model, options, &data);
  *message = s.message();
  if (!s.ok() || data.size() != 1) return nullptr;
  return &MeasurementKind(data.rows[0].kind);
}

// Each line's columns are what the reader takes as that kind: all of them, the required ones
// alone, and never with one required column missing. The tracker kinds' measured columns are their
// headers' kColumns.
TEST(TrackerKinds, TableColumnsAreWhatTheReaderAccepts) {
  const RobotModel model = MakeCobot6();
  for (const MeasurementKindInfo& kind : MeasurementKinds()) {
    const TableColumns c = SplitTableColumns(kind.columns);
    ASSERT_FALSE(c.required.empty()) << kind.name;
    EXPECT_NE(std::find(c.required.begin(), c.required.end(), kind.key_column), c.required.end())
        << kind.name << ": the key column is required";
    std::vector<std::string> all = c.required;
    all.insert(all.end(), c.optional.begin(), c.optional.end());
    std::string message;
    const MeasurementKindInfo* read = ReadAs(model, all, &message);
    ASSERT_NE(read, nullptr) << kind.name << ": " << message;
    EXPECT_EQ(read->id, kind.id) << kind.name;
    read = ReadAs(model, c.required, &message);
    ASSERT_NE(read, nullptr) << kind.name << ": " << message;
    EXPECT_EQ(read->id, kind.id) << kind.name;
    for (size_t k = 0; k < c.required.size(); ++k) {
      std::vector<std::string> fewer = all;
      fewer.erase(std::find(fewer.begin(), fewer.end(), c.required[k]));
      read = ReadAs(model, fewer, &message);
      EXPECT_TRUE(read == nullptr || read->id != kind.id)
          << kind.name << " read without its column " << c.required[k];
    }
    if (IsTrackerKind(kind.id)) {
      const std::vector<std::string> header_columns = VisitTrackerKind(kind.id, [](auto tag) {
        using Kind = typename decltype(tag)::type;
        return std::vector<std::string>(std::begin(Kind::kColumns), std::end(Kind::kColumns));
      });
      EXPECT_EQ(header_columns, c.required) << kind.name;
      EXPECT_EQ(TrackerResiduals(kind.id), kind.residuals) << kind.name;
    }
  }
  // The pose's quaternion is all four columns or none.
  std::string message;
  EXPECT_EQ(ReadAs(model, {"x", "y", "z", "quat_x", "quat_y", "quat_w"}, &message), nullptr);
  EXPECT_NE(message.find("incomplete orientation: missing 'quat_z'"), std::string::npos) << message;
}

std::vector<double> Blocks(const RobotModel& model, int tool) {
  const int n = model.num_joints();
  std::vector<double> b(static_cast<size_t>(n + 1) * kSe3AmbientSize);
  for (int i = 0; i < n; ++i) Se3ToArray(model.joints[i].origin, b.data() + i * kSe3AmbientSize);
  Se3ToArray(model.tools[tool].origin, b.data() + n * kSe3AmbientSize);
  return b;
}

// The kind's templated Residual (inverse_sigma 1) of every row at `model`, stacked.
template <typename Kind>
Eigen::VectorXd KindResiduals(const Kind& kind, const RobotModel& model,
                              const MeasurementSet& data) {
  const int n = model.num_joints();
  Eigen::VectorXd r(static_cast<Eigen::Index>(Kind::kResiduals) * data.size());
  for (int row = 0; row < data.size(); ++row) {
    std::vector<double> b = Blocks(model, data.target(row));
    std::vector<const double*> blocks;
    for (int i = 0; i <= n; ++i) blocks.push_back(b.data() + i * kSe3AmbientSize);
    const JointMotions<double> motions(model, data.q(row));
    kind.Residual(n, blocks.data(), motions, Kind::Observe(data, row),
                  r.data() + static_cast<Eigen::Index>(Kind::kResiduals) * row);
  }
  return r;
}

struct TrackerCase {
  RobotModel model;
  MeasurementSet data;
  Parameterization p;
};

// Rows of `id` measured on the model itself with small noise (0.01 mm, 20 urad): the analytic
// linearization is exact to first order in the errors there.
TrackerCase MakeCase(MeasurementKindId id) {
  TrackerCase c;
  c.model = MakeCobot6();
  SimulationOptions o;
  o.count = 25;
  o.seed = 11;
  o.noise_sigma = 0.01;
  o.pose = id == MeasurementKindId::kPose;
  o.orientation_noise_sigma = 2e-5;
  c.data = SimulateMeasurements(c.model, {}, o);
  c.p = MakeParameterization(c.model, ParameterizationKind::kIdentifiable, TrackerDataKind(id));
  return c;
}

// The linear solver's rows through the dispatch are the kind's Residual and its central
// differences: H = J^T J, g = -J^T r, cost = r^T r / 2.
TEST(TrackerKinds, LinearRowsThroughDispatchAreTheKindsResiduals) {
  const double w = 300;  // mm per rad
  for (const MeasurementKindId id : {MeasurementKindId::kPosition, MeasurementKindId::kPose}) {
    SCOPED_TRACE(MeasurementKind(id).name);
    const TrackerCase c = MakeCase(id);
    ASSERT_EQ(c.data.has_orientation(), id == MeasurementKindId::kPose);
    internal::NormalEquationsOptions options;
    options.use_orientation = id == MeasurementKindId::kPose;
    options.orientation_weight = w;
    const internal::NormalEquations lin =
        internal::NormalEquationsOf(c.model, c.data, c.p, Eigen::VectorXd(), options);
    VisitTrackerKind(id, [&](auto tag) {
      using Kind = typename decltype(tag)::type;
      const Kind kind = Kind::Make(1.0, w);
      const Eigen::VectorXd r = KindResiduals(kind, c.model, c.data);
      ASSERT_EQ(r.size(), static_cast<Eigen::Index>(MeasurementKind(id).residuals) * c.data.size());
      const int P = c.p.num_parameters;
      Eigen::MatrixXd J(r.size(), P);
      const double h = 1e-6;
      for (int k = 0; k < P; ++k) {
        Eigen::VectorXd x = Eigen::VectorXd::Zero(P);
        RobotModel plus = c.model, minus = c.model;
        x(k) = h;
        ApplyUpdate(c.p, x, &plus);
        x(k) = -h;
        ApplyUpdate(c.p, x, &minus);
        J.col(k) = (KindResiduals(kind, plus, c.data) - KindResiduals(kind, minus, c.data)) / (2 * h);
      }
      const Eigen::MatrixXd H = J.transpose() * J;
      const Eigen::VectorXd g = -J.transpose() * r;
      EXPECT_NEAR(lin.cost, 0.5 * r.squaredNorm(), 1e-9 * (1 + lin.cost));
      EXPECT_LT((lin.H - H).cwiseAbs().maxCoeff(), 1e-5 * H.cwiseAbs().maxCoeff());
      EXPECT_LT((lin.g - g).cwiseAbs().maxCoeff(), 1e-4 * g.cwiseAbs().maxCoeff() + 1e-9);
      // Not a trivial agreement: the noise gives a gradient, and the kinds differ.
      EXPECT_GT(g.norm(), 0);
      EXPECT_EQ(lin.H.rows(), P);
    });
  }
}

// The Ceres problem's residual blocks (AddTo, through the dispatch) are the kind's Residual with
// inverse_sigma = 1 / sigma and the orientation weight, row by row, and their Jacobian's J^T J
// is the problem's normal matrix (the linear rows of the same kind).
TEST(TrackerKinds, CeresResidualsThroughDispatchAreTheKindsResiduals) {
  const double w = 300, sigma = 0.02;
  for (const MeasurementKindId id : {MeasurementKindId::kPosition, MeasurementKindId::kPose}) {
    SCOPED_TRACE(MeasurementKind(id).name);
    const TrackerCase c = MakeCase(id);
    CalibrationProblemOptions o;
    o.use_orientation = id == MeasurementKindId::kPose;
    o.orientation_weight = w;
    o.sigma = sigma;
    CalibrationProblem builder(c.model, c.data, o);
    ceres::Problem problem;
    builder.AddTo(&problem);
    std::vector<double*> blocks;
    for (int f = 0; f < c.model.num_frames(); ++f) {
      if (builder.frame_solved(f)) blocks.push_back(builder.frame_block(f));
    }
    ceres::Problem::EvaluateOptions eo;
    eo.parameter_blocks = blocks;
    std::vector<double> residuals;
    ceres::CRSMatrix crs;
    double cost = 0;
    ASSERT_TRUE(problem.Evaluate(eo, &cost, &residuals, nullptr, &crs));
    const Eigen::VectorXd expected = VisitTrackerKind(id, [&](auto tag) {
      using Kind = typename decltype(tag)::type;
      return KindResiduals(Kind::Make(1.0 / sigma, w), c.model, c.data);
    });
    ASSERT_EQ(static_cast<Eigen::Index>(residuals.size()), expected.size());
    for (size_t k = 0; k < residuals.size(); ++k) {
      EXPECT_NEAR(residuals[k], expected(k), 1e-9 * (1 + std::abs(expected(k)))) << k;
    }
    Eigen::MatrixXd J = Eigen::MatrixXd::Zero(crs.num_rows, crs.num_cols);
    for (int row = 0; row < crs.num_rows; ++row) {
      for (int k = crs.rows[row]; k < crs.rows[row + 1]; ++k) J(row, crs.cols[k]) = crs.values[k];
    }
    const ProblemNormalEquations ne = builder.NormalEquations();
    ASSERT_EQ(ne.H.rows(), J.cols());
    const Eigen::MatrixXd H = J.transpose() * J;
    // Equal up to the linearization's first-order error in the pose rows' log (eq. (18): the
    // rows' errors are ~2e-5 rad, ~4e-6 of the largest entry; Ceres differentiates the log itself).
    EXPECT_LT((ne.H - H).cwiseAbs().maxCoeff(), 5e-5 * H.cwiseAbs().maxCoeff());
    EXPECT_NEAR(ne.cost, cost, 1e-9 * (1 + cost));
  }
}

// The simulation's rows are the kind's Simulate of the true pose with the same draws: position
// rows are the pose rows' positions (the position's three draws come first), and the pose rows'
// orientations are off the true ones by the orientation noise.
TEST(TrackerKinds, SimulationIsTheKindsSimulate) {
  const RobotModel model = MakeCobot6();
  SimulationOptions o;
  o.count = 30;
  o.seed = 4;
  o.noise_sigma = 0.05;
  o.orientation_noise_sigma = 1e-3;
  const MeasurementSet position = SimulateMeasurements(model, {}, o);
  o.pose = true;
  const MeasurementSet pose = SimulateMeasurements(model, {}, o);
  ASSERT_EQ(position.size(), o.count);
  ASSERT_EQ(pose.size(), o.count);
  EXPECT_FALSE(position.has_orientation());
  EXPECT_TRUE(pose.has_orientation());
  double max_angle = 0, sum_angle2 = 0;
  for (int r = 0; r < o.count; ++r) {
    // The pose rows draw three more numbers per row, so the rows' configurations differ after the
    // first: compare each set with its own truth.
    const SE3d truth = ToolPose(model, pose.q(r), pose.target(r));
    const double angle = LogSO3(Eigen::Matrix3d(truth.R.transpose() * pose.orientation(r))).norm();
    max_angle = std::max(max_angle, angle);
    sum_angle2 += angle * angle;
    EXPECT_LT((pose.position(r) - truth.t).norm(), 6 * o.noise_sigma);
    EXPECT_LT((position.position(r) - ToolPosition(model, position.q(r), 0)).norm(),
              6 * o.noise_sigma);
  }
  EXPECT_EQ(Eigen::Map<const Eigen::VectorXd>(position.q(0), 6),
            Eigen::Map<const Eigen::VectorXd>(pose.q(0), 6));
  // Three axes of 1 mrad: the rms angle about sqrt(3) mrad.
  EXPECT_LT(max_angle, 6e-3);
  EXPECT_NEAR(std::sqrt(sum_angle2 / o.count), std::sqrt(3.0) * 1e-3, 0.6e-3);
}

}  // namespace tracker_kind_test
}  // namespace
}  // namespace lpoe
