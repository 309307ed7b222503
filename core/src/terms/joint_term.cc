#include "lpoe/terms/joint_term.h"

#include <algorithm>

#include <glog/logging.h>

#include "terms/joint_term_kind.h"
#include "lpoe/terms/joint_errors.h"

namespace lpoe {

namespace internal {

// The entries of the registry, declared here once each.
#define LPOE_JOINT_TERM(entry) const JointTermKind& entry();
#include "terms/joint_term_registry.inc"
#undef LPOE_JOINT_TERM

const std::vector<const JointTermKind*>& JointTermKinds() {
  static const std::vector<const JointTermKind*> kinds = {
#define LPOE_JOINT_TERM(entry) &entry(),
#include "terms/joint_term_registry.inc"
#undef LPOE_JOINT_TERM
  };
  return kinds;
}

const JointTermKind* FindJointTermKind(const std::string& name) {
  for (const JointTermKind* kind : JointTermKinds()) {
    if (name == kind->name()) return kind;
  }
  return nullptr;
}

void JointTermKind::AddOffsets(const RobotModel& model, const std::vector<double>& theta,
                               const double* q, double* dq) const {
  const int n = model.num_joints();
  const int P = static_cast<int>(theta.size());
  thread_local std::vector<double> y;
  y.resize(P);
  const std::vector<int> joints = ParameterJoints(model);
  CHECK_EQ(static_cast<int>(joints.size()), P) << name();
  const bool single = std::all_of(joints.begin(), joints.end(), [](int j) { return j >= 0; });
  if (single && RegressorValues(model, q, y.data())) {
    // Per joint, the sum over its parameters, then added (as a per-joint block sum).
    thread_local std::vector<double> sum;
    sum.assign(n, 0.0);
    for (int k = 0; k < P; ++k) sum[joints[k]] += y[k] * theta[k];
    for (int j = 0; j < n; ++j) dq[j] += sum[j];
    return;
  }
  thread_local Eigen::MatrixXd Y;
  Regressor(model, q, &Y);
  Eigen::Map<Eigen::VectorXd>(dq, n) +=
      Y * Eigen::Map<const Eigen::VectorXd>(theta.data(), static_cast<Eigen::Index>(P));
}

namespace {

// A registry entry's term on a fixed reference model: what the solvers see.
class RegisteredJointTerm : public JointTerm {
 public:
  RegisteredJointTerm(const JointTermKind& kind, const RobotModel& reference)
      : kind_(kind),
        reference_(reference),
        num_parameters_(kind.NumParameters(reference)),
        names_(kind.ParameterNames(reference)),
        joint_of_(kind.ParameterJoints(reference)) {
    CHECK_EQ(static_cast<int>(names_.size()), num_parameters_) << kind.name();
    CHECK_EQ(static_cast<int>(joint_of_.size()), num_parameters_) << kind.name();
    for (int j : joint_of_) all_single_ = all_single_ && j >= 0;
  }

  std::string name() const override { return kind_.name(); }
  int num_joints() const override { return reference_.num_joints(); }
  int num_parameters() const override { return num_parameters_; }
  std::string ParameterName(int k) const override {
    CHECK_GE(k, 0);
    CHECK_LT(k, num_parameters_);
    return names_[k];
  }
  void Regressor(const double* q, double* Y) const override {
    thread_local Eigen::MatrixXd m;  // no allocation per row
    kind_.Regressor(reference_, q, &m);  // rounding noise already zero
    CHECK_EQ(m.rows(), num_joints());
    CHECK_EQ(m.cols(), num_parameters());
    Eigen::Map<Eigen::MatrixXd>(Y, m.rows(), m.cols()) = m;
  }
  bool RegressorValues(const double* q, double* y) const override {
    return all_single_ && kind_.RegressorValues(reference_, q, y);
  }
  int ParameterJoint(int k) const override {
    CHECK_GE(k, 0);
    CHECK_LT(k, num_parameters_);
    return joint_of_[k];
  }

