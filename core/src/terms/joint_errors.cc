#include "lpoe/terms/joint_errors.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include <Eigen/SVD>
#include <glog/logging.h>

#include "lpoe/kinematics/eigen_decompositions.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/parallel.h"
#include "lpoe/model/residual_layer.h"

namespace lpoe {
namespace {

// Torque lengths are in mm; torques in N m.
constexpr double kMetresPerMillimetre = 1e-3;

// Link frames T_0,k(q) (after joint k moved) and joint twists (w_j, v_j) in the base frame.
struct ChainState {
  std::vector<SE3d> link;
  std::vector<Vector6d> twist;
};

// `origins`: the joint origins to use instead of the model's (nullptr: the model's). The chain is
// kinematics.h's ForwardChain (SE3Accumulator<double>): before joint i moves its frame gives the
// twist Ad_{G_i} s_i, after it the link frame.
void ComputeChainState(const RobotModel& model, const double* q, ChainState* state,
                       const std::vector<SE3d>* origins = nullptr) {
  const int n = model.num_joints();
  state->link.resize(n);
  state->twist.resize(n);
  auto origin = [&](int i) -> const SE3d& {
    return origins != nullptr ? (*origins)[i] : model.joints[i].origin;
  };
  const ClassifiedJoints models{model.joints.data()};
  auto twist = [&](int i, const SE3Accumulator<double>& G) {  // Ad_G s_i: the model's pose column
    models.Visit(i, [&](auto m) {
      decltype(m)::PoseColumn(G.X.R.data(), G.X.t.data(), model.joints[i].twist,
                              state->twist[i].data());
    });
  };
  auto link = [&](int i, const SE3Accumulator<double>& X) { state->link[i] = X.X; };
  SE3Accumulator<double> X;
  X.X = SE3d();
  // sin and cos of every joint value at once (SinCosMany: within 1 ulp of the exact values, the
  // same value for the same q wherever it is computed).
  if (n <= kMaxGivenSinCosJoints) {
    double sin_q[kMaxGivenSinCosJoints], cos_q[kMaxGivenSinCosJoints];
    SinCosMany(q, n, sin_q, cos_q);
    ForwardChain(n, origin, MakeGivenSinCosMotions(model.joints.data(), q, models, sin_q, cos_q), &X,
                 twist, link);
  } else {
    ForwardChain(n, origin, MakeOnTheFlyMotions(model.joints.data(), q, models), &X, twist, link);
  }
}

// The compliance regressor's entries at their own joints for gravity g (linear in g): y[c] =
// Y(j, c) for every parameter c of joint j (layout of NumComplianceParameters: joint j's links, then
// its payload column); every other entry of Y is zero.
void ComplianceValuesFor(const RobotModel& model, const ChainState& state, const Eigen::Vector3d& g,
                         double* y) {
  const int n = model.num_joints();
  for (int j = 0; j < n; ++j) {
    const Eigen::Vector3d w = state.twist[j].head<3>();
    const Eigen::Vector3d v = state.twist[j].tail<3>();
    const double scale =
        model.joints[j].type == JointType::kRevolute ? kMetresPerMillimetre : 1.0;
    const Eigen::Vector3d gw = g.cross(w);
    const double vg = v.dot(g);
    double a = 0;
    Eigen::Vector3d b = Eigen::Vector3d::Zero();
    double* out = y + ComplianceLinkIndex(n, j, j);
    for (int k = j; k < n; ++k, out += 4) {
      const SE3d& L = state.link[k];
      a = scale * (gw.dot(L.t) + vg);
      b = scale * (L.R.transpose() * gw);
      out[0] = a;
      out[1] = b(0);
      out[2] = b(1);
      out[3] = b(2);
    }
    // The payload sits on the last link: a and b are link n-1's.
    *out = model.payload.mass * (a + b.dot(model.payload.com));
  }
}

// The compliance regressor for gravity g (linear in g).
void ComplianceRegressorFor(const RobotModel& model, const ChainState& state,
                            const Eigen::Vector3d& g, Eigen::MatrixXd* Y) {
  const int n = model.num_joints();
  const int P = NumComplianceParameters(n);
  thread_local std::vector<double> y;
  y.resize(P);
  ComplianceValuesFor(model, state, g, y.data());
  Y->setZero(n, P);
  for (int j = 0; j < n; ++j) {
    for (int c = ComplianceLinkIndex(n, j, j); c <= CompliancePayloadIndex(n, j); ++c) {
      (*Y)(j, c) = y[c];
    }
  }
}

// Every joint's 4 harmonic entries (zero for a prismatic joint), joint after joint; sin and cos of
// all joint values at once (SinCosMany).
void HarmonicsValues(const RobotModel& model, const double* q, double* out) {
  const int n = model.num_joints();
  double stack[2 * kMaxGivenSinCosJoints];
  std::vector<double> heap(n <= kMaxGivenSinCosJoints ? 0 : 2 * static_cast<size_t>(n));
  double* sc = heap.empty() ? stack : heap.data();
  SinCosMany(q, n, sc, sc + n);
  for (int j = 0; j < n; ++j, out += kHarmonicsPerJoint) {
    if (model.joints[j].type != JointType::kRevolute) {
      out[0] = out[1] = out[2] = out[3] = 0;
      continue;
    }
    const double s1 = sc[j], c1 = sc[n + j];
    out[0] = s1;
    out[1] = c1;
    out[2] = 2 * s1 * c1;       // sin 2q
    out[3] = c1 * c1 - s1 * s1;  // cos 2q
  }
}

// Entries below kJointErrorRoundingCutoff of the largest |y| set to exact zeros (a NaN is kept).
void ZeroRoundingNoiseImpl(double* y, int size) {
  double largest = 0;
  for (int k = 0; k < size; ++k) largest = std::max(largest, std::abs(y[k]));
  const double cutoff = kJointErrorRoundingCutoff * largest;
  for (int k = 0; k < size; ++k) {
    if (std::abs(y[k]) < cutoff) y[k] = 0.0;
  }
}

bool AllFinite(const std::vector<double>& v) {
  for (double x : v) {
    if (!std::isfinite(x)) return false;
  }
  return true;
}

}  // namespace

bool ParseJointTermList(const std::string& text, std::vector<std::string>* names,
                        std::string* error) {
  if (text.empty() || text == "none") {
    names->clear();
    return true;
  }
  std::vector<std::string> out;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    if (!IsJointTermName(item)) {
      *error = "unknown joint error term " + std::string("'") + item + "' (known: " +
               JointTermNameList() + ")";
      return false;
    }
    if (std::find(out.begin(), out.end(), item) != out.end()) {
      *error = "'" + item + "' is listed more than once";
      return false;
    }
    out.push_back(item);
  }
  if (out.empty() || text.back() == ',') {
    *error = "not a comma-separated list of " + JointTermNameList();
    return false;
  }
  *names = out;
  return true;
}

