#include "parse_util.h"

#include <cstdio>

namespace lpoe {
namespace internal {

Status LineError(const std::string& source, int line, const std::string& what,
                 const std::string& expected) {
  std::string msg = source;
  msg += ':';
  msg += std::to_string(line < 1 ? 1 : line);
  msg += ": ";
  msg += what;
  msg += "; expected ";
  msg += expected;
  return Status::Error(std::move(msg));
}

std::string Quote(std::string_view s, size_t max_shown) {
  std::string out = "'";
  for (size_t i = 0; i < s.size() && i < max_shown; ++i) {
    const unsigned char c = static_cast<unsigned char>(s[i]);
    if (c < 0x20 || c == 0x7f) {
      char buf[8];
      std::snprintf(buf, sizeof(buf), "\\x%02x", c);
      out += buf;
    } else {
      out += static_cast<char>(c);
    }
  }
  if (s.size() > max_shown) out += "...";
  out += "'";
  return out;
}

}  // namespace internal
}  // namespace lpoe
