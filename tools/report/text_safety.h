// Text that reaches a report writer: names and paths may hold any bytes, of any length.
// Everything a tool writes into JSON, HTML, a CSV comment or a plot label goes through one of these
// (JSON through JsonText, tools/report/json_text.h), so no writer aborts on invalid UTF-8 and no label
// reaches a fixed-size buffer. Free of other dependencies, so that fuzz/fuzz_report_text.cc
// compiles it on its own.
#ifndef LPOE_TOOLS_TEXT_SAFETY_H_
#define LPOE_TOOLS_TEXT_SAFETY_H_

#include <cstddef>
#include <string>

namespace lpoe {
namespace tools {

// `text` with every byte sequence that is not valid UTF-8 (stray continuation bytes, truncated or
// overlong sequences, surrogates, code points above U+10FFFF) replaced by U+FFFD, one per maximal
// invalid subpart (as nlohmann::json's error_handler_t::replace does). Names and paths may hold
// any bytes; every text a report writer emits (JSON, HTML, plot labels) goes through this or
// JsonText (tools/report/json_text.h), never aborting on such bytes.
std::string ValidUtf8(const std::string& text);

// `text` cut to at most `max_bytes` bytes at a UTF-8 character boundary, with "..." appended when
// cut (then at most max_bytes + 3 bytes). For labels that reach fixed-size buffers (PLplot).
std::string TruncateUtf8(const std::string& text, size_t max_bytes);

// `text` for a one-line '#' comment of a CSV the tools write (a model name or a path there): control
// bytes (a newline would start a data row) become '?', invalid UTF-8 U+FFFD.
std::string CommentText(const std::string& text);

// Longest label handed to PLplot (bytes, before "..."): its text routines copy into fixed-size
// buffers (a joint name of ~2,000 characters crashed it), and a longer label does not fit a panel.
constexpr size_t kMaxPlotLabelBytes = 120;

// A label as PLplot may take it: valid UTF-8, cut to kMaxPlotLabelBytes, and PLplot's escape
// character '#' doubled (so that a name holding "#u" or "#[0x25c6]" is drawn as written, not
// interpreted).
std::string PlotLabel(const std::string& text);

}  // namespace tools
}  // namespace lpoe

#endif  // LPOE_TOOLS_TEXT_SAFETY_H_
