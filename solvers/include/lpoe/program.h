// Robot programs compensated in place: a program's motion targets are read by a parser
// per language, compensated with the calibrated model, and written back into a copy of the text in
// which only the bytes of the targets' numbers change (docs/programs.md).
//
// Design (language-neutral):
//   parser (one file per language: program_urscript.cc, program_rapid.cc)
//       text -> ParsedProgram: target records (name, line, kind, the byte range and value of every
//       number, how the numbers encode the target, the frame and TCP the target is used with, a
//       seed hint) and run-time targets (Offs(...), pose arithmetic...) reported as not
//       compensated;
//   CompensateProgram (one step for every language)
//       calibrated inverse kinematics per record, new numbers in the record's own encoding;
//   RewriteProgram
//       the original text with those byte ranges replaced, every other byte as it was.
// A third language (KUKA KRL) is one more parser: it fills the same records.
#ifndef LPOE_PROGRAM_H_
#define LPOE_PROGRAM_H_

#include <cstddef>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "lpoe/inverse_kinematics.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/kinematics/se3.h"
#include "lpoe/status.h"

namespace re2 {
class RE2;
}  // namespace re2

namespace lpoe {

enum class ProgramLanguage { kUrScript, kRapid };
const char* ProgramLanguageName(ProgramLanguage language);
// "urscript" | "rapid".
bool ProgramLanguageFromName(std::string_view name, ProgramLanguage* language);
// .script/.urscript -> URScript; .mod/.modx/.prg -> RAPID (case-insensitive).
bool ProgramLanguageFromPath(std::string_view path, ProgramLanguage* language);

// Largest program accepted (bytes).
constexpr size_t kMaxProgramBytes = size_t{64} << 20;

// One number of the program text: bytes [begin, end) (a leading sign included), its value as
// written, and the decimals it is rewritten with.
struct ProgramNumber {
  size_t begin = 0, end = 0;
  double value = 0;
  int decimals = 6;
};

enum class ProgramTargetKind { kCartesian, kJoint };

// How a Cartesian target's numbers encode the pose of the TCP in its frame.
enum class PoseEncoding {
  kMetresRotationVector,       // x y z (m), rx ry rz (rotation vector, rad): URScript p[...]
  kMillimetresQuaternionWxyz,  // x y z (mm), q1..q4 = w x y z: RAPID robtarget
};
// How a joint target's numbers encode the joints (one number per joint).
enum class JointEncoding { kRadians, kDegrees };

enum class ProgramTargetStatus {
  kCompensated,
  kNotCompensated,  // see `reason`: computed at run time, unreachable, branch change, ...
  kNotSelected,     // taught point left alone (its name does not match targets_only)
};
const char* ProgramTargetStatusName(ProgramTargetStatus status);

struct ProgramTarget {
  std::string name;  // variable / declaration name, or "<instruction>:<line>" for an inline one
  int line = 0;      // line of its numbers (of the expression for a run-time target)
  ProgramTargetKind kind = ProgramTargetKind::kCartesian;
  // Cartesian: 6 numbers (kMetresRotationVector) or 7 (kMillimetresQuaternionWxyz). Joint: one per
  // joint. Empty for a run-time target.
  std::vector<ProgramNumber> numbers;
  PoseEncoding pose_encoding = PoseEncoding::kMetresRotationVector;
  JointEncoding joint_encoding = JointEncoding::kRadians;

  // The context of its use by motion instructions, resolved by the parser.
  bool used = false;  // by some motion instruction
  int order = 0;      // program order of the first use (seeds are chained in this order)
  SE3d frame;         // the work object / feature the target is expressed in, robot base (mm)
  SE3d tcp;           // the TCP in the flange frame (mm)
  // A stationary tool (RAPID tooldata robhold FALSE, with a wobjdata robhold TRUE): `tcp` is the
  // fixed tool's frame in the robot base frame, `frame` the work object on the flange, and the
  // numbers are the tool's pose in the work object: flange = tcp * target^-1 * frame^-1.
  bool stationary_tool = false;
  std::string frame_name, tcp_name;
  std::vector<double> qnear;  // rad: the controller's seed (URScript qnear); empty: none
  // Quadrants of joints (RAPID confdata cf1, cf4, cf6): used for the seed, rewritten from the
  // compensated joints.
  struct Quadrant {
    int joint = 0;
    ProgramNumber number;
  };
  std::vector<Quadrant> quadrants;

  // Set by the parser when the target cannot be compensated (run-time value, conflicting uses...).
  bool compensable = true;
  std::string reason;

