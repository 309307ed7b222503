#include "calibration/problem_setup.h"

#include <utility>

#include <glog/logging.h>

#include "calibration/block_kind.h"
#include "identifiability/identifiability.h"
#include "lpoe/measurements/measurement_kind_dispatch.h"

namespace lpoe {
namespace internal {
namespace {

// The parameterization's reduction with joint-space terms, from the solvers' shared analysis
// (identifiability.h), and its by-products.
void DecideParameterization(const RobotModel& nominal, const MeasurementSet& data,
                            const ProblemSetupRequest& request, ProblemSetup* s) {
  if (request.parameterization_override != nullptr) {
    CHECK(request.joint_terms.empty()) << "joint-space terms with a parameterization override";
    CHECK(!RequestsNonlinearBlocks(request)) << "a bilinear effect with a parameterization override";
    s->all = *request.parameterization_override;
    s->solved = s->all;
    return;
  }
  if (!request.joint_terms.empty()) {
    s->regressors = std::make_shared<JointSpaceRegressors>();
    s->analysed = std::make_shared<NormalEquations>();
  }
  SolverParameterizationRequest r = ParameterizationRequestOf(request);
  r.analysed = s->analysed.get();
  r.regressors = s->regressors.get();
  r.analysed_parameterization = &s->analysed_parameterization;
  s->all = SolverParameterization(nominal, data, r);
  // The slots' basis for the reduced blocks (the tilt's bilinear columns do not use the slots).
  if (s->regressors) SetSlotBasis(s->all, s->regressors.get());
  s->solved = s->all;
  LeaveOutUnmeasuredTools(nominal, data, &s->solved);
  // The bilinear blocks asked for (block_kind.h: the gravity tilt), after the joint blocks.
  for (const BlockKind* kind : BlockKinds()) {
    const BilinearBlockKind* bilinear = kind->bilinear();
    if (bilinear == nullptr || !bilinear->Requested(request) || !s->block_status.ok()) continue;
    s->block_status = bilinear->Add(request, &s->all);
    if (s->block_status.ok()) s->block_status = bilinear->Add(request, &s->solved);
  }
}

// The frames' gauge directions the full parameterization solves anyway (those of `unidentifiable`
// still in a frame's basis).
int GaugeDirections(const Parameterization& p, bool full) {
  int gauge = 0;
  for (const Direction& d : p.unidentifiable) {
    gauge += full && d.joint_block < 0 && p.basis[d.frame].cols() > 0 &&
             (p.basis[d.frame].transpose() * d.vector).norm() > 0.5;
  }
  return gauge;
}

}  // namespace

Eigen::VectorXd InitialJointState(const Parameterization& p,
                                  const std::vector<JointTermValues>& initial) {
  const int F = p.num_frame_parameters();
  Eigen::VectorXd x = Eigen::VectorXd::Zero(p.num_joint_parameters());
  for (const JointBlock& block : p.joint_blocks) {
    for (const JointTermValues& v : initial) {
      if (v.term == nullptr || v.term->name() != block.term->name()) continue;
      CHECK_EQ(v.theta.size(), block.basis.rows()) << block.term->name();
      x.segment(block.offset - F, block.basis.cols()) = block.basis.transpose() * v.theta;
    }
  }
  return x;
}

ProblemSetup SetUpProblem(const RobotModel& nominal, const MeasurementSet& data,
                          const ProblemSetupRequest& request) {
  ProblemSetup s;
  s.overridden = request.parameterization_override != nullptr;
  s.full = !s.overridden && request.parameterization == ParameterizationKind::kFull;
  DecideParameterization(nominal, data, request, &s);
  const int n = nominal.num_joints();
  s.frame_solved.assign(nominal.num_frames(), false);
  for (int i = 0; i < n; ++i) s.frame_solved[i] = true;
  for (int r = 0; r < data.size(); ++r) s.frame_solved[n + data.target(r)] = true;
  s.structure = request.structure_reference ? *request.structure_reference : nominal;
  s.per_row = TrackerResiduals(TrackerKindId(request.use_orientation));
  s.equations = static_cast<long>(s.per_row) * data.size();
  s.identifiable = s.solved.num_parameters - GaugeDirections(s.solved, s.full);
  s.initial_joint_state = InitialJointState(s.solved, request.initial_joint_terms);
  // The prior's reference is fixed here (the start model unless given), so that a sub-solve from
  // another start (the linear solver's warm start) keeps it.
  if (request.prior && !s.full) {
    if (request.prior->reference) {
      s.anchored_prior = request.prior;
    } else {
      auto copy = std::make_shared<ParameterPrior>(*request.prior);
      copy->reference = std::make_shared<const RobotModel>(nominal);
      s.anchored_prior = copy;
    }
    s.prior = ResolvePrior(*s.anchored_prior, nominal, data, s.solved);
  }
  return s;
}

}  // namespace internal
}  // namespace lpoe
