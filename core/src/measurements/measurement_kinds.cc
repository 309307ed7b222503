#include "lpoe/measurements/measurement_kinds.h"

#include <cctype>

#include "lpoe/measurements/measurement_kind_dispatch.h"

namespace lpoe {
namespace {

bool SameNameIgnoringCase(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i) {
    if (std::tolower(static_cast<unsigned char>(a[i])) !=
        std::tolower(static_cast<unsigned char>(b[i]))) {
      return false;
    }
  }
  return true;
}

bool HeaderHas(const std::vector<std::string>& header, std::string_view name) {
  for (const std::string& h : header) {
    if (SameNameIgnoringCase(h, name)) return true;
  }
  return false;
}

}  // namespace

const std::vector<MeasurementKindInfo>& MeasurementKinds() {
  static const std::vector<MeasurementKindInfo> kinds = {
      {MeasurementKindId::kPosition, "position", "q1..qN,x,y,z[,target]", "x",
       PositionMeasurement::kResiduals, PositionMeasurement::kFeatureSize, "", "", true, true,
       "position errors (tracker)", "mm per axis", PositionMeasurement::kLeftOutReason},
      {MeasurementKindId::kPose, "pose", "q1..qN,x,y,z,quat_x,quat_y,quat_z,quat_w[,target]",
       "quat_w", PoseMeasurement::kResiduals, PoseMeasurement::kFeatureSize, "", "", true, true,
       "pose errors (6D tracker)", "mm per axis", PoseMeasurement::kLeftOutReason},
      {MeasurementKindId::kDistance, "distance", "q1..qN,distance[,pivot][,target][,sigma]",
       "distance", DistanceMeasurement::kResiduals, DistanceMeasurement::kFeatureSize, "pivot",
       "pivot", true, false, "distance errors (ballbar)", "mm",
       DistanceMeasurement::kLeftOutReason},
      {MeasurementKindId::kPlane, "plane", "q1..qN,plane[,offset][,target][,sigma]", "plane",
       PlaneMeasurement::kResiduals, PlaneMeasurement::kFeatureSize, "plane", "plane", false, false,
       "plane contact errors (touch probe)", "mm", PlaneMeasurement::kLeftOutReason},
  };
  return kinds;
}

// Each table line is its kind's: the dispatch reaches the header the line names.
static_assert(KindOf<MeasurementKindId::kPosition>::kKind == MeasurementKindId::kPosition, "");
static_assert(KindOf<MeasurementKindId::kPose>::kKind == MeasurementKindId::kPose, "");
static_assert(KindOf<MeasurementKindId::kDistance>::kKind == MeasurementKindId::kDistance, "");
static_assert(KindOf<MeasurementKindId::kPlane>::kKind == MeasurementKindId::kPlane, "");

const MeasurementKindInfo& MeasurementKind(MeasurementKindId id) {
  return MeasurementKinds()[static_cast<int>(id)];
}

const MeasurementKindInfo* FindMeasurementKind(std::string_view name) {
  if (SameNameIgnoringCase(name, "ballbar")) return &MeasurementKind(MeasurementKindId::kDistance);
  if (SameNameIgnoringCase(name, "planes")) return &MeasurementKind(MeasurementKindId::kPlane);
  for (const MeasurementKindInfo& k : MeasurementKinds()) {
    if (SameNameIgnoringCase(name, k.name)) return &k;
  }
  return nullptr;
}

const MeasurementKindInfo* DetectMeasurementKind(const std::vector<std::string>& header,
                                                 std::string* ambiguous) {
  const bool distance = HeaderHas(header, "distance");
  const bool plane = HeaderHas(header, "plane");
  const bool tracker = HeaderHas(header, "x") || HeaderHas(header, "y") || HeaderHas(header, "z");
  const int count = (distance ? 1 : 0) + (plane ? 1 : 0) + (tracker ? 1 : 0);
  if (count > 1) {
    if (ambiguous != nullptr) {
      *ambiguous = std::string("the header has the columns of ") +
                   (distance ? "'distance' " : "") + (plane ? "'plane' " : "") +
                   (tracker ? "'x, y, z' " : "") + "(one kind per file)";
    }
    return nullptr;
  }
  if (distance) return &MeasurementKind(MeasurementKindId::kDistance);
  if (plane) return &MeasurementKind(MeasurementKindId::kPlane);
  if (tracker) {
    return HeaderHas(header, "quat_w") ? &MeasurementKind(MeasurementKindId::kPose)
                                       : &MeasurementKind(MeasurementKindId::kPosition);
  }
  return nullptr;
}

std::string MeasurementKindNames() {
  std::string out;
  for (const MeasurementKindInfo& k : MeasurementKinds()) {
    if (!out.empty()) out += ", ";
    out += k.name;
  }
  return out;
}

}  // namespace lpoe
