// Measurement planning (lpoe/planning.h): the constants its model, candidates and selector share
// (planning_model.cc, planning_candidates.cc, planning_selector.cc). Internal to lpoe_solvers.
#ifndef LPOE_SOLVERS_SRC_PLANNING_INTERNAL_H_
#define LPOE_SOLVERS_SRC_PLANNING_INTERNAL_H_

#include <limits>

namespace lpoe {
namespace planning_internal {

inline constexpr double kInf = std::numeric_limits<double>::infinity();
// O1/O3 scaling: expected magnitude of a parameter error (the paper's Table 2 has rotations of
// 1-5 mrad and translations of 0.5-3 mm).
inline constexpr double kRotationErrorScale = 1e-3;    // rad
inline constexpr double kTranslationErrorScale = 1.0;  // mm
// M = delta I + sum J^T J in pool-scaled coordinates, where one pose contributes a unit mean
// diagonal: keeps M^-1 defined while the plan has fewer poses than it needs.
inline constexpr double kRegularization = 1e-6;
// A joint value may exceed its limit by this much (round-off of a written file).
inline constexpr double kLimitTolerance = 1e-9;
// O3 scaling of a joint-space combination: the value that moves the tools by this much (RMS, mm)
// over the reference configurations (the simulator's small arm: compliance 0.5 mm, harmonics
// 0.08 mm at the tool, docs/joint_errors.md).
inline constexpr double kJointErrorEffectScale = 0.1;  // mm

}  // namespace planning_internal
}  // namespace lpoe

#endif  // LPOE_SOLVERS_SRC_PLANNING_INTERNAL_H_
