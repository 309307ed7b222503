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

void EffectiveJointValues(const std::vector<JointTermValues>& terms, int num_joints,
                          const double* q, double* q_eff) {
  for (int j = 0; j < num_joints; ++j) q_eff[j] = q[j];
  Eigen::MatrixXd Y;
  for (const JointTermValues& t : terms) {
    CHECK_EQ(t.term->num_joints(), num_joints);
    CHECK_EQ(t.theta.size(), t.term->num_parameters());
    Y.resize(num_joints, t.term->num_parameters());
    t.term->Regressor(q, Y.data());
    Eigen::Map<Eigen::VectorXd>(q_eff, num_joints) += Y * t.theta;
  }
}

MeasurementSet WithEffectiveJointValues(const std::vector<JointTermValues>& terms,
                                        const MeasurementSet& data) {
  MeasurementSet out = data;
  if (terms.empty()) return out;
  for (int r = 0; r < data.size(); ++r) {
    EffectiveJointValues(terms, data.num_joints(), data.q(r), out.mutable_q(r));
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
