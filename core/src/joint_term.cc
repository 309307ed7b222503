#include "lpoe/joint_term.h"

#include <glog/logging.h>

namespace lpoe {

// The factories of the registry, declared here once each.
#define LPOE_JOINT_TERM(name, factory) \
  std::unique_ptr<JointTerm> factory(const RobotModel& reference);
#include "joint_term_registry.inc"
#undef LPOE_JOINT_TERM

namespace {

struct Entry {
  const char* name;
  std::unique_ptr<JointTerm> (*factory)(const RobotModel&);
};

const std::vector<Entry>& Registry() {
  static const std::vector<Entry> entries = {
#define LPOE_JOINT_TERM(name, factory) {name, &factory},
#include "joint_term_registry.inc"
#undef LPOE_JOINT_TERM
  };
  return entries;
}

}  // namespace

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
  std::string known;
  for (const Entry& e : Registry()) {
    if (name == e.name) {
      *term = e.factory(reference);
      return Status::Ok();
    }
    known += known.empty() ? e.name : std::string(", ") + e.name;
  }
  return Status::Error("unknown joint error term '" + name + "' (known: " +
                       (known.empty() ? std::string("none") : known) + ")");
}

std::vector<std::string> JointTermNames() {
  std::vector<std::string> names;
  for (const Entry& e : Registry()) names.push_back(e.name);
  return names;
}

}  // namespace lpoe
