// lpoe_plan --measurement=ballbar|plane (docs/measurements.md, "Planning"): ballbar poses on the
// pivots' spheres within the bar's stroke, or probe contacts on the faces of an artefact.
#ifndef LPOE_TOOLS_LPOE_PLAN_CONTACT_H_
#define LPOE_TOOLS_LPOE_PLAN_CONTACT_H_

namespace lpoe {
namespace tools {

// The whole run for --measurement=ballbar|plane; the tools' exit code.
int RunContactPlan();

}  // namespace tools
}  // namespace lpoe

#endif  // LPOE_TOOLS_LPOE_PLAN_CONTACT_H_
