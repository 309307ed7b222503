// Shared pieces of the command-line tools: exit codes, --help handling, tables.
#ifndef LPOE_TOOLS_TOOL_COMMON_H_
#define LPOE_TOOLS_TOOL_COMMON_H_

#include <cstdint>
#include <iosfwd>
#include <string>
#include <vector>

#include "lpoe/analysis.h"
#include "lpoe/calibration.h"
#include "lpoe/io/io.h"
#include "lpoe/model/statistics.h"
#include "lpoe/io/urdf.h"
#include "report/text_safety.h"

namespace lpoe {
namespace tools {

// Exit codes of every tool (documented in the README).
enum ExitCode {
  kExitOk = 0,
  kExitUsage = 1,            // bad or conflicting flags
  kExitInput = 2,            // an input file is missing or malformed
  kExitNotIdentifiable = 3,  // the data cannot identify the model
  kExitNotConverged = 4,     // iteration limit reached
  kExitNumerical = 5,        // non-finite values or a step that cannot reduce the cost
  kExitOutput = 6,           // an output file could not be written
  kExitDisagree = 7,         // lpoe_compare: the solvers disagree
  kExitImplausible = 8,      // the result failed the plausibility verdict (lpoe/plausibility.h)
};

// "--name must be in [lo, hi], got v" unless lo <= value <= hi (NaN fails); `lo_open`: lo < value.
Status CheckRange(const char* name, double value, double lo, double hi, bool lo_open = false);

// A --holdout split that leaves the verification set empty or too few identification rows.
Status CheckHoldoutSplit(double holdout, int identification_rows, int verification_rows);
// The same for the rows of `in` when a hold-out was asked for (holdout > 0); Ok otherwise.
struct Inputs;
Status CheckHoldoutSplit(double holdout, const Inputs& in);

// Parses flags; on --help / --helpfull prints the usage message and this tool's flags only (with
// their ranges from lpoe/options.h and defaults as written) and exits 0. Checks every flag the
// option table gives a range (lpoe/options.h) and exits 1 naming the first out of range.
// Initializes glog to stderr.
void InitTool(const char* usage, int* argc, char*** argv);

// The shared --angle_unit and --length_unit (common_flags.cc); the error names the flag.
Status ParseUnitFlags(AngleUnit* angle, LengthUnit* length);
// The same for a tool's run: on an error prints "error: <message>" on stderr and returns false (a
// usage error, exit 1). `mm_per_unit` (may be null): MillimetresPer(*length).
bool UnitsFromFlags(AngleUnit* angle, LengthUnit* length, double* mm_per_unit);
// Reads the tool's --model with the URDF chain flags (CheckUrdfFlagsHaveAUrdf, then
// ReadModelWithUrdfFlags); on an error prints it and returns kExitUsage (the URDF flags) or
// kExitInput (the file), else kExitOk.
int ReadModelFlag(RobotModel* model);
// Millimetres per unit of --length_unit (1 or 1000).
inline double MillimetresPer(LengthUnit unit) {
  return unit == LengthUnit::kMetres ? 1000.0 : 1.0;
}
// Joint values (row-major, the model's joints per row) read in `unit` to mm: prismatic joints
// scaled, revolute ones untouched. `to_unit`: the reverse (mm to `unit`, for writing).
void ScalePrismaticJoints(const RobotModel& model, LengthUnit unit, std::vector<double>* q,
                          bool to_unit = false);

// The directory of the shipped data: $LPOE_DATA_DIR when set, else share/lpoe_calib/data of the
// install prefix the running program sits in (<prefix>/bin/..), else data/ of the source tree the
// program was built from.
std::string DataDir();

// The chain selection from this tool's --base_link, --tip_link and --tool_links flags (defined in
// common_flags.cc with the other shared options). False when one of them is given
// but `model_path` is not a URDF.
bool UrdfOptionsFromFlags(const std::string& model_path, UrdfOptions* options);
// Reads a model (YAML, or URDF when the name ends in .urdf) with the chain those flags select: the
// same --base_link / --tip_link / --tool_links in every tool that reads a model. An error when the
// flags are given with a YAML model.
// `other_urdf`: another model of the tool may be the URDF the flags are for (lpoe_compensate's
// --model and --nominal): a YAML model is then read as it is (CheckUrdfFlagsHaveAUrdf checks that
// one of them is a URDF).
Status ReadModelWithUrdfFlags(const std::string& path, RobotModel* model, bool other_urdf = false);
Status CheckUrdfFlagsHaveAUrdf(const std::vector<std::string>& paths);

bool ParseAngleUnit(const std::string& text, AngleUnit* unit);

// The input flags lpoe_calibrate and lpoe_compare share, checked in one place: the units, the
// parameterization, the --holdout range and --verify/--holdout given together. The error names the
// flag (a usage error, exit 1).
struct InputFlags {
  std::string angle_unit, length_unit, parameterization, verify;
  double holdout = 0;
  std::string split = "random";  // --split: random | sequential
};
struct InputSettings {
  AngleUnit angle_unit = AngleUnit::kRadians;
  CsvOptions csv;  // angle and length unit of the CSV files
  ParameterizationKind parameterization = ParameterizationKind::kIdentifiable;
  SplitKind split = SplitKind::kRandom;
};
Status ParseInputFlags(const InputFlags& flags, InputSettings* settings);

// The model and measurements of a run, split into identification and verification rows.
struct Inputs {
  RobotModel nominal;
  MeasurementSet identification, verification;
  CsvReadReport skipped;            // lost-beam rows of the identification file
  CsvReadReport verification_skipped;  // the same for the --verify file
  std::string verification_source;  // the --verify path, "holdout" or empty
  bool from_urdf = false;           // the model was read from a URDF, kept in `urdf`
  UrdfSource urdf;
  // Joint values read as degrees that look like radians (DegreesUnitHint): also warned about.
  std::string angle_unit_hint;
};

// Reads the model (YAML, or URDF when the name ends in .urdf in any case) and the measurements,
// warns on stderr about ignored columns, skipped lost-beam rows (of both files) and positions that
// look like the wrong length unit, and splits off the verification rows (the `verify` file, or a
// seeded random `holdout` fraction, moved out without copying the rest). On failure returns the
// message of the bad file.
Status LoadInputs(const std::string& model_path, const std::string& measurements_path,
                  const std::string& verify_path, const CsvOptions& csv, double holdout,
                  uint64_t split_seed, Inputs* inputs, const UrdfOptions& urdf_options = {},
                  SplitKind split = SplitKind::kRandom);

// The input files of a run. With no --measurements, the shipped section-4 data set: the nominal
// cobot6, its identification rows and (unless a hold-out is asked for) its verification rows.
struct InputPaths {
  std::string model, measurements, verify;
};
InputPaths ResolveInputPaths(const std::string& model_flag, const std::string& measurements_flag,
                             const std::string& verify_flag, bool holdout);

// The inputs of lpoe_calibrate and lpoe_compare from their flags: the files (ResolveInputPaths of
// --model, --measurements and flags.verify) and the settings (ParseInputFlags; its error).
Status ResolveInputs(const std::string& model_flag, const std::string& measurements_flag,
                     const InputFlags& flags, InputPaths* paths, InputSettings* settings);

class OutputSet;
// Registers the files of `paths` as inputs of `outputs` (--model, --measurements, --verify).
void AddInputs(const InputPaths& paths, OutputSet* outputs);

// True when both paths name the same existing file (same device and inode), or are equal strings.
bool SameFile(const std::string& a, const std::string& b);

// `path` with its extension (after the last '.' of its last component) replaced by ".json", or
// ".json" appended (lpoe_plan's default --report).
std::string JsonBeside(const std::string& path);

// Exit code for a calibration termination.
int ExitCodeFor(Termination t);

// Prints the convergence history (the paper's Fig. 6).
void PrintIterationTable(std::ostream& os, const CalibrationResult& result);

// Writes `items` joined by `separator`, in lines of at most `width` characters where the items
// allow (an item longer than a line gets a line of its own), each line indented by `indent` spaces
// and ended by a newline. For the long lists of the identifiability report (60 names of
// joint-space combinations are common), which a person reads in a terminal.
void PrintWrapped(std::ostream& os, const std::vector<std::string>& items,
                  const std::string& separator, int indent, int width = 100);

// The end of a tool's run: flushes stdout (the tool's text comes before an output written to
// /dev/stdout), commits `outputs` unless `staged` (the first staging error, or Ok) failed, then
// prints "wrote PATH" for each file written unless `quiet`. On failure prints "error: <message>" on
// stderr and returns kExitOutput, else kExitOk. `written` (may be null) receives the paths.
int CommitOutputs(const Status& staged, OutputSet* outputs, bool quiet,
                  std::vector<std::string>* written = nullptr);

// Prints before/after statistics per axis and norm.
void PrintBeforeAfter(std::ostream& os, const std::string& title, const ErrorStatistics& before,
                      const ErrorStatistics& after);

}  // namespace tools
}  // namespace lpoe

#endif  // LPOE_TOOLS_TOOL_COMMON_H_
