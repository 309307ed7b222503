// The options every tool shares, defined once in common_flags.cc (their help and defaults from
// lpoe/options.h): the model and its URDF chain, the units of the CSV files, --quiet and the main
// --output. A tool includes this header to read them.
#ifndef LPOE_TOOLS_COMMON_FLAGS_H_
#define LPOE_TOOLS_COMMON_FLAGS_H_

#include <gflags/gflags.h>

DECLARE_string(model);
DECLARE_string(base_link);
DECLARE_string(tip_link);
DECLARE_string(tool_links);
DECLARE_string(angle_unit);
DECLARE_string(length_unit);
DECLARE_bool(quiet);
DECLARE_string(output);

#endif  // LPOE_TOOLS_COMMON_FLAGS_H_
