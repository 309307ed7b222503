// Python bindings: robot programs compensated in place (lpoe/program.h), as
// lpoe_compensate --program does it.
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <string>
#include <utility>
#include <vector>

#include "lpoe/options.h"
#include "lpoe/program.h"
#include "python_api.h"

namespace py = pybind11;

namespace lpoe {
namespace python {
namespace {

struct PyProgramCompensation {
  std::string text;    // the compensated program
  std::string report;  // ProgramReportJson
  py::list targets;    // one dict per target
  bool flange_rotation_identified = false;
  std::string flange_note;  // FlangeRotationNote
};

PyProgramCompensation CompensateProgramPy(const RobotModel& model, const RobotModel& nominal,
                                          const std::string& program, const std::string& language,
                                          const std::string& flange, const std::string& frame,
                                          const std::string& targets_only, int max_iterations,
                                          int restarts) {
  ProgramLanguage lang;
  if (!ProgramLanguageFromName(language, &lang)) {
    throw LpoeError("compensate_program: language must be 'urscript' or 'rapid', not '" + language +
                    "'");
  }
  // lpoe_compensate's ranges (the option table, lpoe/options.h).
  for (const auto& [name, value] : {std::pair<const char*, double>{"max_iterations", max_iterations},
                                    {"restarts", restarts}}) {
    if (Status s = CheckOption("lpoe_compensate", name, value); !s.ok()) {
      throw LpoeError("compensate_program: " + s.message());
    }
  }
  ProgramOptions options;
  options.flange = flange;
  options.frame = frame;
  options.targets_only = targets_only;
  options.ik.max_iterations = max_iterations;
  options.ik.restarts = restarts;
  ParsedProgram parsed;
  PyProgramCompensation out;
  {
    py::gil_scoped_release release;
    Check(CompensateProgramText(program, lang, model, nominal, options, &out.text, &parsed));
  }
  out.report = ProgramReportJson(parsed);
  out.flange_rotation_identified = parsed.flange_rotation_identified;
  out.flange_note = FlangeRotationNote(parsed);
  for (const ProgramTarget& t : parsed.targets) {
    py::dict d;
    d["name"] = t.name;
    d["line"] = t.line;
    d["kind"] = t.kind == ProgramTargetKind::kJoint ? "joint" : "cartesian";
    d["status"] = ProgramTargetStatusName(t.status);
    d["reason"] = t.reason;
    d["frame"] = t.frame_name;
    d["tcp"] = t.tcp_name;
    d["correction_mm"] = t.correction_mm;
    d["correction_deg"] = t.correction_deg;
    out.targets.append(d);
  }
  return out;
}

}  // namespace

void BindProgram(py::module_& m) {
  py::class_<PyProgramCompensation>(m, "ProgramCompensation",
                                    "The result of lpoe.compensate_program.")
      .def_readonly("text", &PyProgramCompensation::text,
                    "the compensated program: the input with only its targets' numbers changed")
      .def_readonly("report", &PyProgramCompensation::report,
                    "the JSON report lpoe_compensate --report writes")
      .def_readonly("flange_rotation_identified",
                    &PyProgramCompensation::flange_rotation_identified,
                    "the calibration held tools fixed (known SMR nests), so the flange's rotation "
                    "about its axis was identified")
      .def_readonly("flange_note", &PyProgramCompensation::flange_note,
                    "what the TCPs owe to the flange's rotation about its axis (the report's "
                    "flange_note)")
      .def_readonly("targets", &PyProgramCompensation::targets,
                    "one dict per target: name, line, kind, status (compensated | "
                    "not_compensated | not_selected), reason, frame, tcp, correction_mm, "
                    "correction_deg");
  m.def("compensate_program", &CompensateProgramPy, py::arg("model"), py::arg("nominal"),
        py::arg("program"), py::kw_only(), py::arg("language"), py::arg("flange") = "",
        py::arg("frame") = "", py::arg("targets_only") = "",
        py::arg("max_iterations") =
            static_cast<int>(OptionDefault("lpoe_compensate", "max_iterations")),
        py::arg("restarts") = static_cast<int>(OptionDefault("lpoe_compensate", "restarts")),
        "a robot program (URScript or RAPID text) compensated with the calibrated `model` for a "
        "controller running `nominal` (as lpoe_compensate --program; docs/programs.md). flange: "
        "the controller's flange its TCPs are relative to (a tool or flange frame; default tool0, "
        "else flange, else the last joint's frame); frame: the frame of its poses, 'base', "
        "'measurement' or 'link:NAME' (default: 'link:base' for URScript when the model has that "
        "frame, as ur_description's UR Base, else 'base')");
}

}  // namespace python
}  // namespace lpoe
