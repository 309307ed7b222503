// Refusals shared by the command-line tools and the Python module, written once, so that
// a case the CLI refuses is refused by the binding with the same message (lpoe.Error there).
#ifndef LPOE_REFUSALS_H_
#define LPOE_REFUSALS_H_

#include <string>
#include <vector>

#include "lpoe/model/robot_model.h"
#include "lpoe/status.h"

namespace lpoe {

// A plan or data set of `rows` scalar observations for `parameters` parameters. With no more rows
// than parameters the fit is exact whatever the errors: the residuals are zero, no standard
// deviation can be estimated and no verdict can fail, so the set cannot check itself. `what`
// names the set ("the plan of 9 poses"). Ok when rows > parameters.
Status CheckRedundancy(int rows, int parameters, const std::string& what);

// The rank of a plan's or data set's information against its parameters: an error naming both
// unless rank == parameters.
Status CheckFullRank(int rank, int parameters, const std::string& what);

// A nominal model given beside a calibrated one (lpoe_compensate --nominal, lpoe.compensate
// nominal=) must describe the same arm: as many joints, joint by joint of the same type (revolute
// or prismatic), and at least the calibrated model's tools. The message names the first mismatch.
Status CheckNominalMatches(const RobotModel& calibrated, const RobotModel& nominal);

// Every number of the model (joint origins and twists, limits where given, tools, registration,
// payload, joint-error values) finite: a model with NaN or infinity is written nowhere.
Status CheckModelFinite(const RobotModel& model);

// Known SMR nests (lpoe_calibrate --fixed_tools, lpoe.calibrate fixed_tools=): marks the tools
// `names` of `model` fixed (Tool::fixed; tools the model marks already stay fixed). An empty name
// or one that is not a tool of the model is refused, naming it and the model's tools; nothing is
// changed then.
Status SetFixedTools(const std::vector<std::string>& names, RobotModel* model);

// Splits a comma-separated list of names ("smr1,smr2"; surrounding blanks trimmed); an empty item
// ("smr1,,smr2", a trailing comma) is refused. An empty text is an empty list.
Status ParseNameList(const std::string& text, std::vector<std::string>* names);

}  // namespace lpoe

#endif  // LPOE_REFUSALS_H_
