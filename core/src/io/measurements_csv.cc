// Measurements as CSV (docs/file_formats.md; lpoe/io/io.h), read as a stream: the file is parsed in
// chunks while it is read, so memory holds the kept rows (MeasurementSet) and one chunk, never the
// file's text. Every error is "<file>:<line>: <what is wrong>; expected <what>", line 64-bit.
#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <exception>
#include <iterator>
#include <limits>
#include <string>
#include <string_view>
#include <thread>
#include <unordered_map>
#include <utility>
#include <vector>

#include "io/file_util.h"
#include "lpoe/io/io.h"
#include "lpoe/measurements/measurement_kind_dispatch.h"
#include "lpoe/parallel.h"
#include "lpoe/io/csv_rules.h"
#include "io/parse_util.h"

namespace lpoe {
namespace {

using internal::AppendNumber;
using internal::LineError;
using internal::NumberParse;
using internal::ParseNumber;
using internal::Quote;
using internal::ShortNumber;
using internal::Trim;

// A measured quaternion must be unit to this tolerance (trackers export 4 to 9 decimals); it is
// then normalized.
constexpr double kMeasuredQuaternionTolerance = 1e-3;
// Plausibility bounds on measurement values: positions (mm, after the unit conversion) and raw
// joint values (as written).
constexpr double kMaxAbsPositionMm = 1e6;
constexpr double kMaxAbsJointValue = 1e4;
// A line longer than this is not a measurement row (a row of 20 joints with 25-character numbers
// has about 600 bytes; a header with many extra columns a few kB).
constexpr size_t kMaxLineBytes = size_t{1} << 20;
// Lines of lost-beam rows kept for the report (the count is always complete).
constexpr size_t kMaxReportedSkippedLines = 1000;
// Read chunk of ReadMeasurements.
constexpr size_t kChunkBytes = size_t{4} << 20;
// Lines are parsed in blocks of about this size, on two threads when there are two cores and the
// block has at least kMinParallelBytes.
constexpr size_t kBlockBytes = size_t{4} << 20;
constexpr size_t kMinParallelBytes = size_t{64} << 10;

enum class ColumnKind { kQ, kX, kY, kZ, kTarget, kQuatX, kQuatY, kQuatZ, kQuatW, kIgnored };

// The tracker kinds' measured columns are their headers' (kColumns): the position's x, y, z, and
// the pose's, which are the position's followed by quat_x..quat_w.
constexpr bool SameColumnName(const char* a, const char* b) {
  return *a == *b && (*a == '\0' || SameColumnName(a + 1, b + 1));
}
constexpr int kNumPositionColumns = static_cast<int>(std::size(PositionMeasurement::kColumns));
constexpr int kNumPoseColumns = static_cast<int>(std::size(PoseMeasurement::kColumns));
static_assert(kNumPositionColumns == 3 && kNumPoseColumns == 7,
              "the reader stores x, y, z and a quaternion");
static_assert(SameColumnName(PoseMeasurement::kColumns[0], PositionMeasurement::kColumns[0]) &&
                  SameColumnName(PoseMeasurement::kColumns[1], PositionMeasurement::kColumns[1]) &&
                  SameColumnName(PoseMeasurement::kColumns[2], PositionMeasurement::kColumns[2]),
              "pose rows hold the position's columns first");

// Index of `lower` (a lower-case header name) in PoseMeasurement::kColumns within [begin, end);
// -1 when not there.
int TrackerColumnIndex(const std::string& lower, int begin, int end) {
  for (int k = begin; k < end; ++k) {
    if (lower == PoseMeasurement::kColumns[k]) return k;
  }
  return -1;
}

struct Column {
  ColumnKind kind = ColumnKind::kQ;
  int joint = 0;     // kQ: 0-based joint index
  std::string name;  // as written in the header (trimmed)
};

std::string ExpectedColumns(const RobotModel& model) {
  const int n = model.num_joints();
  std::string s = n == 1 ? std::string("q1") : "q1..q" + std::to_string(n);
  s += " (or the joint names), x, y, z, optional target, optional quat_x, quat_y, quat_z, quat_w";
  return s;
}

std::string ToLower(std::string_view s) {
  std::string out(s);
  for (char& c : out) {
    if (c >= 'A' && c <= 'Z') c = static_cast<char>(c - 'A' + 'a');
  }
  return out;
}

// Splits `line` at commas into `fields` (string_views into `line`).
void SplitFields(std::string_view line, std::vector<std::string_view>* fields) {
  fields->clear();
  size_t start = 0;
  while (true) {
    const void* hit = std::memchr(line.data() + start, ',', line.size() - start);
    if (hit == nullptr) {
      fields->push_back(line.substr(start));
      return;
    }
    const size_t pos = static_cast<const char*>(hit) - line.data();
    fields->push_back(line.substr(start, pos - start));
    start = pos + 1;
  }
}

bool IsBlankOrComment(std::string_view line) {
  for (const char c : line) {
    if (c == ' ' || c == '\t') continue;
    return c == '#';
  }
  return true;
}

// Tool index for a target field: a tool name first, else a 0-based index. -1 when neither.
int ResolveTarget(std::string_view field, const RobotModel& model) {
  for (int t = 0; t < model.num_tools(); ++t) {
    if (field == model.tools[t].name) return t;
  }
  if (field.empty() || field.size() > 9) return -1;
  int index = 0;
  const auto r = std::from_chars(field.data(), field.data() + field.size(), index);
  if (r.ec != std::errc() || r.ptr != field.data() + field.size()) return -1;
  return index >= 0 && index < model.num_tools() ? index : -1;
}

std::string ToolList(const RobotModel& model) {
  std::string s;
  for (int t = 0; t < model.num_tools(); ++t) {
    if (t > 0) s += ", ";
    s += Quote(model.tools[t].name);
  }
  return s;
}

// A target name the reader maps back to the same tool; otherwise the index is written.
bool TargetNameRoundTrips(const RobotModel& model, int tool) {
  const std::string& name = model.tools[tool].name;
  if (name.empty() || Trim(name).size() != name.size()) return false;
  if (name.find_first_of(",\r\n\"") != std::string::npos) return false;
  return ResolveTarget(name, model) == tool;
}

// The header: columns by name (case-insensitive for the standard names, exact for joint names);
// columns with other names are ignored and listed.
class MeasurementHeader {
 public:
  Status Parse(std::string_view line, int64_t line_number, const std::string& source,
               const RobotModel& model) {
    const int num_joints = model.num_joints();
    std::vector<std::string_view> fields;
    SplitFields(line, &fields);
    const std::string expected = "a header with columns " + ExpectedColumns(model);
    std::unordered_map<std::string_view, int> joint_by_name;
    for (int j = 0; j < num_joints; ++j) joint_by_name.emplace(model.joints[j].name, j);
    std::vector<int> q_column(num_joints, -1);
    int xyz_column[3] = {-1, -1, -1};
    int quat_column[4] = {-1, -1, -1, -1};
    const char* const* kQuatNames = PoseMeasurement::kColumns + kNumPositionColumns;
    for (size_t c = 0; c < fields.size(); ++c) {
      const std::string_view raw = Trim(fields[c]);
      Column col;
      col.name = std::string(raw);
      const std::string lower = ToLower(raw);
      if (raw.empty()) {
        return LineError(source, line_number,
                         "header column " + std::to_string(c + 1) + " has an empty name", expected);
      }
      double dummy;
      if (ParseNumber(raw, &dummy) != NumberParse::kNotANumber) {
        return LineError(source, line_number,
                         "the first line is data (" + Quote(raw) + " where a column name belongs)",
                         expected);
      }
      int* slot = nullptr;
      const auto joint = joint_by_name.find(raw);
      if (lower.size() >= 2 && lower[0] == 'q' && lower[1] >= '1' && lower[1] <= '9' &&
          std::all_of(lower.begin() + 1, lower.end(),
                      [](char ch) { return ch >= '0' && ch <= '9'; })) {
        int k = 0;
        const auto r = std::from_chars(lower.data() + 1, lower.data() + lower.size(), k);
        if (r.ec != std::errc() || k > num_joints) {
          return LineError(source, line_number,
                           "extra joint column " + Quote(raw) + ": the model has " +
                               std::to_string(num_joints) + " joints",
                           expected);
        }
        col.kind = ColumnKind::kQ;
        col.joint = k - 1;
        slot = &q_column[k - 1];
      } else if (const int axis = TrackerColumnIndex(lower, 0, kNumPositionColumns); axis >= 0) {
        col.kind = static_cast<ColumnKind>(static_cast<int>(ColumnKind::kX) + axis);
        slot = &xyz_column[axis];
      } else if (lower == "target") {
        col.kind = ColumnKind::kTarget;
        slot = &target_column_;
      } else if (joint != joint_by_name.end()) {
        col.kind = ColumnKind::kQ;
        col.joint = joint->second;
        slot = &q_column[joint->second];
      } else if (const int k = TrackerColumnIndex(lower, kNumPositionColumns, kNumPoseColumns);
                 k >= 0) {
        col.kind = static_cast<ColumnKind>(static_cast<int>(ColumnKind::kQuatX) + k -
                                           kNumPositionColumns);
        slot = &quat_column[k - kNumPositionColumns];
      }
      if (slot == nullptr) {
        col.kind = ColumnKind::kIgnored;
        ignored_.push_back(col.name);
        columns_.push_back(std::move(col));
        continue;
      }
      if (*slot >= 0) {
        const std::string what =
            col.kind == ColumnKind::kQ
                ? "joint " + std::to_string(col.joint + 1) + " given twice: " +
                      Quote(columns_[*slot].name) + " and " + Quote(raw)
                : "duplicated column " + Quote(raw);
        return LineError(source, line_number,
                         what + " (columns " + std::to_string(*slot + 1) + " and " +
                             std::to_string(c + 1) + ")",
                         "each column once");
      }
      *slot = static_cast<int>(c);
      columns_.push_back(std::move(col));
    }
    std::string missing;
    auto add_missing = [&missing](const std::string& name) {
      missing += missing.empty() ? "" : ", ";
      missing += "'" + name + "'";
    };
    for (int k = 0; k < num_joints; ++k) {
      if (q_column[k] < 0) add_missing("q" + std::to_string(k + 1));
    }
    for (int a = 0; a < kNumPositionColumns; ++a) {
      if (xyz_column[a] < 0) add_missing(PositionMeasurement::kColumns[a]);
    }
    if (!missing.empty()) {
      return LineError(source, line_number,
                       "missing column" +
                           std::string(missing.find(',') != std::string::npos ? "s " : " ") +
                           missing,
                       expected);
    }
    const int num_quat =
        static_cast<int>(std::count_if(quat_column, quat_column + 4, [](int c) { return c >= 0; }));
    if (num_quat != 0 && num_quat != 4) {
      for (int k = 0; k < 4; ++k) {
        if (quat_column[k] < 0) add_missing(kQuatNames[k]);
      }
      return LineError(source, line_number, "incomplete orientation: missing " + missing,
                       "all four of quat_x, quat_y, quat_z, quat_w, or none");
    }
    // The file's kind (measurement_kinds.h): pose with the quaternion's columns, else position.
    kind_ = TrackerKindId(num_quat == 4);
    return Status::Ok();
  }