int NumComplianceParameters(int num_joints) {
  // sum_{j<n} 4 (n - j) + 1 = 2 n (n + 1) + n.
  return 2 * num_joints * (num_joints + 1) + num_joints;
}

int ComplianceLinkIndex(int num_joints, int joint, int link) {
  DCHECK(0 <= joint && joint <= link && link < num_joints);
  // Blocks of joints before `joint`: sum_{i<j} 4 (n - i) + 1.
  const int before = 4 * (joint * num_joints - joint * (joint - 1) / 2) + joint;
  return before + 4 * (link - joint);
}

int CompliancePayloadIndex(int num_joints, int joint) {
  return ComplianceLinkIndex(num_joints, joint, joint) + 4 * (num_joints - joint);
}

int NumHarmonicsParameters(int num_joints) { return kHarmonicsPerJoint * num_joints; }

Status ValidateJointErrorTerms(const RobotModel& model) {
  if (!model.gravity.allFinite()) return Status::Error("gravity: non-finite number");
  if (!std::isfinite(model.payload.mass) || model.payload.mass < 0) {
    std::ostringstream os;
    os << "payload: mass " << model.payload.mass << " kg must be finite and >= 0";
    return Status::Error(os.str());
  }
  if (!model.payload.com.allFinite()) return Status::Error("payload: non-finite centre of mass");
  const std::vector<SE3d>& origins = model.joint_errors.regressor_origins;
  if (!origins.empty() && static_cast<int>(origins.size()) != model.num_joints()) {
    std::ostringstream os;
    os << "joint_errors: " << origins.size() << " regressor origins; expected one per joint ("
       << model.num_joints() << ")";
    return Status::Error(os.str());
  }
  for (const SE3d& o : origins) {
    if (!o.t.allFinite() || !o.R.allFinite() ||
        !(o.R.transpose() * o.R - Eigen::Matrix3d::Identity()).isZero(1e-9)) {
      return Status::Error("joint_errors: a regressor origin is not a finite rigid transform");
    }
  }
  const std::vector<JointTermEntry>& terms = model.joint_errors.terms;
  for (size_t t = 0; t < terms.size(); ++t) {
    const std::string& name = terms[t].name;
    if (!IsJointTermName(name)) {
      return Status::Error("joint_errors: unknown term '" + name + "' (known: " +
                           JointTermNameList() + ")");
    }
    for (size_t u = 0; u < t; ++u) {
      if (terms[u].name == name) return Status::Error("joint_errors: '" + name + "' twice");
    }
    const std::vector<double>& v = terms[t].values;
    const int expected = NumJointErrorParameters(model, name);
    if (!v.empty() && static_cast<int>(v.size()) != expected) {
      std::ostringstream os;
      os << "joint_errors: " << name << " has " << v.size() << " parameters; expected "
         << expected << " for " << model.num_joints() << " joints";
      return Status::Error(os.str());
    }
    if (!AllFinite(v)) {
      return Status::Error("joint_errors: non-finite " + name + " parameter");
    }
  }
  return Status::Ok();
}

