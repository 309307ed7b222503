// Per-pose kinematics of the cobot6 chain: forward kinematics (pose and position only, double and
// ceres::Jet), the position Jacobian in the identifiable basis (3 x 27), the cost of the sin/cos
// calls alone (the floor of position-only FK), and, when KDL is available, the same chain through
// KDL's ChainFkSolverPos_recursive and ChainJntToJacSolver in the same binary. main() first checks
// that KDL's forward kinematics equals ours to 1e-9 on every configuration used, so that the
// comparison is between two evaluations of the same chain.
//
// Every benchmark cycles through kConfigurationPool random configurations; times are per pose.
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include <benchmark/benchmark.h>
#include <ceres/jet.h>

#include "benchmark_data.h"
#include "lpoe/kinematics/kinematics.h"
#include "lpoe/model/parameterization.h"
#include "lpoe/model/robot_model.h"

#ifdef LPOE_HAVE_KDL
#include <kdl/chain.hpp>
#include <kdl/chainfksolverpos_recursive.hpp>
#include <kdl/chainjnttojacsolver.hpp>
#include <kdl/frames.hpp>
#include <kdl/jntarray.hpp>
#include <kdl/jacobian.hpp>

#include "kdl_chain.h"
#endif

namespace lpoe {
namespace {

using bench::kConfigurationPool;
// Jet width of the Ceres position residual (PositionResidual::kStride).
using Jet2 = ceres::Jet<double, 2>;

// The model, its prepared evaluators and the configuration pool, built once for the whole run.
struct Cobot6 {
  RobotModel model = MakeCobot6();
  Parameterization identifiable =
      MakeParameterization(model, ParameterizationKind::kIdentifiable, DataKind::kPosition);
  KinematicChain chain{model};
  BasisJacobian jacobian{model, identifiable};
  std::vector<double> q = bench::RandomConfigurations(model, kConfigurationPool, 17);
  const double* Q(int k) const { return q.data() + static_cast<size_t>(k) * model.num_joints(); }
};

const Cobot6& Robot() {
  static const Cobot6 robot;
  return robot;
}

class Kinematics : public benchmark::Fixture {
 public:
  void SetUp(const benchmark::State&) override { robot_ = &Robot(); }

 protected:
  const Cobot6* robot_ = nullptr;
};

// The reference for position-only FK: the 6 sin/cos pairs it cannot avoid.
BENCHMARK_DEFINE_F(Kinematics, BM_SinCos6)(benchmark::State& state) {
  int k = 0;
  for (auto _ : state) {
    const double* q = robot_->Q(k);
    double s[6], c[6];
    for (int i = 0; i < 6; ++i) SinCos(q[i], &s[i], &c[i]);
    benchmark::DoNotOptimize(s);
    benchmark::DoNotOptimize(c);
    k = (k + 1) & (kConfigurationPool - 1);
  }
}
BENCHMARK_REGISTER_F(Kinematics, BM_SinCos6);

// T_0,tool(q) through the public convenience function (checks joint kinds per call).
BENCHMARK_DEFINE_F(Kinematics, BM_ToolPose)(benchmark::State& state) {
  int k = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(ToolPose(robot_->model, robot_->Q(k)));
    k = (k + 1) & (kConfigurationPool - 1);
  }
}
BENCHMARK_REGISTER_F(Kinematics, BM_ToolPose);

// T_0,tool(q) on the prepared chain (joint kinds decided once).
BENCHMARK_DEFINE_F(Kinematics, BM_ChainPoseFast)(benchmark::State& state) {
  int k = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(robot_->chain.Pose(robot_->Q(k)));
    k = (k + 1) & (kConfigurationPool - 1);
  }
}
BENCHMARK_REGISTER_F(Kinematics, BM_ChainPoseFast);

BENCHMARK_DEFINE_F(Kinematics, BM_ToolPosition)(benchmark::State& state) {
  int k = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(ToolPosition(robot_->model, robot_->Q(k)));
    k = (k + 1) & (kConfigurationPool - 1);
  }
}
BENCHMARK_REGISTER_F(Kinematics, BM_ToolPosition);

