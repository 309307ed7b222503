// lpoe_simulate: synthetic calibration data as in the paper's section 4 (eqs. (33), (34)).
//
// Writes the nominal model, the measurement CSV(s) and optionally the "actual" robot the
// measurements were taken on (its joint-zero errors folded into its local frames and its
// non-geometric terms, --joint_errors, in its joint_errors section, so that its prediction at the
// recorded q reproduces the noise-free measurements).
#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <iostream>
#include <sstream>
#include <string>

#include <gflags/gflags.h>
#include <glog/logging.h>

#include "lpoe/measurements/contact_measurements.h"
#include "lpoe/io/io.h"
#include "lpoe/terms/joint_errors.h"
#include "lpoe/terms/joint_term.h"
#include "lpoe/io/joint_table.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/model/refusals.h"
#include "lpoe/model/simulation.h"
#include "lpoe/io/urdf.h"
#include "common/output_files.h"
#include "io/parse_util.h"
#include "common/common_flags.h"
#include "common/tool_common.h"

DEFINE_string(robot, "cobot6",
              "Built-in nominal robot: cobot6 (paper Table 1) | ur5 | arm7 | prismatic. Ignored "
              "when --model is given.");
DEFINE_string(errors, "table2",
              "Kinematic errors of the actual robot: table2 (paper Table 2, cobot6 only) | random "
              "| none.");
DEFINE_double(error_rotation, 0.005, "random errors: local-frame rotation bound per axis (rad).");
DEFINE_double(error_translation, 3.0, "random errors: local-frame translation bound per axis (mm).");
DEFINE_double(error_tilt, 0.03, "random errors: joint-axis tilt bound (rad).");
DEFINE_double(error_zero, 0.03, "random errors: joint-zero offset bound (rad or mm).");
DEFINE_uint64(error_seed, 7, "Seed of the random errors.");
DEFINE_int32(count, 100, "Number of configurations (at most 10^7; ignored with --joints).");
DEFINE_string(joints, "",
              "Measure at the configurations of this CSV (q1..qN in --angle_unit, other columns "
              "ignored; e.g. a plan of lpoe_plan) instead of random ones; with --all_tools every "
              "tool at each configuration.");
DEFINE_int32(verify_count, 0,
             "The last verify_count configurations go to --verify_out instead of --output.");
DEFINE_double(noise_sigma, 0.0,
              "Gaussian noise, standard deviation per axis (mm). The paper's 'variance 0.2' is "
              "sigma = sqrt(0.2) = 0.447 mm.");
DEFINE_bool(pose, false, "Also record the tool orientation (pose data: quat_* columns).");
DEFINE_double(orientation_noise_sigma, 0.0, "Orientation noise per axis (rad), with --pose.");
DEFINE_bool(all_tools, false,
            "Cycle the measured target through all tools of the model (with --joints: measure "
            "every tool at each configuration).");
DEFINE_uint64(seed, 1, "Seed of the configurations and the noise.");
DEFINE_string(joint_errors, "none",
              "Non-geometric errors of the actual robot (docs/joint_errors.md): none | a "
              "comma-separated list of the registry's joint-space terms (compliance, harmonics, "
              "...; docs/joint_errors.md lists them and how each is simulated). Compliance: joints "
              "deflect under the gravity torque of the links beyond them; harmonics: joint errors "
              "periodic in q and 2q.");
DEFINE_string(stiffness, "",
              "Joint stiffnesses, comma-separated, one per joint (N m/rad; N/mm for prismatic "
              "joints; 0 = rigid). Default: 2e4 for joints 1-2, 3e3 for joint 3, 1.5e3 beyond.");
DEFINE_double(mass_scale, 1.0,
              "Scales the simulated link masses (default 0.1 kg + 1.25 kg/m of link length).");