  const std::vector<Column>& columns() const { return columns_; }
  const std::vector<std::string>& ignored() const { return ignored_; }
  bool has_orientation() const { return kind_ == MeasurementKindId::kPose; }

 private:
  std::vector<Column> columns_;
  std::vector<std::string> ignored_;
  MeasurementKindId kind_ = MeasurementKindId::kPosition;
  int target_column_ = -1;
};

// One thread's share of the rows: where they go, and the state of the row being parsed.
struct RowSink {
  explicit RowSink(int num_joints) : rows(num_joints), q(num_joints) {}
  MeasurementSet rows;
  int64_t line_number = 0;  // of the last line read
  int64_t bytes = 0;        // read so far, line ends included
  int64_t skipped = 0;      // rows without a measurement
  std::vector<int64_t> skipped_lines;  // the first kMaxReportedSkippedLines of them
  Status error = Status::Ok();
  // The row being parsed.
  std::vector<double> q;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  Eigen::Vector4d quat = Eigen::Vector4d::Zero();
};

// The CSV reader: fed chunks of text split anywhere, it parses every complete line at once and
// keeps only an incomplete last line (bounded by kMaxLineBytes) between chunks. Once the header is
// read, the complete lines of a chunk are parsed in blocks of about kBlockBytes, each cut at a line
// end near its middle: the first half on the calling thread, the second on another (each into its
// own rows), then appended in order. Rows do not depend on each other, so the rows, their lines
// and the first error are those of a serial read whatever the threads do.
class CsvReader {
 public:
  CsvReader(const std::string& source, const RobotModel& model, const CsvOptions& options)
      : source_(source), model_(model), main_(model.num_joints()), part_(model.num_joints()) {
    const int n = model.num_joints();
    // Revolute joints get the degree factor; prismatic joints are in mm (or m) either way.
    const double length = options.length_unit == LengthUnit::kMetres ? 1000.0 : 1.0;
    scale_.assign(n, 1.0);
    for (int j = 0; j < n; ++j) {
      if (model.joints[j].type == JointType::kRevolute) {
        if (options.angle_unit == AngleUnit::kDegrees) scale_[j] = kDegreesToRadians;
      } else {
        scale_[j] = length;
      }
    }
    length_scale_ = length;
    threads_ = std::thread::hardware_concurrency() >= 2;
  }

