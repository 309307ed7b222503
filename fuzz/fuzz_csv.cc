// libFuzzer target: ParseMeasurementsCsv on arbitrary bytes, against the cobot6 model (one tool)
// and a two-tool variant, with joint values in radians and in degrees. Checks that nothing crashes,
// that errors are "<file>:<line>: ..." messages, that accepted rows are finite, and that what was
// accepted round-trips through MeasurementsToCsv.
#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>

#include "fuzz_common.h"
#include "lpoe/io/io.h"
#include "lpoe/model/robot_model.h"

namespace {

using lpoe::AngleUnit;
using lpoe::MeasurementSet;
using lpoe::RobotModel;

const RobotModel& OneTool() {
  static const RobotModel* model = new RobotModel(lpoe::MakeCobot6());
  return *model;
}

const RobotModel& TwoTools() {
  static const RobotModel* model = [] {
    RobotModel* m = new RobotModel(lpoe::MakeCobot6());
    lpoe::Tool second = m->tools[0];
    second.name = "smr2";
    second.origin.t = Eigen::Vector3d(-40, 30, 60);
    m->tools.push_back(second);
    return m;
  }();
  return *model;
}

void CheckAccepted(const RobotModel& model, const MeasurementSet& data,
                   const lpoe::CsvReadReport& report) {
  if (data.empty()) lpoe::fuzz::Fail("accepted an empty measurement set", "");
  if (data.num_joints() != model.num_joints()) lpoe::fuzz::Fail("wrong joint count", "");
  for (int r = 0; r < data.size(); ++r) {
    for (int j = 0; j < data.num_joints(); ++j) {
      if (!std::isfinite(data.q(r)[j])) lpoe::fuzz::Fail("accepted a non-finite joint value", "");
    }
    if (!data.position(r).allFinite()) lpoe::fuzz::Fail("accepted a non-finite position", "");
    if (data.target(r) < 0 || data.target(r) >= model.num_tools()) {
      lpoe::fuzz::Fail("accepted a target that is not a tool", std::to_string(data.target(r)));
    }
    if (data.has_orientation() && !data.orientation(r).allFinite()) {
      lpoe::fuzz::Fail("accepted a non-finite orientation", "");
    }
    if (data.source_line(r) < 1) lpoe::fuzz::Fail("row without a source line", "");
  }
  if (static_cast<int64_t>(report.skipped_lines.size()) !=
      std::min<int64_t>(report.skipped_zero_rows, lpoe::CsvReadReport::kMaxSkippedLines)) {
    lpoe::fuzz::Fail("skipped-row count and line list disagree", "");
  }
}

void RoundTrip(const RobotModel& model, const MeasurementSet& data) {
  const std::string csv = lpoe::MeasurementsToCsv(model, data, "round trip");
  MeasurementSet again;
  const lpoe::Status s =
      lpoe::ParseMeasurementsCsv(csv, "roundtrip.csv", model, AngleUnit::kRadians, &again);
  if (!s.ok()) lpoe::fuzz::Fail("written measurements do not read back: " + s.message(), csv);
  if (again.size() != data.size()) lpoe::fuzz::Fail("round trip changed the row count", csv);
  for (int r = 0; r < data.size(); ++r) {
    for (int j = 0; j < data.num_joints(); ++j) {
      if (again.q(r)[j] != data.q(r)[j]) lpoe::fuzz::Fail("round trip changed a joint value", csv);
    }
    if (again.position(r) != data.position(r)) {
      lpoe::fuzz::Fail("round trip changed a position", csv);
    }
    if (again.target(r) != data.target(r)) lpoe::fuzz::Fail("round trip changed a target", csv);
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* bytes, size_t size) {
  const std::string text(reinterpret_cast<const char*>(bytes), size);
  for (const RobotModel* model : {&OneTool(), &TwoTools()}) {
    for (AngleUnit unit : {AngleUnit::kRadians, AngleUnit::kDegrees}) {
      MeasurementSet data;
      lpoe::CsvReadReport report;
      const lpoe::Status s =
          lpoe::ParseMeasurementsCsv(text, "fuzz.csv", *model, unit, &data, &report);
      if (!s.ok()) {
        lpoe::fuzz::CheckErrorMessage(s, "fuzz.csv");
        if (!data.empty()) lpoe::fuzz::Fail("data changed on error", s.message());
        continue;
      }
      CheckAccepted(*model, data, report);
      RoundTrip(*model, data);
    }
  }
  return 0;
}
