// The Python module `lpoe` (pybind11): models, measurements, prediction, Jacobians, calibration.
//
// Conventions (as in the C++ library): lengths in mm, angles in rad, numpy float64 arrays in and
// out, one row per configuration. Every user error of the library (a Status) is raised as
// `lpoe.Error` (a ValueError) carrying the library's "file:line: what is wrong" message; nothing
// aborts the interpreter. Long loops release the GIL.
#include <pybind11/eigen.h>
#include <pybind11/functional.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cmath>
#include <sstream>
#include <string>
#include <vector>

#include "lpoe/io/io.h"
#include "lpoe/model/model_limits.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/measurements/measurements.h"
#include "lpoe/model/parameterization.h"
#include "lpoe/model/residual_layer.h"
#include "lpoe/model/robot_model.h"
#include "lpoe/io/urdf.h"
#include "python_api.h"

namespace py = pybind11;

namespace lpoe {
namespace python {
namespace {

py::ssize_t Rows(const RowArray& a, py::ssize_t cols, const char* what) {
  return RowsOf(a, cols, what);
}

int ToolIndex(const RobotModel& model, const py::object& tool) { return ToolIndexOf(model, tool); }

Eigen::Matrix4d ToMatrix(const SE3d& T) {
  Eigen::Matrix4d M = Eigen::Matrix4d::Identity();
  M.topLeftCorner<3, 3>() = T.R;
  M.topRightCorner<3, 1>() = T.t;
  return M;
}

// A 4x4 homogeneous transform as a model holds it: finite, a rotation (orthonormal to 1e-6,
// determinant +1), the last row [0, 0, 0, 1], a translation within a model file's range (mm).
SE3d FromMatrix(const Eigen::Matrix4d& M, const char* what) {
  const Eigen::Matrix3d R = M.topLeftCorner<3, 3>();
  const Eigen::Vector3d t = M.topRightCorner<3, 1>();
  if (!M.allFinite()) throw LpoeError(std::string(what) + ": the matrix has NaN or infinity");
  if (!((R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff() < 1e-6) ||
      !(R.determinant() > 0) ||
      !((M.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).cwiseAbs().maxCoeff() < 1e-12)) {
    throw LpoeError(std::string(what) +
                    ": not a rigid transform (a rotation, orthonormal to 1e-6 with determinant "
                    "+1, and the last row [0, 0, 0, 1])");
  }
  if (!(t.cwiseAbs().maxCoeff() <= kMaxModelLengthMm)) {
    throw LpoeError(std::string(what) + ": the translation is beyond " +
                    std::to_string(static_cast<long>(kMaxModelLengthMm)) + " mm");
  }
  return SE3d(R, t);
}

py::array_t<double> Predict(const RobotModel& model, const RowArray& q, const py::object& tool) {
  Check(model.Validate());  // an empty lpoe.Model() or one edited into another: an error, no abort
  const int n = model.num_joints();
  const py::ssize_t m = Rows(q, n, "joint values");
  const std::vector<int> tools = ToolsPerRow(model, tool, m, "tool");
  py::array_t<double> out({m, static_cast<py::ssize_t>(3)});
  const double* in = q.data();
  double* o = out.mutable_data();
  {
    py::gil_scoped_release release;
    PredictPositionsInto(model, in, m, tools.data(), o);
  }
  // The last guard: a prediction that is not finite is an error naming its row.
  for (py::ssize_t k = 0; k < 3 * m; ++k) {
    if (!std::isfinite(o[k])) {
      throw LpoeError("predict: row " + std::to_string(k / 3) +
                      ": the model predicts a non-finite position there");
    }
  }
  return out;
}

}  // namespace

void BindModel(py::module_& m);
void BindMeasurements(py::module_& m);
void BindCalibration(py::module_& m);
void BindJacobians(py::module_& m);
void BindAnalysis(py::module_& m);
void BindProgram(py::module_& m);  // bind_program.cc

}  // namespace python
}  // namespace lpoe

PYBIND11_MODULE(_lpoe, m) {
  using namespace lpoe;
  using namespace lpoe::python;
  m.doc() = "lpoe-calib: LPoE kinematic calibration of serial robots from laser-tracker data";
  static py::exception<LpoeError> error(m, "Error", PyExc_ValueError);
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const LpoeError& e) {
      error(e.what());
    } catch (const py::cast_error& e) {
      // An argument of the wrong type reaching a cast inside a function (tool=None, tool=1.0,
      // verify=5): lpoe.Error like every other bad argument, not pybind11's RuntimeError.
      error((std::string("an argument has the wrong type: ") + e.what()).c_str());
    }
  });

  py::class_<RobotModel>(m, "Model", "A robot model: local joint frames, twists, tools (mm, rad).")
      .def(py::init<>())
      .def_readwrite("name", &RobotModel::name)
      .def_property_readonly("num_joints", &RobotModel::num_joints)
      .def_property_readonly("num_tools", &RobotModel::num_tools)
      .def_property_readonly("joint_names",
                             [](const RobotModel& r) {
                               std::vector<std::string> v;
                               for (const Joint& j : r.joints) v.push_back(j.name);
                               return v;
                             })
      .def_property_readonly("joint_types",
                             [](const RobotModel& r) {
                               std::vector<std::string> v;
                               for (const Joint& j : r.joints) v.push_back(JointTypeName(j.type));
                               return v;
                             })
      .def_property_readonly("tool_names",
                             [](const RobotModel& r) {
                               std::vector<std::string> v;
                               for (const Tool& t : r.tools) v.push_back(t.name);
                               return v;
                             })
      .def_property_readonly(
          "fixed_tools",
          [](const RobotModel& r) {
            std::vector<std::string> v;
            for (const Tool& t : r.tools) {
              if (t.fixed) v.push_back(t.name);
            }
            return v;
          },
          "names of the tools held as given by a calibration (known SMR nests: YAML fixed: true, "
          "calibrate(fixed_tools=...))")
      .def_property_readonly(
          "limits",
          [](const RobotModel& r) {
            Eigen::MatrixX2d L(r.num_joints(), 2);
            for (int i = 0; i < r.num_joints(); ++i) L.row(i) << r.joints[i].lower, r.joints[i].upper;
            return L;
          },
          "(N, 2) joint limits [lower, upper] (rad or mm; inf when none)")
      .def(
          "joint_origin", [](const RobotModel& r, int i) { return ToMatrix(r.joints.at(i).origin); },
          py::arg("joint"), "4x4 local frame T_{i-1,i}(0) of joint i (0-based), mm")
      .def(
          "set_joint_origin",
          [](RobotModel& r, int i, const Eigen::Matrix4d& M) { r.joints.at(i).origin = FromMatrix(M, "joint origin"); },
          py::arg("joint"), py::arg("matrix"))
      .def(
          "joint_twist", [](const RobotModel& r, int i) { return r.joints.at(i).twist; },
          py::arg("joint"), "twist (omega, v) of joint i in its own frame")
      .def(
          "tool_origin",
          [](const RobotModel& r, const py::object& tool) {
            return ToMatrix(r.tools[ToolIndex(r, tool)].origin);
          },
          py::arg("tool") = 0, "4x4 tool frame T_n,tool in the last joint's frame, mm")
      .def_property(
          "measurement_base",
          [](const RobotModel& r) { return ToMatrix(r.T_measurement_base); },
          [](RobotModel& r, const Eigen::Matrix4d& M) { r.T_measurement_base = FromMatrix(M, "measurement_base"); },
          "4x4 pose of the robot base in the measurement (tracker) frame, as registration found "
          "it (identity when the data were in the base frame); compensate() uses it")
      .def_property_readonly(
          "joint_errors",
          [](const RobotModel& r) {
            py::dict d;  // registry order (lpoe.joint_error_terms())
            for (const std::string& name : JointTermNames()) {
              if (r.joint_errors.Has(name)) d[py::str(name)] = r.joint_errors.Values(name);
            }
            return d;
          },
          "the joint-space terms the model carries: {term name: list of values in the term's "
          "layout} (docs/joint_errors.md)")
      .def("validate", [](const RobotModel& r) { Check(r.Validate()); },
           "raises lpoe.Error when the model is not usable")
      .def("to_yaml", &RobotModelToYaml, "the model as YAML text (as lpoe_calibrate writes it)")
      .def("predict", &Predict, py::arg("q"), py::arg("tool") = 0,
           "tool position (M, 3) in mm at joint values q (M, N), with every error term the model "
           "carries; tool: a name or index for every row, or one per row (a list or array of "
           "names or indices, e.g. Measurements.targets)")
      .def_property_readonly(
          "has_residual_layer", [](const RobotModel& r) { return bool(r.residual_layer); },
          "whether the model carries a learned residual layer (docs/residual_layer.md), which "
          "predict() adds")
      .def(
          "predict_std",
          [](const RobotModel& r, const RowArray& q, const py::object& tool) {
            if (!r.residual_layer) {
              throw LpoeError("predict_std: the model carries no residual layer");
            }
            const int n = r.num_joints();
            const py::ssize_t m = Rows(q, n, "joint values");
            const int t = ToolIndex(r, tool);
            py::array_t<double> out(m);
            double* o = out.mutable_data();
            for (py::ssize_t k = 0; k < m; ++k) {
              o[k] = r.residual_layer->Std(q.data() + k * n, t);
              if (!std::isfinite(o[k])) {
                throw LpoeError("predict_std: row " + std::to_string(k) +
                                ": the standard deviation is not finite there");
              }
            }
            return out;
          },
          py::arg("q"), py::arg("tool") = 0,
          "the residual layer's predictive standard deviation per axis (M,) in mm at joint values "
          "q (M, N), as lpoe_predict --predict_std writes it")
      .def(
          "pose",
          [](const RobotModel& r, const RowArray& q, const py::object& tool) {
            Check(r.Validate());
            if (Rows(q, r.num_joints(), "joint values") != 1 || q.ndim() != 1) {
              throw LpoeError("pose: expected one configuration of " +
                              std::to_string(r.num_joints()) + " joint values");
            }
            const Eigen::Matrix4d M = ToMatrix(ToolPose(r, q.data(), ToolIndex(r, tool)));
            if (!M.allFinite()) throw LpoeError("pose: the model's pose is not finite there");
            return M;
          },
          py::arg("q"), py::arg("tool") = 0, "4x4 tool pose at one configuration (geometric model)")
      .def("copy", [](const RobotModel& r) { return RobotModel(r); })
      .def("__repr__", [](const RobotModel& r) {
        return "<lpoe.Model '" + r.name + "': " + std::to_string(r.num_joints()) + " joints, " +
               std::to_string(r.num_tools()) + " tools>";
      });

  m.def(
      "read_model",
      [](const std::string& path, const std::string& base_link, const std::string& tip_link,
         const py::object& tool_links_obj) {
        // tool_links: a list of link names, or one string separated by commas as the flag.
        std::vector<std::string> tool_links;
        if (py::isinstance<py::str>(tool_links_obj)) {
          std::stringstream ss(tool_links_obj.cast<std::string>());
          for (std::string name; std::getline(ss, name, ',');) {
            if (!name.empty()) tool_links.push_back(name);
          }
        } else if (!tool_links_obj.is_none()) {
          tool_links = tool_links_obj.cast<std::vector<std::string>>();
        }
        RobotModel model;
        const bool urdf = IsUrdfPath(path);
        if (!urdf && (!base_link.empty() || !tip_link.empty() || !tool_links.empty())) {
          throw LpoeError("base_link, tip_link and tool_links select a URDF chain; " + path +
                          " is not a URDF (a name ending in .urdf)");
        }
        if (urdf) {
          UrdfOptions options;
          options.base_link = base_link;
          options.tip_link = tip_link;
          options.tool_links = tool_links;
          Check(ReadRobotModelUrdf(path, &model, options));
        } else {
          Check(ReadAnyRobotModel(path, &model));
        }
        return model;
      },
      py::arg("path"), py::kw_only(), py::arg("base_link") = "", py::arg("tip_link") = "",
      py::arg("tool_links") = py::none(),
      "reads a robot model: YAML, or URDF when the name ends in .urdf, with the chain from "
      "base_link (default: the root link) to tip_link and the measured tools tool_links (links fixed "
      "to the last moving link, a list or a comma-separated string; default: the tip), as every "
      "tool's --model, --base_link, --tip_link and --tool_links (the same option table, "
      "lpoe/options.h)");
  m.def(
      "write_model",
      [](const std::string& path, const RobotModel& model) {
        const bool urdf = path.size() >= 5 && path.compare(path.size() - 5, 5, ".urdf") == 0;
        if (urdf && (model.residual_layer || !model.joint_errors.empty())) {
          // What lpoe_calibrate warns for its --urdf_output: a URDF holds the geometry only.
          const std::string what = std::string(model.residual_layer ? "the residual layer" : "") +
                                   (model.residual_layer && !model.joint_errors.empty() ? " and " : "") +
                                   (model.joint_errors.empty() ? "" : "the joint-space terms");
          if (PyErr_WarnEx(PyExc_UserWarning,
                           (path + ": a URDF carries the geometry only: " + what +
                            " of this model are not written (write YAML to keep them)")
                               .c_str(),
                           1) != 0) {
            throw py::error_already_set();
          }
        }
        Check(WriteAnyRobotModel(path, model));
      },
      py::arg("path"), py::arg("model"),
      "writes a model atomically: URDF when the name ends in .urdf (the geometry only: a model's "
      "joint-space terms and residual layer are left out with a UserWarning), else YAML");
  m.def(
      "model_from_yaml",
      [](const std::string& text, const std::string& source) {
        RobotModel model;
        Check(ParseRobotModelYaml(text, source, &model));
        return model;
      },
      py::arg("text"), py::arg("source") = "<string>", "parses model YAML text");

  BindMeasurements(m);
  BindCalibration(m);
  BindJacobians(m);
  BindAnalysis(m);
  BindProgram(m);
}
