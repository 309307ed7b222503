// lpoe_compensate --program=IN --output=OUT: see lpoe_compensate_program.h and
// docs/programs.md. The flags shared with the CSV modes are defined in lpoe_compensate.cc. (The
// file name contains the tool's: tool_common's --help lists the flags of such files.)
#include "lpoe_compensate_program.h"

#include <gflags/gflags.h>

#include <iostream>
#include <string>
#include <vector>

#include "lpoe/compensation.h"
#include "lpoe/io/io.h"
#include "lpoe/program.h"
#include "common/output_files.h"
#include "common/common_flags.h"
#include "common/tool_common.h"

DEFINE_string(program, "",
              "Robot program to compensate (URScript .script/.urscript, RAPID .mod/.modx/.prg): "
              "--output gets the same text with only the numbers of its motion targets changed. "
              "Needs --nominal (the model the controller runs).");
DEFINE_string(language, "",
              "Language of --program: urscript | rapid (default: from its extension).");
DEFINE_string(flange, "",
              "The controller's flange, which a TCP is relative to (--tcp, a program's set_tcp or "
              "tooldata): a tool or a flange frame of the models (a URDF link fixed to the last "
              "link) [tool0, else flange, else the last joint's frame].");
DEFINE_string(targets_only, "",
              "Compensate only the program targets whose whole name matches this regular "
              "expression (RE2 syntax, matched in linear time); the others (taught points) are "
              "left as they are.");

namespace lpoe {
namespace tools {

namespace {
constexpr int kExitNotAllCompensated = 8;  // --strict, as in the CSV modes
}  // namespace

bool ProgramModeRequested() { return !FLAGS_program.empty(); }

int RunProgramMode() {
  if (FLAGS_model.empty() || FLAGS_nominal.empty() || FLAGS_output.empty()) {
    std::cerr << "error: --program needs --model (calibrated), --nominal (the controller's model) "
                 "and --output\n";
    return kExitUsage;
  }
  if (!FLAGS_targets.empty() || !FLAGS_joints.empty()) {
    std::cerr << "error: --program replaces --targets and --joints; give one of them\n";
    return kExitUsage;
  }
  ProgramLanguage language;
  if (!FLAGS_language.empty() ? !ProgramLanguageFromName(FLAGS_language, &language)
                              : !ProgramLanguageFromPath(FLAGS_program, &language)) {
    std::cerr << "error: "
              << (FLAGS_language.empty() ? "cannot tell the language of " + FLAGS_program +
                                               " from its extension; give --language=urscript|rapid"
                                         : "--language must be urscript or rapid")
              << "\n";
    return kExitUsage;
  }
  if (!FLAGS_targets_only.empty()) {
    if (Status s = CheckTargetsOnly(FLAGS_targets_only); !s.ok()) {
      std::cerr << "error: --" << s.message() << "\n";
      return kExitUsage;
    }
  }
  OutputSet outputs;
  outputs.AddInput("--model", FLAGS_model);
  outputs.AddInput("--nominal", FLAGS_nominal);
  outputs.AddInput("--program", FLAGS_program);
  outputs.AddOutput("--output", FLAGS_output);
  outputs.AddOutput("--report", FLAGS_report);
  if (Status s = outputs.Check(); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitUsage;
  }
  RobotModel calibrated, nominal;
  if (Status s = tools::CheckUrdfFlagsHaveAUrdf({FLAGS_model, FLAGS_nominal}); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitUsage;
  }
  for (auto [path, model] : {std::pair{&FLAGS_model, &calibrated}, {&FLAGS_nominal, &nominal}}) {
    if (Status s = tools::ReadModelWithUrdfFlags(*path, model, /*other_urdf=*/true); !s.ok()) {
      std::cerr << "error: " << s.message() << "\n";
      return kExitInput;
    }
  }
  if (SE3d flange; !FLAGS_flange.empty()) {
    if (Status s = FindFlange(calibrated, FLAGS_flange, &flange); !s.ok()) {
      std::cerr << "error: --flange: " << FLAGS_model << ": " << s.message() << "\n";
      return kExitUsage;
    }
  }
  std::string text;
  if (Status s = ReadFile(FLAGS_program, &text); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitInput;
  }
  ProgramOptions options;
  options.flange = FLAGS_flange;
  // --frame as given; by default the language's (URScript with ur_description: link:base).
  if (!gflags::GetCommandLineFlagInfoOrDie("frame").is_default) {
    options.frame = FLAGS_frame;
    TargetFrame kind;
    std::string link;
    SE3d pose;
    if (!ParseTargetFrame(FLAGS_frame, &kind, &link) || kind == TargetFrame::kMeasurement) {
      std::cerr << "error: --frame=" << FLAGS_frame << " with --program: a program's poses are "
                << "in the base frame (base) or a controller base (link:NAME)\n";
      return kExitUsage;
    }
    if (Status s = kind == TargetFrame::kLink ? FindBaseFrame(nominal, link, &pose) : Status::Ok();
        !s.ok()) {
      std::cerr << "error: --frame=" << FLAGS_frame << ": " << FLAGS_nominal << ": " << s.message()
                << "\n";
      return kExitUsage;
    }
  }
  options.targets_only = FLAGS_targets_only;
  options.ik = IkOptionsFromFlags();
  ParsedProgram program;
  std::string out;
  if (Status s =
          CompensateProgramText(text, language, calibrated, nominal, options, &out, &program);
      !s.ok()) {
    std::cerr << "error: " << FLAGS_program << ": " << s.message() << "\n";
    // A compensation that is not finite is a numerical failure (exit 5), the rest bad input.
    return s.message().find("the compensation is not finite") != std::string::npos
               ? kExitNumerical
               : kExitInput;
  }
  Status staged = outputs.Stage(FLAGS_output, out);
  if (staged.ok() && !FLAGS_report.empty()) {
    staged = outputs.Stage(FLAGS_report, ProgramReportJson(program));
  }
  if (CommitOutputs(staged, &outputs, true) != kExitOk) return kExitOutput;
  int counts[3] = {};
  for (const ProgramTarget& t : program.targets) {
    ++counts[static_cast<int>(t.status)];
    if (t.status == ProgramTargetStatus::kNotCompensated && !FLAGS_quiet) {
      std::cerr << FLAGS_program << ":" << t.line << ": " << t.name
                << ": not compensated: " << t.reason << "\n";
    }
  }
  if (!FLAGS_quiet) {  // --quiet: only errors (the report has all of it)
    std::cerr << "lpoe_compensate: " << FLAGS_program << ": poses read in the frame "
              << program.frame << ", TCPs relative to " << program.flange << "\n";
    std::cerr << "lpoe_compensate: " << FlangeRotationNote(program) << "\n";
    std::cerr << "lpoe_compensate: " << program.targets.size() << " targets in "
              << ProgramLanguageName(language) << " program " << FLAGS_program << ": compensated "
              << counts[0] << ", not_compensated " << counts[1] << ", not_selected " << counts[2]
              << "\n";
  }
  if (FLAGS_strict && counts[static_cast<int>(ProgramTargetStatus::kNotCompensated)] > 0) {
    return kExitNotAllCompensated;
  }
  return kExitOk;
}

}  // namespace tools
}  // namespace lpoe