  // The total input size when known (a regular file): lets the reader reserve the row storage once
  // instead of growing it by doubling.
  void set_total_bytes(int64_t bytes) { total_bytes_ = bytes; }

  Status Feed(const char* data, size_t size) {
    const char* p = data;
    const char* end = data + size;
    if (!carry_.empty()) {
      const char* nl = static_cast<const char*>(std::memchr(p, '\n', size));
      if (nl == nullptr) return Carry(p, end);
      if (carry_.size() + static_cast<size_t>(nl - p) > kMaxLineBytes) return LineTooLong();
      carry_.append(p, nl);
      Status s = Line(carry_, &main_);
      if (!s.ok()) return s;
      carry_.clear();
      p = nl + 1;
    }
    // Up to the header, one line at a time.
    while (!have_header_ && p < end) {
      const char* nl = static_cast<const char*>(std::memchr(p, '\n', end - p));
      if (nl == nullptr) return Carry(p, end);
      Status s = Line(std::string_view(p, static_cast<size_t>(nl - p)), &main_);
      if (!s.ok()) return s;
      p = nl + 1;
    }
    // The complete lines, in blocks.
    const char* last = end;
    while (last > p && last[-1] != '\n') --last;
    while (p < last) {
      const char* block_end = last;
      if (last - p > static_cast<std::ptrdiff_t>(kBlockBytes)) {
        block_end = static_cast<const char*>(
                        std::memchr(p + kBlockBytes, '\n', last - p - kBlockBytes)) + 1;
      }
      Status s = Block(p, block_end);
      if (!s.ok()) return s;
      MaybeReserve();
      p = block_end;
    }
    return Carry(p, end);
  }

