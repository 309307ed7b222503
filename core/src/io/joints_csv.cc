// Joint-value CSV for prediction (lpoe_predict) and the positions it writes.
#include <charconv>
#include <cmath>
#include <string>
#include <string_view>
#include <vector>

#include "lpoe/io/csv_rules.h"
#include "lpoe/terms/joint_errors.h"
#include "io/parse_util.h"

namespace lpoe {
namespace {

constexpr double kRadiansPerDegree = 3.14159265358979323846 / 180.0;

using internal::Trim;

bool ParseFinite(std::string_view s, double* v) {
  return internal::ParseNumber(s, v) == internal::NumberParse::kOk;
}


}  // namespace

Status ParseJointsCsv(const std::string& text, const std::string& source, const RobotModel& model,
                      bool degrees, std::vector<double>* q, std::vector<int>* targets) {
  using internal::LineError;
  using internal::Quote;
  const int n = model.num_joints();
  std::string_view rest(text);
  if (rest.substr(0, 3) == "\xEF\xBB\xBF") rest.remove_prefix(3);
  std::vector<int> column;  // joint column of q1..qN
  int target_column = -1;
  CsvHeader header;
  std::vector<double> values;
  std::vector<int> row_targets;
  const std::string expected_header = "a header naming q1..q" + std::to_string(n);
  int line_number = 0;
  while (!rest.empty()) {
    const size_t end = rest.find('\n');
    std::string_view line = rest.substr(0, end);
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    line = Trim(line);
    rest = end == std::string_view::npos ? std::string_view() : rest.substr(end + 1);
    ++line_number;
    if (line.empty() || line[0] == '#') continue;
    const std::vector<std::string_view> fields = internal::SplitFields(line);
    if (column.empty()) {  // the header, by the shared rules (lpoe/io/csv_rules.h)
      if (Status s = ParseCsvHeader(fields, source, line_number, &header); !s.ok()) return s;
      column.assign(n, -1);
      target_column = header.Find("target");
      for (int j = 0; j < n; ++j) {
        column[j] = header.Find("q" + std::to_string(j + 1));
        if (column[j] < 0) {
          return LineError(source, line_number, "no column q" + std::to_string(j + 1),
                           expected_header + " (the model has " + std::to_string(n) + " joints)");
        }
      }
      continue;
    }
    if (Status s = CheckCsvRowFields(fields.size(), header, source, line_number); !s.ok()) return s;
    for (int j = 0; j < n; ++j) {
      double v = 0;
      const std::string_view field = fields[column[j]];
      if (!ParseFinite(field, &v) || std::abs(v) > kMaxAbsCsvJointValue) {
        return LineError(source, line_number,
                         "q" + std::to_string(j + 1) + " " + Quote(field) + " is not a joint value",
                         "a finite number of magnitude at most 1e4: joint values in rad (deg with "
                         "--angle_unit=deg) or mm");
      }
      if (degrees && model.joints[j].type == JointType::kRevolute) v *= kRadiansPerDegree;
      values.push_back(v);
    }
    if (target_column >= 0) {
      const std::string_view field =
          target_column < static_cast<int>(fields.size()) ? fields[target_column] : "";
      int t = model.FindTool(std::string(field));
      int index = -1;
      if (t < 0 && !field.empty() &&
          std::from_chars(field.data(), field.data() + field.size(), index).ptr ==
              field.data() + field.size() &&
          index >= 0 && index < model.num_tools()) {
        t = index;
      }
      if (t < 0) {
        return LineError(source, line_number, "target " + Quote(field) + " is not a tool",
                         "a tool name of the model or an index from 0 to " +
                             std::to_string(model.num_tools() - 1));
      }
      row_targets.push_back(t);
    }
  }
  if (column.empty()) return LineError(source, line_number, "no header", expected_header);
  *q = std::move(values);
  *targets = std::move(row_targets);
  return Status::Ok();
}

std::string PositionsToCsv(const std::vector<Eigen::Vector3d>& positions) {
  std::string out = "x,y,z\n";
  for (const Eigen::Vector3d& p : positions) {
    for (int k = 0; k < 3; ++k) {
      internal::AppendNumber(p(k), &out);
      out += k < 2 ? ',' : '\n';
    }
  }
  return out;
}

}  // namespace lpoe