void ComplianceRegressor(const RobotModel& model, const double* q, Eigen::MatrixXd* Y) {
  thread_local ChainState state;  // no allocation per call (solvers evaluate it for every row)
  ComputeChainState(model, q, &state);
  ComplianceRegressorFor(model, state, model.gravity, Y);
}

void ComplianceRegressorGravityAxes(const RobotModel& model, const double* q,
                                    Eigen::MatrixXd Y[3]) {
  ChainState state;
  ComputeChainState(model, q, &state);
  for (int a = 0; a < 3; ++a) {
    ComplianceRegressorFor(model, state, Eigen::Vector3d::Unit(a), &Y[a]);
  }
}

void ComplianceValuesGravityAxes(const RobotModel& model, const double* q, double* const y[3]) {
  thread_local ChainState state;  // no allocation per call (solvers evaluate it for every row)
  ComputeChainState(model, q, &state);
  for (int a = 0; a < 3; ++a) ComplianceValuesFor(model, state, Eigen::Vector3d::Unit(a), y[a]);
}

Eigen::Matrix<double, 3, 2> GravityTiltAxes(const Eigen::Vector3d& gravity) {
  Eigen::Matrix<double, 3, 2> axes = Eigen::Matrix<double, 3, 2>::Zero();
  const double norm = gravity.norm();
  if (!(norm > 0)) return axes;
  const Eigen::Vector3d d = gravity / norm;
  int least = 0;  // the base axis least aligned with gravity (the first on ties: x for -z)
  for (int a = 1; a < 3; ++a) {
    if (std::abs(d(a)) < std::abs(d(least)) - 1e-12) least = a;
  }
  Eigen::Vector3d u1 = Eigen::Vector3d::Unit(least) - d(least) * d;
  u1.normalize();
  axes.col(0) = u1;
  axes.col(1) = u1.cross(d);
  return axes;
}