  // Ends the input (a last line without '\n' is read) and hands over the rows.
  Status Finish(MeasurementSet* data, CsvReadReport* report) {
    if (!carry_.empty()) {
      Status s = Line(carry_, &main_);
      if (!s.ok()) return s;
      carry_.clear();
    }
    if (!have_header_) {
      return LineError(source_, std::max<int64_t>(main_.line_number, 1),
                       "no header line (the file is empty)",
                       "a header with columns " + ExpectedColumns(model_) +
                           ", then one row per measurement");
    }
    MeasurementSet& out = main_.rows;
    if (out.empty()) {
      const std::string skipped =
          main_.skipped > 0
              ? " (" + std::to_string(main_.skipped) + " rows without a measurement skipped)"
              : std::string();
      return LineError(source_, header_line_, "no measurement rows after the header" + skipped,
                       "at least one row of measurements");
    }
    // Reserved room beyond what was used is mostly untouched pages; give it back all the same when
    // it is large (one reallocation).
    if (reserved_rows_ > out.size() + out.size() / 8) out.ShrinkToFit();
    if (report != nullptr) {
      report->ignored_columns = header_.ignored();
      report->skipped_zero_rows = main_.skipped;
      report->skipped_lines = std::move(main_.skipped_lines);
    }
    *data = std::move(out);
    return Status::Ok();
  }

 private:
  Status Carry(const char* p, const char* end) {
    if (carry_.size() + static_cast<size_t>(end - p) > kMaxLineBytes) return LineTooLong();
    carry_.append(p, end);
    return Status::Ok();
  }

  Status LineTooLong() const {
    return LineError(source_, main_.line_number + 1,
                     "a line longer than " + std::to_string(kMaxLineBytes) + " bytes",
                     "one measurement per line (a text CSV file with '\\n' line ends)");
  }

  // Complete lines [p, end) after the header, possibly on two threads.
  Status Block(const char* p, const char* end) {
    const size_t size = static_cast<size_t>(end - p);
    const char* mid =
        threads_ && size >= kMinParallelBytes
            ? static_cast<const char*>(std::memchr(p + size / 2, '\n', size - size / 2)) + 1
            : end;
    if (mid == end) return Lines(p, end, &main_);
    part_.rows.Clear();
    part_.skipped = 0;
    part_.skipped_lines.clear();
    part_.bytes = 0;
    part_.line_number = main_.line_number + std::count(p, mid, '\n');
    Status first = Status::Ok();
    ForEachTask(2, 2, [&](int task, int) {
      if (task == 0) {
        first = Lines(p, mid, &main_);
      } else {
        part_.error = Lines(mid, end, &part_);
      }
    });
    if (!first.ok()) return first;
    if (!part_.error.ok()) return part_.error;
    if (main_.rows.size() > kMaxRows - part_.rows.size()) {
      return TooManyRows(part_.rows.source_line(kMaxRows - main_.rows.size()));
    }
    main_.rows.Append(part_.rows);
    main_.line_number = part_.line_number;
    main_.bytes += part_.bytes;
    main_.skipped += part_.skipped;
    for (const int64_t line : part_.skipped_lines) {
      if (main_.skipped_lines.size() >= kMaxReportedSkippedLines) break;
      main_.skipped_lines.push_back(line);
    }
    return Status::Ok();
  }

