// The options of the tools and of the Python module, defined once: name, default as written, range
// and help. The tools' gflags definitions take their default and help from here and InitTool checks
// every flag a tool has against its range (a usage error, exit 1, before any work); the Python
// functions take the same defaults for their keyword arguments and the library workflows
// (compensation.h, planning_workflow.h) check their requests against the same ranges, so that a
// value refused by a tool is refused by lpoe with the same message.
//
// An option belongs to every tool (scope "") or to one (scope "lpoe_plan"): the same name means the
// same thing wherever it appears with the same scope.
#ifndef LPOE_OPTIONS_H_
#define LPOE_OPTIONS_H_

#include <string>
#include <vector>

#include "lpoe/status.h"

namespace lpoe {

struct OptionSpec {
  const char* scope;         // "" (every tool that has it) or the tool's name
  const char* name;          // without "--"
  const char* default_text;  // as written ("0.03", "rad", ""); the flag's default
  bool has_range = false;
  double lo = 0, hi = 0;     // numeric options: lo <= value <= hi (lo < value when lo_open)
  bool lo_open = false;
  bool hi_open = false;
  const char* help = "";
};

// Every option, shared ones first.
const std::vector<OptionSpec>& Options();
// The option `name` of `tool` (its own, else a shared one); null when the table has none.
const OptionSpec* FindOption(const std::string& tool, const std::string& name);
// The help text of an option (CHECK-fails when the table has none: a programming error).
const char* OptionHelp(const std::string& tool, const std::string& name);
double OptionDefault(const std::string& tool, const std::string& name);
// The default as written ("linear", "" for none); a flag's "true" / "false" as a bool (CHECK-fails
// on any other text).
const char* OptionDefaultText(const std::string& tool, const std::string& name);
bool OptionDefaultBool(const std::string& tool, const std::string& name);
// "[1, 10000]", "(0, 90]", "[0, inf)"; empty without a range.
std::string OptionRangeText(const OptionSpec& spec);
// "--name must be in [lo, hi], got v" unless the value is in the option's range (NaN fails).
Status CheckOption(const std::string& tool, const std::string& name, double value);

}  // namespace lpoe

#endif  // LPOE_OPTIONS_H_
