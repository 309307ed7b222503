// File formats (docs/file_formats.md): the robot model as YAML, measurements as CSV, and the file
// utilities they share. Every reader reports bad input as a Status whose message names the file,
// the line and what was expected; no reader throws or aborts on any input, and every reader works
// in memory bounded by the useful data (measurements are streamed; model files are size-bounded).
#ifndef LPOE_IO_H_
#define LPOE_IO_H_

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "lpoe/measurements/measurements.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/status.h"

namespace lpoe {

enum class AngleUnit { kRadians, kDegrees };
enum class LengthUnit { kMillimetres, kMetres };

// "mm" | "m" (the --length_unit flag); false for anything else.
bool ParseLengthUnit(const std::string& text, LengthUnit* unit);

// ---------------------------------------------------------------------------------------------------
// Robot model (YAML).

// Model files (YAML, URDF) larger than this are refused: a robot description is kilobytes, and the
// bound keeps /dev/zero or a wrong path from exhausting memory.
constexpr size_t kMaxModelFileBytes = size_t{64} << 20;

// Reads a robot model from YAML text; `source` names the file in messages. The model is validated.
// Joints may give `limits: [lower, upper]` (rad or mm; -.inf/.inf for an open side). A file holding
// more than one YAML document is refused.
Status ParseRobotModelYaml(const std::string& text, const std::string& source, RobotModel* model);
Status ReadRobotModel(const std::string& path, RobotModel* model);

// True when `path` ends in ".urdf" in any letter case.
bool IsUrdfPath(const std::string& path);
// Reads a model file by its name: URDF when IsUrdfPath(path) (default UrdfOptions), else YAML.
Status ReadRobotModelFile(const std::string& path, RobotModel* model);

// Writes YAML that reproduces forward kinematics after a round trip (numbers in their shortest
// exact form; orientations as quaternions so that no rpy singularity loses precision; limits
// when the joint has any).
std::string RobotModelToYaml(const RobotModel& model);
Status WriteRobotModel(const std::string& path, const RobotModel& model);

// ---------------------------------------------------------------------------------------------------
// Measurements (CSV).

// How to read a measurements CSV. Angles of revolute joints are converted from degrees, lengths
// (x, y, z and prismatic joint values) from metres when the options say so.
struct CsvOptions {
  AngleUnit angle_unit = AngleUnit::kRadians;
  LengthUnit length_unit = LengthUnit::kMillimetres;
};

// What a CSV reader dropped without failing: rows whose x, y and z are all exactly 0 or any of them
// NaN/Inf (a laser tracker that lost the beam writes such rows; non-finite joint values remain
// errors), and columns the model does not use (a timestamp, a temperature, a tracker status).
struct CsvReadReport {
  int64_t skipped_zero_rows = 0;
  // 1-based lines of the first kMaxSkippedLines skipped rows (skipped_zero_rows counts them all).
  std::vector<int64_t> skipped_lines;
  static constexpr size_t kMaxSkippedLines = 1000;
  std::vector<std::string> ignored_columns;  // header names, in file order
};

// Measurements CSV: a header naming the columns, in any order: q1..qN or the model's joint names,
// x, y, z, optional target (tool name or index from 0), optional orientation columns quat_x,
// quat_y, quat_z, quat_w (pose data; unit quaternions to 1e-3). Other columns are ignored and
// listed in the report. '#' lines are comments; CRLF and a UTF-8 BOM are accepted. Lines are at
// most 1 MiB. On error `data` and `report` are left unchanged; `report` may be null.
Status ParseMeasurementsCsv(const std::string& text, const std::string& source,
                            const RobotModel& model, const CsvOptions& options,
                            MeasurementSet* data, CsvReadReport* report);
// Reads the file as a stream (parsed in chunks while it is read; the text is never held whole).
// Regular files, pipes and character devices are accepted, directories refused.
Status ReadMeasurements(const std::string& path, const RobotModel& model,
                        const CsvOptions& options, MeasurementSet* data, CsvReadReport* report);

// The same with lengths in mm.
Status ParseMeasurementsCsv(const std::string& text, const std::string& source,
                            const RobotModel& model, AngleUnit unit, MeasurementSet* data);
Status ParseMeasurementsCsv(const std::string& text, const std::string& source,
                            const RobotModel& model, AngleUnit unit, MeasurementSet* data,
                            CsvReadReport* report);
Status ReadMeasurements(const std::string& path, const RobotModel& model, AngleUnit unit,
                        MeasurementSet* data);
Status ReadMeasurements(const std::string& path, const RobotModel& model, AngleUnit unit,
                        MeasurementSet* data, CsvReadReport* report);

// The warnings a tool prints after reading `source` (ignored columns, lost-beam rows with their
// first lines), one "warning: ..." line each, or "" when there is nothing to say.
std::string CsvReadWarnings(const std::string& source, const CsvReadReport& report);

// An upper bound of the distance from the model's base to any tool (mm): the sum of the joint
// origins' translations (plus the travel of limited prismatic joints) and the longest tool offset.
double ModelReach(const RobotModel& model);
// A unit hint from the data's extent against the model's reach, or "" when they fit: points
// spread over less than 1/50 of the reach look like metres ("... use --length_unit=m"); more than
// 20 times the reach, like a unit too small.
std::string LengthUnitHint(const RobotModel& model, const MeasurementSet& data);

std::string MeasurementsToCsv(const RobotModel& model, const MeasurementSet& data,
                              const std::string& comment = "");
Status WriteMeasurements(const std::string& path, const RobotModel& model,
                         const MeasurementSet& data, const std::string& comment = "");

// ---------------------------------------------------------------------------------------------------
// Files.

// Writes `contents` to `path` atomically: a temporary file in the same directory, flushed, then
// renamed over the target. On failure nothing is left behind and an existing file is untouched.
Status WriteFileAtomically(const std::string& path, const std::string& contents);

// A file written atomically piece by piece (outputs too large to build in memory): Open() creates a
// temporary file in the same directory, Append() writes to it, Commit() flushes it and renames it over
// `path`. Without a successful Commit() (an error, or destruction first) the temporary file is
// removed and an existing file at `path` is untouched.
class AtomicFileWriter {
 public:
  AtomicFileWriter() = default;
  ~AtomicFileWriter();
  AtomicFileWriter(const AtomicFileWriter&) = delete;
  AtomicFileWriter& operator=(const AtomicFileWriter&) = delete;

