// A test-only joint-space term whose parameters move several joints (ParameterJoint -1, the
// default), shared by the joint-term tests (joint_normal_equations_test, joint_term_columns_test):
// dq_j = sum_k (1 + 0.1 j k) f(q_j, q_(j+k+1 mod n)) theta_k, a coupling of every joint with every
// parameter, like a gravity tilt acting through every joint's compliance torque. Header only.
#ifndef LPOE_TESTS_COUPLED_JOINT_TERM_H_
#define LPOE_TESTS_COUPLED_JOINT_TERM_H_

#include <cmath>
#include <string>

#include "lpoe/terms/joint_term.h"

namespace lpoe {
namespace testing {

class CoupledJointTerm : public JointTerm {
 public:
  // f(a, b): a b / n (kProduct, zero at q = 0) or sin(a + b) (kSine).
  enum class Form { kProduct, kSine };
  CoupledJointTerm(int n, Form form) : n_(n), form_(form) {}
  std::string name() const override { return "coupled"; }
  int num_joints() const override { return n_; }
  int num_parameters() const override { return 3; }
  std::string ParameterName(int k) const override { return "c" + std::to_string(k); }
  void Regressor(const double* q, double* Y) const override {
    for (int k = 0; k < 3; ++k) {
      for (int j = 0; j < n_; ++j) {
        const double c = 1 + 0.1 * j * k, a = q[j], b = q[(j + k + 1) % n_];
        Y[k * n_ + j] = form_ == Form::kSine ? c * std::sin(a + b) : c * a * b / n_;
      }
    }
  }

 private:
  int n_;
  Form form_;
};

}  // namespace testing
}  // namespace lpoe

#endif  // LPOE_TESTS_COUPLED_JOINT_TERM_H_
