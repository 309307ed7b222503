#include "lpoe/io/csv_rules.h"

#include <algorithm>
#include <cmath>

#include "io/parse_util.h"

namespace lpoe {
namespace {

bool EqualNoCase(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  for (size_t k = 0; k < a.size(); ++k) {
    char x = a[k], y = b[k];
    if (x >= 'A' && x <= 'Z') x = static_cast<char>(x - 'A' + 'a');
    if (y >= 'A' && y <= 'Z') y = static_cast<char>(y - 'A' + 'a');
    if (x != y) return false;
  }
  return true;
}

}  // namespace

int CsvHeader::Find(std::string_view name) const {
  for (size_t c = 0; c < names.size(); ++c) {
    if (EqualNoCase(names[c], name)) return static_cast<int>(c);
  }
  return -1;
}

Status ParseCsvHeader(const std::vector<std::string_view>& fields, const std::string& source,
                      int64_t line, CsvHeader* header) {
  CsvHeader out;
  out.line = line;
  for (size_t c = 0; c < fields.size(); ++c) {
    const std::string_view name = internal::Trim(fields[c]);
    const int before = out.Find(name);
    if (before >= 0 && !name.empty()) {
      return internal::LineError(source, line,
                                 "column " + internal::Quote(name) + " appears twice (columns " +
                                     std::to_string(before + 1) + " and " +
                                     std::to_string(c + 1) + ")",
                                 "each column once");
    }
    out.names.emplace_back(name);
  }
  *header = std::move(out);
  return Status::Ok();
}

Status CheckCsvRowFields(size_t fields, const CsvHeader& header, const std::string& source,
                         int64_t line) {
  const size_t expected = header.names.size();
  if (fields == expected) return Status::Ok();
  const std::string as_header =
      std::to_string(expected) + " fields as in the header on line " + std::to_string(header.line);
  if (fields < expected) {
    const std::string& missing = header.names[fields];
    return internal::LineError(source, line,
                               "the row has " + std::to_string(fields) + " field" +
                                   (fields == 1 ? "" : "s") + ", no " +
                                   (missing.empty() ? "column " + std::to_string(fields + 1)
                                                    : internal::Quote(missing, 40)),
                               as_header);
  }
  return internal::LineError(source, line,
                             "the row has " + std::to_string(fields) + " fields, the header " +
                                 std::to_string(expected),
                             as_header + " (numbers take a decimal point, never a comma)");
}

std::string JointUnitHint(const RobotModel& model, const std::vector<double>& max_abs) {
  constexpr double kTwoPi = 2 * 3.14159265358979323846;
  for (int j = 0; j < model.num_joints() && j < static_cast<int>(max_abs.size()); ++j) {
    const Joint& joint = model.joints[j];
    if (joint.type != JointType::kRevolute || !(max_abs[j] > kTwoPi)) continue;
    // A joint whose declared limits reach beyond one turn may be commanded there.
    if (std::isfinite(joint.lower) && std::isfinite(joint.upper) &&
        std::max(-joint.lower, joint.upper) >= max_abs[j]) {
      continue;
    }
    return "revolute joint values up to " + internal::ShortNumber(max_abs[j]) + " (q" +
           std::to_string(j + 1) +
           ") read as radians look like degrees: use --angle_unit=deg if they are";
  }
  return "";
}

std::string DegreesUnitHint(const RobotModel& model, const std::vector<double>& max_abs) {
  // Every revolute joint within one turn *of degrees* (2 pi degrees = 0.11 rad): radians read as
  // degrees. A real campaign moves some joint by more than 6.3 degrees.
  constexpr double kTwoPiDegrees = 2 * 3.14159265358979323846 * 3.14159265358979323846 / 180.0;
  int revolute = 0;
  double largest = 0;
  for (int j = 0; j < model.num_joints() && j < static_cast<int>(max_abs.size()); ++j) {
    if (model.joints[j].type != JointType::kRevolute) continue;
    ++revolute;
    if (!(max_abs[j] <= kTwoPiDegrees)) return "";
    largest = std::max(largest, max_abs[j]);
  }
  if (revolute == 0) return "";
  return "revolute joint values read as degrees reach only " +
         internal::ShortNumber(largest * 180.0 / 3.14159265358979323846) +
         " deg on any joint: they look like radians: use --angle_unit=rad if they are";
}

}  // namespace lpoe
