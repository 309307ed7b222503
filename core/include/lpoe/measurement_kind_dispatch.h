// From a measurement kind's id (a line of the kind table, measurement_kinds.h) to its computation
// (the kind's header: position_measurement.h, pose_measurement.h, distance_measurement.h,
// plane_measurement.h). The solvers dispatch through VisitMeasurementKind: it calls a generic
// callable with the kind's type, so each branch is the kind's inlined template code (a switch on
// the id, no virtual call). Dispatch once per batch of rows of one kind where rows are many (the
// tracker's linear solver, one kind per file); per row where kinds mix (contact rows).
//
// Adding a kind: its header (a struct with kResiduals, kFeatureSize, kKind, kLeftOutReason, the
// templated Residual, the analytic Linearize, the simulation), one line of the table
// (measurement_kinds.cc) and one case below.
#ifndef LPOE_MEASUREMENT_KIND_DISPATCH_H_
#define LPOE_MEASUREMENT_KIND_DISPATCH_H_

#include <utility>

#include "lpoe/distance_measurement.h"
#include "lpoe/measurement_kinds.h"
#include "lpoe/plane_measurement.h"
#include "lpoe/pose_measurement.h"
#include "lpoe/position_measurement.h"

namespace lpoe {

// A kind's type as a value: f(KindTag<Kind>{}) and `typename decltype(tag)::type` inside.
template <typename Kind>
struct KindTag {
  using type = Kind;
};

// The kind type of an id, at compile time.
template <MeasurementKindId Id>
struct KindOfId;
template <>
struct KindOfId<MeasurementKindId::kPosition> {
  using type = PositionMeasurement;
};
template <>
struct KindOfId<MeasurementKindId::kPose> {
  using type = PoseMeasurement;
};
template <>
struct KindOfId<MeasurementKindId::kDistance> {
  using type = DistanceMeasurement;
};
template <>
struct KindOfId<MeasurementKindId::kPlane> {
  using type = PlaneMeasurement;
};
template <MeasurementKindId Id>
using KindOf = typename KindOfId<Id>::type;

// The kind a tracker's rows are solved as: pose when orientations are measured and used, else
// position.
inline MeasurementKindId TrackerKindId(bool use_orientation) {
  return use_orientation ? MeasurementKindId::kPose : MeasurementKindId::kPosition;
}

// f(KindTag<the kind's type>{}); every branch must return the same type.
template <typename F>
decltype(auto) VisitMeasurementKind(MeasurementKindId id, F&& f) {
  switch (id) {
    case MeasurementKindId::kPose:
      return std::forward<F>(f)(KindTag<PoseMeasurement>{});
    case MeasurementKindId::kDistance:
      return std::forward<F>(f)(KindTag<DistanceMeasurement>{});
    case MeasurementKindId::kPlane:
      return std::forward<F>(f)(KindTag<PlaneMeasurement>{});
    case MeasurementKindId::kPosition:
    default:
      return std::forward<F>(f)(KindTag<PositionMeasurement>{});
  }
}

}  // namespace lpoe

#endif  // LPOE_MEASUREMENT_KIND_DISPATCH_H_