  // Complete lines [p, end) into `sink` (thread-safe for distinct sinks: the header is read-only).
  Status Lines(const char* p, const char* end, RowSink* sink) const {
    while (p < end) {
      const char* nl = static_cast<const char*>(std::memchr(p, '\n', end - p));
      Status s = DataLine(std::string_view(p, static_cast<size_t>(nl - p)), sink);
      if (!s.ok()) return s;
      p = nl + 1;
    }
    return Status::Ok();
  }

  // A line up to the header or after it (main_ only: one thread).
  Status Line(std::string_view line, RowSink* sink) {
    if (!have_header_) {
      ++sink->line_number;
      sink->bytes += line.size() + 1;
      if (line.size() > kMaxLineBytes) {
        --sink->line_number;
        return LineTooLong();
      }
      if (sink->line_number == 1 && line.substr(0, 3) == "\xEF\xBB\xBF") line.remove_prefix(3);
      if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
      if (IsBlankOrComment(line)) return Status::Ok();
      Status s = header_.Parse(line, sink->line_number, source_, model_);
      if (!s.ok()) return s;
      have_header_ = true;
      header_line_ = sink->line_number;
      return Status::Ok();
    }
    return DataLine(line, sink);
  }

  // A line after the header.
  Status DataLine(std::string_view line, RowSink* sink) const {
    ++sink->line_number;
    sink->bytes += line.size() + 1;
    if (line.size() > kMaxLineBytes) {
      return LineError(source_, sink->line_number,
                       "a line longer than " + std::to_string(kMaxLineBytes) + " bytes",
                       "one measurement per line (a text CSV file with '\\n' line ends)");
    }
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    if (IsBlankOrComment(line)) return Status::Ok();
    return Row(line, sink);
  }

  Status TooManyRows(int64_t line_number) const {
    return LineError(source_, line_number, "more than " + std::to_string(kMaxRows) + " rows",
                     "at most 2^31 - 1 measurement rows per file");
  }

  Status FieldCountError(std::string_view line, int64_t line_number) const {
    // The rule every CSV reader shares (lpoe/io/csv_rules.h): the count, and the first column a short
    // row lacks ("the row has 5 fields, no 'q6'").
    const size_t fields = static_cast<size_t>(std::count(line.begin(), line.end(), ',')) + 1;
    ::lpoe::CsvHeader header;
    header.line = header_line_;
    for (const Column& c : header_.columns()) header.names.push_back(c.name);
    return CheckCsvRowFields(fields, header, source_, line_number);
  }

  // A number field's value into the row being parsed, range-checked: false, with *error set, when
  // it is out of range (the message in a function of its own, off the per-field path).
  bool Store(const Column& col, double v, std::string_view field, int64_t line_number,
             RowSink* sink, Status* error) const {
    switch (col.kind) {
      case ColumnKind::kQ:
        if (std::abs(v) > kMaxAbsJointValue) {
          *error = OutOfRange(col, field, line_number);
          return false;
        }
        sink->q[col.joint] = v * scale_[col.joint];
        break;
      case ColumnKind::kX:
      case ColumnKind::kY:
      case ColumnKind::kZ:
        v *= length_scale_;
        if (std::abs(v) > kMaxAbsPositionMm) {
          *error = OutOfRange(col, field, line_number);
          return false;
        }
        sink->position(static_cast<int>(col.kind) - static_cast<int>(ColumnKind::kX)) = v;
        break;
      case ColumnKind::kQuatX:
      case ColumnKind::kQuatY:
      case ColumnKind::kQuatZ:
      case ColumnKind::kQuatW:
        sink->quat(static_cast<int>(col.kind) - static_cast<int>(ColumnKind::kQuatX)) = v;
        break;
      case ColumnKind::kTarget:
      case ColumnKind::kIgnored:
        break;
    }
    return true;
  }

  __attribute__((noinline, cold)) Status OutOfRange(const Column& col, std::string_view field,
                                                    int64_t line_number) const {
    if (col.kind == ColumnKind::kQ) {
      return LineError(
          source_, line_number,
          "column " + Quote(col.name) + ": value " + Quote(field) + " is out of range",
          "a joint value of magnitude at most " + ShortNumber(kMaxAbsJointValue));
    }
    return LineError(
        source_, line_number,
        "column " + Quote(col.name) + ": value " + Quote(field) + " is out of range",
        "a position of magnitude at most " + ShortNumber(kMaxAbsPositionMm) + " mm" +
            (length_scale_ == 1.0 ? std::string()
                                  : " (" + ShortNumber(kMaxAbsPositionMm / length_scale_) + " m)"));
  }

