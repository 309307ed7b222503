#include "lpoe/io/joint_table.h"

#include <cctype>
#include <cmath>
#include <string_view>

#include "lpoe/io/csv_rules.h"
#include "io/parse_util.h"

namespace lpoe {
namespace {

using internal::SplitFields;
using internal::Trim;

Status Error(const std::string& source, int line, const std::string& what) {
  return Status::Error(source + ":" + std::to_string(line) + ": " + what);
}

}  // namespace

Status ParseJointTable(const std::string& text, const std::string& source, const RobotModel& model,
                       AngleUnit unit, JointTable* table) {
  const int n = model.num_joints();
  JointTable out;
  std::vector<int> q_column(n, -1);
  CsvHeader csv_header;
  std::string_view rest(text);
  if (rest.substr(0, 3) == "\xEF\xBB\xBF") rest.remove_prefix(3);
  int line_number = 0;
  bool have_header = false;
  while (!rest.empty()) {
    const size_t nl = rest.find('\n');
    std::string_view line = rest.substr(0, nl);
    rest.remove_prefix(nl == std::string_view::npos ? rest.size() : nl + 1);
    ++line_number;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    const std::string_view trimmed = Trim(line);
    if (trimmed.empty() || trimmed.front() == '#') continue;
    const std::vector<std::string_view> fields = SplitFields(line);
    if (!have_header) {
      have_header = true;
      out.header = std::string(line);
      CsvHeader header;  // the shared rules (lpoe/io/csv_rules.h): no column twice
      if (Status s = ParseCsvHeader(fields, source, line_number, &header); !s.ok()) return s;
      out.names = header.names;
      csv_header = std::move(header);
      for (int j = 0; j < n; ++j) {
        q_column[j] = csv_header.Find("q" + std::to_string(j + 1));
        if (q_column[j] < 0) {
          return Error(source, line_number,
                       "missing column 'q" + std::to_string(j + 1) + "'; expected a header with q1..q" +
                           std::to_string(n) + " (other columns are kept but not used)");
        }
      }
      continue;
    }
    if (Status s = CheckCsvRowFields(fields.size(), csv_header, source, line_number); !s.ok()) {
      return s;
    }
    for (int j = 0; j < n; ++j) {
      const std::string_view f = fields[q_column[j]];
      double v = 0;
      if (internal::ParseNumber(f, &v) != internal::NumberParse::kOk || std::abs(v) > kMaxAbsCsvJointValue) {
        return Error(source, line_number,
                     "column 'q" + std::to_string(j + 1) + "': '" + std::string(f.substr(0, 40)) +
                         "' is not a joint value; expected a finite number of magnitude at most 1e4");
      }
      if (unit == AngleUnit::kDegrees && model.joints[j].type == JointType::kRevolute) {
        v *= kDegreesToRadians;
      }
      out.q.push_back(v);
    }
    out.lines.emplace_back(line);
  }
  if (!have_header) return Error(source, 1, "no header line; expected q1..q" + std::to_string(n));
  if (out.lines.empty()) return Error(source, line_number, "no configuration rows after the header");
  *table = std::move(out);
  return Status::Ok();
}

Status ReadJointTable(const std::string& path, const RobotModel& model, AngleUnit unit,
                      JointTable* table) {
  std::string text;
  if (Status s = ReadFile(path, &text); !s.ok()) return s;
  return ParseJointTable(text, path, model, unit, table);
}

}  // namespace lpoe
