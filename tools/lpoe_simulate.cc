// lpoe_simulate: synthetic calibration data as in the paper's section 4 (eqs. (33), (34)).
//
// Writes the nominal model, the measurement CSV(s) and optionally the "actual" robot the
// measurements were taken on (its joint-zero errors folded into its local frames, so that its
// forward kinematics at the recorded q reproduces the noise-free measurements).
#include <cmath>
#include <iostream>
#include <sstream>
#include <string>

#include <gflags/gflags.h>
#include <glog/logging.h>

#include "lpoe/io.h"
#include "lpoe/kinematics.h"
#include "lpoe/simulation.h"
#include "lpoe/urdf.h"
#include "tool_common.h"

DEFINE_string(robot, "cobot6",
              "Built-in nominal robot: cobot6 (paper Table 1) | ur5 | arm7 | prismatic. Ignored "
              "when --model is given.");
DEFINE_string(model, "",
              "Nominal robot model to simulate instead of a built-in one: YAML, or URDF when the "
              "name ends in .urdf. Joint values are drawn within the joints' limits.");
DEFINE_string(errors, "table2",
              "Kinematic errors of the actual robot: table2 (paper Table 2, cobot6 only) | random "
              "| none.");
DEFINE_double(error_rotation, 0.005, "random errors: local-frame rotation bound per axis (rad).");
DEFINE_double(error_translation, 3.0, "random errors: local-frame translation bound per axis (mm).");
DEFINE_double(error_tilt, 0.03, "random errors: joint-axis tilt bound (rad).");
DEFINE_double(error_zero, 0.03, "random errors: joint-zero offset bound (rad or mm).");
DEFINE_uint64(error_seed, 7, "Seed of the random errors.");
DEFINE_int32(count, 100, "Number of configurations.");
DEFINE_int32(verify_count, 0,
             "The last verify_count configurations go to --verify_out instead of --out.");
DEFINE_double(noise_sigma, 0.0,
              "Gaussian noise, standard deviation per axis (mm). The paper's 'variance 0.2' is "
              "sigma = sqrt(0.2) = 0.447 mm.");
DEFINE_bool(pose, false, "Also record the tool orientation (pose data: quat_* columns).");
DEFINE_double(orientation_noise_sigma, 0.0, "Orientation noise per axis (rad), with --pose.");
DEFINE_bool(all_tools, false, "Cycle the measured target through all tools of the model.");
DEFINE_uint64(seed, 1, "Seed of the configurations and the noise.");
DEFINE_string(angle_unit, "rad", "Unit of the revolute joint values written: rad | deg.");
DEFINE_string(out, "", "Measurement CSV to write (required).");
DEFINE_string(verify_out, "", "Verification CSV (the last --verify_count rows).");
DEFINE_string(model_out, "", "Write the nominal model here (YAML).");
DEFINE_string(actual_out, "", "Write the actual (erroneous) robot here (YAML).");

