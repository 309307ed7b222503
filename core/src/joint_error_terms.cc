// The physical joint-error terms of joint_errors.h (compliance under gravity and payload, harmonic
// transmission errors) as joint-space parameter blocks (joint_term.h), registered by name in
// joint_term_registry.inc. The regressor is evaluated on the reference model given at construction
// (the registered start model), so both solvers see it as fixed data.
#include <memory>
#include <string>
#include <vector>

#include <glog/logging.h>

#include "lpoe/joint_errors.h"
#include "lpoe/joint_term.h"

namespace lpoe {
namespace {

class JointErrorTerm : public JointTerm {
 public:
  JointErrorTerm(const RobotModel& reference, JointErrorKind kind)
      : reference_(reference),
        kind_(kind),
        names_(JointErrorParameterNames(reference, kind)) {}

  std::string name() const override { return JointErrorKindName(kind_); }
  int num_joints() const override { return reference_.num_joints(); }
  int num_parameters() const override { return NumJointErrorParameters(num_joints(), kind_); }
  std::string ParameterName(int k) const override {
    CHECK_GE(k, 0);
    CHECK_LT(k, static_cast<int>(names_.size()));
    return names_[k];
  }
  void Regressor(const double* q, double* Y) const override {
    Eigen::MatrixXd m;
    JointErrorRegressor(reference_, kind_, q, &m);  // rounding noise already zero
    CHECK_EQ(m.rows(), num_joints());
    CHECK_EQ(m.cols(), num_parameters());
    Eigen::Map<Eigen::MatrixXd>(Y, m.rows(), m.cols()) = m;
  }

 private:
  const RobotModel reference_;
  const JointErrorKind kind_;
  const std::vector<std::string> names_;
};

}  // namespace

std::unique_ptr<JointTerm> MakeComplianceJointTerm(const RobotModel& reference) {
  return std::make_unique<JointErrorTerm>(reference, JointErrorKind::kCompliance);
}

std::unique_ptr<JointTerm> MakeHarmonicsJointTerm(const RobotModel& reference) {
  return std::make_unique<JointErrorTerm>(reference, JointErrorKind::kHarmonics);
}

}  // namespace lpoe
