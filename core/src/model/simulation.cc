#include "lpoe/model/simulation.h"

#include <algorithm>
#include <cmath>
#include <random>

#include <glog/logging.h>

#include "terms/joint_term_kind.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/measurements/measurement_kind_dispatch.h"

namespace lpoe {
namespace {

// Portable random numbers: the standard distributions are implementation-defined, and data sets
// generated from a seed must be the same everywhere.
class Random {
 public:
  explicit Random(uint64_t seed) : engine_(seed) {}
  double Uniform() { return static_cast<double>(engine_() >> 11) * 0x1.0p-53; }  // [0, 1)
  double Uniform(double lo, double hi) { return lo + (hi - lo) * Uniform(); }
  double Gaussian() {  // Box-Muller
    if (has_spare_) {
      has_spare_ = false;
      return spare_;
    }
    double u1 = Uniform();
    while (u1 <= 0.0) u1 = Uniform();
    const double u2 = Uniform();
    const double r = std::sqrt(-2.0 * std::log(u1));
    spare_ = r * std::sin(2 * kPi * u2);
    has_spare_ = true;
    return r * std::cos(2 * kPi * u2);
  }

 private:
  std::mt19937_64 engine_;
  bool has_spare_ = false;
  double spare_ = 0;
};

// Makes a twist valid for its joint type: unit omega with omega . v = 0, or omega = 0 and unit v.
Vector6d NormalizeTwist(JointType type, Vector6d s) {
  if (type == JointType::kRevolute) {
    Eigen::Vector3d w = s.head<3>().normalized();
    Eigen::Vector3d v = s.tail<3>();
    v -= w.dot(v) * w;
    s << w, v;
  } else {
    s.head<3>().setZero();
    s.tail<3>().normalize();
  }
  return s;
}

}  // namespace

KinematicErrors PaperTable2Errors() {
  KinematicErrors e;
  const double dp[7][6] = {{0, 0.001, 0.002, 2, 1.5, 0.5},      {0, 0.002, 0.003, -2, 1.2, 2.4},
                           {0.001, 0.004, 0.003, 2, -1, 2},     {0.001, 0.005, 0.002, 2, 1.5, -1},
                           {0.002, 0.003, 0, -1, 1.6, 2.3},     {0.003, 0.001, -0.004, 2, 3, 1},
                           {0.005, 0.002, -0.003, 1.6, 2, 3.2}};
  for (const auto& row : dp) e.frame.push_back(Eigen::Map<const Vector6d>(row));
  // Table 2's ds' column is written (v, omega) (docs/conventions.md): its non-zero entries tilt the
  // unit rotation axis. Stored here in our (omega, v) order.
  auto tilt = [](double wx, double wy, double wz) {
    Vector6d s;
    s << wx, wy, wz, 0, 0, 0;
    return s;
  };
  e.twist = {tilt(0, std::sin(0.01), -1 + std::cos(0.01)),
             tilt(0, -std::sin(0.015), -1 + std::cos(0.015)),
             tilt(std::sin(0.023), 0, -1 + std::cos(0.023)),
             tilt(-std::sin(0.004), 0, -1 + std::cos(0.004)),
             tilt(0, std::sin(0.031), -1 + std::cos(0.031)),
             tilt(std::sin(0.013), 0, -1 + std::cos(0.013))};
  e.joint_zero = {0, 0.03, 0.01, 0.02, 0.015, 0.02};
  return e;
}

KinematicErrors RandomErrors(const RobotModel& model, double rot, double trans, double tilt,
                             double zero, uint64_t seed) {
  Random rng(seed);
  KinematicErrors e;
  for (int f = 0; f < model.num_frames(); ++f) {
    Vector6d d;
    for (int k = 0; k < 3; ++k) d(k) = rng.Uniform(-rot, rot);
    for (int k = 3; k < 6; ++k) d(k) = rng.Uniform(-trans, trans);
    e.frame.push_back(d);
  }
  for (const Joint& j : model.joints) {
    // Tilt the axis (rotation part for revolute, direction for prismatic) about a random
    // perpendicular by an angle in [-tilt, tilt].
    const Eigen::Vector3d axis =
        j.type == JointType::kRevolute ? j.twist.head<3>() : j.twist.tail<3>();
    // Drawn one by one: the order in which a constructor's arguments are evaluated is unspecified
    // (gcc goes right to left, clang left to right), and a simulation must not depend on the
    // compiler. This is gcc's order, so that the figures computed so far stay as they were.
    const double rz = rng.Gaussian();
    const double ry = rng.Gaussian();
    const double rx = rng.Gaussian();
    Eigen::Vector3d r(rx, ry, rz);
    r -= r.dot(axis) * axis;
    r.normalize();
    const Eigen::Vector3d tilted = ExpSO3(Eigen::Vector3d(rng.Uniform(-tilt, tilt) * r)) * axis;
    Vector6d ds = Vector6d::Zero();
    if (j.type == JointType::kRevolute) {
      ds.head<3>() = tilted - axis;
    } else {
      ds.tail<3>() = tilted - axis;
    }
    e.twist.push_back(ds);
    e.joint_zero.push_back(rng.Uniform(-zero, zero));
  }
  return e;
}

RobotModel ApplyErrors(const RobotModel& nominal, const KinematicErrors& errors) {
  CHECK_EQ(static_cast<int>(errors.frame.size()), nominal.num_frames());
  CHECK_EQ(static_cast<int>(errors.twist.size()), nominal.num_joints());
  RobotModel actual = nominal;
  const int n = nominal.num_joints();
  for (int f = 0; f < nominal.num_frames(); ++f) {
    SE3d& T = f < n ? actual.joints[f].origin : actual.tools[f - n].origin;
    T = T * ExpSE3(errors.frame[f]);  // eq. (33)
  }
  for (int i = 0; i < n; ++i) {
    Joint& j = actual.joints[i];
    j.twist = NormalizeTwist(j.type, j.twist + errors.twist[i]);
  }
  return actual;
}

JointErrorPhysics SmallArmJointErrors(const RobotModel& model, const SmallArmOptions& options) {
  const int n = model.num_joints();
  CHECK(options.stiffness.empty() || static_cast<int>(options.stiffness.size()) == n);
  Random rng(options.seed);
  JointErrorPhysics physics;
  physics.seed = options.seed;
  for (int k = 0; k < n; ++k) {
    physics.stiffness.push_back(!options.stiffness.empty() ? options.stiffness[k]
                                : k < 2                    ? 2e4
                                : k == 2                   ? 3e3
                                                           : 1.5e3);
    const Eigen::Vector3d next =
        k + 1 < n ? model.joints[k + 1].origin.t : model.tools[0].origin.t;  // link k's frame
    constexpr double kBaseMassKg = 0.1, kMassPerMetre = 1.25, kComJitterMm = 10.0;
    physics.link_mass.push_back(options.mass_scale *
                                (kBaseMassKg + kMassPerMetre * 1e-3 * next.norm()));
    Eigen::Vector3d com = 0.5 * next;
    for (int a = 0; a < 3; ++a) com(a) += rng.Uniform(-kComJitterMm, kComJitterMm);
    physics.link_com.push_back(com);
  }
  for (int k = 0; k < n; ++k) {
    Eigen::Vector4d h = Eigen::Vector4d::Zero();
    if (model.joints[k].type == JointType::kRevolute) {
      for (int order = 0; order < 2; ++order) {
        const double amplitude = rng.Uniform(options.harmonics_min, options.harmonics_max);
        const double phase = rng.Uniform(-kPi, kPi);
        h(2 * order) = amplitude * std::cos(phase);      // sin coefficient
        h(2 * order + 1) = amplitude * std::sin(phase);  // cos coefficient
      }
    }
    physics.harmonics.push_back(h);
  }
  return physics;
}

void ApplyJointErrorPhysics(const JointErrorPhysics& physics, const std::vector<std::string>& terms,
                            RobotModel* actual) {
  CHECK_EQ(static_cast<int>(physics.stiffness.size()), actual->num_joints());
  for (const std::string& name : terms) {
    const internal::JointTermKind* kind = internal::FindJointTermKind(name);
    CHECK(kind != nullptr) << "unknown joint error term '" << name << "'";
    *actual->joint_errors.MutableValues(name) = kind->Simulate(*actual, physics);
  }
}

RobotModel FoldJointZeros(const RobotModel& actual, const std::vector<double>& joint_zero) {
  CHECK_EQ(static_cast<int>(joint_zero.size()), actual.num_joints());
  RobotModel out = actual;
  // Each term rewritten for the commanded angle; what it leaves over joins the joint zero.
  std::vector<double> zero = joint_zero;
  for (JointTermEntry& t : out.joint_errors.terms) {
    if (t.values.empty()) continue;
    const internal::JointTermKind* kind = internal::FindJointTermKind(t.name);
    CHECK(kind != nullptr) << "unknown joint error term '" << t.name << "'";
    std::vector<double> extra(joint_zero.size(), 0.0);
    kind->FoldJointZeros(actual, joint_zero, &t.values, &extra);
    for (size_t j = 0; j < zero.size(); ++j) zero[j] += extra[j];
  }
  for (int i = 0; i < out.num_joints(); ++i) {
    out.joints[i].origin = out.joints[i].origin * JointMotion(out.joints[i], zero[i]);
  }
  return out;
}

MeasurementSet SimulateMeasurements(const RobotModel& actual, const std::vector<double>& joint_zero,
                                    const SimulationOptions& options) {
  const int n = actual.num_joints();
  CHECK(joint_zero.empty() || static_cast<int>(joint_zero.size()) == n);
  std::vector<double> lo = options.lower, hi = options.upper;
  if (lo.empty()) {
    for (const Joint& j : actual.joints) {
      // The default window, within the joint's limits (shifted inside them when disjoint).
      const double width = j.type == JointType::kRevolute ? 2 * kPi : 200.0;
      double a = std::max(-width / 2, j.lower), b = std::min(width / 2, j.upper);
      if (a > b) {
        a = std::isfinite(j.lower) ? j.lower : j.upper - width;
        b = std::isfinite(j.upper) ? j.upper : j.lower + width;
      }
      lo.push_back(a);
      hi.push_back(b);
    }
  }
  CHECK_EQ(static_cast<int>(lo.size()), n);
  CHECK_EQ(static_cast<int>(hi.size()), n);

  Random rng(options.seed);
  MeasurementSet data(n);
  const std::vector<double>& given = options.configurations;
  CHECK_EQ(given.size() % std::max(n, 1), 0u);
  // Given configurations: every tool at each (all_tools) or tool 0; otherwise random ones.
  const int tools_per_pose = !given.empty() && options.all_tools ? actual.num_tools() : 1;
  const int count = given.empty() ? options.count : static_cast<int>(given.size() / n) * tools_per_pose;
  data.Reserve(count);
  std::vector<double> q(n), q_actual(n), q_effective(n);
  // The rows' measurement kind (position, or pose with options.pose) simulates each row's reading
  // (its header's Simulate): chosen once.
  VisitTrackerKind(TrackerKindId(options.pose), [&](auto tag) {
    using Kind = typename decltype(tag)::type;
    for (int r = 0; r < count; ++r) {
      for (int i = 0; i < n; ++i) {
        q[i] = given.empty() ? rng.Uniform(lo[i], hi[i]) : given[(r / tools_per_pose) * n + i];
        q_actual[i] = q[i] + (joint_zero.empty() ? 0.0 : joint_zero[i]);
      }
      const int target = options.all_tools ? r % actual.num_tools() : 0;
      EffectiveJoints(actual, q_actual.data(), q_effective.data());
      Kind::Simulate(ToolPose(actual, q_effective.data(), target),  // eq. (34)
                     q.data(), target, options.noise_sigma, options.orientation_noise_sigma,
                     [&rng] { return rng.Gaussian(); }, &data);
    }
  });
  return data;
}

}  // namespace lpoe
