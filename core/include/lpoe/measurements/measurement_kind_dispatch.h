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

#include "lpoe/measurements/distance_measurement.h"
#include "lpoe/measurements/measurement_kinds.h"
#include "lpoe/measurements/plane_measurement.h"
#include "lpoe/measurements/pose_measurement.h"
#include "lpoe/measurements/position_measurement.h"

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
// position. This is the one place the user-facing option use_orientation becomes a kind; the
// tracker solvers then take the kind's residual count, data kind, residual, Jacobian and
// identifiability rule from it (VisitTrackerKind below, the table's line).
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

// The tracker kinds (position, pose: a tool frame measured in the robot's base frame, no unknown
// feature): f(KindTag<PositionMeasurement or PoseMeasurement>{}). For the code that only tracker
// kinds have (Observe, Linearize on a BasisJacobian, Make, Simulate): both branches must compile
// for both tracker kinds only. Dispatch once per solve (one kind per tracker file), not per row.
template <typename F>
decltype(auto) VisitTrackerKind(MeasurementKindId id, F&& f) {
  if (id == MeasurementKindId::kPose) return std::forward<F>(f)(KindTag<PoseMeasurement>{});
  return std::forward<F>(f)(KindTag<PositionMeasurement>{});
}

// Whether `id` is a tracker kind (VisitTrackerKind).
constexpr bool IsTrackerKind(MeasurementKindId id) {
  return id == MeasurementKindId::kPosition || id == MeasurementKindId::kPose;
}

// The tracker kind's residuals per row (the table's line: 3 position, 6 pose).
inline int TrackerResiduals(MeasurementKindId id) { return MeasurementKind(id).residuals; }

// The data kind the tracker kind's parameterization is made for (its header's kData): which frame
// directions its rows can see (parameterization.h).
inline DataKind TrackerDataKind(MeasurementKindId id) {
  return VisitTrackerKind(id, [](auto kind) { return decltype(kind)::type::kData; });
}

}  // namespace lpoe

#endif  // LPOE_MEASUREMENT_KIND_DISPATCH_H_