BENCHMARK_DEFINE_F(Kinematics, BM_ChainPositionFast)(benchmark::State& state) {
  int k = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(robot_->chain.Position(robot_->Q(k)));
    k = (k + 1) & (kConfigurationPool - 1);
  }
}
BENCHMARK_REGISTER_F(Kinematics, BM_ChainPositionFast);

// The templated chain on doubles (what autodiff code calls), for comparison with the fast paths.
BENCHMARK_DEFINE_F(Kinematics, BM_ChainPoseTemplateDouble)(benchmark::State& state) {
  std::vector<SE3d> origins;
  for (const Joint& j : robot_->model.joints) origins.push_back(j.origin);
  const SE3d tool = robot_->model.tools[0].origin;
  int k = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(ChainPose(robot_->model, origins.data(), tool, robot_->Q(k)));
    k = (k + 1) & (kConfigurationPool - 1);
  }
}
BENCHMARK_REGISTER_F(Kinematics, BM_ChainPoseTemplateDouble);

BENCHMARK_DEFINE_F(Kinematics, BM_ChainPositionTemplateDouble)(benchmark::State& state) {
  std::vector<SE3d> origins;
  for (const Joint& j : robot_->model.joints) origins.push_back(j.origin);
  const Eigen::Vector3d tool = robot_->model.tools[0].origin.t;
  int k = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(ChainPosition(robot_->model, origins.data(), tool, robot_->Q(k)));
    k = (k + 1) & (kConfigurationPool - 1);
  }
}
BENCHMARK_REGISTER_F(Kinematics, BM_ChainPositionTemplateDouble);

// Frames as Jets carrying 2 derivative components (one autodiff pass of the Ceres residual).
void JetFrames(const RobotModel& m, std::vector<SE3<Jet2>>* origins, SE3<Jet2>* tool) {
  origins->clear();
  for (int i = 0; i < m.num_joints(); ++i) {
    SE3<Jet2> X = m.joints[i].origin.cast<Jet2>();
    X.t(0).v(i % 2) = 1.0;
    origins->push_back(X);
  }
  *tool = m.tools[0].origin.cast<Jet2>();
  tool->t(2).v(1) = 1.0;
}

BENCHMARK_DEFINE_F(Kinematics, BM_ChainPoseJet2)(benchmark::State& state) {
  std::vector<SE3<Jet2>> origins;
  SE3<Jet2> tool;
  JetFrames(robot_->model, &origins, &tool);
  int k = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(ChainPose(robot_->model, origins.data(), tool, robot_->Q(k)));
    k = (k + 1) & (kConfigurationPool - 1);
  }
}
BENCHMARK_REGISTER_F(Kinematics, BM_ChainPoseJet2);

BENCHMARK_DEFINE_F(Kinematics, BM_ChainPositionJet2)(benchmark::State& state) {
  std::vector<SE3<Jet2>> origins;
  SE3<Jet2> tool;
  JetFrames(robot_->model, &origins, &tool);
  int k = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(ChainPosition(robot_->model, origins.data(), tool.t, robot_->Q(k)));
    k = (k + 1) & (kConfigurationPool - 1);
  }
}
BENCHMARK_REGISTER_F(Kinematics, BM_ChainPositionJet2);

// P and dP/dx, 3 x 27 in the identifiable basis (what the linear solver evaluates per pose).
BENCHMARK_DEFINE_F(Kinematics, BM_PositionJacobian3x27)(benchmark::State& state) {
  const int P = robot_->jacobian.num_parameters();
  std::vector<double> J(3 * P);
  std::vector<FrameRt> frames(robot_->model.num_joints() + 1);
  int k = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(robot_->jacobian.Position(robot_->Q(k), 0, J.data(), 3, frames.data()));
    benchmark::ClobberMemory();
    k = (k + 1) & (kConfigurationPool - 1);
  }
  state.counters["parameters"] = P;
}
BENCHMARK_REGISTER_F(Kinematics, BM_PositionJacobian3x27);

