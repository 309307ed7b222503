// libFuzzer target: names and paths of arbitrary bytes fed to what every report writer uses for
// them: tools::JsonText (all JSON reports: lpoe_calibrate --report, lpoe_plan's report,
// lpoe_compensate --report, the Python report_json), tools::ValidUtf8 (the HTML report),
// tools::PlotLabel (every PLplot label) and tools::CommentText (CSV comment lines). Checks that
// nothing throws or crashes, that the JSON text parses back with every string equal to
// ValidUtf8(input), that every result is valid UTF-8, that a plot label stays within its bound,
// and that a comment stays one line.
#include <cstddef>
#include <cstdint>
#include <string>

#include <nlohmann/json.hpp>

#include "fuzz_common.h"
#include "report/json_text.h"
#include "report/text_safety.h"

namespace {

using lpoe::fuzz::Fail;
using namespace lpoe::tools;

void CheckValid(const std::string& s, const char* what, const std::string& input) {
  if (ValidUtf8(s) != s) Fail(std::string(what) + " is not valid UTF-8", input);
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* bytes, size_t size) {
  const std::string input(reinterpret_cast<const char*>(bytes), size);
  // The input split at its first NUL into a "name" and a "path" (both may hold any other bytes).
  const size_t nul = input.find('\0');
  const std::string name = input.substr(0, nul);
  const std::string path = nul == std::string::npos ? std::string() : input.substr(nul + 1);

  const std::string valid = ValidUtf8(input);
  CheckValid(valid, "ValidUtf8", input);
  if (ValidUtf8(valid) != valid) Fail("ValidUtf8 is not idempotent", input);

  // The reports' shapes: ordered (lpoe_calibrate, HTML) and plain (lpoe_plan, lpoe_compensate).
  nlohmann::ordered_json ordered;
  ordered["model"] = name;
  ordered["input"] = path;
  ordered["joints"] = {name, path};
  nlohmann::json plain = {{"model", name}, {"input", path}, {"outputs", {path, name}}};
  std::string text, text_plain;
  try {
    text = JsonText(ordered);
    text_plain = JsonText(plain);
  } catch (const std::exception& e) {
    Fail(std::string("JsonText threw: ") + e.what(), input);
  }
  CheckValid(text, "JsonText", input);
  try {
    const nlohmann::ordered_json back = nlohmann::ordered_json::parse(text);
    if (back["model"].get<std::string>() != ValidUtf8(name) ||
        back["input"].get<std::string>() != ValidUtf8(path) ||
        back["joints"][1].get<std::string>() != ValidUtf8(path)) {
      Fail("JsonText's strings differ from ValidUtf8 of the input", input);
    }
    (void)nlohmann::json::parse(text_plain);
  } catch (const std::exception& e) {
    Fail(std::string("JsonText's output does not parse back: ") + e.what(), input);
  }

  const std::string label = PlotLabel(input);
  CheckValid(label, "PlotLabel", input);
  // '#' doubled at most: twice the bound, plus "...".
  if (label.size() > 2 * kMaxPlotLabelBytes + 3) Fail("PlotLabel longer than its bound", input);
  for (size_t k = 0; k < label.size(); ++k) {
    if (label[k] == '#') {
      if (k + 1 >= label.size() || label[k + 1] != '#') Fail("PlotLabel left a lone '#'", input);
      ++k;
    }
  }
  const std::string cut = TruncateUtf8(input, 64);
  if (cut.size() > 64 + 3) Fail("TruncateUtf8 longer than its bound", input);
  const std::string comment = CommentText(input);
  CheckValid(comment, "CommentText", input);
  for (char c : comment) {
    if (c == '\n' || c == '\r') Fail("CommentText left a line break", input);
  }
  return 0;
}