  // Set by CompensateProgram.
  ProgramTargetStatus status = ProgramTargetStatus::kNotCompensated;
  std::vector<double> new_values;     // one per number (in the program's units)
  std::vector<double> new_quadrants;  // one per quadrant
  double correction_mm = 0;           // change of the target's position (joint: of the TCP)
  double correction_deg = 0;          // change of its orientation (joint: largest joint change)
  std::vector<double> q_compensated;  // the joints the compensated target makes the robot take
  std::vector<double> q_controller;   // the controller's joints for the original target (the seed)
};

struct ParsedProgram {
  ProgramLanguage language = ProgramLanguage::kUrScript;
  std::vector<ProgramTarget> targets;  // in text order

  // Set by CompensateProgram: how far the program's TCP can be off because of the flange's
  // rotation about the last joint's axis (docs/programs.md, "Frames and the flange").
  // The largest distance (mm) of a compensated target's TCP from the last joint's axis of the
  // calibrated model: a rotation error delta about that axis moves such a TCP by this times delta.
  double tcp_off_flange_axis_mm = 0;
  // The calibrated model holds tools fixed (known SMR nests, Tool::fixed): the flange rotation
  // about its axis (the last joint's zero) was identified. Otherwise it is a convention of the
  // calibration, traded against the SMR offsets, and not identified.
  bool flange_rotation_identified = false;
  std::string fixed_tools;  // their names, comma-separated
  // Set by CompensateProgram: the frame the program's poses were read in ("base" the models' base
  // frame, "link:NAME" a named base frame, see ProgramOptions::frame) and the flange its TCPs are
  // relative to.
  std::string frame, flange;
};

// Parses `text`; errors name the line ("line 12: ..."). Checks UTF-8, balanced brackets, the size.
Status ParseProgram(std::string_view text, ProgramLanguage language, ParsedProgram* program);

struct ProgramOptions {
  // The controller's flange the program's TCPs are relative to: a tool or a flange frame of both
  // models (lpoe/compensation.h, FindFlange); empty: tool0, else flange, else the last joint's
  // frame.
  std::string flange;
  // The frame of the program's poses (below its work objects / features), as lpoe_compensate's
  // --frame: "base" (the models' base frame), "link:NAME" (a named base frame of the models) or
  // "measurement". Empty: ProgramFrame's default.
  std::string frame;
  // Regular expression (RE2 syntax: ECMAScript's without backreferences and lookaround; matched
  // in time linear in the name, names of any length): only targets whose whole name matches are
  // compensated (the rest are taught points, kNotSelected). Empty: every target.
  std::string targets_only;
  // Joints (rad) the first target's inverse kinematics starts from when the program gives no
  // seed; empty: the middle of each joint's limits (0 for unlimited joints).
  std::vector<double> home;
  IkOptions ik;
};

// The targets_only filter: an RE2 regular expression on the whole target name, matched in time
// linear in the name (no recursion, no backtracking; names of any length). An empty pattern
// selects every name.
class TargetNameFilter {
 public:
  // An error saying why RE2 refuses the pattern ("targets_only '...' is not a regular expression
  // (RE2 syntax): ...").
  Status Compile(const std::string& pattern);
  bool Matches(std::string_view name) const;

 private:
  std::shared_ptr<const re2::RE2> re_;
};

// Checks a ProgramOptions::targets_only pattern (TargetNameFilter::Compile).
Status CheckTargetsOnly(const std::string& pattern);

// The tool named `flange`, else a tool named "flange", else the only tool; -1 with a message.
// (Programs resolve their flange with FindFlange, lpoe/compensation.h.)

// For each compensable record, in program order: the nominal model's inverse kinematics on the
// original target (seeded by qnear, the quadrants, or the previous target's joints) gives the
// controller's joints; the calibrated model's inverse kinematics from there gives joints q at which
// the real robot's TCP is at the target; the nominal TCP pose at q, in the target's frame, is the
// new target. Joint targets: the joints at which the calibrated TCP reaches the nominal TCP pose
// of the original joints. Fills status, reason, new_values, corrections.
Status CompensateProgram(const RobotModel& calibrated, const RobotModel& nominal,
                         const ProgramOptions& options, ParsedProgram* program);

// `text` with the numbers of every compensated target replaced by its new values.
std::string RewriteProgram(std::string_view text, const ParsedProgram& program);

// JSON report: counts per status and one entry per target (name, line, kind, status, reason,
// correction_mm, correction_deg).
std::string ProgramReportJson(const ParsedProgram& program);

// What the program's TCPs owe to the flange's rotation about its axis, in words: identified (the
// calibration held tools fixed), or not, with the lever arm (tcp_off_flange_axis_mm, and the mm a
// TCP moves per 0.1 deg there). The JSON report carries it as `flange_note`.
std::string FlangeRotationNote(const ParsedProgram& program);

// Parse, compensate, rewrite.
Status CompensateProgramText(std::string_view text, ProgramLanguage language,
                             const RobotModel& calibrated, const RobotModel& nominal,
                             const ProgramOptions& options, std::string* output,
                             ParsedProgram* program);

}  // namespace lpoe

#endif  // LPOE_PROGRAM_H_
