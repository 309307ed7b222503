// Ballbar and plane calibration: the parameterization decided from the data and the linear
// (Levenberg-Marquardt) solver (lpoe/contact_calibration.h).
#include "lpoe/contact_calibration.h"

#include <algorithm>
#include <cmath>
#include <sstream>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/QR>
#include <Eigen/SVD>

#include "linearization/joint_term_columns.h"
#include "contact/contact_kinds.h"
#include "identifiability/identifiability.h"
#include "lpoe/measurements/distance_measurement.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/measurements/plane_measurement.h"
#include "lpoe/measurements/position_measurement.h"
#include "lpoe/model/residual_layer.h"

namespace lpoe {
namespace {

std::string ContactFrameName(const RobotModel& m, int f) {
  const int n = m.num_joints();
  return f < n ? m.joints[f].name : m.tools[f - n].name;
}

std::string ContactDirectionName(const Vector6d& v) {
  static const char* kNames[6] = {"rx", "ry", "rz", "vx", "vy", "vz"};
  int best = 0;
  v.cwiseAbs().maxCoeff(&best);
  std::string name = kNames[best];
  if (std::abs(v(best)) < 1.0 - 1e-9) name += "~";
  return name;
}

// Renumbers offsets and parameter names of a frame-only parameterization after bases changed.
void RenumberContactFrames(const RobotModel& model, Parameterization* p) {
  p->parameters.clear();
  p->num_parameters = 0;
  for (size_t f = 0; f < p->basis.size(); ++f) {
    p->offset[f] = p->num_parameters;
    for (int c = 0; c < p->basis[f].cols(); ++c) {
      Direction d;
      d.frame = static_cast<int>(f);
      d.vector = p->basis[f].col(c);
      d.name = ContactFrameName(model, static_cast<int>(f)) + "." + ContactDirectionName(d.vector);
      p->parameters.push_back(d);
    }
    p->num_parameters += static_cast<int>(p->basis[f].cols());
  }
}

bool AnyLengthRow(const ContactMeasurementSet& data) {
  for (const ContactRow& r : data.rows) {
    if (MeasurementKind(r.kind).measures_length) return true;
  }
  return false;
}

}  // namespace

bool ParseScaleHold(const std::string& text, ScaleHold* hold) {
  if (text == "auto") *hold = ScaleHold::kAuto;
  else if (text == "on") *hold = ScaleHold::kOn;
  else if (text == "off") *hold = ScaleHold::kOff;
  else return false;
  return true;
}

Eigen::Matrix3Xd ScaleWeights(const RobotModel& nominal, const ContactMeasurementSet& data) {
  Eigen::Matrix3Xd W(3, data.size());
  for (int i = 0; i < data.size(); ++i) {
    W.col(i) = ToolPosition(nominal, data.joints(i), data.rows[i].target);
  }
  if (data.size() == 0) return W;
  const Eigen::Vector3d mean = W.rowwise().mean();
  W.colwise() -= mean;
  const double den = W.squaredNorm();
  return den > 0 ? Eigen::Matrix3Xd(W / den) : W;
}

double ScaleOf(const RobotModel& model, const RobotModel& nominal,
               const ContactMeasurementSet& data) {
  const Eigen::Matrix3Xd W = ScaleWeights(nominal, data);
  double S = 0;
  for (int i = 0; i < data.size(); ++i) {
    S += W.col(i).dot(ToolPosition(model, data.joints(i), data.rows[i].target));
  }
  return S;
}

Status InitialContactFeatures(const RobotModel& model, const ContactMeasurementSet& data,
                              ContactFeatures* features) {
  ContactFeatures out;
  std::vector<std::vector<int>> pivot_rows(data.pivots.size()), plane_rows(data.planes.size());
  for (int r = 0; r < data.size(); ++r) {
    const ContactRow& row = data.rows[r];
    if (row.kind == MeasurementKindId::kDistance) pivot_rows[row.feature].push_back(r);
    if (row.kind == MeasurementKindId::kPlane) plane_rows[row.feature].push_back(r);
  }
  for (size_t k = 0; k < pivot_rows.size(); ++k) {
    const std::vector<int>& rows = pivot_rows[k];
    if (rows.size() < 4) {
      return Status::Error("pivot '" + data.pivots[k] + "' has " + std::to_string(rows.size()) +
                           " distances; at least 4 (in practice 50 or more) locate a pivot");
    }
    // |P|^2 - d^2 = 2 P.c - (|c|^2 - ...): linear in (c, k = |c|^2).
    Eigen::MatrixXd A(rows.size(), 4);
    Eigen::VectorXd b(rows.size());
    std::vector<Eigen::Vector3d> P(rows.size());
    for (size_t i = 0; i < rows.size(); ++i) {
      const ContactRow& row = data.rows[rows[i]];
      P[i] = ToolPosition(model, data.joints(rows[i]), row.target);
      A.row(i) << 2 * P[i].transpose(), -1.0;
      b(i) = P[i].squaredNorm() - row.value * row.value;
    }
    Eigen::ColPivHouseholderQR<Eigen::MatrixXd> qr(A);
    if (qr.rank() < 4) {
      return Status::Error("pivot '" + data.pivots[k] +
                           "': the ball's positions lie in a plane; they must surround the pivot");
    }
    Eigen::Vector3d c = qr.solve(b).head<3>();
    for (int it = 0; it < 20; ++it) {  // Gauss-Newton on |P - c| - d
      Eigen::MatrixXd J(rows.size(), 3);
      Eigen::VectorXd e(rows.size());
      for (size_t i = 0; i < rows.size(); ++i) {
        const Eigen::Vector3d d = P[i] - c;
        J.row(i) = -d.normalized().transpose();
        e(i) = d.norm() - data.rows[rows[i]].value;
      }
      const Eigen::Vector3d step = J.colPivHouseholderQr().solve(-e);
      c += step;
      if (step.norm() < 1e-12) break;
    }
    if (!c.allFinite()) return Status::Error("pivot '" + data.pivots[k] + "': no sphere fits");
    out.pivots.push_back(c);
  }
  for (size_t k = 0; k < plane_rows.size(); ++k) {
    const std::vector<int>& rows = plane_rows[k];
    if (rows.size() < 3) {
      return Status::Error("plane '" + data.planes[k] + "' has " + std::to_string(rows.size()) +
                           " contacts; at least 3 (in practice 30 or more) locate a plane");
    }
    Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
    double offset = 0;
    std::vector<Eigen::Vector3d> P(rows.size());
    for (size_t i = 0; i < rows.size(); ++i) {
      P[i] = ToolPosition(model, data.joints(rows[i]), data.rows[rows[i]].target);
      centroid += P[i];
      offset += data.rows[rows[i]].value;
    }
    centroid /= rows.size();
    offset /= rows.size();
    Eigen::Matrix3d C = Eigen::Matrix3d::Zero();
    for (const Eigen::Vector3d& p : P) C += (p - centroid) * (p - centroid).transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(C);
    if (!(eig.eigenvalues()(1) > 1e-6 * std::max(eig.eigenvalues()(2), 1e-300))) {
      return Status::Error("plane '" + data.planes[k] +
                           "': the contacts lie on a line; they must spread over the plane");
    }
    Eigen::Vector3d n = eig.eigenvectors().col(0);
    // Towards the robot's base (the side the probe comes from, usually); either side fits.
    if (n.dot(-centroid) < 0) n = -n;
    out.planes.emplace_back(n(0), n(1), n(2), n.dot(centroid) - offset);
  }
  *features = std::move(out);
  return Status::Ok();
}

void ContactLinearize(const RobotModel& model, const ContactFeatures& features,
                      const ContactParameterization& p, const RobotModel& nominal,
                      const ContactMeasurementSet& data, const ContactCalibrationOptions& options,
                      Eigen::VectorXd* r, Eigen::MatrixXd* J) {
  int rows = 0;
  for (const ContactRow& row : data.rows) rows += MeasurementKind(row.kind).residuals;
  const int gauge = p.num_gauge_rows();
  const int total = rows + gauge + (p.scale_held ? 1 : 0);
  r->resize(total);
  if (J != nullptr) J->setZero(total, p.num_parameters);
  // Columns of the robot: the frames' (BasisJacobian on the frame blocks alone), then the
  // joint-space blocks' J_q(q_eff) Y(q) basis_b (joint_term.h).
  const int P = p.frames.num_parameters;
  const int Pf = p.frames.num_frame_parameters();
  const int n = model.num_joints();
  const std::vector<JointBlock>& blocks = p.frames.joint_blocks;
  Parameterization frames_only;
  const Parameterization* pf = &p.frames;
  if (!blocks.empty()) {
    frames_only = p.frames;
    frames_only.joint_blocks.clear();
    frames_only.parameters.resize(Pf);
    frames_only.num_parameters = Pf;
    pf = &frames_only;
  }
  BasisJacobian bj(model, *pf);
  std::vector<FrameRt> scratch(n + 1);
  Eigen::Matrix<double, 3, Eigen::Dynamic> Jp =
      Eigen::Matrix<double, 3, Eigen::Dynamic>::Zero(3, std::max(P, 1));
  Eigen::Matrix<double, 3, Eigen::Dynamic> Jraw(3, std::max(Pf, 1));
  Eigen::Matrix<double, 3, Eigen::Dynamic> Jq(3, std::max(n, 1));
  Eigen::RowVectorXd frame_row(std::max(P, 1));
  double feature_row[3];
  int at = 0;
  double S = 0;
  Eigen::RowVectorXd dS = Eigen::RowVectorXd::Zero(std::max(P, 1));
  // The terms' values at the features' state (q_eff = q + sum_b Y_b(q) theta_b, joint_term.h) and
  // the rows' joint-term columns [Y_b(q) basis_b] (joint_term_columns.h): the tracker solvers' own.
  std::vector<JointTermValues> theta;
  for (size_t b = 0; b < blocks.size(); ++b) {
    if (b < features.joint_theta.size() && features.joint_theta[b].size() > 0) {
      theta.push_back({blocks[b].term, features.joint_theta[b]});
    }
  }
  internal::JointTermColumns joint_columns;
  if (!blocks.empty()) joint_columns = internal::JointTermColumns(p.frames, n);
  Eigen::MatrixXd R;
  Eigen::VectorXd q_eff(n);
  for (int i = 0; i < data.size(); ++i) {
    const ContactRow& row = data.rows[i];
    const double* q = data.joints(i);
    Eigen::Vector3d X;
    if (blocks.empty()) {
      X = bj.Position(q, row.target, Jp.data(), 3, scratch.data());
      if (p.scale_held) {
        S += p.scale_weights.col(i).dot(X);
        if (J != nullptr) dS.head(P) += p.scale_weights.col(i).transpose() * Jp.leftCols(P);
      }
    } else {
      // The scale hold is on the frames' predictions at the joint values read (ScaleOf).
      if (p.scale_held) {
        const Eigen::Vector3d Xs = bj.Position(q, row.target, Jraw.data(), 3, scratch.data());
        S += p.scale_weights.col(i).dot(Xs);
        if (J != nullptr) dS.head(Pf) += p.scale_weights.col(i).transpose() * Jraw.leftCols(Pf);
      }
      EffectiveJointValues(theta, n, q, q_eff.data());
      X = bj.Position(q_eff.data(), row.target, Jp.data(), 3, scratch.data());
      if (J != nullptr) {
        bj.PositionJointJacobian(scratch.data(), Jq.data(), 3);
        joint_columns.Evaluate(i, q, &R);
        if (R.cols() > 0) Jp.middleCols(Pf, R.cols()) = Jq.leftCols(n) * R;
      }
    }
    const double w = 1.0 / row.sigma;
    const int used = internal::VisitContactRowKind(row.kind, [&](auto tag) -> int {
      using Kind = typename decltype(tag)::type;
      if constexpr (Kind::kFeatureSize > 0) {
        const Kind kind{w};
        (*r)(at) = kind.Linearize(X, Jp.data(), P,
                                  internal::ContactFeatureData<Kind>(features, row.feature),
                                  row.value, frame_row.data(), feature_row);
        if (J != nullptr) {
          J->row(at).head(P) = frame_row.head(P);
          const int column = internal::ContactFeatureColumn<Kind>(p, row.feature);
          for (int k = 0; k < Kind::kFeatureTangent; ++k) (*J)(at, column + k) = feature_row[k];
        }
        return Kind::kResiduals;
      } else {
        for (int k = 0; k < 3; ++k) {
          (*r)(at + k) = (X(k) - row.position(k)) * w;
          if (J != nullptr) J->row(at + k).head(P) = w * Jp.row(k).head(P);
        }
        return 3;
      }
    });
    at += used;
  }
  if (gauge > 0) {
    (*r).segment(at, gauge) = (p.gauge_rows * FeatureVector(features) - p.gauge_values) / p.gauge_sigma;
    if (J != nullptr) {
      // Ambient columns from the local coordinates: pivots as they are, a plane's (a1, a2, dd) as
      // (B(n) a, dd).
      for (int k = 0; k < p.num_pivots; ++k) {
        J->block(at, p.pivot_offset + 3 * k, gauge, 3) = p.gauge_rows.middleCols(3 * k, 3) / p.gauge_sigma;
      }
      for (int k = 0; k < p.num_planes; ++k) {
        const int a = 3 * p.num_pivots + 4 * k;
        const Eigen::Matrix<double, 3, 2> B =
            PlaneTangentBasis(features.planes[k].head<3>());
        J->block(at, p.plane_offset + 3 * k, gauge, 2) = p.gauge_rows.middleCols(a, 3) * B / p.gauge_sigma;
        J->col(p.plane_offset + 3 * k + 2).segment(at, gauge) = p.gauge_rows.col(a + 3) / p.gauge_sigma;
      }
    }
    at += gauge;
  }
  if (p.scale_held) {
    // The prior on S (ScaleOf): (S(model) - 1) / scale_sigma, dS/dx = sum_j w_j^T dP_j/dx.
    (*r)(at) = (S - 1.0) / options.scale_sigma;
    if (J != nullptr) J->row(at).head(P) = dS.head(P) / options.scale_sigma;
  }
}

std::vector<double> ContactErrors(const RobotModel& model, const ContactFeatures& features,
                                  const ContactMeasurementSet& data) {
  std::vector<double> out(data.size());
  const bool joint_errors = !model.joint_errors.empty();
  std::vector<double> q_eff(model.num_joints());
  for (int i = 0; i < data.size(); ++i) {
    const ContactRow& row = data.rows[i];
    const double* q = data.joints(i);
    if (joint_errors) {
      EffectiveJoints(model, q, q_eff.data());
      q = q_eff.data();
    }
    Eigen::Vector3d X = ToolPosition(model, q, row.target);
    // A layer's correction at the commanded joint values (PredictToolPosition).
    if (model.residual_layer) X += model.residual_layer->Mean(data.joints(i), row.target);
    out[i] = internal::VisitContactRowKind(row.kind, [&](auto tag) -> double {
      using Kind = typename decltype(tag)::type;
      if constexpr (Kind::kFeatureSize > 0) {
        return Kind::template Error<double>(
            X, internal::ContactFeatureData<Kind>(features, row.feature), row.value);
      } else {
        return (X - row.position).norm();
      }
    });
  }
  return out;
}

Eigen::VectorXd FeatureVector(const ContactFeatures& features) {
  Eigen::VectorXd f(3 * features.pivots.size() + 4 * features.planes.size());
  int at = 0;
  for (const Eigen::Vector3d& c : features.pivots) {
    f.segment<3>(at) = c;
    at += 3;
  }
  for (const Eigen::Vector4d& pl : features.planes) {
    f.segment<4>(at) = pl;
    at += 4;
  }
  return f;
}

void ApplyFeatureStep(const ContactParameterization& p, const Eigen::VectorXd& x,
                      ContactFeatures* features) {
  for (int k = 0; k < p.num_pivots; ++k) features->pivots[k] += x.segment<3>(p.pivot_offset + 3 * k);
  for (int k = 0; k < p.num_planes; ++k) {
    Eigen::Vector4d next;
    PlaneMeasurement::Plus(features->planes[k].data(), x.data() + p.plane_offset + 3 * k, next.data());
    features->planes[k] = next;
  }
  const std::vector<JointBlock>& blocks = p.frames.joint_blocks;
  if (features->joint_theta.size() < blocks.size()) features->joint_theta.resize(blocks.size());
  for (size_t b = 0; b < blocks.size(); ++b) {
    const int P = blocks[b].term->num_parameters();
    Eigen::VectorXd& theta = features->joint_theta[b];
    if (theta.size() != P) theta = Eigen::VectorXd::Zero(P);
    if (blocks[b].basis.cols() > 0) {
      theta += blocks[b].basis * x.segment(blocks[b].offset, blocks[b].basis.cols());
    }
  }
}

void StoreContactJointTerms(const ContactParameterization& p, const ContactFeatures& features,
                            const RobotModel& nominal, ContactCalibrationResult* result) {
  result->joint_terms.clear();
  const std::vector<JointBlock>& blocks = p.frames.joint_blocks;
  for (size_t b = 0; b < blocks.size(); ++b) {
    JointTermValues v;
    v.term = blocks[b].term;
    v.theta = b < features.joint_theta.size() && features.joint_theta[b].size() > 0
                  ? features.joint_theta[b]
                  : Eigen::VectorXd::Zero(blocks[b].term->num_parameters());
    // Every term is a registry entry (MakeJointTerm): its name is the model's key.
    *result->model.joint_errors.MutableValues(v.term->name()) =
        std::vector<double>(v.theta.data(), v.theta.data() + v.theta.size());
    result->joint_terms.push_back(std::move(v));
  }
  if (!blocks.empty()) {
    result->model.joint_errors.regressor_origins.clear();
    for (const Joint& j : nominal.joints) {
      result->model.joint_errors.regressor_origins.push_back(j.origin);
    }
  }
}

namespace {

// The column layout after the frames: pivots (3 each), then planes (3 local coordinates each).
void LayoutContactColumns(ContactParameterization* p) {
  p->pivot_offset = p->frames.num_parameters;
  p->plane_offset = p->pivot_offset + 3 * p->num_pivots;
  p->num_parameters = p->plane_offset + 3 * p->num_planes;
}

// Tools no row measures: no columns (their directions left out with the reason).
void LeaveOutUnmeasuredContactTools(const RobotModel& model, const ContactMeasurementSet& data,
                                    Parameterization* frames) {
  const int n = model.num_joints();
  std::vector<bool> measured(model.num_tools(), false);
  for (const ContactRow& row : data.rows) measured[row.target] = true;
  for (int t = 0; t < model.num_tools(); ++t) {
    Eigen::MatrixXd& B = frames->basis[n + t];
    if (measured[t] || B.cols() == 0) continue;
    for (int c = 0; c < B.cols(); ++c) {
      Direction d;
      d.frame = n + t;
      d.vector = B.col(c);
      d.name = ContactFrameName(model, n + t) + "." + ContactDirectionName(d.vector);
      d.reason = "tool never measured in these data: not identified, kept as given";
      frames->unidentifiable.push_back(d);
    }
    B.resize(6, 0);
  }
  RenumberContactFrames(model, frames);
}

// Whether the robot's scale is held (a prior on ScaleOf) and why: asked for, or no row of a kind
// that measures a length (the kind table's measures_length).
void DecideContactScaleHold(const RobotModel& model, const ContactMeasurementSet& data,
                            const ContactCalibrationOptions& options, ContactParameterization* p) {
  const bool length = AnyLengthRow(data);
  p->scale_held = options.hold_scale == ScaleHold::kOn ||
                  (options.hold_scale == ScaleHold::kAuto && !length);
  if (p->scale_held) {
    p->scale_weights = ScaleWeights(model, data);
    p->scale_reason =
        length ? "the robot's scale is held at the nominal model's (asked for)"
               : "no row measures a length (planes alone): scaling the robot and the planes "
                 "together leaves the contacts (nearly) unchanged, so the robot's scale is held at "
                 "the nominal model's (a prior on the scale; add a ballbar or a known length to "
                 "measure it)";
  } else {
    p->scale_reason = length ? "the robot's scale is measured (distances or tracker positions)"
                             : "the robot's scale is not held (--hold_scale=off) although no row "
                               "measures a length: it is weakly determined";
  }
}

// The null space of the column-scaled Jacobian at the start, orthonormal, in unscaled
// coordinates. Fewer residuals than unknowns leaves directions undetermined that are not the
// base's (at most six): refused with the counts, before the null space is split among frames and
// features.
Status ContactNullSpace(const RobotModel& model, const ContactFeatures& features,
                        const ContactMeasurementSet& data, const ContactCalibrationOptions& options,
                        const ContactParameterization& p, Eigen::MatrixXd* null_space) {
  Eigen::VectorXd r;
  Eigen::MatrixXd J;
  ContactLinearize(model, features, p, model, data, options, &r, &J);
  Eigen::VectorXd scale(J.cols());
  for (int c = 0; c < J.cols(); ++c) {
    const double norm = J.col(c).norm();
    scale(c) = norm > 0 ? 1.0 / norm : 1.0;
  }
  const Eigen::MatrixXd Js = J * scale.asDiagonal();
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(Js, Eigen::ComputeFullV);
  const Eigen::VectorXd& s = svd.singularValues();
  int rank = 0;
  while (rank < s.size() && s(rank) > options.null_tolerance * s(0)) ++rank;
  if (J.rows() < J.cols() && J.cols() - rank > 6) {
    return Status::Error(std::to_string(data.size()) + " rows (" + std::to_string(J.rows()) +
                         " residuals) cannot determine the " + std::to_string(J.cols()) +
                         " unknowns of the robot's frames, pivots and planes: give more rows");
  }
  Eigen::MatrixXd N = scale.asDiagonal() * svd.matrixV().rightCols(J.cols() - rank);
  if (N.cols() > 0) N = Eigen::HouseholderQR<Eigen::MatrixXd>(N).householderQ() *
                        Eigen::MatrixXd::Identity(N.rows(), N.cols());
  *null_space = std::move(N);
  return Status::Ok();
}

// Why the base's directions are left out: the left-out rule of the one kind in the data that does
// not see the base (the kind table's left_out_reason), or the joint reason when several are.
const char* ContactLeftOutReason(const ContactMeasurementSet& data) {
  const char* reason = nullptr;
  int blind_kinds = 0;
  for (const MeasurementKindInfo& kind : MeasurementKinds()) {
    if (kind.left_out_reason == nullptr || data.Count(kind.id) == 0) continue;
    if (reason == nullptr) reason = kind.left_out_reason;
    ++blind_kinds;
  }
  if (blind_kinds > 1) {
    return "distances and probe contacts do not see the robot's base relative to the pivots and "
           "planes (moving the base with every pivot and plane leaves every residual unchanged): "
           "not identified, kept as given";
  }
  return reason != nullptr ? reason : MeasurementKind(MeasurementKindId::kPlane).left_out_reason;
}

// Past the base frame: the null vectors N held on the features, when the features see all of
// them (a frame block's reduced basis would depend on the path the solver takes through the later
// frames, a function of the features does not). True when held (N is then empty).
bool HoldNullSpaceOnFeatures(const ContactFeatures& features, Eigen::MatrixXd* N,
                             ContactParameterization* p) {
  const int feature_cols = p->num_parameters - p->pivot_offset;
  Eigen::MatrixXd M(3 * p->num_pivots + 4 * p->num_planes, N->cols());  // ambient
  for (int j = 0; j < N->cols(); ++j) {
    for (int q = 0; q < p->num_pivots; ++q) {
      M.block<3, 1>(3 * q, j) = N->block<3, 1>(p->pivot_offset + 3 * q, j);
    }
    for (int q = 0; q < p->num_planes; ++q) {
      const Eigen::Matrix<double, 3, 2> B = PlaneTangentBasis(features.planes[q].head<3>());
      const int a = 3 * p->num_pivots + 4 * q;
      M.block<3, 1>(a, j) = B * N->block<2, 1>(p->plane_offset + 3 * q, j);
      M(a + 3, j) = (*N)(p->plane_offset + 3 * q + 2, j);
    }
  }
  Eigen::JacobiSVD<Eigen::MatrixXd> m(M, Eigen::ComputeThinU);
  if (feature_cols > 0 && M.rows() >= N->cols() &&
      m.singularValues()(m.singularValues().size() - 1) > 1e-3 * m.singularValues()(0)) {
    p->gauge_rows = m.matrixU().leftCols(N->cols()).transpose();
    p->gauge_values = p->gauge_rows * FeatureVector(features);
    p->num_base_directions += static_cast<int>(N->cols());
    N->resize(N->rows(), 0);
    return true;
  }
  return false;
}

// The base's directions left out frame by frame from the base: the directions of frame f that null
// vectors move, then the null vectors that do not move it; what no frame takes is refused.
Status LeaveOutBaseDirections(const RobotModel& model, const ContactFeatures& features,
                              const char* reason, Eigen::MatrixXd N, ContactParameterization* p) {
  for (int f = 0; f < model.num_frames() && N.cols() > 0; ++f) {
    const int k = static_cast<int>(p->frames.basis[f].cols());
    if (k == 0) continue;
    if (f > 0 && N.cols() > 0 && HoldNullSpaceOnFeatures(features, &N, p)) break;
    const Eigen::MatrixXd A = N.middleRows(p->frames.offset[f], k);
    Eigen::JacobiSVD<Eigen::MatrixXd> a(A, Eigen::ComputeFullU | Eigen::ComputeFullV);
    int moved = 0;
    while (moved < a.singularValues().size() && a.singularValues()(moved) > 1e-6) ++moved;
    if (moved == 0) continue;
    const Eigen::MatrixXd B = p->frames.basis[f];
    for (int c = 0; c < moved; ++c) {
      Direction d;
      d.frame = f;
      d.vector = B * a.matrixU().col(c);
      d.name = ContactFrameName(model, f) + "." + ContactDirectionName(d.vector);
      d.reason = reason;
      p->frames.unidentifiable.push_back(d);
    }
    p->num_base_directions += moved;
    p->frames.basis[f] = B * a.matrixU().rightCols(k - moved);
    N = N * a.matrixV().rightCols(N.cols() - moved);
  }
  if (N.cols() > 0) {
    return Status::Error(std::to_string(N.cols()) +
                         " combinations of the pivots and planes are not determined by these data "
                         "(a pivot or plane with too few or degenerate rows)");
  }
  p->base_reason = p->num_base_directions > 0 ? reason : "";
  if (p->num_gauge_rows() > 0) {
    p->base_reason += "; " + std::to_string(p->num_base_directions - p->num_gauge_rows()) +
                      " directions of the first frame are left out and " +
                      std::to_string(p->num_gauge_rows()) +
                      " (the first joint's zero and position along its axis, relative to the " +
                      "features) are held on the pivots and planes";
  }
  RenumberContactFrames(model, &p->frames);
  LayoutContactColumns(p);
  return Status::Ok();
}

// The joint-space blocks, whole, after the frames; then each reduced to the combinations the
// data separate from the frames, the features (pivots, planes: with the gauge and scale rows,
// every direction of theirs is determined) and the earlier blocks (JointBlockBases of the
// tracker solvers, on the normal matrix reordered as [frames, features, joint blocks]).
Status AddContactJointBlocks(const RobotModel& model, const ContactFeatures& features,
                             const ContactMeasurementSet& data,
                             const ContactCalibrationOptions& options, ContactParameterization* p) {
  for (const auto& term : options.joint_terms) {
    if (term->num_joints() != model.num_joints()) {
      return Status::Error("joint-space term '" + term->name() + "' was built for " +
                           std::to_string(term->num_joints()) + " joints, the model has " +
                           std::to_string(model.num_joints()));
    }
    AddJointBlock(term, &p->frames);
  }
  LayoutContactColumns(p);
  Eigen::VectorXd r;
  Eigen::MatrixXd J;
  ContactLinearize(model, features, *p, model, data, options, &r, &J);
  const int Pf = p->frames.num_frame_parameters();
  const int Pj = p->frames.num_parameters - Pf;
  const int Fc = p->num_parameters - p->pivot_offset;
  Eigen::MatrixXd Jr(J.rows(), J.cols());
  Jr << J.leftCols(Pf), J.rightCols(Fc), J.middleCols(Pf, Pj);
  Parameterization pa;
  pa.num_parameters = p->num_parameters;
  pa.joint_blocks = p->frames.joint_blocks;
  for (JointBlock& b : pa.joint_blocks) b.offset += Fc;
  const Eigen::MatrixXd H = Jr.transpose() * Jr;
  const std::vector<Eigen::MatrixXd> bases =
      internal::JointBlockBases(H, pa, options.joint_term_tolerance);
  for (size_t b = 0; b < bases.size(); ++b) {
    SetJointBlockBasis(static_cast<int>(b), bases[b],
                       "not separable from the geometry, the pivots and planes or the earlier "
                       "joint-space terms with these data",
                       &p->frames);
  }
  LayoutContactColumns(p);
  return Status::Ok();
}

}  // namespace

Status MakeContactParameterization(const RobotModel& model, const ContactFeatures& features,
                                   const ContactMeasurementSet& data,
                                   const ContactCalibrationOptions& options,
                                   ContactParameterization* out) {
  ContactParameterization p;
  p.frames = MakeParameterization(model, ParameterizationKind::kIdentifiable, DataKind::kPosition);
  LeaveOutUnmeasuredContactTools(model, data, &p.frames);
  DecideContactScaleHold(model, data, options, &p);
  p.num_pivots = static_cast<int>(features.pivots.size());
  p.num_planes = static_cast<int>(features.planes.size());
  LayoutContactColumns(&p);
  Eigen::MatrixXd N;
  Status s = ContactNullSpace(model, features, data, options, p, &N);
  if (s.ok()) s = LeaveOutBaseDirections(model, features, ContactLeftOutReason(data), N, &p);
  if (s.ok() && !options.joint_terms.empty()) {
    s = AddContactJointBlocks(model, features, data, options, &p);
  }
  if (!s.ok()) return s;
  *out = std::move(p);
  return Status::Ok();
}

bool StartContactCalibration(const RobotModel& nominal, const ContactMeasurementSet& data,
                             const ContactCalibrationOptions& options, const char* solver,
                             ContactCalibrationResult* result) {
  result->solver = solver;
  result->model = nominal;
  Status s = InitialContactFeatures(nominal, data, &result->features);
  if (s.ok()) {
    s = MakeContactParameterization(nominal, result->features, data, options,
                                    &result->parameterization);
  }
  if (!s.ok()) result->message = s.message();
  return s.ok();
}

void FinishContactCalibration(const RobotModel& nominal, const ContactMeasurementSet& data,
                              ContactCalibrationResult* result) {
  StoreContactJointTerms(result->parameterization, result->features, nominal, result);
  result->errors = ContactErrors(result->model, result->features, data);
  result->scale = ScaleOf(result->model, nominal, data);
}

ContactCalibrationResult CalibrateContactsLinear(const RobotModel& nominal,
                                                 const ContactMeasurementSet& data,
                                                 const ContactCalibrationOptions& options) {
  ContactCalibrationResult result;
  if (!StartContactCalibration(nominal, data, options, "linear", &result)) return result;
  const ContactParameterization& p = result.parameterization;
  for (const JointBlock& b : p.frames.joint_blocks) {
    result.features.joint_theta.push_back(Eigen::VectorXd::Zero(b.term->num_parameters()));
  }
  Eigen::VectorXd r;
  Eigen::MatrixXd J;
  ContactLinearize(result.model, result.features, p, nominal, data, options, &r, &J);
  double cost = 0.5 * r.squaredNorm();
  result.initial_cost = cost;
  double lambda = 1e-6;
  bool converged = false;
  for (int it = 0; it < options.max_iterations && !converged; ++it) {
    result.iterations = it + 1;
    // The step from the column-scaled Jacobian by QR (not the normal equations: the scale hold's
    // row is stiff, and squaring the condition number would cost its digits).
    Eigen::VectorXd d(J.cols());
    for (int c = 0; c < J.cols(); ++c) {
      const double norm = J.col(c).norm();
      d(c) = norm > 0 ? 1.0 / norm : 1.0;
    }
    const Eigen::MatrixXd Js = J * d.asDiagonal();
    // Converged when the Gauss-Newton step itself promises less than function_tolerance of the
    // cost (a damped step's small decrease after rejected steps is short, not final).
    {
      const Eigen::VectorXd z = Js.colPivHouseholderQr().solve(-r);
      const double predicted = cost - 0.5 * (r + Js * z).squaredNorm();
      if (!(predicted > options.function_tolerance * cost)) {
        converged = true;
        break;
      }
    }
    bool accepted = false;
    for (int attempt = 0; attempt < 20; ++attempt) {
      Eigen::MatrixXd A(Js.rows() + Js.cols(), Js.cols());
      A << Js, std::sqrt(lambda) * Eigen::MatrixXd::Identity(Js.cols(), Js.cols());
      Eigen::VectorXd b = Eigen::VectorXd::Zero(A.rows());
      b.head(r.size()) = -r;
      const Eigen::VectorXd x = d.asDiagonal() * A.householderQr().solve(b);
      if (!x.allFinite()) {
        lambda *= 10;
        continue;
      }
      RobotModel model = result.model;
      ApplyUpdate(p.frames, x.head(p.frames.num_parameters), &model);
      ContactFeatures features = result.features;
      ApplyFeatureStep(p, x, &features);
      Eigen::VectorXd r2;
      ContactLinearize(model, features, p, nominal, data, options, &r2, nullptr);
      const double cost2 = 0.5 * r2.squaredNorm();
      if (cost2 <= cost) {
        result.model = std::move(model);
        result.features = std::move(features);
        // A step that leaves the cost exactly as it was: at the minimum to round-off (the
        // Gauss-Newton step's promise is then round-off too, e.g. with joint-space terms, whose
        // kept combinations can be conditioned to 1e4 in the scaled columns).
        converged = cost2 == 0 || cost2 == cost;
        cost = cost2;
        lambda = std::max(lambda / 10, 1e-15);
        accepted = true;
        break;
      }
      lambda *= 10;
    }
    if (!accepted) {
      converged = true;  // no step lowers the cost: at the minimum to round-off
      break;
    }
    ContactLinearize(result.model, result.features, p, nominal, data, options, &r, &J);
  }
  result.cost = cost;
  FinishContactCalibration(nominal, data, &result);
  result.ok = converged;
  result.message = converged ? "converged" : "not converged (iteration limit)";
  return result;
}

}  // namespace lpoe
