// A joint-space effect that is bilinear with a joint-space term, its partner (docs/architecture.md,
// "Where to add a block kind"). The gravity tilt is one: it turns the gravity that the compliance
// term's torques are computed with.
//
// With the partner's coordinates x (k numbers, its block's basis B: theta = B x) and the effect's
// own parameters t (m numbers), the partner's joint offsets are
//
//   dq = sum_a w_a(t) Z_a(q) x,   Z_a = Y_a(q) B   (a = 0 .. A-1),
//
// where Y_a are fixed parts of the partner's regressor and w(t) weights with the partner's own
// regressor at t = 0: Y(q) = sum_a w_a(0) Y_a(q). Linearised, the effect contributes
//
//   d(dq)/dt = sum_a (dw/dt)_a Z_a x          (n x m: its columns, before J_q),
//   d(dq)/dx = Y B + sum_a (w(t) - w(0))_a Z_a  (the partner's columns at the current t),
//
// and q_eff gains sum_a (w(t) - w(0))_a Z_a x. BilinearJointColumns is the one function both solvers
// take these from; an effect supplies only w, its derivative, the Z_a of a row and the partner's
// term at t (a model that carries the identified values then predicts with the partner alone).
#ifndef LPOE_TERMS_BILINEAR_TERM_H_
#define LPOE_TERMS_BILINEAR_TERM_H_

#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "lpoe/terms/joint_term.h"

namespace lpoe {

class BilinearJointEffect {
 public:
  virtual ~BilinearJointEffect() = default;

  // The effect's name: its block kind's and the item of a list of joint errors that asks for it
  // ("tilt").
  virtual const char* name() const = 0;
  // The registry name of the partner term ("compliance").
  virtual const char* partner() const = 0;
  // m, the number of the effect's own parameters, and their names ("gravity.tilt1").
  virtual int num_parameters() const = 0;
  virtual std::string parameter_name(int i) const = 0;
  // A, the number of weights.
  virtual int num_weights() const = 0;
  // w(t) - w(0) (A) and dw/dt (A x m) at t (m numbers).
  virtual void Weights(const double* t, Eigen::VectorXd* dw, Eigen::MatrixXd* dw_dt) const = 0;
  // Z_a = Y_a(q) basis (n x basis.cols() each, A of them) for one configuration q; `basis` is the
  // partner block's (P x k).
  virtual void RowRegressors(const Eigen::MatrixXd& basis, const double* q,
                             std::vector<Eigen::MatrixXd>* Z) const = 0;
  // The partner's term at t: its regressor is sum_a w_a(t) Y_a (an error when it cannot be built).
  virtual Status PartnerAt(const JointTerm& partner, const double* t,
                           std::shared_ptr<const JointTerm>* out) const = 0;
};

// The effect's joint-space columns for one row (see the top of this file): Z from RowRegressors,
// x the partner's coordinates (k), t the effect's parameters. Any output may be null.
void BilinearJointColumns(const BilinearJointEffect& effect, const double* t,
                          const std::vector<Eigen::MatrixXd>& Z, const double* x,
                          Eigen::VectorXd* ddq, Eigen::MatrixXd* dR, Eigen::MatrixXd* D);

}  // namespace lpoe

#endif  // LPOE_TERMS_BILINEAR_TERM_H_
