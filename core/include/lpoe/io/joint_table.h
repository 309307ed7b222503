// Joint configurations from a CSV file (a plan, a candidate list, a workspace sample): a header
// naming q1..qN (any order, case-insensitive) and any other columns, which are kept as text but not
// interpreted; '#' lines are comments; CRLF and a UTF-8 BOM are accepted. Revolute joint values are
// converted from degrees when told so; prismatic values are mm.
#ifndef LPOE_JOINT_TABLE_H_
#define LPOE_JOINT_TABLE_H_

#include <string>
#include <vector>

#include "lpoe/io/io.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/status.h"

namespace lpoe {

struct JointTable {
  std::string header;              // the header line as written
  std::vector<std::string> names;  // its column names (trimmed)
  std::vector<std::string> lines;  // each data row as written (no line break)
  std::vector<double> q;           // rad / mm, row-major, model.num_joints() per row
  int rows() const { return static_cast<int>(lines.size()); }
};

Status ParseJointTable(const std::string& text, const std::string& source, const RobotModel& model,
                       AngleUnit unit, JointTable* table);
Status ReadJointTable(const std::string& path, const RobotModel& model, AngleUnit unit,
                      JointTable* table);

}  // namespace lpoe

#endif  // LPOE_JOINT_TABLE_H_
