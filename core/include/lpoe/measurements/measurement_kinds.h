// The registry of measurement kinds (docs/architecture.md, docs/measurements.md): what a CSV file of
// each kind holds, how many residuals a row gives, which unknown feature (a ballbar pivot, a touched
// plane) its rows share, what the kind cannot see and what its report table is called. Every kind's
// computation is one header: position_measurement.h, pose_measurement.h, distance_measurement.h,
// plane_measurement.h (the residual templated for Ceres, the analytic Linearize of the linear
// solver, the simulation of a row). This table is the one place that lists them: the readers detect
// a file's kind from its columns with it, the tools take --data_kind from it and the reports name
// the kinds from it.
#ifndef LPOE_MEASUREMENT_KINDS_H_
#define LPOE_MEASUREMENT_KINDS_H_

#include <string>
#include <string_view>
#include <vector>

namespace lpoe {

enum class MeasurementKindId { kPosition = 0, kPose = 1, kDistance = 2, kPlane = 3 };

struct MeasurementKindInfo {
  MeasurementKindId id;
  const char* name;          // "position", "pose", "distance", "plane" (--data_kind)
  const char* columns;       // the CSV columns, as docs/file_formats.md gives them
  const char* key_column;    // the column whose presence selects the kind ("x", "quat_w", ...)
  int residuals;             // residuals per row
  int feature_size;          // ambient size of the unknown feature a row refers to (0: none)
  const char* feature_column;  // the column naming the feature ("pivot", "plane"), or ""
  const char* feature_noun;    // "pivot", "plane"
  // Whether the kind measures a length in the robot's frame: without any such row the robot's
  // scale is not determined (planes alone, docs/identifiability.md).
  bool measures_length;
  // Whether the kind sees the robot's base relative to the measuring device (a tracker does; a
  // ballbar's pivots and a probed artefact are estimated, so their data do not).
  bool sees_base;
  const char* report_table;  // title of the kind's error table in the reports
  const char* noise_unit;    // "mm" (per axis for position and pose)
  // The kind's left-out rule: why the directions its data cannot see (the base relative to the
  // features, when !sees_base) are left out, as the reports give it; null when it sees the base.
  // From the kind's header (kLeftOutReason).
  const char* left_out_reason;
};

// position, pose, distance, plane (in MeasurementKindId order). Each line of the table is checked at
// compile time against its kind's header (residuals, feature size, kind id); the solvers reach a
// kind's computation from its id with VisitMeasurementKind (measurement_kind_dispatch.h).
const std::vector<MeasurementKindInfo>& MeasurementKinds();
const MeasurementKindInfo& MeasurementKind(MeasurementKindId id);
// By name ("distance", also "ballbar"; "plane", also "planes"); null when unknown.
const MeasurementKindInfo* FindMeasurementKind(std::string_view name);
// The kind a header selects (names compared case-insensitively): "distance" -> distance,
// "plane" -> plane, quat_x..quat_w -> pose, x,y,z -> position; null when none. A header with the
// key columns of two kinds is ambiguous: null, and `*ambiguous` (when given) says which.
const MeasurementKindInfo* DetectMeasurementKind(const std::vector<std::string>& header,
                                                 std::string* ambiguous = nullptr);
// "position, pose, distance, plane".
std::string MeasurementKindNames();

}  // namespace lpoe

#endif  // LPOE_MEASUREMENT_KINDS_H_