DEFINE_double(harmonics_min_arcsec, 5.0, "Smallest amplitude of each simulated harmonic (arcsec).");
DEFINE_double(harmonics_max_arcsec, 30.0, "Largest amplitude of each simulated harmonic (arcsec).");
DEFINE_uint64(joint_error_seed, 11, "Seed of the link centres of mass and the harmonic phases.");
DEFINE_double(payload_mass, 0.0,
              "Payload on the flange (kg), known: written to both the nominal and the actual model.");
DEFINE_string(payload_com, "0,0,0", "Payload centre of mass x,y,z (mm, last joint's frame).");
DEFINE_double(gravity_tilt, 0.0,
              "Tilt of the actual robot's base about the base x axis (rad): its gravity vector is "
              "turned by this angle while the nominal model keeps gravity along -z.");
DEFINE_string(gravity_tilt_deg, "",
              "Tilt of the actual robot's gravity as t1,t2 (degrees) about the two axes "
              "perpendicular to the nominal gravity that lpoe_calibrate --joint_errors=...,tilt "
              "reports (x and y of the base for gravity along -z), e.g. 0.3,0.1. Not with "
              "--gravity_tilt.");
DEFINE_string(out, "", "Old name of --output (every other tool says --output); accepted with a "
                       "warning for one release.");
DEFINE_string(verify_out, "", "Verification CSV (the last --verify_count rows).");
DEFINE_string(model_out, "", "Write the nominal model here (YAML).");
DEFINE_string(actual_out, "", "Write the actual (erroneous) robot here (YAML).");
// Ballbar distances and probe contacts (docs/measurements.md).
DEFINE_string(measurement, "position",
              "position (a tracker: x,y,z) | ballbar (distances to pivots: q1..qN,distance,pivot) | "
              "plane (probe contacts on three faces of a cube: q1..qN,plane,offset). --noise_sigma "
              "is the noise of a distance or of a contact along the normal.");
DEFINE_double(bar_length, 150.0, "ballbar: the bar's length (mm).");
DEFINE_double(stroke, 1.0, "ballbar: the length varies by up to this around --bar_length (mm).");
DEFINE_int32(pivots, 3, "ballbar: number of pivots, placed in front of the robot.");
DEFINE_double(probe_radius, 3.0, "plane: the probe tip's radius (mm), the rows' offset.");
DEFINE_double(cube_size, 100.0, "plane: the cube's edge (mm); its +x, +y, +z faces are touched.");

