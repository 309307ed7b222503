// lpoe_compensate --program: a robot program (URScript, RAPID) compensated in place (issue 32).
// The library side is solvers/include/lpoe/program.h; this is the tool's flags and files.
#ifndef LPOE_TOOLS_LPOE_COMPENSATE_PROGRAM_H_
#define LPOE_TOOLS_LPOE_COMPENSATE_PROGRAM_H_

namespace lpoe {
namespace tools {

// --program was given.
bool ProgramModeRequested();
// Runs the program mode; returns the exit code.
int RunProgramMode();

}  // namespace tools
}  // namespace lpoe

#endif  // LPOE_TOOLS_LPOE_COMPENSATE_PROGRAM_H_
