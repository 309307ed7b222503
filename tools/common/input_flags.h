// The input flags lpoe_calibrate and lpoe_compare both define, each with its own help:
// --measurements, --verify, --holdout, --split and --parameterization (with the shared --model and
// units, common_flags.h). Only a tool that defines them may call InputsFromFlags (lpoe_tool_input_flags,
// input_flags.cc, is linked into a tool only when it does).
#ifndef LPOE_TOOLS_INPUT_FLAGS_H_
#define LPOE_TOOLS_INPUT_FLAGS_H_

#include <gflags/gflags.h>

#include "common/tool_common.h"

DECLARE_string(measurements);
DECLARE_string(verify);
DECLARE_double(holdout);
DECLARE_string(split);
DECLARE_string(parameterization);

namespace lpoe {
namespace tools {

// The files and settings those flags give (ResolveInputs); on an error prints "error: <message>"
// on stderr and returns false (a usage error, exit 1).
bool InputsFromFlags(InputPaths* paths, InputSettings* settings);

}  // namespace tools
}  // namespace lpoe

#endif  // LPOE_TOOLS_INPUT_FLAGS_H_
