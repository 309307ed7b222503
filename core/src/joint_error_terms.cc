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
        names_(JointErrorParameterNames(reference, kind)) {
    // Layout (joint_errors.h): harmonics 4 per joint; compliance per joint j the 4 products of
    // every link k >= j, then c_j. Each parameter moves its own joint only.
    const int n = reference.num_joints();
    for (int j = 0; j < n; ++j) {
      const int count = kind == JointErrorKind::kHarmonics ? 4 : 4 * (n - j) + 1;
      joint_of_.insert(joint_of_.end(), count, j);
    }
    CHECK_EQ(joint_of_.size(), names_.size());
  }

  std::string name() const override { return JointErrorKindName(kind_); }
  int num_joints() const override { return reference_.num_joints(); }
  int num_parameters() const override { return NumJointErrorParameters(num_joints(), kind_); }
  std::string ParameterName(int k) const override {
    CHECK_GE(k, 0);
    CHECK_LT(k, static_cast<int>(names_.size()));
    return names_[k];
  }
  void Regressor(const double* q, double* Y) const override {
    thread_local Eigen::MatrixXd m;  // no allocation per row
    JointErrorRegressor(reference_, kind_, q, &m);  // rounding noise already zero
    CHECK_EQ(m.rows(), num_joints());
    CHECK_EQ(m.cols(), num_parameters());
    Eigen::Map<Eigen::MatrixXd>(Y, m.rows(), m.cols()) = m;
  }
  bool RegressorValues(const double* q, double* y) const override {
    JointErrorRegressorValues(reference_, kind_, q, y);  // rounding noise already zero
    return true;
  }
  int ParameterJoint(int k) const override {
    CHECK_GE(k, 0);
    CHECK_LT(k, static_cast<int>(joint_of_.size()));
    return joint_of_[k];
  }

 private:
  const RobotModel reference_;
  const JointErrorKind kind_;
  const std::vector<std::string> names_;
  std::vector<int> joint_of_;  // ParameterJoint
};

}  // namespace

std::unique_ptr<JointTerm> MakeComplianceJointTerm(const RobotModel& reference) {
  return std::make_unique<JointErrorTerm>(reference, JointErrorKind::kCompliance);
}

std::unique_ptr<JointTerm> MakeHarmonicsJointTerm(const RobotModel& reference) {
  return std::make_unique<JointErrorTerm>(reference, JointErrorKind::kHarmonics);
}

}  // namespace lpoe
