#include "benchmark_data.h"

#include <cmath>
#include <map>
#include <memory>
#include <mutex>
#include <random>

#include "lpoe/model/simulation.h"

namespace lpoe {
namespace bench {

std::vector<double> RandomConfigurations(const RobotModel& model, int count, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> angle(-M_PI, M_PI);
  std::vector<double> q(static_cast<size_t>(count) * model.num_joints());
  for (double& v : q) v = angle(rng);
  return q;
}

const MeasurementSet& Cobot6Data(int rows) {
  static std::mutex mutex;
  static std::map<int, std::unique_ptr<MeasurementSet>> cache;
  std::lock_guard<std::mutex> lock(mutex);
  std::unique_ptr<MeasurementSet>& slot = cache[rows];
  if (!slot) {
    const RobotModel nominal = MakeCobot6();
    const KinematicErrors errors = PaperTable2Errors();
    const RobotModel actual = ApplyErrors(nominal, errors);
    SimulationOptions options;
    options.count = rows;
    options.noise_sigma = 0.03;
    options.seed = 1;
    slot = std::make_unique<MeasurementSet>(
        SimulateMeasurements(actual, errors.joint_zero, options));
  }
  return *slot;
}

}  // namespace bench
}  // namespace lpoe