  Status Row(std::string_view line, RowSink* sink) const {
    const int64_t line_number = sink->line_number;
    const std::vector<Column>& columns = header_.columns();
    const char* p = line.data();
    const char* const end = line.data() + line.size();
    int target = 0;
    bool lost_beam = false;
    Status status = Status::Ok();
    bool more = true;  // a comma ended the last field
    for (size_t c = 0; c < columns.size(); ++c) {
      if (!more) return FieldCountError(line, line_number);
      const Column& col = columns[c];
      double v = 0;
      std::string_view field;
      if (col.kind != ColumnKind::kIgnored && col.kind != ColumnKind::kTarget) {
        // The common spelling of a number, read up to the comma or the line end that must follow
        // it (the same value as below, without the search for the comma and the blanks).
        const char* after = internal::ParsePlainDecimal(p, end, &v);
        if (after != nullptr && (after == end || *after == ',')) {
          field = std::string_view(p, static_cast<size_t>(after - p));
          more = after != end;
          if (more) p = after + 1;
          if (Store(col, v, field, line_number, sink, &status)) continue;
          return status;
        }
      }
      const char* comma = static_cast<const char*>(std::memchr(p, ',', end - p));
      const char* field_end = comma == nullptr ? end : comma;
      field = Trim(std::string_view(p, static_cast<size_t>(field_end - p)));
      more = comma != nullptr;
      if (more) p = comma + 1;
      if (col.kind == ColumnKind::kIgnored) continue;
      if (col.kind == ColumnKind::kTarget) {
        target = ResolveTarget(field, model_);
        if (target < 0) {
          return LineError(source_, line_number, "column 'target': unknown tool " + Quote(field),
                           "a tool name (" + ToolList(model_) + ") or an index from 0 to " +
                               std::to_string(model_.num_tools() - 1));
        }
        continue;
      }
      const NumberParse r = ParseNumber(field, &v);
      const bool is_position = col.kind == ColumnKind::kX || col.kind == ColumnKind::kY ||
                               col.kind == ColumnKind::kZ;
      if (r == NumberParse::kNonFinite && is_position) {
        // A tracker that lost the beam may export NaN/Inf: the row is skipped like a row of zeros.
        lost_beam = true;
        continue;
      }
      if (r != NumberParse::kOk) {
        const std::string what =
            field.empty() ? "column " + Quote(col.name) + " is empty"
            : r == NumberParse::kNotANumber
                ? "column " + Quote(col.name) + ": " + Quote(field) + " is not a number"
                : "column " + Quote(col.name) + ": non-finite value " + Quote(field);
        return LineError(source_, line_number, what, "a finite decimal number");
      }
      if (!Store(col, v, field, line_number, sink, &status)) return status;
    }
    if (more) return FieldCountError(line, line_number);  // fields left over
    const Eigen::Vector3d& position = sink->position;
    if (lost_beam || (position(0) == 0.0 && position(1) == 0.0 && position(2) == 0.0)) {
      // Lost beam (zeros or non-finite x, y, z): skipped and reported, not an error.
      ++sink->skipped;
      if (sink->skipped_lines.size() < kMaxReportedSkippedLines) {
        sink->skipped_lines.push_back(line_number);
      }
      return Status::Ok();
    }
    // (The rows of both threads together are checked when they are appended.)
    if (sink->rows.size() == kMaxRows) return TooManyRows(line_number);
    if (header_.has_orientation()) {
      const double norm = sink->quat.norm();
      if (!(std::abs(norm - 1.0) <= kMeasuredQuaternionTolerance)) {
        return LineError(source_, line_number, "quat_x..quat_w have norm " + ShortNumber(norm),
                         "a unit quaternion (norm within " +
                             ShortNumber(kMeasuredQuaternionTolerance) + " of 1)");
      }
      sink->rows.AddPose(sink->q.data(),
                         SE3d(QuaternionToRotation<double>(sink->quat / norm), position), target,
                         line_number);
    } else {
      sink->rows.Add(sink->q.data(), position, target, line_number);
    }
    return Status::Ok();
  }

  // Once 4096 rows are read, reserves the rows the whole file will hold at the bytes per line seen
  // so far (plus 1/16): the columns are then filled without reallocation.
  void MaybeReserve() {
    constexpr int kSampleRows = 4096;
    const int rows = main_.rows.size();
    if (reserved_rows_ > 0 || total_bytes_ <= 0 || rows < kSampleRows) return;
    const double bytes_per_row = static_cast<double>(main_.bytes) / rows;
    const double estimate =
        static_cast<double>(total_bytes_) / bytes_per_row * (1.0 + 1.0 / 16) + 1024;
    reserved_rows_ = static_cast<int>(std::min<double>(estimate, kMaxRows));
    main_.rows.Reserve(reserved_rows_);
  }