 private:
  const JointTermKind& kind_;
  const RobotModel reference_;
  const int num_parameters_;
  const std::vector<std::string> names_;
  const std::vector<int> joint_of_;
  bool all_single_ = true;
};

const JointTermKind& KindOrDie(const std::string& name) {
  const JointTermKind* kind = FindJointTermKind(name);
  CHECK(kind != nullptr) << "unknown joint error term '" << name << "' (known: "
                         << JointTermNameList() << ")";
  return *kind;
}

}  // namespace
}  // namespace internal

using internal::FindJointTermKind;
using internal::JointTermKind;
using internal::JointTermKinds;
using internal::KindOrDie;

namespace {

// Per term: the joint each parameter moves when every parameter moves one (JointTerm::ParameterJoint
// >= 0, so that RegressorValues may apply), else empty.
std::vector<std::vector<int>> ParameterJoints(const std::vector<JointTermValues>& terms) {
  std::vector<std::vector<int>> joints(terms.size());
  for (size_t t = 0; t < terms.size(); ++t) {
    const JointTerm& term = *terms[t].term;
    for (int k = 0; k < term.num_parameters(); ++k) {
      const int j = term.ParameterJoint(k);
      CHECK_LT(j, term.num_joints()) << term.name() << ": ParameterJoint(" << k << ")";
      if (j < 0) {
        joints[t].clear();
        break;
      }
      joints[t].push_back(j);
    }
  }
  return joints;
}

void AddJointOffsets(const std::vector<JointTermValues>& terms,
                     const std::vector<std::vector<int>>& joints, int num_joints, const double* q,
                     double* q_eff, Eigen::VectorXd* y, Eigen::VectorXd* dq, Eigen::MatrixXd* Y) {
  for (int j = 0; j < num_joints; ++j) q_eff[j] = q[j];
  for (size_t i = 0; i < terms.size(); ++i) {
    const JointTermValues& t = terms[i];
    CHECK_EQ(t.term->num_joints(), num_joints);
    CHECK_EQ(t.theta.size(), t.term->num_parameters());
    // The regressor's entries at their joints alone when the term gives them (no n x P matrix).
    y->resize(t.term->num_parameters());
    if (!joints[i].empty() && t.term->RegressorValues(q, y->data())) {
      dq->setZero(num_joints);
      for (int k = 0; k < y->size(); ++k) (*dq)(joints[i][k]) += (*y)(k) * t.theta(k);
      Eigen::Map<Eigen::VectorXd>(q_eff, num_joints) += *dq;
      continue;
    }
    Y->resize(num_joints, t.term->num_parameters());
    t.term->Regressor(q, Y->data());
    Eigen::Map<Eigen::VectorXd>(q_eff, num_joints) += *Y * t.theta;
  }
}

}  // namespace

void EffectiveJointValues(const std::vector<JointTermValues>& terms, int num_joints,
                          const double* q, double* q_eff) {
  Eigen::VectorXd y, dq;
  Eigen::MatrixXd Y;
  AddJointOffsets(terms, ParameterJoints(terms), num_joints, q, q_eff, &y, &dq, &Y);
}

MeasurementSet WithEffectiveJointValues(const std::vector<JointTermValues>& terms,
                                        const MeasurementSet& data) {
  MeasurementSet out = data;
  if (terms.empty()) return out;
  const std::vector<std::vector<int>> joints = ParameterJoints(terms);
  Eigen::VectorXd y, dq;
  Eigen::MatrixXd Y;
  for (int r = 0; r < data.size(); ++r) {
    AddJointOffsets(terms, joints, data.num_joints(), data.q(r), out.mutable_q(r), &y, &dq, &Y);
  }
  return out;
}

Status MakeJointTerm(const std::string& name, const RobotModel& reference,
                     std::shared_ptr<const JointTerm>* term) {
  const JointTermKind* kind = FindJointTermKind(name);
  if (kind == nullptr) {
    return Status::Error("unknown joint error term '" + name + "' (known: " +
                         JointTermNameList() + ")");
  }
  *term = std::make_shared<internal::RegisteredJointTerm>(*kind, reference);
  return Status::Ok();
}

std::vector<std::string> JointTermNames() {
  std::vector<std::string> names;
  for (const JointTermKind* kind : JointTermKinds()) names.push_back(kind->name());
  return names;
}

bool IsJointTermName(const std::string& name) { return FindJointTermKind(name) != nullptr; }

std::vector<std::string> InRegistryOrder(const std::vector<std::string>& names) {
  std::vector<std::string> out;
  for (const JointTermKind* kind : JointTermKinds()) {
    if (std::find(names.begin(), names.end(), kind->name()) != names.end()) {
      out.push_back(kind->name());
    }
  }
  return out;
}

std::string JointTermNameList() {
  std::string known;
  for (const JointTermKind* kind : JointTermKinds()) {
    known += known.empty() ? kind->name() : std::string(", ") + kind->name();
  }
  return known.empty() ? std::string("none") : known;
}

int NumJointErrorParameters(const RobotModel& model, const std::string& name) {
  return KindOrDie(name).NumParameters(model);
}

std::vector<std::string> JointErrorParameterNames(const RobotModel& model,
                                                  const std::string& name) {
  return KindOrDie(name).ParameterNames(model);
}

void JointErrorRegressor(const RobotModel& model, const std::string& name, const double* q,
                         Eigen::MatrixXd* Y) {
  KindOrDie(name).Regressor(model, q, Y);
}

std::vector<int> JointErrorParameterJoints(const RobotModel& model, const std::string& name) {
  return KindOrDie(name).ParameterJoints(model);
}

void JointErrorOffsets(const RobotModel& model, const double* q, double* dq) {
  const int n = model.num_joints();
  for (int j = 0; j < n; ++j) dq[j] = 0;
  if (model.joint_errors.empty()) return;
  for (const JointTermKind* kind : JointTermKinds()) {
    const std::vector<double>& theta = model.joint_errors.Values(kind->name());
    if (theta.empty()) continue;
    kind->AddOffsets(model, theta, q, dq);
  }
}

}  // namespace lpoe