  Status Open(const std::string& path);
  Status Append(const char* data, size_t size);
  Status Append(const std::string& data) { return Append(data.data(), data.size()); }
  Status Commit();

 private:
  Status Fail(const char* what, int err);
  int fd_ = -1;
  std::string path_, tmp_;
};

// A text file read line by line in blocks (inputs too large to hold in memory). Accepts what
// ReadFile accepts (regular files, pipes, character devices).
class LineReader {
 public:
  LineReader();
  ~LineReader();
  LineReader(const LineReader&) = delete;
  LineReader& operator=(const LineReader&) = delete;

  Status Open(const std::string& path);
  // The next line without its '\n', in `*line` (valid until the next call). False at the end of
  // the file or on a read error (then `status()` says what went wrong).
  bool Next(std::string* line);
  const Status& status() const { return status_; }

 private:
  struct File;
  File* file_;
  std::string buffer_;
  size_t pos_ = 0;
  bool eof_ = false;
  Status status_;
};

// Reads a whole file, refusing more than `max_bytes` (a device such as /dev/zero, or a FIFO, is
// read until the bound) and directories. The overload without a bound uses kMaxReadFileBytes.
constexpr size_t kMaxReadFileBytes = size_t{1} << 30;
Status ReadFile(const std::string& path, size_t max_bytes, std::string* contents);
Status ReadFile(const std::string& path, std::string* contents);

}  // namespace lpoe

#endif  // LPOE_IO_H_
