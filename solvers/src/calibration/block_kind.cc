#include "calibration/block_kind.h"

#include "calibration/problem_setup.h"

namespace lpoe {
namespace internal {

#define LPOE_BLOCK_KIND(Entry) const BlockKind& Entry();
#include "calibration/block_kind_registry.inc"
#undef LPOE_BLOCK_KIND

const std::vector<const BlockKind*>& BlockKinds() {
  static const std::vector<const BlockKind*> kinds = {
#define LPOE_BLOCK_KIND(Entry) &Entry(),
#include "calibration/block_kind_registry.inc"
#undef LPOE_BLOCK_KIND
  };
  return kinds;
}

const BlockKind* FindBlockKind(const std::string& name) {
  for (const BlockKind* kind : BlockKinds()) {
    if (name == kind->name()) return kind;
  }
  return nullptr;
}

bool HasNonlinearBlocks(const Parameterization& p) {
  for (const BlockKind* kind : BlockKinds()) {
    if (kind->In(p)) return true;
  }
  return false;
}

Status CheckBlockKindPartners(const std::vector<std::shared_ptr<const JointTerm>>& terms,
                              const ProblemSetupRequest& request) {
  for (const BlockKind* kind : BlockKinds()) {
    if (!kind->Requested(request) || kind->partner_term() == nullptr) continue;
    bool found = false;
    for (const auto& term : terms) found = found || (term && term->name() == kind->partner_term());
    if (!found) return Status::Error(kind->needs_partner_message());
  }
  return Status::Ok();
}

void AddNonlinearRowColumns(const Parameterization& p, const double* q,
                            const Eigen::VectorXd& joint_state, Eigen::Ref<Eigen::MatrixXd> R,
                            Eigen::VectorXd* q_eff) {
  for (const BlockKind* kind : BlockKinds()) {
    if (kind->In(p)) kind->RowColumns(p, q, joint_state, R, q_eff);
  }
}

void FillBlockKindResults(const Parameterization& p, const Eigen::VectorXd& joint_state,
                          const Eigen::MatrixXd& covariance, CalibrationResult* out) {
  for (const BlockKind* kind : BlockKinds()) {
    if (kind->In(p)) kind->FillResult(p, joint_state, covariance, out);
  }
}

}  // namespace internal
}  // namespace lpoe
