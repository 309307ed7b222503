// The rules every CSV reader of the library and the tools applies to its header and rows, written
// once: the measurement reader (measurements_csv.cc) and the joint readers
// (ParseJointTable for lpoe_plan and lpoe_simulate, ParseJointsCsv for lpoe_predict, the streamed
// targets / program reader of lpoe_compensate) all refuse
//   - a column named twice (names compared case-insensitively: "q1,Q1" is one column twice), and
//   - a data row with more or fewer fields than the header (a decimal comma "0,1,0,2" reads as
//     more fields; a short row names the first column it lacks: "the row has 5 fields, no q6"),
// with the message "<file>:<line>: <what>; expected <what>". Joint values are at most 1e4 in
// magnitude, positions at most 1e6 mm; JointUnitHint warns when radians look like degrees.
#ifndef LPOE_CSV_RULES_H_
#define LPOE_CSV_RULES_H_

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "lpoe/model/robot_model.h"
#include "lpoe/status.h"

namespace lpoe {

// Largest magnitude of a joint value (rad or mm) and of a position (mm) any reader accepts.
inline constexpr double kMaxAbsCsvJointValue = 1e4;
inline constexpr double kMaxAbsCsvPositionMm = 1e6;

// A CSV header: its column names as written (trimmed).
struct CsvHeader {
  std::vector<std::string> names;
  int64_t line = 0;  // where it is in its file (1-based)
  // The column named `name` (case-insensitive), or -1.
  int Find(std::string_view name) const;
};

// Reads the header from its (trimmed) fields; refuses a name given twice.
Status ParseCsvHeader(const std::vector<std::string_view>& fields, const std::string& source,
                      int64_t line, CsvHeader* header);

// A data row of `fields` fields against `header`: Ok when the counts match; otherwise
// "the row has 5 fields, no q6" (the first column missing) or "the row has 8 fields, the header 6"
// (with a hint at decimal commas), naming the file and line.
Status CheckCsvRowFields(size_t fields, const CsvHeader& header, const std::string& source,
                         int64_t line);

// A warning (empty when none) when joint values read as radians look like degrees: some revolute
// joint's largest magnitude `max_abs[j]` (rad) is above 2 pi, where no revolute joint of a serial
// arm is normally commanded and where degrees of ordinary poses land (unless the joint's declared
// limits reach that far).
std::string JointUnitHint(const RobotModel& model, const std::vector<double>& max_abs);
// The reverse: values read as degrees (max_abs in radians after the conversion) that stay within
// 2 pi degrees on every revolute joint look like radians; "" otherwise.
std::string DegreesUnitHint(const RobotModel& model, const std::vector<double>& max_abs);

}  // namespace lpoe

#endif  // LPOE_CSV_RULES_H_
