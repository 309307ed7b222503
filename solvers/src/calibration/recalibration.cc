// Recalibration and fleet priors (lpoe/recalibration.h, docs/recalibration.md).
#include "lpoe/recalibration.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <sstream>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <Eigen/QR>

#include "lpoe/kinematics/eigen_decompositions.h"
#include "lpoe/io/io.h"
#include "lpoe/model/parameterization.h"
#include "lpoe/kinematics/se3.h"

namespace lpoe {
namespace {

// The information of a covariance block C: its (pseudo-)inverse on the directions `B` (orthonormal
// columns) that a calibration estimates, the default tolerances `fallback` on the others. A joint
// frame's rotation about and translation along its own axis are never estimated (a fleet's sample
// has a variance of round-off there, which inverted would hold them at an absurd strength), nor
// are a tool's rotations from position data.
Eigen::MatrixXd InformationOf(const Eigen::MatrixXd& C, const Eigen::MatrixXd& fallback,
                              const Eigen::MatrixXd& B) {
  const Eigen::MatrixXd Cb = B.transpose() * C * B;
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(0.5 * (Cb + Cb.transpose()));
  const double largest = eig.eigenvalues().cwiseAbs().maxCoeff();
  Eigen::MatrixXd inverse = Eigen::MatrixXd::Zero(Cb.rows(), Cb.cols());
  for (int k = 0; k < eig.eigenvalues().size(); ++k) {
    const double l = eig.eigenvalues()(k);
    if (largest > 0 && l > 1e-12 * largest) {
      inverse += eig.eigenvectors().col(k) * eig.eigenvectors().col(k).transpose() / l;
    }
  }
  const Eigen::MatrixXd N = Eigen::MatrixXd::Identity(C.rows(), C.rows()) - B * B.transpose();
  return B * inverse * B.transpose() + N * fallback * N;
}

// The directions of frame f a calibration estimates (see InformationOf).
Eigen::MatrixXd EstimatedDirections(const RobotModel& model, int f, const Eigen::MatrixXd& C) {
  if (f < model.num_joints()) return IdentifiableJointBasis(model.joints[f].twist);
  // Position data leave a tool's rotation unestimated: a block without rotation (to round-off).
  const double largest = C.cwiseAbs().maxCoeff();
  if (!(C.topLeftCorner<3, 3>().cwiseAbs().maxCoeff() > 1e-12 * largest)) {
    return Eigen::MatrixXd::Identity(6, 6).rightCols(3);
  }
  return Eigen::MatrixXd::Identity(6, 6);
}

const std::string& RecalibrationFrameName(const RobotModel& m, int f) {
  const int n = m.num_joints();
  return f < n ? m.joints[f].name : m.tools[f - n].name;
}

// Same chain: joint count, types, names; tools by name.
Status SameChain(const RobotModel& a, const RobotModel& b, const std::string& what) {
  if (a.num_joints() != b.num_joints()) {
    return Status::Error(what + " has " + std::to_string(b.num_joints()) + " joints, the first " +
                         std::to_string(a.num_joints()) + ": a fleet prior needs one chain");
  }
  for (int j = 0; j < a.num_joints(); ++j) {
    if (a.joints[j].name != b.joints[j].name || a.joints[j].type != b.joints[j].type) {
      return Status::Error(what + ": joint " + std::to_string(j + 1) + " is '" + b.joints[j].name +
                           "', the first model's '" + a.joints[j].name +
                           "': a fleet prior needs one chain");
    }
  }
  if (a.num_tools() != b.num_tools()) {
    return Status::Error(what + " has " + std::to_string(b.num_tools()) + " tools, the first " +
                         std::to_string(a.num_tools()) + ": a fleet prior needs the same tools");
  }
  for (int t = 0; t < a.num_tools(); ++t) {
    if (a.tools[t].name != b.tools[t].name) {
      return Status::Error(what + ": tool " + std::to_string(t + 1) + " is '" + b.tools[t].name +
                           "', the first model's '" + a.tools[t].name +
                           "': a fleet prior needs the same tools");
    }
  }
  return Status::Ok();
}

// The pseudo-inverse of a symmetric positive semi-definite matrix (eigenvalues below 1e-12 of the
// largest left out).
Eigen::MatrixXd PseudoInverse(const Eigen::MatrixXd& M) {
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(0.5 * (M + M.transpose()));
  const double largest = eig.eigenvalues().cwiseAbs().maxCoeff();
  Eigen::MatrixXd out = Eigen::MatrixXd::Zero(M.rows(), M.cols());
  for (int k = 0; k < eig.eigenvalues().size(); ++k) {
    const double l = eig.eigenvalues()(k);
    if (largest > 0 && l > 1e-12 * largest) {
      out += eig.eigenvectors().col(k) * eig.eigenvectors().col(k).transpose() / l;
    }
  }
  return out;
}

}  // namespace

int EstimatedDimension(const RobotModel& model, int f, const Eigen::MatrixXd& covariance) {
  if (covariance.rows() != 6) return 6;
  return static_cast<int>(EstimatedDirections(model, f, covariance).cols());
}

double FleetPredictiveFactor(int robots, int p) {
  const double N = robots;
  if (robots > p + 2) return (N + 1) * (N - 1) / (N * (N - p - 2));
  return (N + 1) / N;
}

RobotModel CalibratedModel(const PipelineResult& run) {
  RobotModel calibrated = run.result.model;
  if (run.registered && run.registration.moved) {
    calibrated.T_measurement_base = run.registration.T_measurement_base;
  }
  return calibrated;
}

std::string CalibratedModelYaml(const RobotModel& calibrated, const CalibrationResult& result) {
  std::string yaml = RobotModelToYaml(calibrated);
  if (result.covariance.rows() == result.parameterization.num_parameters &&
      result.covariance.rows() > 0) {
    yaml += ModelCovarianceYaml(calibrated, CovarianceOf(result));
  }
  return yaml;
}

ModelCovariance CovarianceOf(const CalibrationResult& result) {
  ModelCovariance out;
  const Parameterization& p = result.parameterization;
  const RobotModel& m = result.model;
  out.frames.assign(m.num_frames(), Eigen::MatrixXd());
  out.data_sigma = result.prior_data_sigma;
  if (result.covariance.rows() != p.num_parameters) return out;
  for (int f = 0; f < m.num_frames() && f < static_cast<int>(p.basis.size()); ++f) {
    const Eigen::MatrixXd& B = p.basis[f];
    if (B.cols() == 0) continue;
    out.frames[f] =
        B * result.covariance.block(p.offset[f], p.offset[f], B.cols(), B.cols()) * B.transpose();
  }
  for (const JointBlock& b : p.joint_blocks) {
    if (b.basis.cols() == 0) continue;
    out.term_names.push_back(b.term->name());
    out.terms.push_back(b.basis *
                        result.covariance.block(b.offset, b.offset, b.basis.cols(), b.basis.cols()) *
                        b.basis.transpose());
  }
  return out;
}

ParameterPrior PriorFromCovariance(const RobotModel& model, const ModelCovariance& covariance,
                                   const PriorScales& scales) {
  ParameterPrior prior;
  prior.reference = std::make_shared<const RobotModel>(model);
  prior.scales = scales;
  prior.informative = true;
  prior.data_sigma_mm = covariance.data_sigma;
  for (int f = 0; f < model.num_frames(); ++f) {
    const Matrix6d fallback = DefaultFrameInformation(model, f, scales, 1.0);
    const bool has = f < static_cast<int>(covariance.frames.size()) &&
                     covariance.frames[f].rows() == 6;
    prior.frame_information.push_back(
        has ? Matrix6d(InformationOf(covariance.frames[f], fallback,
                                     EstimatedDirections(model, f, covariance.frames[f])))
            : fallback);
  }
  for (size_t b = 0; b < covariance.terms.size(); ++b) {
    JointTermPrior t;
    t.name = covariance.term_names[b];
    const std::vector<double>& v = model.joint_errors.Values(t.name);
    t.reference = Eigen::Map<const Eigen::VectorXd>(v.data(), static_cast<Eigen::Index>(v.size()));
    const Eigen::MatrixXd& C = covariance.terms[b];
    t.information = InformationOf(C, Eigen::MatrixXd::Zero(C.rows(), C.cols()),
                                  Eigen::MatrixXd::Identity(C.rows(), C.cols()));
    prior.joint_terms.push_back(t);
  }
  return prior;
}

Status ReadPrior(const std::string& path, const PriorScales& scales, RobotModel* model,
                 ParameterPrior* prior) {
  RobotModel m;
  if (Status s = ReadRobotModel(path, &m); !s.ok()) return s;
  ModelCovariance c;
  if (Status s = ReadModelCovariance(path, m, &c); !s.ok()) return s;
  *prior = PriorFromCovariance(m, c, scales);
  *model = std::move(m);
  return Status::Ok();
}

namespace {

// Recalibrate's state between rounds: per frame 0 held by the prior, 1 only the previous joint's
// zero freed, 2 freed; the zero's direction of a frame whose group is "jointN zero".
struct RecalibrationFrameState {
  std::vector<int> state;
  std::vector<Vector6d> zero_direction;
};

bool ChangedBeyondChance(double chi2, int dof) {
  return chi2 > dof + 5 * std::sqrt(2.0 * dof) + 10;
}

// The frames whose prior discrepancy at `geometric` is far beyond chance (frame 0, the base, is
// the registration's: not tested), each named "jointN frame", a tool's name, or "jointN zero" when
// most of it lies along the previous joint's zero (its direction noted in `st`).
std::vector<ChangedGroup> ChangedFrames(const RobotModel& reference, const ParameterPrior& prior,
                                        const Parameterization& p, const RobotModel& geometric,
                                        RecalibrationFrameState* st) {
  std::vector<ChangedGroup> changed;
  for (int f = 1; f < reference.num_frames() && f < static_cast<int>(p.basis.size()); ++f) {
    if (p.basis[f].cols() == 0 || f >= static_cast<int>(prior.frame_information.size()) ||
        st->state[f] == 2) {
      continue;
    }
    const Matrix6d info = FrameInformation(prior, reference, f);
    const Vector6d xi = FrameDeviation(reference, geometric, f);
    // Only the identified directions count (the others are the start's, not estimated).
    const Eigen::MatrixXd& B = p.basis[f];
    const Eigen::VectorXd z = B.transpose() * xi;
    const Eigen::MatrixXd I = B.transpose() * info * B;
    const double chi2 = z.dot(I * z);
    const int dof = static_cast<int>(B.cols());
    if (!ChangedBeyondChance(chi2, dof)) continue;
    ChangedGroup g;
    g.frame = f;
    g.chi2 = chi2;
    g.dof = dof;
    const int n = reference.num_joints();
    g.name = RecalibrationFrameName(reference, f) + (f < n ? " frame" : "");
    if (f < n && f >= 1 && st->state[f] == 0) {
      // A zero shift of the joint before: the rotation about its axis, pushed into this frame
      // (Ad of this frame's inverse applied to that joint's twist). When it carries most of the
      // discrepancy, that zero alone is the group (freed first; the frame follows in a later
      // round if the rest of its discrepancy stays).
      const Vector6d u = Adjoint(reference.joints[f].origin.Inverse()) * reference.joints[f - 1].twist;
      const Eigen::VectorXd uz = B.transpose() * u;
      const double uIu = uz.dot(I * uz);
      if (uIu > 0) {
        const double along = std::pow(uz.dot(I * z), 2) / uIu;
        if (along > 0.5 * chi2) {
          g.name = reference.joints[f - 1].name + " zero";
          st->zero_direction[f] = u;
        }
      }
    }
    changed.push_back(g);
  }
  return changed;
}

// Joint-space terms (--joint_errors) with a prior of their own: per joint, the marginal
// discrepancy of that joint's parameters under the term's prior (parameters that may move several
// joints form one group of the whole term), appended to `changed`.
void ChangedJointTerms(const RobotModel& reference, const ParameterPrior& prior,
                       const Parameterization& p, const RobotModel& model,
                       std::vector<ChangedGroup>* changed) {
  for (const JointBlock& b : p.joint_blocks) {
    if (b.basis.cols() == 0) continue;
    const std::string& name = b.term->name();
    const int P = static_cast<int>(b.basis.rows());
    const JointTermPrior* t = nullptr;
    for (const JointTermPrior& given : prior.joint_terms) {
      if (given.name == name && given.information.rows() == P) t = &given;
    }
    const std::vector<double>& v = model.joint_errors.Values(name);
    if (t == nullptr || static_cast<int>(v.size()) != P) continue;
    Eigen::VectorXd d = Eigen::Map<const Eigen::VectorXd>(v.data(), P);
    if (t->reference.size() == P) d -= t->reference;
    const Eigen::MatrixXd C = PseudoInverse(t->information / (prior.scale * prior.scale));
    for (int j = -1; j < b.term->num_joints(); ++j) {
      std::vector<int> K;
      for (int k = 0; k < P; ++k) {
        if (b.term->ParameterJoint(k) == j) K.push_back(k);
      }
      if (K.empty()) continue;
      Eigen::VectorXd dk(K.size());
      Eigen::MatrixXd Ck(K.size(), K.size());
      for (size_t r = 0; r < K.size(); ++r) {
        dk(r) = d(K[r]);
        for (size_t c = 0; c < K.size(); ++c) Ck(r, c) = C(K[r], K[c]);
      }
      const double chi2 = dk.dot(PseudoInverse(Ck) * dk);
      const int dof = static_cast<int>(K.size());
      if (!ChangedBeyondChance(chi2, dof)) continue;
      ChangedGroup g;
      g.frame = -1;
      g.term = name;
      g.joint = j;
      g.name = (j >= 0 ? reference.joints[j].name + " " : std::string()) + name;
      g.chi2 = chi2;
      g.dof = dof;
      changed->push_back(g);
    }
  }
}

// A joint-space term's group freed: its parameters get the default joint-term tolerance (a
// standard deviation of joint_term_mrad per parameter), the term's others keep their marginal
// information.
void FreeJointTermGroup(const ChangedGroup& worst, const Parameterization& p,
                        ParameterPrior* prior) {
  for (JointTermPrior& t : prior->joint_terms) {
    if (t.name != worst.term) continue;
    std::shared_ptr<const JointTerm> term;
    for (const JointBlock& b : p.joint_blocks) {
      if (b.term->name() == worst.term) term = b.term;
    }
    if (!term) break;
    const int P = static_cast<int>(t.information.rows());
    const Eigen::MatrixXd C = PseudoInverse(t.information);
    std::vector<int> keep, freed;
    for (int k = 0; k < P; ++k) (term->ParameterJoint(k) == worst.joint ? freed : keep).push_back(k);
    Eigen::MatrixXd next = Eigen::MatrixXd::Zero(P, P);
    if (!keep.empty()) {
      Eigen::MatrixXd Ck(keep.size(), keep.size());
      for (size_t r = 0; r < keep.size(); ++r) {
        for (size_t c = 0; c < keep.size(); ++c) Ck(r, c) = C(keep[r], keep[c]);
      }
      const Eigen::MatrixXd Ik = PseudoInverse(Ck);
      for (size_t r = 0; r < keep.size(); ++r) {
        for (size_t c = 0; c < keep.size(); ++c) next(keep[r], keep[c]) = Ik(r, c);
      }
    }
    const double sigma = 1e-3 * prior->scales.joint_term_mrad;
    for (int k : freed) next(k, k) = 1.0 / (sigma * sigma);
    t.information = next;
  }
}

// A frame's group freed: a "jointN zero" group (first time) gives the zero's direction the
// tolerances and keeps the frame's other directions' marginal information; otherwise the frame
// gets the tolerances.
void FreeFrameGroup(const ChangedGroup& worst, const RobotModel& reference,
                    RecalibrationFrameState* st, ParameterPrior* prior) {
  const double k2 = prior->scale * prior->scale;
  const Matrix6d tolerances =
      DefaultFrameInformation(reference, worst.frame, prior->scales, 1.0) * k2;
  if (st->state[worst.frame] == 0 && worst.name.size() > 5 &&
      worst.name.compare(worst.name.size() - 5, 5, " zero") == 0) {
    const Eigen::Matrix<double, 6, 1> q = st->zero_direction[worst.frame].normalized();
    const Eigen::MatrixXd qm = q;
    const Eigen::HouseholderQR<Eigen::MatrixXd> qr(qm);
    const Eigen::MatrixXd full = qr.householderQ() * Eigen::MatrixXd::Identity(6, 6);
    const Eigen::MatrixXd Bo = full.rightCols(5);
    const Matrix6d& info = prior->frame_information[worst.frame];
    const Eigen::LDLT<Matrix6d> ldlt(info);
    const Eigen::MatrixXd C = ldlt.solve(Matrix6d::Identity());
    const Eigen::MatrixXd qq = q * q.transpose();
    Matrix6d next = Bo * (Bo.transpose() * C * Bo).inverse() * Bo.transpose() +
                    qq * tolerances * qq;
    prior->frame_information[worst.frame] = 0.5 * (next + next.transpose());
    st->state[worst.frame] = 1;
  } else {
    prior->frame_information[worst.frame] = tolerances;
    st->state[worst.frame] = 2;
  }
}

}  // namespace

RecalibrationResult Recalibrate(const RobotModel& nominal, const MeasurementSet& identification,
                                const MeasurementSet& verification,
                                const PipelineOptions& options) {
  RecalibrationResult out;
  PipelineOptions o = options;
  out.run = RunCalibrationPipeline(nominal, identification, verification, o);
  ++out.solves;
  if (!options.prior || !options.prior->reference) return out;
  auto prior = std::make_shared<ParameterPrior>(*options.prior);
  const RobotModel& reference = *prior->reference;
  // The discrepancies are judged under the prior the pipeline solved with (the base's
  // registration directions free).
  FreeRegistrationDirections(reference, prior.get());
  constexpr int kRounds = 6;
  RecalibrationFrameState st;
  st.state.assign(reference.num_frames(), 0);
  st.zero_direction.assign(reference.num_frames(), Vector6d::Zero());
  for (int round = 0; round < kRounds && out.run.result.converged(); ++round) {
    const Parameterization& p = out.run.result.parameterization;
    std::vector<ChangedGroup> changed = ChangedFrames(reference, *prior, p, out.run.geometric, &st);
    ChangedJointTerms(reference, *prior, p, out.run.result.model, &changed);
    if (changed.empty()) break;
    // The worst group only: a large change spreads its misfit over the neighbouring frames at the
    // MAP estimate, which are consistent again once it is freed.
    const ChangedGroup worst = *std::max_element(
        changed.begin(), changed.end(), [](const ChangedGroup& a, const ChangedGroup& b) {
          return a.chi2 / std::max(1, a.dof) < b.chi2 / std::max(1, b.dof);
        });
    out.changed.push_back(worst);
    if (worst.frame < 0) {
      FreeJointTermGroup(worst, p, prior.get());
    } else {
      FreeFrameGroup(worst, reference, &st, prior.get());
    }
    o.prior = prior;
    out.run = RunCalibrationPipeline(nominal, identification, verification, o);
    ++out.solves;
  }
  return out;
}

Status FleetPrior(const std::vector<RobotModel>& models, RobotModel* mean,
                  ModelCovariance* covariance) {
  if (models.size() < 2) {
    return Status::Error("a fleet prior needs at least two calibrated models (a full covariance of "
                         "a frame needs " + std::to_string(kRobotsForFullCovariance) + ")");
  }
  for (size_t k = 1; k < models.size(); ++k) {
    if (Status s = SameChain(models[0], models[k], "model " + std::to_string(k + 1)); !s.ok()) {
      return s;
    }
  }
  const RobotModel& first = models[0];
  RobotModel m = first;
  ModelCovariance c;
  c.models = static_cast<int>(models.size());
  const int n = first.num_joints();
  const double count = static_cast<double>(models.size());
  for (int f = 0; f < first.num_frames(); ++f) {
    // The mean on SE(3): iterated from the first model (two rounds are plenty for mm and mrad).
    SE3d& T = f < n ? m.joints[f].origin : m.tools[f - n].origin;
    for (int it = 0; it < 3; ++it) {
      Vector6d sum = Vector6d::Zero();
      for (const RobotModel& r : models) sum += FrameDeviation(m, r, f);
      T = T * ExpSE3(Vector6d(sum / count));
    }
    Matrix6d S = Matrix6d::Zero();
    for (const RobotModel& r : models) {
      const Vector6d d = FrameDeviation(m, r, f);
      S += d * d.transpose();
    }
    // The covariance of a new robot's deviation (the posterior predictive, see the header).
    const Eigen::MatrixXd sample = S / (count - 1);
    c.frames.push_back(sample *
                       FleetPredictiveFactor(c.models, EstimatedDimension(m, f, sample)));
  }
  // Joint terms every model carries: the mean and sample covariance of their values.
  for (const JointTermEntry& e : first.joint_errors.terms) {
    if (e.values.empty()) continue;
    bool all = true;
    for (const RobotModel& r : models) all = all && r.joint_errors.Values(e.name).size() == e.values.size();
    if (!all) continue;
    const int P = static_cast<int>(e.values.size());
    Eigen::VectorXd mu = Eigen::VectorXd::Zero(P);
    for (const RobotModel& r : models) {
      mu += Eigen::Map<const Eigen::VectorXd>(r.joint_errors.Values(e.name).data(), P);
    }
    mu /= count;
    Eigen::MatrixXd S = Eigen::MatrixXd::Zero(P, P);
    for (const RobotModel& r : models) {
      const Eigen::VectorXd d =
          Eigen::Map<const Eigen::VectorXd>(r.joint_errors.Values(e.name).data(), P) - mu;
      S += d * d.transpose();
    }
    std::vector<double>& values = *m.joint_errors.MutableValues(e.name);
    values.assign(mu.data(), mu.data() + P);
    c.term_names.push_back(e.name);
    c.terms.push_back(S / (count - 1) * FleetPredictiveFactor(c.models, P));
  }
  *mean = std::move(m);
  *covariance = std::move(c);
  return Status::Ok();
}

}  // namespace lpoe