Eigen::Matrix<double, 3, 2> TiltedGravityJacobian(const Eigen::Vector3d& gravity,
                                                  const Eigen::Matrix<double, 3, 2>& axes,
                                                  const double* tilt) {
  // exp(w + e) g = exp(w) exp(J_r(w) e) g ~ exp(w) g - exp(w) [g]^ J_r(w) e,
  // J_r(w) = I - B w^ + C w^2 (Rodrigues coefficients).
  const Eigen::Vector3d w = axes.col(0) * tilt[0] + axes.col(1) * tilt[1];
  double a, b, c;
  RodriguesCoefficients<double>(w.squaredNorm(), &a, &b, &c);
  const Eigen::Matrix3d W = Hat3(w);
  const Eigen::Matrix3d J_r = Eigen::Matrix3d::Identity() - b * W + c * (W * W);
  return -ExpSO3(w) * Hat3(gravity) * J_r * axes;
}

Eigen::Vector2d GravityTiltBetween(const Eigen::Vector3d& from, const Eigen::Vector3d& to) {
  const Eigen::Matrix<double, 3, 2> axes = GravityTiltAxes(from);
  const Eigen::Vector3d a = from.normalized(), b = to.normalized();
  const Eigen::Vector3d axis = a.cross(b);
  const double s = axis.norm();
  if (!(s > 0)) return Eigen::Vector2d::Zero();
  const Eigen::Vector3d w = axis / s * std::atan2(s, a.dot(b));  // the shortest turn, about a
  return axes.transpose() * w;  // w is perpendicular to `from`, i.e. in the span of the axes
}

GravityTiltModel::GravityTiltModel(const RobotModel& reference)
    : reference_(reference), axes_(GravityTiltAxes(reference.gravity)) {}

void GravityTiltModel::AxisRegressors(const double* q, Eigen::MatrixXd Y[3]) const {
  ComplianceRegressorGravityAxes(reference_, q, Y);
}

void GravityTiltModel::AxisValues(const double* q, double* const y[3]) const {
  ComplianceValuesGravityAxes(reference_, q, y);
}

const char* GravityTiltModel::partner() const { return "compliance"; }

std::string GravityTiltModel::parameter_name(int i) const {
  return "gravity.tilt" + std::to_string(i + 1);
}

void GravityTiltModel::Weights(const double* t, Eigen::VectorXd* dw,
                               Eigen::MatrixXd* dw_dt) const {
  if (dw != nullptr) *dw = Tilted(t) - gravity();
  if (dw_dt != nullptr) *dw_dt = TiltedGravityJacobian(gravity(), axes_, t);
}

void GravityTiltModel::RowRegressors(const Eigen::MatrixXd& basis, const double* q,
                                     std::vector<Eigen::MatrixXd>* Z) const {
  const int n = reference_.num_joints();
  const int P = NumComplianceParameters(n);
  CHECK_EQ(basis.rows(), P) << "the tilt's partner block is not the compliance term";
  const Eigen::Index k = basis.cols();
  thread_local std::vector<double> values;
  values.resize(3 * static_cast<size_t>(P));
  double* const y[3] = {values.data(), values.data() + P, values.data() + 2 * P};
  AxisValues(q, y);
  Z->resize(3);
  for (int a = 0; a < 3; ++a) (*Z)[a].resize(n, k);
  // Z_a(j, i) = basis column i's joint-j segment . y_a's joint-j segment: contiguous in both, the
  // three axes in one pass over the basis.
  const double* B = basis.data();
  for (int j = 0; j < n; ++j) {
    const int first = ComplianceLinkIndex(n, j, j);
    const int count = CompliancePayloadIndex(n, j) - first + 1;
    const double* y0 = y[0] + first;
    const double* y1 = y[1] + first;
    const double* y2 = y[2] + first;
    for (Eigen::Index i = 0; i < k; ++i) {
      const double* b = B + i * P + first;
      double z0 = 0, z1 = 0, z2 = 0;
      for (int c = 0; c < count; ++c) {
        z0 += b[c] * y0[c];
        z1 += b[c] * y1[c];
        z2 += b[c] * y2[c];
      }
      (*Z)[0](j, i) = z0;
      (*Z)[1](j, i) = z1;
      (*Z)[2](j, i) = z2;
    }
  }
}

Status GravityTiltModel::PartnerAt(const JointTerm& partner, const double* t,
                                   std::shared_ptr<const JointTerm>* out) const {
  RobotModel tilted = reference_;
  tilted.gravity = Tilted(t);
  return MakeJointTerm(partner.name(), tilted, out);
}

