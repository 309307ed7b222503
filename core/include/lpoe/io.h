// File formats of docs/conventions.md: the robot model as YAML, measurements as CSV. Every reader
// reports bad input as a Status whose message names the file, the line and what was expected; no
// reader throws or aborts on any input.
#ifndef LPOE_IO_H_
#define LPOE_IO_H_

#include <string>
#include <vector>

#include "lpoe/measurements.h"
#include "lpoe/robot_model.h"
#include "lpoe/status.h"

namespace lpoe {

enum class AngleUnit { kRadians, kDegrees };

// Reads a robot model from YAML text; `source` names the file in messages. The model is validated.
Status ParseRobotModelYaml(const std::string& text, const std::string& source, RobotModel* model);
Status ReadRobotModel(const std::string& path, RobotModel* model);

// Writes YAML that reproduces forward kinematics after a round trip (numbers with 17 significant
// digits; orientations as quaternions so that no rpy singularity loses precision).
std::string RobotModelToYaml(const RobotModel& model);
Status WriteRobotModel(const std::string& path, const RobotModel& model);

// Measurements CSV: header with q1..qN, x, y, z, optional target, optional orientation columns
// quat_x, quat_y, quat_z, quat_w (pose data). '#' lines are comments; CRLF and a UTF-8 BOM are
// accepted. Joint angles of revolute joints are converted from degrees when `unit` says so.
Status ParseMeasurementsCsv(const std::string& text, const std::string& source,
                            const RobotModel& model, AngleUnit unit, MeasurementSet* data);

// What a CSV reader dropped without failing: rows whose x, y and z are all exactly 0 or any of them
// NaN/Inf (a laser tracker that lost the beam writes such rows; non-finite joint values remain
// errors). `skipped_lines` holds their 1-based line numbers.
struct CsvReadReport {
  int skipped_zero_rows = 0;
  std::vector<int> skipped_lines;
};
// As above, and fills `report` (may be null). The overload without a report forwards here with
// null. On error `data` and `report` are left unchanged.
Status ParseMeasurementsCsv(const std::string& text, const std::string& source,
                            const RobotModel& model, AngleUnit unit, MeasurementSet* data,
                            CsvReadReport* report);
Status ReadMeasurements(const std::string& path, const RobotModel& model, AngleUnit unit,
                        MeasurementSet* data);
Status ReadMeasurements(const std::string& path, const RobotModel& model, AngleUnit unit,
                        MeasurementSet* data, CsvReadReport* report);

std::string MeasurementsToCsv(const RobotModel& model, const MeasurementSet& data,
                              const std::string& comment = "");
Status WriteMeasurements(const std::string& path, const RobotModel& model,
                         const MeasurementSet& data, const std::string& comment = "");

// Writes `contents` to `path` atomically: a temporary file in the same directory, flushed, then
// renamed over the target. On failure nothing is left behind and an existing file is untouched.
Status WriteFileAtomically(const std::string& path, const std::string& contents);
Status ReadFile(const std::string& path, std::string* contents);

}  // namespace lpoe

#endif  // LPOE_IO_H_