namespace lpoe {
namespace {

constexpr char kUsage[] =
    "Simulates laser-tracker measurements of a robot with kinematic errors (paper section 4).\n\n"
    "  lpoe_simulate --output=points.csv                       # cobot6, Table 2, 100 rows\n"
    "  lpoe_simulate --count=100 --verify_count=30 --noise_sigma=0.03 \\\n"
    "      --output=identification.csv --verify_out=verification.csv --model_out=cobot6.yaml\n"
    "  lpoe_simulate --model=nominal.yaml --errors=random --joints=poses.csv --all_tools \\\n"
    "      --noise_sigma=0.02 --output=planned.csv                # at the poses of a plan\n"
    "  lpoe_simulate --joint_errors=compliance,harmonics --errors=random --count=300 \\\n"
    "      --noise_sigma=0.01 --output=arm.csv --actual_out=actual.yaml   # a small arm that deflects\n\n"
    "--model: the nominal model to simulate (default: the built-in --robot); --output: the "
    "measurement CSV.\n\n"
    "Exit codes: 0 written, 1 bad flags or outputs (one names an input or another output, or its "
    "directory is missing or not writable: checked before any work), 2 bad input file, 5 a "
    "non-finite model would be written, 6 an output could not be written (then none is).";

constexpr double kDegreesPerRadian = 180.0 / 3.14159265358979323846;
constexpr double kRadiansPerArcsec = 1.0 / 206264.80624709636;

// A comma-separated list of finite numbers (the one reader of such lists, parse_util.h).
bool ParseNumberList(const std::string& text, std::vector<double>* out) {
  return internal::ParseNumberList(text, ',', out);
}

using tools::kExitInput;
using tools::kExitOk;
using tools::kExitOutput;
using tools::kExitUsage;

// What the steps of a simulation share: the robots, the errors and the files to write.
struct Simulation {
  AngleUnit unit;
  LengthUnit length_unit;
  double mm_per_unit = 1;
  RobotModel nominal;
  KinematicErrors errors;
  std::vector<std::string> joint_error_kinds;
  SmallArmOptions small_arm;
  std::vector<double> com;
  std::vector<double> tilt_deg;
  RobotModel actual;
  tools::OutputSet files;
};

// --output (or its old name), --count and --verify_count; then the outputs against the inputs.
int CheckCountsAndOutputs(tools::OutputSet* files) {
  // 10^7 rows are about 2 GB of CSV text held before writing; more is not a test set.
  constexpr int kMaxCount = 10000000;
  if (!FLAGS_out.empty()) {
    if (!FLAGS_output.empty()) {
      std::cerr << "error: give --output (or its old name --out), not both\n";
      return kExitUsage;
    }
    std::cerr << "warning: --out is now --output, as in every other tool; --out will go in the "
                 "next release\n";
    FLAGS_output = FLAGS_out;
  }
  if (FLAGS_output.empty()) {
    std::cerr << "error: --output is required (see --help)\n";
    return kExitUsage;
  }
  if (FLAGS_count < 1 || FLAGS_count > kMaxCount) {
    std::cerr << "error: --count must be in [1, " << kMaxCount << "], got " << FLAGS_count << "\n";
    return kExitUsage;
  }
  if (FLAGS_verify_count < 0 || FLAGS_verify_count >= FLAGS_count) {
    std::cerr << "error: need 0 <= --verify_count < --count\n";
    return kExitUsage;
  }
  if (FLAGS_verify_count > 0 && FLAGS_verify_out.empty()) {
    std::cerr << "error: --verify_count needs --verify_out\n";
    return kExitUsage;
  }
  // The error and noise bounds: their ranges (lpoe/options.h) were checked by InitTool.
  // No output may overwrite the model or another output (by file identity).
  files->AddInput("--model", FLAGS_model);
  files->AddInput("--joints", FLAGS_joints);
  files->AddOutput("--output", FLAGS_output);
  if (FLAGS_verify_count > 0) files->AddOutput("--verify_out", FLAGS_verify_out);
  files->AddOutput("--model_out", FLAGS_model_out);
  files->AddOutput("--actual_out", FLAGS_actual_out);
  if (Status s = files->Check(); !s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return kExitUsage;
  }
  return kExitOk;
}

// The nominal robot: --model (YAML or URDF) or the built-in --robot.
int NominalFromFlags(RobotModel* nominal) {
  UrdfOptions urdf_options;
  if (!tools::UrdfOptionsFromFlags(FLAGS_model, &urdf_options)) {
    std::cerr << "error: --base_link, --tip_link and --tool_links need a URDF --model\n";
    return kExitUsage;
  }
  if (!FLAGS_model.empty()) {
    const Status s =
        IsUrdfPath(FLAGS_model)
            ? ReadRobotModelUrdf(FLAGS_model, nominal, urdf_options)
            : ReadRobotModel(FLAGS_model, nominal);
    if (!s.ok()) {
      std::cerr << "error: " << s.message() << "\n";
      return kExitInput;
    }
  } else if (FLAGS_robot == "cobot6") {
    *nominal = MakeCobot6();
  } else if (FLAGS_robot == "ur5") {
    *nominal = MakeUr5Like();
  } else if (FLAGS_robot == "arm7") {
    *nominal = MakeSevenJointArm();
  } else if (FLAGS_robot == "prismatic") {
    *nominal = MakeArmWithPrismatic();
  } else {
    std::cerr << "error: unknown --robot '" << FLAGS_robot << "'\n";
    return kExitUsage;
  }
  return kExitOk;
}

// The kinematic errors of --errors.
int ErrorsFromFlags(const RobotModel& nominal, KinematicErrors* errors) {
  if (FLAGS_errors == "table2") {
    if (nominal.num_joints() != 6 || nominal.num_tools() != 1) {
      std::cerr << "error: --errors=table2 is defined for a 6-joint robot with one tool\n";
      return kExitUsage;
    }
    *errors = PaperTable2Errors();
  } else if (FLAGS_errors == "random") {
    *errors = RandomErrors(nominal, FLAGS_error_rotation, FLAGS_error_translation,
                           FLAGS_error_tilt, FLAGS_error_zero, FLAGS_error_seed);
  } else if (FLAGS_errors == "none") {
    *errors = RandomErrors(nominal, 0, 0, 0, 0, 0);
  } else {
    std::cerr << "error: --errors must be table2, random or none\n";
    return kExitUsage;
  }
  return kExitOk;
}

// The joint-space physics of the actual robot: terms, stiffness, masses, payload, gravity tilt.
int JointPhysicsFromFlags(Simulation* sim) {
  if (std::string why; !ParseJointTermList(FLAGS_joint_errors, &sim->joint_error_kinds, &why)) {
    std::cerr << "error: --joint_errors must be none or a comma-separated list of "
              << JointTermNameList() << ": " << why << "\n";
    return kExitUsage;
  }
  SmallArmOptions& small_arm = sim->small_arm;
  small_arm.seed = FLAGS_joint_error_seed;
  small_arm.mass_scale = FLAGS_mass_scale;
  small_arm.harmonics_min = FLAGS_harmonics_min_arcsec * kRadiansPerArcsec;
  small_arm.harmonics_max = FLAGS_harmonics_max_arcsec * kRadiansPerArcsec;
  if (!FLAGS_stiffness.empty()) {
    bool ok = ParseNumberList(FLAGS_stiffness, &small_arm.stiffness) &&
              static_cast<int>(small_arm.stiffness.size()) == sim->nominal.num_joints();
    for (double k : small_arm.stiffness) ok = ok && k >= 0;
    if (!ok) {
      std::cerr << "error: --stiffness needs " << sim->nominal.num_joints()
                << " comma-separated numbers >= 0\n";
      return kExitUsage;
    }
  }
  if (!(FLAGS_mass_scale >= 0) || !(FLAGS_harmonics_min_arcsec >= 0) ||
      !(FLAGS_harmonics_max_arcsec >= FLAGS_harmonics_min_arcsec)) {
    std::cerr << "error: need --mass_scale >= 0 and 0 <= --harmonics_min_arcsec <= "
                 "--harmonics_max_arcsec\n";
    return kExitUsage;
  }
  if (!(FLAGS_payload_mass >= 0) || !ParseNumberList(FLAGS_payload_com, &sim->com) ||
      sim->com.size() != 3) {
    std::cerr << "error: need --payload_mass >= 0 and --payload_com=x,y,z\n";
    return kExitUsage;
  }
  if (!(std::abs(FLAGS_gravity_tilt) <= 0.1)) {
    std::cerr << "error: --gravity_tilt must be within [-0.1, 0.1] rad\n";
    return kExitUsage;
  }
  std::vector<double>& tilt_deg = sim->tilt_deg;
  if (!FLAGS_gravity_tilt_deg.empty()) {
    if (!ParseNumberList(FLAGS_gravity_tilt_deg, &tilt_deg) || tilt_deg.size() != 2 ||
        !(std::abs(tilt_deg[0]) <= 5.0 && std::abs(tilt_deg[1]) <= 5.0)) {
      std::cerr << "error: --gravity_tilt_deg must be two angles t1,t2 within [-5, 5] degrees, "
                   "got '"
                << FLAGS_gravity_tilt_deg << "'\n";
      return kExitUsage;
    }
    if (FLAGS_gravity_tilt != 0) {
      std::cerr << "error: give --gravity_tilt (rad, about x) or --gravity_tilt_deg, not both\n";
      return kExitUsage;
    }
  }
  return kExitOk;
}

// The actual robot: the nominal with the payload, the errors, the tilted gravity and the joint
// physics.
void MakeActualRobot(Simulation* sim) {
  RobotModel& nominal = sim->nominal;
  nominal.payload.mass = FLAGS_payload_mass;
  nominal.payload.com = Eigen::Vector3d(sim->com[0], sim->com[1], sim->com[2]);
  RobotModel& actual = sim->actual;
  actual = ApplyErrors(nominal, sim->errors);
  actual.gravity = ExpSO3(Eigen::Vector3d(FLAGS_gravity_tilt, 0, 0)) * nominal.gravity;
  if (!sim->tilt_deg.empty()) {
    const double t[2] = {sim->tilt_deg[0] * M_PI / 180.0, sim->tilt_deg[1] * M_PI / 180.0};
    actual.gravity = TiltedGravity<double>(nominal.gravity, t);
  }
  ApplyJointErrorPhysics(SmallArmJointErrors(nominal, sim->small_arm),
                         InRegistryOrder(sim->joint_error_kinds), &actual);
}

// --measurement=ballbar or plane: the flags these kinds allow.
int CheckContactFlags(const Simulation& sim) {
  if (FLAGS_measurement != "ballbar" && FLAGS_measurement != "plane") {
    std::cerr << "error: --measurement must be position, ballbar or plane, got '"
              << FLAGS_measurement << "'\n";
    return kExitUsage;
  }
  if (!FLAGS_joints.empty() || FLAGS_verify_count > 0 || FLAGS_pose || FLAGS_all_tools ||
      sim.unit != AngleUnit::kRadians || sim.length_unit != LengthUnit::kMillimetres) {
    std::cerr << "error: --measurement=" << FLAGS_measurement
              << " writes radians and millimetres: --joints, --verify_count, --pose, "
                 "--all_tools and the unit flags are not available with it\n";
    return kExitUsage;
  }
  if (FLAGS_count > 100000 || FLAGS_pivots < 1 || FLAGS_pivots > 20 ||
      !(FLAGS_bar_length > 0 && FLAGS_bar_length <= 2000) ||
      !(FLAGS_stroke >= 0 && FLAGS_stroke < FLAGS_bar_length) ||
      !(FLAGS_probe_radius >= 0 && FLAGS_probe_radius <= 100) ||
      !(FLAGS_cube_size > 0 && FLAGS_cube_size <= 2000)) {
    std::cerr << "error: need --count <= 100000, 1 <= --pivots <= 20, 0 < --bar_length <= 2000, "
                 "0 <= --stroke < --bar_length, 0 <= --probe_radius <= 100, 0 < --cube_size "
                 "<= 2000\n";
    return kExitUsage;
  }
  return kExitOk;
}

// Distances or contacts, measured on the actual robot with its joint zeros folded in; written.
int SimulateContacts(Simulation* sim) {
  if (int rc = CheckContactFlags(*sim); rc != kExitOk) return rc;
  const RobotModel& nominal = sim->nominal;
  const RobotModel truth = FoldJointZeros(sim->actual, sim->errors.joint_zero);
  ContactMeasurementSet contacts;
  Status s;
  std::ostringstream what;
  if (FLAGS_measurement == "ballbar") {
    BallbarSimulationOptions o;
    o.count = FLAGS_count;
    o.bar_length = FLAGS_bar_length;
    o.stroke = FLAGS_stroke;
    o.noise = FLAGS_noise_sigma;
    o.num_pivots = FLAGS_pivots;
    o.seed = FLAGS_seed;
    std::vector<Eigen::Vector3d> pivots;
    s = SimulateBallbar(truth, o, &contacts, &pivots);
    what << "# ballbar: bar " << FLAGS_bar_length << " mm +- " << FLAGS_stroke << " mm; pivots";
    for (const Eigen::Vector3d& c : pivots) what << " (" << c.transpose() << ")";
  } else {
    PlaneSimulationOptions o;
    o.count = FLAGS_count;
    o.probe_radius = FLAGS_probe_radius;
    o.noise = FLAGS_noise_sigma;
    o.cube_size = FLAGS_cube_size;
    o.seed = FLAGS_seed;
    std::vector<Eigen::Vector4d> planes;
    s = SimulatePlaneContacts(truth, o, &contacts, &planes);
    what << "# touch probe: radius " << FLAGS_probe_radius << " mm, cube " << FLAGS_cube_size
         << " mm; planes n.x = d:";
    for (const Eigen::Vector4d& p : planes) what << " (" << p.transpose() << ")";
  }
  if (!s.ok()) {
    std::cerr << "error: " << s.message() << "\n";
    return tools::kExitNumerical;
  }
  RobotModel actual_model = truth;
  actual_model.name = nominal.name + "_actual";
  std::string text = "# lpoe_simulate: robot " + nominal.name + ", errors " + FLAGS_errors +
                     (sim->joint_error_kinds.empty() ? "" : ", joint errors " + FLAGS_joint_errors) +
                     ", noise sigma " + std::to_string(FLAGS_noise_sigma) + " mm, seed " +
                     std::to_string(FLAGS_seed) + "\n" + what.str() + "\n" +
                     ContactMeasurementsCsv(nominal, contacts,
                                            FLAGS_measurement == "ballbar"
                                                ? MeasurementKindId::kDistance
                                                : MeasurementKindId::kPlane);
  tools::OutputSet& files = sim->files;
  Status staged = files.Stage(FLAGS_output, text);
  if (staged.ok() && !FLAGS_model_out.empty()) {
    staged = files.Stage(FLAGS_model_out, RobotModelToYaml(nominal));
  }
  if (staged.ok() && !FLAGS_actual_out.empty()) {
    staged = files.Stage(FLAGS_actual_out, RobotModelToYaml(actual_model));
  }
  return tools::CommitOutputs(staged, &files, FLAGS_quiet);
}

// The simulation options of a position (or pose) run; --joints read and checked.
int PositionOptionsFromFlags(const Simulation& sim, SimulationOptions* options) {
  options->count = FLAGS_count;
  if (!FLAGS_joints.empty()) {
    JointTable table;
    if (Status s = ReadJointTable(FLAGS_joints, sim.nominal, sim.unit, &table); !s.ok()) {
      std::cerr << "error: " << s.message() << "\n";
      return kExitInput;
    }
    options->configurations = table.q;
    tools::ScalePrismaticJoints(sim.nominal, sim.length_unit, &options->configurations);
    const int rows = table.rows() * (FLAGS_all_tools ? sim.nominal.num_tools() : 1);
    if (FLAGS_verify_count >= rows) {
      std::cerr << "error: --verify_count must be below the " << rows << " rows of --joints\n";
      return kExitUsage;
    }
  }
  options->noise_sigma = FLAGS_noise_sigma;
  options->pose = FLAGS_pose;
  options->orientation_noise_sigma = FLAGS_orientation_noise_sigma;
  options->seed = FLAGS_seed;
  options->all_tools = FLAGS_all_tools;
  return kExitOk;
}

// The simulated rows in the units of the flags (--length_unit, --angle_unit).
void ToFileUnits(const Simulation& sim, MeasurementSet* data) {
  const RobotModel& nominal = sim.nominal;
  if (sim.length_unit != LengthUnit::kMillimetres) {  // positions and prismatic joints
    for (int r = 0; r < data->size(); ++r) {
      data->mutable_position(r) /= sim.mm_per_unit;
      for (int i = 0; i < nominal.num_joints(); ++i) {
        if (nominal.joints[i].type == JointType::kPrismatic) {
          data->mutable_q(r)[i] /= sim.mm_per_unit;
        }
      }
    }
  }
  if (sim.unit == AngleUnit::kDegrees) {
    for (int r = 0; r < data->size(); ++r) {
      for (int i = 0; i < nominal.num_joints(); ++i) {
        if (nominal.joints[i].type == JointType::kRevolute) {
          data->mutable_q(r)[i] *= kDegreesPerRadian;
        }
      }
    }
  }
}

// Positions (and orientations) measured on the actual robot; the CSVs and models written.
int SimulatePositions(Simulation* sim) {
  const RobotModel& nominal = sim->nominal;
  SimulationOptions options;
  if (int rc = PositionOptionsFromFlags(*sim, &options); rc != kExitOk) return rc;
  MeasurementSet data = SimulateMeasurements(sim->actual, sim->errors.joint_zero, options);
  ToFileUnits(*sim, &data);

  std::ostringstream comment;
  comment << "lpoe_simulate: robot " << nominal.name << ", errors " << FLAGS_errors
          << ", joint errors " << FLAGS_joint_errors << ", noise sigma " << FLAGS_noise_sigma
          << " mm, seed " << FLAGS_seed << ", joint values in " << FLAGS_angle_unit
          << (sim->length_unit == LengthUnit::kMillimetres ? ""
                                                           : ", lengths in " + FLAGS_length_unit);
  MeasurementSet identification, verification;
  data.SplitAt(data.size() - FLAGS_verify_count, &identification, &verification);

  // The actual robot with the joint-zero errors folded in: T_i(0) <- T_i(0) exp(s_i dq_i).
  RobotModel actual_out = FoldJointZeros(sim->actual, sim->errors.joint_zero);
  actual_out.name = nominal.name + "_actual";

  struct Output {
    std::string path;
    std::string text;
  };
  std::vector<Output> outputs = {
      {FLAGS_output, MeasurementsToCsv(nominal, identification, comment.str())}};
  if (FLAGS_verify_count > 0) {
    outputs.push_back({FLAGS_verify_out, MeasurementsToCsv(nominal, verification, comment.str())});
  }
  if (!FLAGS_model_out.empty()) outputs.push_back({FLAGS_model_out, RobotModelToYaml(nominal)});
  if (!FLAGS_actual_out.empty()) {
    outputs.push_back({FLAGS_actual_out, RobotModelToYaml(actual_out)});
  }
  // Non-finite values are written nowhere (lpoe/model/refusals.h).
  for (const auto& [path, m] :
       {std::pair<const std::string*, const RobotModel*>{&FLAGS_model_out, &nominal},
        {&FLAGS_actual_out, &actual_out}}) {
    if (Status s = CheckModelFinite(*m); !path->empty() && !s.ok()) {
      std::cerr << "error: " << *path << ": " << s.message() << "\n";
      return tools::kExitNumerical;
    }
  }
  Status staged;
  for (const Output& o : outputs) {
    if (staged.ok()) staged = sim->files.Stage(o.path, o.text);
  }
  return tools::CommitOutputs(staged, &sim->files, FLAGS_quiet);
}

int Run() {
  Simulation sim;
  if (int rc = CheckCountsAndOutputs(&sim.files); rc != kExitOk) return rc;
  if (!tools::UnitsFromFlags(&sim.unit, &sim.length_unit, &sim.mm_per_unit)) return kExitUsage;
  if (int rc = NominalFromFlags(&sim.nominal); rc != kExitOk) return rc;
  if (int rc = ErrorsFromFlags(sim.nominal, &sim.errors); rc != kExitOk) return rc;
  if (int rc = JointPhysicsFromFlags(&sim); rc != kExitOk) return rc;
  MakeActualRobot(&sim);
  return FLAGS_measurement != "position" ? SimulateContacts(&sim) : SimulatePositions(&sim);
}

}  // namespace
}  // namespace lpoe

int main(int argc, char** argv) {
  lpoe::tools::InitTool(lpoe::kUsage, &argc, &argv);
  return lpoe::Run();
}