void BilinearJointColumns(const BilinearJointEffect& effect, const double* t,
                          const std::vector<Eigen::MatrixXd>& Z, const double* x,
                          Eigen::VectorXd* ddq, Eigen::MatrixXd* dR, Eigen::MatrixXd* D) {
  thread_local Eigen::VectorXd dw;
  thread_local Eigen::MatrixXd dw_dt, Zx;
  effect.Weights(t, &dw, D != nullptr ? &dw_dt : nullptr);
  const int A = effect.num_weights();
  CHECK_EQ(static_cast<int>(Z.size()), A);
  const Eigen::Index n = Z[0].rows(), k = Z[0].cols();
  const Eigen::Map<const Eigen::VectorXd> xv(x, k);
  Zx.resize(n, A);  // Z[a] x
  for (int a = 0; a < A; ++a) Zx.col(a).noalias() = Z[a] * xv;
  if (ddq != nullptr) *ddq = Zx * dw;
  if (dR != nullptr) {
    *dR = dw(0) * Z[0];
    for (int a = 1; a < A; ++a) *dR += dw(a) * Z[a];
  }
  if (D != nullptr) *D = Zx * dw_dt;
}

void HarmonicsRegressor(const RobotModel& model, const double* q, Eigen::MatrixXd* Y) {
  const int n = model.num_joints();
  Y->setZero(n, NumHarmonicsParameters(n));
  std::vector<double> y(static_cast<size_t>(kHarmonicsPerJoint) * n);
  HarmonicsValues(model, q, y.data());
  for (int j = 0; j < n; ++j) {
    for (int c = 0; c < kHarmonicsPerJoint; ++c) {
      (*Y)(j, kHarmonicsPerJoint * j + c) = y[kHarmonicsPerJoint * j + c];
    }
  }
}

void ZeroJointErrorRoundingNoise(Eigen::MatrixXd* Y) {
  // Entries at rounding level (e.g. the gravity torque about a vertical axis) are exact zeros: the
  // solvers scale every column to unit norm, and a column of rounding noise would otherwise be
  // identified with huge values that cancel only on this very geometry.
  if (Y->size() == 0) return;
  const double cutoff = kJointErrorRoundingCutoff * Y->cwiseAbs().maxCoeff();
  *Y = (Y->array().abs() < cutoff).select(0.0, *Y);
}

void ZeroJointErrorRoundingNoise(double* y, int size) { ZeroRoundingNoiseImpl(y, size); }

void ComplianceRegressorValues(const RobotModel& model, const double* q, double* y,
                               const std::vector<SE3d>* origins) {
  thread_local ChainState state;  // no allocation per call (solvers evaluate it for every row)
  ComputeChainState(model, q, &state, origins);
  ComplianceValuesFor(model, state, model.gravity, y);
  ZeroRoundingNoiseImpl(y, NumComplianceParameters(model.num_joints()));
}

void HarmonicsRegressorValues(const RobotModel& model, const double* q, double* y) {
  HarmonicsValues(model, q, y);
  ZeroRoundingNoiseImpl(y, NumHarmonicsParameters(model.num_joints()));
}

void EffectiveJoints(const RobotModel& model, const double* q, double* q_eff) {
  const int n = model.num_joints();
  std::vector<double> dq(n);
  JointErrorOffsets(model, q, dq.data());
  for (int j = 0; j < n; ++j) q_eff[j] = q[j] + dq[j];
}

Eigen::Vector3d PredictToolPosition(const RobotModel& model, const double* q, int tool) {
  Eigen::Vector3d p;
  if (model.joint_errors.empty()) {
    p = ToolPosition(model, q, tool);
  } else {
    std::vector<double> q_eff(model.num_joints());
    EffectiveJoints(model, q, q_eff.data());
    p = ToolPosition(model, q_eff.data(), tool);
  }
  if (model.residual_layer) p += model.residual_layer->Mean(q, tool);
  return p;
}