  static constexpr int kMaxRows = std::numeric_limits<int>::max();

  const std::string& source_;
  const RobotModel& model_;
  MeasurementHeader header_;
  bool have_header_ = false;
  bool threads_ = false;
  int64_t header_line_ = 0;
  int64_t total_bytes_ = -1;
  int reserved_rows_ = 0;
  std::string carry_;
  std::vector<double> scale_;
  double length_scale_ = 1.0;
  RowSink main_;  // every row read so far, in order
  RowSink part_;  // the second half of a block (second thread)
};

Status ReadMeasurementsImpl(const std::string& path, const RobotModel& model,
                            const CsvOptions& options, MeasurementSet* data,
                            CsvReadReport* report) {
  internal::InputFile file;
  Status s = file.Open(path);
  if (!s.ok()) return s;
  CsvReader reader(path, model, options);
  reader.set_total_bytes(file.size());
  std::vector<char> buf(kChunkBytes);
  while (true) {
    size_t got = 0;
    s = file.Read(buf.data(), buf.size(), &got);
    if (!s.ok()) return s;
    if (got == 0) break;
    s = reader.Feed(buf.data(), got);
    if (!s.ok()) return s;
  }
  return reader.Finish(data, report);
}

}  // namespace

bool ParseLengthUnit(const std::string& text, LengthUnit* unit) {
  if (text == "mm") {
    *unit = LengthUnit::kMillimetres;
    return true;
  }
  if (text == "m") {
    *unit = LengthUnit::kMetres;
    return true;
  }
  return false;
}

Status ParseMeasurementsCsv(const std::string& text, const std::string& source,
                            const RobotModel& model, const CsvOptions& options,
                            MeasurementSet* data, CsvReadReport* report) {
  try {
    CsvReader reader(source, model, options);
    reader.set_total_bytes(static_cast<int64_t>(text.size()));
    Status s = reader.Feed(text.data(), text.size());
    if (!s.ok()) return s;
    return reader.Finish(data, report);
  } catch (const std::exception& e) {  // std::bad_alloc on absurdly large input
    return LineError(source, 1, std::string("cannot read the measurements: ") + e.what(),
                     "a measurements CSV that fits in memory");
  }
}

Status ParseMeasurementsCsv(const std::string& text, const std::string& source,
                            const RobotModel& model, AngleUnit unit, MeasurementSet* data,
                            CsvReadReport* report) {
  CsvOptions options;
  options.angle_unit = unit;
  return ParseMeasurementsCsv(text, source, model, options, data, report);
}

Status ParseMeasurementsCsv(const std::string& text, const std::string& source,
                            const RobotModel& model, AngleUnit unit, MeasurementSet* data) {
  return ParseMeasurementsCsv(text, source, model, unit, data, nullptr);
}

Status ReadMeasurements(const std::string& path, const RobotModel& model,
                        const CsvOptions& options, MeasurementSet* data, CsvReadReport* report) {
  try {
    return ReadMeasurementsImpl(path, model, options, data, report);
  } catch (const std::exception& e) {  // std::bad_alloc on absurdly large input
    return LineError(path, 1, std::string("cannot read the measurements: ") + e.what(),
                     "a measurements CSV that fits in memory");
  }
}

Status ReadMeasurements(const std::string& path, const RobotModel& model, AngleUnit unit,
                        MeasurementSet* data, CsvReadReport* report) {
  CsvOptions options;
  options.angle_unit = unit;
  return ReadMeasurements(path, model, options, data, report);
}

Status ReadMeasurements(const std::string& path, const RobotModel& model, AngleUnit unit,
                        MeasurementSet* data) {
  return ReadMeasurements(path, model, unit, data, nullptr);
}

std::string CsvReadWarnings(const std::string& source, const CsvReadReport& report) {
  std::string out;
  if (!report.ignored_columns.empty()) {
    out += "warning: " + source + ": ignored " + std::to_string(report.ignored_columns.size()) +
           " column(s) the model does not use:";
    for (const std::string& name : report.ignored_columns) out += " " + Quote(name);
    out += "\n";
  }
  if (report.skipped_zero_rows > 0) {
    out += "warning: " + source + ": skipped " + std::to_string(report.skipped_zero_rows) +
           " row(s) with no measurement (lost beam) at line(s)";
    constexpr size_t kShown = 20;
    const auto& lines = report.skipped_lines;
    for (size_t k = 0; k < std::min(lines.size(), kShown); ++k) out += " " + std::to_string(lines[k]);
    if (static_cast<int64_t>(std::min(lines.size(), kShown)) < report.skipped_zero_rows) {
      out += " ...";
    }
    out += "\n";
  }
  return out;
}

double ModelReach(const RobotModel& model) {
  double reach = 0;
  for (const Joint& joint : model.joints) {
    reach += joint.origin.t.norm();
    // A prismatic joint adds its travel when limited (else its position is not bounded).
    if (joint.type == JointType::kPrismatic && joint.has_limits() && std::isfinite(joint.lower) &&
        std::isfinite(joint.upper)) {
      reach += std::max(std::abs(joint.lower), std::abs(joint.upper));
    }
  }
  double tool = 0;
  for (const Tool& t : model.tools) tool = std::max(tool, t.origin.t.norm());
  return reach + tool;
}

std::string LengthUnitHint(const RobotModel& model, const MeasurementSet& data) {
  if (data.size() < 2) return "";
  // The spread of the points: the largest distance from their centroid. A robot's points lie in a
  // ball of radius `reach` around its base, wherever the measurement frame is, so they spread over
  // at most 2 * reach, and a calibration set normally spans a good part of that.
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (int r = 0; r < data.size(); ++r) centroid += data.position(r);
  centroid /= data.size();
  double spread = 0;
  for (int r = 0; r < data.size(); ++r) {
    spread = std::max(spread, (data.position(r) - centroid).norm());
  }
  const double reach = ModelReach(model);
  if (!(reach > 0) || !std::isfinite(spread)) return "";
  const std::string figures = "the measured points spread " + ShortNumber(spread) +
                              " mm from their centroid, the model reaches " + ShortNumber(reach) +
                              " mm";
  // Metres read as millimetres shrink the spread 1000 times: below 1/50 of the reach is no
  // calibration set of a robot (it would be a set of poses within a few mm of each other).
  if (spread < reach / 50) return figures + ": positions look like metres: use --length_unit=m";
  // Millimetres read as metres (or micrometres as mm) grow it 1000 times.
  if (spread > reach * 20) {
    return figures + ": positions look too large for the model: check --length_unit and the "
                     "model's units (mm)";
  }
  return "";
}

std::string MeasurementsToCsv(const RobotModel& model, const MeasurementSet& data,
                              const std::string& comment) {
  std::string out;
  if (!comment.empty()) {
    size_t start = 0;
    while (start <= comment.size()) {
      size_t end = comment.find('\n', start);
      if (end == std::string::npos) end = comment.size();
      std::string_view line(comment.data() + start, end - start);
      if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
      out += "# ";
      out += line;
      out += '\n';
      start = end + 1;
    }
  }
  const int n = data.num_joints();
  for (int j = 0; j < n; ++j) {
    out += 'q';
    out += std::to_string(j + 1);
    out += ',';
  }
  // The kind's columns (its header's kColumns): the position's, the target, then the pose's others.
  const bool pose = data.has_orientation();
  const int num_columns = pose ? kNumPoseColumns : kNumPositionColumns;
  for (int k = 0; k < kNumPositionColumns; ++k) {
    out += PoseMeasurement::kColumns[k];
    out += ',';
  }
  out += "target";
  for (int k = kNumPositionColumns; k < num_columns; ++k) {
    out += ',';
    out += PoseMeasurement::kColumns[k];
  }
  out += '\n';

  std::vector<std::string> target_text(std::max(model.num_tools(), 0));
  for (int t = 0; t < model.num_tools(); ++t) {
    target_text[t] = TargetNameRoundTrips(model, t) ? model.tools[t].name : std::to_string(t);
  }
  out.reserve(out.size() + static_cast<size_t>(data.size()) * (n + 3 + (pose ? 4 : 0)) * 20);
  for (int row = 0; row < data.size(); ++row) {
    const double* q = data.q(row);
    for (int j = 0; j < n; ++j) {
      AppendNumber(q[j], &out);
      out += ',';
    }
    const Eigen::Vector3d& p = data.position(row);
    for (int a = 0; a < 3; ++a) {
      AppendNumber(p(a), &out);
      out += ',';
    }
    const int t = data.target(row);
    out += t >= 0 && t < model.num_tools() ? target_text[t] : std::to_string(t);
    if (pose) {
      const Eigen::Vector4d quat = RotationToQuaternion<double>(data.orientation(row));
      for (int k = 0; k < 4; ++k) {
        out += ',';
        AppendNumber(quat(k), &out);
      }
    }
    out += '\n';
  }
  return out;
}

Status WriteMeasurements(const std::string& path, const RobotModel& model,
                         const MeasurementSet& data, const std::string& comment) {
  return WriteFileAtomically(path, MeasurementsToCsv(model, data, comment));
}

}  // namespace lpoe
