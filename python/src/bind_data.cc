// Python bindings: measurements, calibration, Jacobians, identifiability.
#include <pybind11/eigen.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <algorithm>
#include <cctype>
#include <string>
#include <vector>

#include "lpoe/joint_error_list.h"
#include "lpoe/measurements/contact_measurements.h"
#include "lpoe/io/csv_rules.h"
#include "lpoe/io/io.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/model/residual_layer.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/measurements/measurement_kind_dispatch.h"
#include "lpoe/measurements/measurement_model.h"
#include "lpoe/measurements/measurements.h"
#include "lpoe/options.h"
#include "lpoe/model/parameterization.h"
#include "lpoe/io/urdf.h"
#include "python_api.h"

namespace py = pybind11;

namespace lpoe {
namespace python {

std::string ShapeText(const py::array& a) {
  std::string s = "(";
  for (py::ssize_t d = 0; d < a.ndim(); ++d) {
    if (d > 0) s += ", ";
    s += std::to_string(a.shape(d));
  }
  return s + (a.ndim() == 1 ? ",)" : ")");
}

py::ssize_t RowsOf(const RowArray& a, py::ssize_t cols, const std::string& what) {
  if (a.ndim() == 1 && a.shape(0) == cols) return 1;
  if (a.ndim() != 2 || a.shape(1) != cols) {
    throw LpoeError(what + ": expected an array of shape (M, " + std::to_string(cols) + "), got " +
                    ShapeText(a));
  }
  return a.shape(0);
}

namespace {

bool EndsWithUrdf(const std::string& path) {
  if (path.size() < 5) return false;
  std::string ext = path.substr(path.size() - 5);
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext == ".urdf";
}

AngleUnit ParseUnit(const std::string& text) {
  if (text == "rad") return AngleUnit::kRadians;
  if (text == "deg") return AngleUnit::kDegrees;
  throw LpoeError("angle_unit: expected 'rad' or 'deg', got '" + text + "'");
}

}  // namespace

ParameterizationKind ParseParameterizationOption(const std::string& text) {
  ParameterizationKind kind;
  if (!ParseParameterization(text, &kind)) {
    throw LpoeError("parameterization: expected 'identifiable' or 'full', got '" + text + "'");
  }
  return kind;
}

bool ParseDataKindOption(const std::string& text, const MeasurementSet& data) {
  if (text == "auto") return data.has_orientation();
  if (text == "position") return false;
  if (text == "pose") {
    if (!data.has_orientation()) throw LpoeError("data_kind='pose' needs measured orientations");
    return true;
  }
  throw LpoeError("data_kind: expected 'auto', 'position' or 'pose', got '" + text + "'");
}

std::vector<std::string> JointErrorNames(const std::string& text, bool allow_bilinear) {
  std::vector<std::string> kinds;
  std::vector<std::string> effects;
  std::string error;
  if (allow_bilinear && !ParseJointErrorList(text, &kinds, &effects, &error)) {
    throw LpoeError("joint_errors: '" + text + "': " + error +
                    " (expected none, a comma-separated list of " + JointTermNameList() + ", " +
                    BilinearEffectsHelp(/*example=*/false) + ", or auto)");
  }
  if (!allow_bilinear && !ParseJointTermList(text, &kinds, &error)) {
    throw LpoeError("joint_errors: expected none or a comma-separated list of " +
                    JointTermNameList() + " (or auto where the tool accepts it), got '" + text +
                    "': " + error);
  }
  // In registry order, compliance first (docs/joint_errors.md), as lpoe_calibrate orders them.
  std::vector<std::string> names = InRegistryOrder(kinds);
  names.insert(names.end(), effects.begin(), effects.end());
  return names;
}

// A tool name (str) as it is, or an integer index as a Python int: an int, a numpy integer or a
// 0-d integer array. A float (1.9, np.float64(1.0), np.array(1.9)) is refused, never truncated.
py::object StrictToolIndex(const py::object& tool) {
  if (py::isinstance<py::str>(tool)) return tool;
  auto refuse = [&]() {
    return LpoeError("tool: an argument has the wrong type: expected a tool name or an integer "
                     "index, got " +
                     py::repr(tool).cast<std::string>() + " (" +
                     py::str(tool.get_type().attr("__name__")).cast<std::string>() + ")");
  };
  if (py::isinstance<py::array>(tool)) {
    const py::array a = tool.cast<py::array>();
    const char kind = a.dtype().kind();
    if (a.ndim() != 0 || (kind != 'i' && kind != 'u')) throw refuse();
    return a.attr("item")();
  }
  if (py::isinstance<py::bool_>(tool) || !PyIndex_Check(tool.ptr())) throw refuse();
  PyObject* index = PyNumber_Index(tool.ptr());
  if (index == nullptr) {
    PyErr_Clear();
    throw refuse();
  }
  return py::reinterpret_steal<py::object>(index);
}

int ToolIndexOf(const RobotModel& model, const py::object& tool_in) {
  const py::object tool = StrictToolIndex(tool_in);
  if (py::isinstance<py::str>(tool)) {
    const int t = model.FindTool(tool.cast<std::string>());
    if (t < 0) throw LpoeError("no tool named '" + tool.cast<std::string>() + "' in the model");
    return t;
  }
  const long long t = tool.cast<long long>();
  if (t < 0 || t >= model.num_tools()) {
    throw LpoeError("tool index " + std::to_string(t) + " out of range [0, " +
                    std::to_string(model.num_tools()) + ")");
  }
  return static_cast<int>(t);
}

bool IsOneTool(const py::object& tool) {
  // An array is one tool only without dimensions (numpy arrays have __index__ when of size 1).
  if (py::isinstance<py::array>(tool)) return tool.cast<py::array>().ndim() == 0;
  return py::isinstance<py::str>(tool) || PyIndex_Check(tool.ptr());
}

std::vector<int> ToolsPerRow(const RobotModel& model, const py::object& tool, long rows,
                             const std::string& what) {
  if (IsOneTool(tool)) return std::vector<int>(rows, ToolIndexOf(model, tool));
  if (!py::isinstance<py::sequence>(tool) && !py::isinstance<py::array>(tool)) {
    throw LpoeError(what + ": an argument has the wrong type: expected a tool name or an integer "
                    "index, or one per row, got " +
                    py::str(tool.get_type().attr("__name__")).cast<std::string>());
  }
  std::vector<int> out;
  out.reserve(rows);
  for (const py::handle item : tool) {
    const py::object value = py::reinterpret_borrow<py::object>(item);
    try {
      out.push_back(ToolIndexOf(model, value));
    } catch (const LpoeError& e) {
      throw LpoeError(what + ": row " + std::to_string(out.size()) + ": " + e.what());
    } catch (const py::error_already_set&) {
      throw LpoeError(what + ": row " + std::to_string(out.size()) + ": " +
                      py::repr(value).cast<std::string>() + " is neither a tool name nor an index");
    }
  }
  if (static_cast<long>(out.size()) != rows) {
    throw LpoeError(what + ": " + std::to_string(out.size()) + " tools for " +
                    std::to_string(rows) + " rows (one per row, or one for all)");
  }
  return out;
}

Status ReadAnyRobotModel(const std::string& path, RobotModel* model) {
  return EndsWithUrdf(path) ? ReadRobotModelUrdf(path, model) : ReadRobotModel(path, model);
}

Status WriteAnyRobotModel(const std::string& path, const RobotModel& model) {
  return EndsWithUrdf(path) ? WriteRobotModelUrdf(path, model) : WriteRobotModel(path, model);
}

void PredictPositionsInto(const RobotModel& model, const double* q, long rows, int tool,
                          double* out) {
  const std::vector<int> tools(static_cast<size_t>(rows), tool);
  PredictPositionsInto(model, q, rows, tools.data(), out);
}

void PredictPositionsInto(const RobotModel& model, const double* q, long rows, const int* tools,
                          double* out) {
  const int n = model.num_joints();
  const KinematicChain chain(model);
  std::vector<double> q_eff(n);
  for (long r = 0; r < rows; ++r) {
    const double* qr = q + r * n;
    if (!model.joint_errors.empty()) {  // the registry's terms (lpoe/terms/joint_term.h)
      EffectiveJoints(model, qr, q_eff.data());
      qr = q_eff.data();
    }
    Eigen::Vector3d p = chain.Position(qr, tools[r]);
    // The residual layer at the commanded joints (lpoe/model/residual_layer.h).
    if (model.residual_layer) p += model.residual_layer->Mean(q + r * n, tools[r]);
    out[3 * r + 0] = p.x();
    out[3 * r + 1] = p.y();
    out[3 * r + 2] = p.z();
  }
}

void BindMeasurements(py::module_& m) {
  py::class_<MeasurementSet>(m, "Measurements",
                             "Tracker measurements: joint values, measured positions (mm), the "
                             "measured tool of each row and (pose data) orientations.")
      .def("__len__", &MeasurementSet::size)
      .def("__repr__",
           [](const MeasurementSet& d) {
             return "<lpoe.Measurements: " + std::to_string(d.size()) + " rows of " +
                    std::to_string(d.num_joints()) + " joints, " +
                    (d.has_orientation() ? "poses>" : "positions>");
           })
      .def_property_readonly("num_joints", &MeasurementSet::num_joints)
      .def_property_readonly("has_orientation", &MeasurementSet::has_orientation)
      .def_property_readonly(
          "kind",
          [](const MeasurementSet& d) {
            return std::string(MeasurementKind(TrackerKindId(d.has_orientation())).name);
          },
          "the measurement kind: 'position' or 'pose' (docs/measurements.md)")
      .def_property_readonly("q",
                             [](const MeasurementSet& d) {
                               py::array_t<double> a({static_cast<py::ssize_t>(d.size()),
                                                      static_cast<py::ssize_t>(d.num_joints())});
                               double* o = a.mutable_data();
                               for (int r = 0; r < d.size(); ++r) {
                                 std::copy(d.q(r), d.q(r) + d.num_joints(),
                                           o + static_cast<size_t>(r) * d.num_joints());
                               }
                               return a;
                             },
                             "(M, N) joint values, rad / mm")
      .def_property_readonly("positions",
                             [](const MeasurementSet& d) {
                               py::array_t<double> a({static_cast<py::ssize_t>(d.size()),
                                                      static_cast<py::ssize_t>(3)});
                               double* o = a.mutable_data();
                               for (int r = 0; r < d.size(); ++r) {
                                 for (int k = 0; k < 3; ++k) o[3 * r + k] = d.position(r)(k);
                               }
                               return a;
                             },
                             "(M, 3) measured positions, mm")
      .def_property_readonly("targets",
                             [](const MeasurementSet& d) {
                               std::vector<int> t(d.size());
                               for (int r = 0; r < d.size(); ++r) t[r] = d.target(r);
                               return py::array_t<int>(t.size(), t.data());
                             },
                             "(M,) index of the measured tool of each row")
      .def_property_readonly("lines",
                             [](const MeasurementSet& d) {
                               std::vector<long> t(d.size());
                               for (int r = 0; r < d.size(); ++r) t[r] = d.source_line(r);
                               return py::array_t<long>(t.size(), t.data());
                             },
                             "(M,) line of each row in its file (0 when not read from a file)")
      .def(
          "subset",
          [](const MeasurementSet& d, const std::vector<int>& rows) {
            for (int r : rows) {
              if (r < 0 || r >= d.size()) {
                throw LpoeError("subset: row " + std::to_string(r) + " out of range [0, " +
                                std::to_string(d.size()) + ")");
              }
            }
            return d.Subset(rows);
          },
          py::arg("rows"), "the listed rows, in that order");

  m.def(
      "joint_error_terms", [] { return JointTermNames(); },
      "the joint-space terms a calibration can identify, in registry order (the names "
      "joint_errors= accepts, docs/joint_errors.md)");

  // Ballbar distances and probe contacts (docs/measurements.md).
  py::class_<ContactMeasurementSet>(
      m, "ContactMeasurements",
      "Ballbar distances or touch-probe contacts on planes: joint values, the measured distance "
      "(mm) or the contact's offset from its plane (the tip radius, mm), the pivot or plane of each "
      "row and its noise (mm).")
      .def("__len__", &ContactMeasurementSet::size)
      .def("__repr__",
           [](const ContactMeasurementSet& d) {
             return "<lpoe.ContactMeasurements: " + std::to_string(d.size()) + " rows, " +
                    std::to_string(d.pivots.size()) + " pivots, " +
                    std::to_string(d.planes.size()) + " planes>";
           })
      .def_property_readonly(
          "kind",
          [](const ContactMeasurementSet& d) {
            return d.size() > 0 && d.Count(d.rows[0].kind) == d.size()
                       ? std::string(MeasurementKind(d.rows[0].kind).name)
                       : std::string("mixed");
          },
          "'distance' (ballbar) or 'plane' (touch probe)")
      .def_property_readonly("q",
                             [](const ContactMeasurementSet& d) {
                               py::array_t<double> a({static_cast<py::ssize_t>(d.size()),
                                                      static_cast<py::ssize_t>(d.num_joints)});
                               std::copy(d.q.begin(), d.q.end(), a.mutable_data());
                               return a;
                             },
                             "(M, N) joint values, rad / mm")
      .def_property_readonly("values",
                             [](const ContactMeasurementSet& d) {
                               std::vector<double> v;
                               for (const ContactRow& r : d.rows) v.push_back(r.value);
                               return py::array_t<double>(v.size(), v.data());
                             },
                             "(M,) distance (mm) or offset from the plane (mm) of each row")
      .def_property_readonly("sigmas",
                             [](const ContactMeasurementSet& d) {
                               std::vector<double> v;
                               for (const ContactRow& r : d.rows) v.push_back(r.sigma);
                               return py::array_t<double>(v.size(), v.data());
                             },
                             "(M,) noise of each row (mm)")
      .def_property_readonly("features",
                             [](const ContactMeasurementSet& d) {
                               std::vector<int> v;
                               for (const ContactRow& r : d.rows) v.push_back(r.feature);
                               return py::array_t<int>(v.size(), v.data());
                             },
                             "(M,) index of each row's pivot (pivots) or plane (planes)")
      .def_property_readonly("targets",
                             [](const ContactMeasurementSet& d) {
                               std::vector<int> v;
                               for (const ContactRow& r : d.rows) v.push_back(r.target);
                               return py::array_t<int>(v.size(), v.data());
                             },
                             "(M,) index of the tool (ball or probe tip) of each row")
      .def_readonly("pivots", &ContactMeasurementSet::pivots, "names of the pivots")
      .def_readonly("planes", &ContactMeasurementSet::planes, "names of the planes");

  m.def(
      "read_measurements",
      [](const std::string& path, const RobotModel& model, const std::string& angle_unit,
         const std::string& length_unit, double sigma) -> py::object {
        CsvOptions options;
        options.angle_unit = ParseUnit(angle_unit);
        if (!ParseLengthUnit(length_unit, &options.length_unit)) {
          throw LpoeError("length_unit: expected 'mm' or 'm', got '" + length_unit + "'");
        }
        const MeasurementKindInfo* kind = nullptr;
        if (DetectMeasurementFileKind(path, &kind).ok() && kind != nullptr &&
            (kind->id == MeasurementKindId::kDistance || kind->id == MeasurementKindId::kPlane)) {
          ContactCsvOptions o;
          o.units = options;
          o.kind = kind;
          o.sigma = sigma;
          ContactMeasurementSet data;
          Check(ReadContactMeasurements(path, model, o, &data));
          return py::cast(std::move(data));
        }
        MeasurementSet data;
        Check(ReadMeasurements(path, model, options, &data, nullptr));
        return py::cast(std::move(data));
      },
      py::arg("path"), py::arg("model"),
      py::arg("angle_unit") = OptionDefaultText("lpoe_calibrate", "angle_unit"),
      py::arg("length_unit") = OptionDefaultText("lpoe_calibrate", "length_unit"),
      py::arg("sigma") = 0.0,
      "reads a measurement CSV for `model` (as lpoe_calibrate's --angle_unit and --length_unit "
      "read it); lost-beam rows are skipped. The kind comes from the columns: tracker files give "
      "lpoe.Measurements (kind 'position' or 'pose'), ballbar and probe files "
      "lpoe.ContactMeasurements (kind 'distance' or 'plane'; `sigma` is their noise in mm when "
      "they have no sigma column)");

  m.def(
      "measurements",
      [](const RobotModel& model, const RowArray& q, const RowArray& positions,
         const py::object& targets, const py::object& quaternions) {
        const int n = model.num_joints();
        if (q.ndim() != 2 || q.shape(1) != n) {
          throw LpoeError("q: expected shape (M, " + std::to_string(n) + "), got " + ShapeText(q));
        }
        const py::ssize_t rows = q.shape(0);
        if (positions.ndim() != 2 || positions.shape(0) != rows || positions.shape(1) != 3) {
          throw LpoeError("positions: expected shape (" + std::to_string(rows) + ", 3), got " +
                          ShapeText(positions));
        }
        std::vector<int> target(rows, 0);
        if (!targets.is_none()) {
          auto t = targets.cast<py::array_t<int, py::array::c_style | py::array::forcecast>>();
          if (t.ndim() != 1 || t.shape(0) != rows) {
            throw LpoeError("targets: expected shape (" + std::to_string(rows) + ",), got " +
                            ShapeText(t));
          }
          for (py::ssize_t r = 0; r < rows; ++r) {
            target[r] = t.at(r);
            if (target[r] < 0 || target[r] >= model.num_tools()) {
              throw LpoeError("targets: row " + std::to_string(r) + ": tool index " +
                              std::to_string(target[r]) + " out of range [0, " +
                              std::to_string(model.num_tools()) + ")");
            }
          }
        }
        const bool pose = !quaternions.is_none();
        RowArray quat;
        if (pose) {
          quat = quaternions.cast<RowArray>();
          if (quat.ndim() != 2 || quat.shape(0) != rows || quat.shape(1) != 4) {
            throw LpoeError("quaternions: expected shape (" + std::to_string(rows) +
                            ", 4) as [x, y, z, w], got " + ShapeText(quat));
          }
        }
        MeasurementSet data(n);
        data.Reserve(static_cast<int>(rows));
        for (py::ssize_t r = 0; r < rows; ++r) {
          const double* qr = q.data() + r * n;
          const Eigen::Vector3d p(positions.at(r, 0), positions.at(r, 1), positions.at(r, 2));
          for (int j = 0; j < n; ++j) {
            if (!std::isfinite(qr[j])) {
              throw LpoeError("q: row " + std::to_string(r) + ": non-finite joint value");
            }
            // The CSV reader's limits (lpoe/io/csv_rules.h), the same for arrays.
            if (std::abs(qr[j]) > kMaxAbsCsvJointValue) {
              throw LpoeError("q: row " + std::to_string(r) + ": joint value of magnitude above 1e4");
            }
          }
          if (!p.allFinite()) {
            throw LpoeError("positions: row " + std::to_string(r) + ": non-finite position");
          }
          if (p.cwiseAbs().maxCoeff() > kMaxAbsCsvPositionMm) {
            throw LpoeError("positions: row " + std::to_string(r) +
                            ": position of magnitude above 1e6 mm");
          }
          if (pose) {
            Eigen::Quaterniond qq(quat.at(r, 3), quat.at(r, 0), quat.at(r, 1), quat.at(r, 2));
            if (!(std::abs(qq.norm() - 1.0) < 1e-6)) {
              throw LpoeError("quaternions: row " + std::to_string(r) +
                              ": not a unit quaternion (norm " + std::to_string(qq.norm()) + ")");
            }
            data.AddPose(qr, SE3d(qq.toRotationMatrix(), p), target[r]);
          } else {
            data.Add(qr, p, target[r]);
          }
        }
        return data;
      },
      py::arg("model"), py::arg("q"), py::arg("positions"), py::arg("targets") = py::none(),
      py::arg("quaternions") = py::none(),
      "measurements from arrays: q (M, N), positions (M, 3) mm, optional targets (M,) and "
      "quaternions (M, 4) [x, y, z, w]");
}


void BindJacobians(py::module_& m) {
  m.def(
      "joint_jacobian",
      [](const RobotModel& model, const RowArray& q, int tool) {
        if (q.ndim() != 1 || q.shape(0) != model.num_joints()) {
          throw LpoeError("q: expected " + std::to_string(model.num_joints()) +
                          " joint values, got shape " + ShapeText(q));
        }
        if (tool < 0 || tool >= model.num_tools()) throw LpoeError("tool index out of range");
        Eigen::MatrixXd J;
        ToolPositionJointJacobian(model, q.data(), tool, &J);
        return J;
      },
      py::arg("model"), py::arg("q"), py::arg("tool") = 0,
      "dP/dq (3, N) of the tool position at one configuration (geometric model), mm per rad/mm");
  m.def(
      "parameter_jacobian",
      [](const RobotModel& model, const RowArray& q, int tool, const std::string& kind_name) {
        if (q.ndim() != 1 || q.shape(0) != model.num_joints()) {
          throw LpoeError("q: expected " + std::to_string(model.num_joints()) +
                          " joint values, got shape " + ShapeText(q));
        }
        if (tool < 0 || tool >= model.num_tools()) throw LpoeError("tool index out of range");
        ParameterizationKind kind;
        if (!ParseParameterization(kind_name, &kind)) {
          throw LpoeError("parameterization: expected 'identifiable' or 'full', got '" +
                          kind_name + "'");
        }
        const Parameterization p = MakeParameterization(model, kind, DataKind::kPosition);
        Eigen::MatrixXd J;
        PredictPositionJacobian(model, p, {}, q.data(), tool, &J);
        std::vector<std::string> names;
        for (const Direction& d : p.parameters) names.push_back(d.name);
        return py::make_tuple(J, names);
      },
      py::arg("model"), py::arg("q"), py::arg("tool") = 0,
      py::arg("parameterization") = OptionDefaultText("lpoe_calibrate", "parameterization"),
      "(dP/dx (3, P), names): the tool position's Jacobian with respect to the right "
      "perturbations x of the local frames in the chosen parameterization (paper eq. 29)");
}

}  // namespace python
}  // namespace lpoe
