// The contact solvers' view of the kind table (measurement_kind_dispatch.h): a contact row's kind
// type, and where the feature it refers to lives (ContactFeatures' pivots or planes, the linear
// solver's columns). Tracker rows in contact data are tool positions (a pose row's orientation is
// not used there).
#ifndef LPOE_SOLVERS_CONTACT_CONTACT_KINDS_H_
#define LPOE_SOLVERS_CONTACT_CONTACT_KINDS_H_

#include <utility>

#include "lpoe/contact_calibration.h"
#include "lpoe/measurements/measurement_kind_dispatch.h"

namespace lpoe {
namespace internal {

// f(KindTag<Kind>{}) for a contact row's kind: DistanceMeasurement, PlaneMeasurement, else
// PositionMeasurement (pose rows as position rows: PoseMeasurement is never instantiated here).
template <typename F>
decltype(auto) VisitContactRowKind(MeasurementKindId id, F&& f) {
  switch (id) {
    case MeasurementKindId::kDistance:
      return std::forward<F>(f)(KindTag<DistanceMeasurement>{});
    case MeasurementKindId::kPlane:
      return std::forward<F>(f)(KindTag<PlaneMeasurement>{});
    default:
      return std::forward<F>(f)(KindTag<PositionMeasurement>{});
  }
}

// The ambient values of feature k of a kind with a feature (DistanceMeasurement: a pivot's 3,
// PlaneMeasurement: a plane's 4).
template <typename Kind>
const double* ContactFeatureData(const ContactFeatures& features, int k);
template <>
inline const double* ContactFeatureData<DistanceMeasurement>(const ContactFeatures& features,
                                                             int k) {
  return features.pivots[k].data();
}
template <>
inline const double* ContactFeatureData<PlaneMeasurement>(const ContactFeatures& features, int k) {
  return features.planes[k].data();
}

// The first of feature k's local columns (kFeatureTangent of them) in the linear solver's x.
template <typename Kind>
int ContactFeatureColumn(const ContactParameterization& p, int k);
template <>
inline int ContactFeatureColumn<DistanceMeasurement>(const ContactParameterization& p, int k) {
  return p.pivot_offset + DistanceMeasurement::kFeatureTangent * k;
}
template <>
inline int ContactFeatureColumn<PlaneMeasurement>(const ContactParameterization& p, int k) {
  return p.plane_offset + PlaneMeasurement::kFeatureTangent * k;
}

}  // namespace internal
}  // namespace lpoe

#endif  // LPOE_SOLVERS_CONTACT_CONTACT_KINDS_H_