namespace lpoe {
namespace {

constexpr char kUsage[] =
    "Simulates laser-tracker measurements of a robot with kinematic errors (paper section 4).\n\n"
    "  lpoe_simulate --out=points.csv                       # cobot6, Table 2, 100 rows\n"
    "  lpoe_simulate --count=100 --verify_count=30 --noise_sigma=0.03 \\\n"
    "      --out=identification.csv --verify_out=verification.csv --model_out=cobot6.yaml";

constexpr double kDegreesPerRadian = 180.0 / 3.14159265358979323846;

int Run() {
  using tools::kExitInput;
  using tools::kExitOk;
  using tools::kExitOutput;
  using tools::kExitUsage;
  if (FLAGS_out.empty()) {
    std::cerr << "error: --out is required (see --help)\n";
    return kExitUsage;
  }
  if (FLAGS_count < 1 || FLAGS_verify_count < 0 || FLAGS_verify_count >= FLAGS_count) {
    std::cerr << "error: need --count >= 1 and 0 <= --verify_count < --count\n";
    return kExitUsage;
  }
  if (FLAGS_verify_count > 0 && FLAGS_verify_out.empty()) {
    std::cerr << "error: --verify_count needs --verify_out\n";
    return kExitUsage;
  }
  if (!(FLAGS_noise_sigma >= 0) || !(FLAGS_orientation_noise_sigma >= 0)) {
    std::cerr << "error: noise sigmas must be >= 0\n";
    return kExitUsage;
  }
  AngleUnit unit;
  if (!tools::ParseAngleUnit(FLAGS_angle_unit, &unit)) {
    std::cerr << "error: --angle_unit must be rad or deg\n";
    return kExitUsage;
  }

  RobotModel nominal;
  UrdfOptions urdf_options;
  if (!tools::UrdfOptionsFromFlags(FLAGS_model, &urdf_options)) {
    std::cerr << "error: --base_link, --tip_link and --tool_links need a URDF --model\n";
    return kExitUsage;
  }
  if (!FLAGS_model.empty()) {
    const Status s =
        IsUrdfPath(FLAGS_model)
            ? ReadRobotModelUrdf(FLAGS_model, &nominal, urdf_options)
            : ReadRobotModel(FLAGS_model, &nominal);
    if (!s.ok()) {
      std::cerr << "error: " << s.message() << "\n";
      return kExitInput;
    }
  } else if (FLAGS_robot == "cobot6") {
    nominal = MakeCobot6();
  } else if (FLAGS_robot == "ur5") {
    nominal = MakeUr5Like();
  } else if (FLAGS_robot == "arm7") {
    nominal = MakeSevenJointArm();
  } else if (FLAGS_robot == "prismatic") {
    nominal = MakeArmWithPrismatic();
  } else {
    std::cerr << "error: unknown --robot '" << FLAGS_robot << "'\n";
    return kExitUsage;
  }

  KinematicErrors errors;
  if (FLAGS_errors == "table2") {
    if (nominal.num_joints() != 6 || nominal.num_tools() != 1) {
      std::cerr << "error: --errors=table2 is defined for a 6-joint robot with one tool\n";
      return kExitUsage;
    }
    errors = PaperTable2Errors();
  } else if (FLAGS_errors == "random") {
    errors = RandomErrors(nominal, FLAGS_error_rotation, FLAGS_error_translation, FLAGS_error_tilt,
                          FLAGS_error_zero, FLAGS_error_seed);
  } else if (FLAGS_errors == "none") {
    errors = RandomErrors(nominal, 0, 0, 0, 0, 0);
  } else {
    std::cerr << "error: --errors must be table2, random or none\n";
    return kExitUsage;
  }
  const RobotModel actual = ApplyErrors(nominal, errors);

  SimulationOptions options;
  options.count = FLAGS_count;
  options.noise_sigma = FLAGS_noise_sigma;
  options.pose = FLAGS_pose;
  options.orientation_noise_sigma = FLAGS_orientation_noise_sigma;
  options.seed = FLAGS_seed;
  options.all_tools = FLAGS_all_tools;
  MeasurementSet data = SimulateMeasurements(actual, errors.joint_zero, options);
  if (unit == AngleUnit::kDegrees) {
    for (int r = 0; r < data.size(); ++r) {
      for (int i = 0; i < nominal.num_joints(); ++i) {
        if (nominal.joints[i].type == JointType::kRevolute) data.mutable_q(r)[i] *= kDegreesPerRadian;
      }
    }
  }

  std::ostringstream comment;
  comment << "lpoe_simulate: robot " << nominal.name << ", errors " << FLAGS_errors
          << ", noise sigma " << FLAGS_noise_sigma << " mm, seed " << FLAGS_seed << ", joint values in "
          << FLAGS_angle_unit;
  MeasurementSet identification, verification;
  data.SplitAt(FLAGS_count - FLAGS_verify_count, &identification, &verification);

  // The actual robot with the joint-zero errors folded in: T_i(0) <- T_i(0) exp(s_i dq_i).
  RobotModel actual_out = actual;
  for (int i = 0; i < actual_out.num_joints(); ++i) {
    actual_out.joints[i].origin =
        actual_out.joints[i].origin * JointMotion(actual_out.joints[i], errors.joint_zero[i]);
  }
  actual_out.name = nominal.name + "_actual";

  struct Output {
    std::string path;
    std::string text;
  };
  std::vector<Output> outputs = {{FLAGS_out, MeasurementsToCsv(nominal, identification, comment.str())}};
  if (FLAGS_verify_count > 0) {
    outputs.push_back({FLAGS_verify_out, MeasurementsToCsv(nominal, verification, comment.str())});
  }
  if (!FLAGS_model_out.empty()) outputs.push_back({FLAGS_model_out, RobotModelToYaml(nominal)});
  if (!FLAGS_actual_out.empty()) outputs.push_back({FLAGS_actual_out, RobotModelToYaml(actual_out)});
  for (const Output& o : outputs) {
    if (Status s = WriteFileAtomically(o.path, o.text); !s.ok()) {
      std::cerr << "error: " << s.message() << "\n";
      return kExitOutput;
    }
    std::cout << "wrote " << o.path << "\n";
  }
  return kExitOk;
}

}  // namespace
}  // namespace lpoe

int main(int argc, char** argv) {
  lpoe::tools::InitTool(lpoe::kUsage, &argc, &argv);
  return lpoe::Run();
}