// The public 3 x 42 frame Jacobian (eq. (29), every direction of every frame).
BENCHMARK_DEFINE_F(Kinematics, BM_ToolPositionJacobian3x42)(benchmark::State& state) {
  Eigen::MatrixXd J;
  int k = 0;
  for (auto _ : state) {
    benchmark::DoNotOptimize(ToolPositionJacobian(robot_->model, robot_->Q(k), 0, &J));
    benchmark::ClobberMemory();
    k = (k + 1) & (kConfigurationPool - 1);
  }
}
BENCHMARK_REGISTER_F(Kinematics, BM_ToolPositionJacobian3x42);

#ifdef LPOE_HAVE_KDL
using bench::KdlChain;

struct KdlCobot6 {
  KDL::Chain chain = KdlChain(Robot().model);
  KDL::ChainFkSolverPos_recursive fk{chain};
  KDL::ChainJntToJacSolver jac{chain};
  std::vector<KDL::JntArray> q;
  KdlCobot6() {
    const Cobot6& r = Robot();
    for (int k = 0; k < kConfigurationPool; ++k) {
      KDL::JntArray a(r.model.num_joints());
      for (int i = 0; i < r.model.num_joints(); ++i) a(i) = r.Q(k)[i];
      q.push_back(a);
    }
  }
};

KdlCobot6& Kdl() {
  static KdlCobot6 kdl;
  return kdl;
}

// KDL's FK equals ours (pose, every pool configuration) to `tolerance` (mm and rotation entries).
bool KdlAgrees(double tolerance, double* worst) {
  const Cobot6& r = Robot();
  KdlCobot6& kdl = Kdl();
  *worst = 0;
  for (int k = 0; k < kConfigurationPool; ++k) {
    KDL::Frame F;
    if (kdl.fk.JntToCart(kdl.q[k], F) < 0) return false;
    const SE3d T = ToolPose(r.model, r.Q(k));
    for (int a = 0; a < 3; ++a) {
      *worst = std::max(*worst, std::abs(F.p(a) - T.t(a)));
      for (int b = 0; b < 3; ++b) *worst = std::max(*worst, std::abs(F.M(a, b) - T.R(a, b)));
    }
  }
  return *worst <= tolerance;
}

void BM_KdlChainFkSolverPos(benchmark::State& state) {
  KdlCobot6& kdl = Kdl();
  KDL::Frame F;
  int k = 0;
  for (auto _ : state) {
    kdl.fk.JntToCart(kdl.q[k], F);
    benchmark::DoNotOptimize(F);
    k = (k + 1) & (kConfigurationPool - 1);
  }
}
BENCHMARK(BM_KdlChainFkSolverPos);

// The 6 x 6 geometric joint Jacobian (a different quantity from ours, the nearest KDL offers).
void BM_KdlChainJntToJacSolver(benchmark::State& state) {
  KdlCobot6& kdl = Kdl();
  KDL::Jacobian J(static_cast<unsigned>(Robot().model.num_joints()));
  int k = 0;
  for (auto _ : state) {
    kdl.jac.JntToJac(kdl.q[k], J);
    benchmark::DoNotOptimize(J.data.data());
    benchmark::ClobberMemory();
    k = (k + 1) & (kConfigurationPool - 1);
  }
}
BENCHMARK(BM_KdlChainJntToJacSolver);
#endif  // LPOE_HAVE_KDL

}  // namespace
}  // namespace lpoe

int main(int argc, char** argv) {
#ifdef LPOE_HAVE_KDL
  constexpr double kKdlTolerance = 1e-9;
  double worst = 0;
  if (!lpoe::KdlAgrees(kKdlTolerance, &worst)) {
    std::fprintf(stderr, "KDL's forward kinematics differs from lpoe's by %g (limit %g): the KDL "
                 "chain does not model cobot6; refusing to compare\n", worst, kKdlTolerance);
    return 1;
  }
  std::fprintf(stderr, "KDL check: forward kinematics agree to %.2g on %d configurations\n", worst,
               lpoe::bench::kConfigurationPool);
#endif
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
