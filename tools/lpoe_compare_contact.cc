// lpoe_compare on ballbar distances and probe contacts (docs/measurements.md): both contact
// solvers on the same files, their predictions compared at the rows' configurations.
#include <gflags/gflags.h>
#include <sys/stat.h>

#include <algorithm>
#include <cstdlib>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "common/common_flags.h"
#include "lpoe/contact_calibration.h"
#include "lpoe/measurements/contact_measurements.h"
#include "lpoe/contact_pipeline.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/measurements/measurement_kinds.h"
#include "common/tool_common.h"

DECLARE_string(measurements);
DECLARE_double(tolerance_mm);
DEFINE_string(sigmas, "",
              "Ballbar and probe files without a sigma column: one noise (mm) per --measurements "
              "file, comma-separated (as lpoe_calibrate's).");

DECLARE_string(joint_errors);  // lpoe_compare.cc

namespace lpoe {
namespace tools {
namespace {

// The tool point at q_eff when the model carries joint-space terms.
Eigen::Vector3d PredictContactPoint(const RobotModel& m, const double* q, int tool) {
  if (m.joint_errors.empty()) return ToolPosition(m, q, tool);
  std::vector<double> q_eff(m.num_joints());
  EffectiveJoints(m, q, q_eff.data());
  return ToolPosition(m, q_eff.data(), tool);
}

}  // namespace

// Whether --measurements names distance or plane files (one, or several comma-separated).
bool ContactCompareRequested() {
  if (FLAGS_measurements.find(',') != std::string::npos) return true;
  if (FLAGS_measurements.empty()) return false;
  // Only a regular file is looked at first (a pipe read for its header would be consumed).
  struct stat st;
  if (::stat(FLAGS_measurements.c_str(), &st) != 0 || !S_ISREG(st.st_mode)) return false;
  const MeasurementKindInfo* kind = nullptr;
  if (!DetectMeasurementFileKind(FLAGS_measurements, &kind).ok() || kind == nullptr) return false;
  return kind->id == MeasurementKindId::kDistance || kind->id == MeasurementKindId::kPlane;
}

int RunContactCompare() {
  std::vector<std::string> files, sigma_items;
  {
    std::stringstream ss(FLAGS_measurements);
    for (std::string f; std::getline(ss, f, ',');) files.push_back(f);
    std::stringstream st(FLAGS_sigmas);
    for (std::string f; std::getline(st, f, ',');) sigma_items.push_back(f);
  }
  if (!sigma_items.empty() && sigma_items.size() != files.size()) {
    std::cerr << "error: --sigmas has " << sigma_items.size() << " values for " << files.size()
              << " --measurements files\n";
    return kExitUsage;
  }
  AngleUnit angle;
  LengthUnit length;
  if (!UnitsFromFlags(&angle, &length, nullptr)) return kExitUsage;
  if (FLAGS_model.empty()) {
    std::cerr << "error: --model is required with distance or plane data\n";
    return kExitUsage;
  }
  RobotModel nominal;
  if (int code = ReadModelFlag(&nominal); code != kExitOk) return code;
  ContactInputOptions input_options;
  input_options.units.angle_unit = angle;
  input_options.units.length_unit = length;
  input_options.tracker_refusal = "lpoe_compare combines distance and plane files only";
  for (const std::string& item : sigma_items) {
    char* end = nullptr;
    const double sigma = std::strtod(item.c_str(), &end);
    if (end == item.c_str() || *end != '\0' || !(sigma > 0 && sigma <= 1e3)) {
      std::cerr << "error: --sigmas: '" << item << "' is not a noise in (0, 1000] mm\n";
      return kExitUsage;
    }
    input_options.sigmas.push_back(sigma);
  }
  ContactInputs inputs;
  bool usage_error = false;
  if (Status s = ReadContactInputs(files, nominal, input_options, &inputs, &usage_error); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return usage_error ? kExitUsage : kExitInput;
  }
  const ContactMeasurementSet& data = inputs.data;
  // Both solvers as lpoe_calibrate runs them (no rows held out).
  ContactPipelineOptions run_options;
  if (Status s = ContactJointTerms(FLAGS_joint_errors, nominal, &run_options.calibration.joint_terms);
      !s.ok()) {
    std::cerr << "error: --joint_errors=" << s.message() << "\n";
    return kExitUsage;
  }
  run_options.solver = "linear";
  const ContactPipelineResult linear_run =
      RunContactPipeline(nominal, data, ContactMeasurementSet(), run_options);
  run_options.solver = "ceres";
  const ContactPipelineResult ceres_run =
      RunContactPipeline(nominal, data, ContactMeasurementSet(), run_options);
  const ContactCalibrationResult& linear = linear_run.calibration;
  const ContactCalibrationResult& ceres = ceres_run.calibration;
  for (const ContactCalibrationResult* r : {&linear, &ceres}) {
    if (!r->ok) {
      std::cerr << "error: " << r->solver << ": " << r->message << "\n";
      return r->iterations == 0 ? kExitNotIdentifiable : kExitNotConverged;
    }
  }
  double largest = 0;
  for (int i = 0; i < data.size(); ++i) {
    const Eigen::Vector3d a = PredictContactPoint(linear.model, data.joints(i), data.rows[i].target);
    const Eigen::Vector3d b = PredictContactPoint(ceres.model, data.joints(i), data.rows[i].target);
    largest = std::max(largest, (a - b).norm());
  }
  std::cout << "lpoe_compare: " << data.size() << " rows of distance and plane data\n"
            << "  linear: cost " << linear.cost << ", " << linear.iterations << " iterations\n"
            << "  ceres:  cost " << ceres.cost << ", " << ceres.iterations << " iterations\n"
            << "  largest difference of the predicted tool points: " << largest << " mm (tolerance "
            << FLAGS_tolerance_mm << " mm)\n";
  return largest <= FLAGS_tolerance_mm ? kExitOk : kExitDisagree;
}

}  // namespace tools
}  // namespace lpoe
