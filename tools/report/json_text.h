// The one way every tool and binding turns a JSON document into text: indented by 2, ended by a
// newline, and with any invalid UTF-8 in its strings (a model or joint name, an input path: they
// may hold any bytes) replaced by U+FFFD instead of throwing nlohmann's type_error 316.
#ifndef LPOE_TOOLS_JSON_TEXT_H_
#define LPOE_TOOLS_JSON_TEXT_H_

#include <string>

#include <nlohmann/json.hpp>

namespace lpoe {
namespace tools {

template <typename Json>
std::string JsonText(const Json& j) {
  return j.dump(2, ' ', false, Json::error_handler_t::replace) + "\n";
}

}  // namespace tools
}  // namespace lpoe

#endif  // LPOE_TOOLS_JSON_TEXT_H_