Status PredictPositions(const RobotModel& model, const std::vector<double>& q,
                        const std::vector<int>& targets, int tool,
                        std::vector<Eigen::Vector3d>* positions) {
  const int n = model.num_joints();
  if (q.size() % n != 0) {
    std::ostringstream os;
    os << q.size() << " joint values are not whole rows of " << n << " joints";
    return Status::Error(os.str());
  }
  const int rows = static_cast<int>(q.size()) / n;
  if (!targets.empty() && static_cast<int>(targets.size()) != rows) {
    std::ostringstream os;
    os << targets.size() << " targets for " << rows << " rows";
    return Status::Error(os.str());
  }
  for (int r = 0; r < rows; ++r) {
    const int t = targets.empty() ? tool : targets[r];
    if (t < 0 || t >= model.num_tools()) {
      std::ostringstream os;
      os << "row " << r + 1 << ": tool index " << t << " is out of range (the model has "
         << model.num_tools() << " tools)";
      return Status::Error(os.str());
    }
    const double* qr = q.data() + static_cast<size_t>(r) * n;
    for (int j = 0; j < n; ++j) {
      if (!std::isfinite(qr[j])) {
        std::ostringstream os;
        os << "row " << r + 1 << ": joint " << j + 1 << " is not finite";
        return Status::Error(os.str());
      }
    }
  }
  // The rows checked, the predictions in fixed chunks on the hardware's threads (lpoe/parallel.h):
  // a residual layer costs microseconds a row.
  std::vector<Eigen::Vector3d> out(rows);
  const RowChunks chunks =
      model.residual_layer ? PartitionRows(rows, 256, 64) : KinematicsRowChunks(rows);
  const int threads = model.residual_layer
                          ? (rows < 512 ? 1 : ThreadsFor(chunks.chunks))
                          : KinematicsThreads(chunks);
  ForEachTask(chunks.chunks, threads, [&](int c, int /*thread*/) {
    for (int r = chunks.begin(c); r < chunks.end(c); ++r) {
      const int t = targets.empty() ? tool : targets[r];
      out[r] = PredictToolPosition(model, q.data() + static_cast<size_t>(r) * n, t);
    }
  });
  *positions = std::move(out);
  return Status::Ok();
}

