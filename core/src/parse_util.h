// Internal helpers shared by the file readers (io.cc, urdf.cc): one format for every input error,
// "<file>:<line>: <what is wrong>; expected <what>".
#ifndef LPOE_CORE_SRC_PARSE_UTIL_H_
#define LPOE_CORE_SRC_PARSE_UTIL_H_

#include <string>
#include <string_view>

#include "lpoe/status.h"

namespace lpoe {
namespace internal {

// The error of an input file at a 1-based line (lines below 1 are reported as line 1).
Status LineError(const std::string& source, int line, const std::string& what,
                 const std::string& expected);

// `s` in single quotes for a message: control bytes escaped, long junk cut after `max_shown`
// characters so that a message stays one readable line.
std::string Quote(std::string_view s, size_t max_shown = 40);

}  // namespace internal
}  // namespace lpoe

#endif  // LPOE_CORE_SRC_PARSE_UTIL_H_
