// Internal pieces shared by the translation units of the Python module.
#ifndef LPOE_PYTHON_PYTHON_API_H_
#define LPOE_PYTHON_PYTHON_API_H_

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "lpoe/measurements/measurements.h"
#include "lpoe/model/model_covariance.h"
#include "lpoe/model/parameterization.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/status.h"

namespace lpoe {
namespace python {

// Raised as lpoe.Error (a ValueError) in Python.
class LpoeError : public std::runtime_error {
 public:
  explicit LpoeError(const std::string& message) : std::runtime_error(message) {}
};

// Arrays taken in: C-contiguous float64 (other dtypes and layouts are converted).
using RowArray = pybind11::array_t<double, pybind11::array::c_style | pybind11::array::forcecast>;

// "(3, 4)" for error messages.
std::string ShapeText(const pybind11::array& a);

// Raises lpoe.Error with the status message when `s` is an error.
inline void Check(const Status& s) {
  if (!s.ok()) throw LpoeError(s.message());
}

// Checks that `a` is an (M, cols) array (a 1-D array of cols values is one row) and returns M;
// raises lpoe.Error naming `what` otherwise.
pybind11::ssize_t RowsOf(const RowArray& a, pybind11::ssize_t cols, const std::string& what);

// A model file by its name: URDF when it ends in .urdf (any case), else YAML.
Status ReadAnyRobotModel(const std::string& path, RobotModel* model);
Status WriteAnyRobotModel(const std::string& path, const RobotModel& model);

// Options shared by several functions, parsed as the tools parse their flags (raising lpoe.Error):
// --parameterization; --data_kind (auto | position | pose; returns use_orientation);
// --joint_errors (none | a comma-separated list of registry terms, lpoe/terms/joint_term.h; returned in
// registry order, compliance first); a tool by index or name.
ParameterizationKind ParseParameterizationOption(const std::string& text);
bool ParseDataKindOption(const std::string& text, const MeasurementSet& data);
// `allow_bilinear`: the bilinear effects (lpoe/joint_error_list.h: "compliance,tilt") are accepted
// and listed last ("tilt").
std::vector<std::string> JointErrorNames(const std::string& text, bool allow_bilinear = false);
int ToolIndexOf(const RobotModel& model, const pybind11::object& tool);
// One tool for every row: a name, an integer (any with __index__) or a 0-d array.
bool IsOneTool(const pybind11::object& tool);
// The tool of each of `rows` rows: one name or index for all, or a sequence (list, tuple, array) of
// names or indices, one per row; raises lpoe.Error naming `what` and the row otherwise.
std::vector<int> ToolsPerRow(const RobotModel& model, const pybind11::object& tool, long rows,
                             const std::string& what);

// Tool positions (mm) of `rows` configurations stored row-major in `q` (num_joints each) into
// `out` (3 per row). No Python objects are touched: callable without the GIL.
void PredictPositionsInto(const RobotModel& model, const double* q, long rows, int tool,
                          double* out);
// The same with the tool of each row (`tools`, `rows` entries).
void PredictPositionsInto(const RobotModel& model, const double* q, long rows, const int* tools,
                          double* out);

// A prior read from a file or built by lpoe.fleet_prior: a model and its covariance block.
struct Prior {
  RobotModel model;
  ModelCovariance covariance;
  std::string source;  // the file, or "fleet prior of N models"
  std::string yaml;    // the file's text (lpoe_prior's for a fleet)
};

// prior= of lpoe.calibrate and lpoe.plan: a file (a calibrated model with its covariance block, or
// lpoe_prior's fleet prior) or an lpoe.Prior; null when None.
std::shared_ptr<Prior> PriorArgument(const pybind11::object& prior);

}  // namespace python
}  // namespace lpoe

#endif  // LPOE_PYTHON_PYTHON_API_H_