Status ReduceJointErrorTerms(const RobotModel& reference, const Parameterization& geometric,
                             const MeasurementSet& data, const std::vector<std::string>& terms,
                             std::vector<JointErrorReduction>* reductions) {
  const int n = reference.num_joints();
  const int rows = data.size();
  if (rows == 0) return Status::Error("no configurations to analyse the joint-error terms on");
  if (data.num_joints() != n) return Status::Error("the data do not match the model's joints");
  const int m = 3 * rows;

  // The geometric Jacobian and the joint Jacobians, row by row.
  BasisJacobian basis_jacobian(reference, geometric);
  std::vector<FrameRt> scratch(n + 1);
  Eigen::MatrixXd A_geometric(m, geometric.num_parameters);
  std::vector<Eigen::Matrix<double, 3, Eigen::Dynamic>> J_q(rows);
  for (int r = 0; r < rows; ++r) {
    basis_jacobian.Position(data.q(r), data.target(r), A_geometric.data() + 3 * r, m,
                            scratch.data());
    J_q[r].resize(3, n);
    basis_jacobian.PositionJointJacobian(scratch.data(), J_q[r].data(), 3);
  }

  // Orthonormal basis of what the geometry (and the terms before) already explain.
  // Columns below kJointErrorRankTolerance of the largest are round-off of a zero effect (a joint
  // whose motion does not move the tool) and are dropped.
  auto scaled = [](Eigen::MatrixXd* A, Eigen::VectorXd* inverse_norms) {
    inverse_norms->resize(A->cols());
    const double largest = A->cols() > 0 ? A->colwise().norm().maxCoeff() : 0.0;
    for (int c = 0; c < A->cols(); ++c) {
      const double norm = A->col(c).norm();
      (*inverse_norms)(c) = norm > kJointErrorRankTolerance * largest ? 1.0 / norm : 0.0;
      A->col(c) *= (*inverse_norms)(c);
    }
  };
  Eigen::VectorXd inverse_norms;
  scaled(&A_geometric, &inverse_norms);
  Eigen::MatrixXd Q;
  {
    Eigen::BDCSVD<Eigen::MatrixXd> svd(A_geometric, Eigen::ComputeThinU);
    const Eigen::VectorXd& s = svd.singularValues();
    int rank = 0;
    while (rank < s.size() && s(rank) > kJointErrorRankTolerance * s(0)) ++rank;
    Q = svd.matrixU().leftCols(rank);
  }

  reductions->clear();
  Eigen::MatrixXd Y;
  for (const std::string& name : terms) {
    if (!IsJointTermName(name)) {
      return Status::Error("unknown joint error term '" + name + "' (known: " +
                           JointTermNameList() + ")");
    }
    JointErrorReduction red;
    red.term = name;
    red.num_full = NumJointErrorParameters(reference, name);
    const std::vector<int> joint_of = JointErrorParameterJoints(reference, name);
    Eigen::MatrixXd A(m, red.num_full);
    for (int r = 0; r < rows; ++r) {
      JointErrorRegressor(reference, name, data.q(r), &Y);
      A.middleRows(3 * r, 3) = J_q[r] * Y;
    }
    scaled(&A, &inverse_norms);
    Eigen::BDCSVD<Eigen::MatrixXd> alone(A);
    const Eigen::VectorXd& s_alone = alone.singularValues();
    const double s_max = s_alone.size() > 0 ? s_alone(0) : 0.0;
    red.rank_alone = 0;
    while (red.rank_alone < s_alone.size() &&
           s_alone(red.rank_alone) > kJointErrorRankTolerance * s_max) {
      ++red.rank_alone;
    }
    const Eigen::MatrixXd residual = A - Q * (Q.transpose() * A);
    Eigen::BDCSVD<Eigen::MatrixXd> svd(residual, Eigen::ComputeThinU | Eigen::ComputeThinV);
    const Eigen::VectorXd& s = svd.singularValues();
    int rank = 0;
    while (rank < s.size() && s(rank) > kJointErrorRankTolerance * s_max) ++rank;
    const Eigen::MatrixXd V = svd.matrixV().leftCols(rank);
    red.basis = inverse_norms.asDiagonal() * V;
    red.singular_values.assign(s.data(), s.data() + rank);
    red.per_joint.assign(n, 0);
    for (int c = 0; c < rank; ++c) {
      Eigen::Index largest = 0;
      V.col(c).cwiseAbs().maxCoeff(&largest);
      // A parameter that may move several joints counts for the first (JointTerm::ParameterJoint).
      ++red.per_joint[std::max(0, joint_of[static_cast<size_t>(largest)])];
    }
    // The kept combinations' effects are orthogonal to Q and to each other (U of the SVD).
    Eigen::MatrixXd grown(m, Q.cols() + rank);
    grown << Q, svd.matrixU().leftCols(rank);
    Q.swap(grown);
    reductions->push_back(std::move(red));
  }
  return Status::Ok();
}

std::vector<double> CompliancePhysicsParameters(const JointErrorPhysics& physics) {
  const int n = static_cast<int>(physics.stiffness.size());
  CHECK_EQ(static_cast<int>(physics.link_mass.size()), n);
  CHECK_EQ(static_cast<int>(physics.link_com.size()), n);
  std::vector<double> theta(NumComplianceParameters(n), 0.0);
  for (int j = 0; j < n; ++j) {
    const double k = physics.stiffness[j];
    const double c = k > 0 && std::isfinite(k) ? 1.0 / k : 0.0;
    for (int l = j; l < n; ++l) {
      const int i = ComplianceLinkIndex(n, j, l);
      theta[i] = c * physics.link_mass[l];
      for (int a = 0; a < 3; ++a) theta[i + 1 + a] = c * physics.link_mass[l] * physics.link_com[l](a);
    }
    theta[CompliancePayloadIndex(n, j)] = c;
  }
  return theta;
}

}  // namespace lpoe
