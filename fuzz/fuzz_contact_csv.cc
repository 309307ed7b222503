// libFuzzer target: ParseContactMeasurementsCsv (ballbar distances, probe contacts) on arbitrary
// bytes, against cobot6, with the kind detected and forced, with and without a default noise.
// Checks that nothing crashes, that errors are "<file>:<line>: ..." messages, that accepted rows are
// finite and refer to existing features and tools, and that what was accepted round-trips through
// ContactMeasurementsCsv.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>

#include "fuzz_common.h"
#include "lpoe/measurements/contact_measurements.h"
#include "lpoe/measurements/measurement_kinds.h"
#include "lpoe/model/robot_model.h"

namespace {

using lpoe::ContactMeasurementSet;
using lpoe::MeasurementKindId;

const lpoe::RobotModel& Model() {
  static const lpoe::RobotModel* model = new lpoe::RobotModel(lpoe::MakeCobot6());
  return *model;
}

void CheckAccepted(const ContactMeasurementSet& data) {
  if (data.size() == 0) lpoe::fuzz::Fail("accepted an empty set", "");
  if (data.q.size() != static_cast<size_t>(data.size()) * data.num_joints) {
    lpoe::fuzz::Fail("joint values and rows disagree", "");
  }
  for (double v : data.q) {
    if (!std::isfinite(v)) lpoe::fuzz::Fail("accepted a non-finite joint value", "");
  }
  for (const lpoe::ContactRow& r : data.rows) {
    if (!std::isfinite(r.value) || !(r.sigma > 0) || !std::isfinite(r.sigma)) {
      lpoe::fuzz::Fail("accepted a non-finite value or a noise <= 0", "");
    }
    const size_t features = r.kind == MeasurementKindId::kDistance ? data.pivots.size() : data.planes.size();
    if (r.feature < 0 || static_cast<size_t>(r.feature) >= features) {
      lpoe::fuzz::Fail("row refers to no feature", "");
    }
    if (r.target < 0 || r.target >= Model().num_tools()) lpoe::fuzz::Fail("bad target", "");
    if (r.line < 1) lpoe::fuzz::Fail("row without a line", "");
  }
}

void RoundTrip(const ContactMeasurementSet& data) {
  const MeasurementKindId kind = data.rows[0].kind;
  const std::string csv = lpoe::ContactMeasurementsCsv(Model(), data, kind);
  ContactMeasurementSet again;
  const lpoe::Status s = lpoe::ParseContactMeasurementsCsv(csv, "roundtrip.csv", Model(), {}, &again);
  if (!s.ok()) lpoe::fuzz::Fail("written rows do not read back: " + s.message(), csv);
  if (again.size() != data.size()) lpoe::fuzz::Fail("round trip changed the row count", csv);
  for (int r = 0; r < data.size(); ++r) {
    if (again.rows[r].value != data.rows[r].value || again.rows[r].sigma != data.rows[r].sigma ||
        again.rows[r].target != data.rows[r].target) {
      lpoe::fuzz::Fail("round trip changed a row", csv);
    }
  }
  for (size_t i = 0; i < data.q.size(); ++i) {
    if (again.q[i] != data.q[i]) lpoe::fuzz::Fail("round trip changed a joint value", csv);
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* bytes, size_t size) {
  const std::string text(reinterpret_cast<const char*>(bytes), size);
  for (const lpoe::MeasurementKindInfo* kind :
       {static_cast<const lpoe::MeasurementKindInfo*>(nullptr), lpoe::FindMeasurementKind("distance"),
        lpoe::FindMeasurementKind("plane")}) {
    for (double sigma : {0.0, 0.002}) {
      lpoe::ContactCsvOptions o;
      o.kind = kind;
      o.sigma = sigma;
      ContactMeasurementSet data;
      const lpoe::Status s = lpoe::ParseContactMeasurementsCsv(text, "fuzz.csv", Model(), o, &data);
      if (!s.ok()) {
        lpoe::fuzz::CheckErrorMessage(s, "fuzz.csv");
        if (data.size() != 0) lpoe::fuzz::Fail("data changed on error", s.message());
        continue;
      }
      CheckAccepted(data);
      RoundTrip(data);
    }
  }
  return 0;
}
