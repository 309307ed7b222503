// lpoe_compensate --program: a robot program (URScript, RAPID) compensated in place.
// The library side is solvers/include/lpoe/program.h; this is the tool's flags and files.
#ifndef LPOE_TOOLS_LPOE_COMPENSATE_PROGRAM_H_
#define LPOE_TOOLS_LPOE_COMPENSATE_PROGRAM_H_

#include <gflags/gflags_declare.h>

#include "lpoe/inverse_kinematics.h"

// The CSV mode's flags the program mode reads too (defined in lpoe_compensate.cc, which includes
// this header first).
DECLARE_string(nominal);
DECLARE_string(report);
DECLARE_string(targets);
DECLARE_string(joints);
DECLARE_string(frame);
DECLARE_string(flange);
DECLARE_bool(strict);

namespace lpoe {
namespace tools {

// The inverse kinematics options of both modes, from --max_iterations, --restarts,
// --position_tolerance, --orientation_tolerance and --singular_threshold (lpoe_compensate.cc).
IkOptions IkOptionsFromFlags();

// --program was given.
bool ProgramModeRequested();
// Runs the program mode; returns the exit code.
int RunProgramMode();

}  // namespace tools
}  // namespace lpoe

#endif  // LPOE_TOOLS_LPOE_COMPENSATE_PROGRAM_H_
