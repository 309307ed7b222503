// Shared inputs of the benchmarks: the cobot6 model and simulated data sets, built once per size
// and kept for the whole run (fixtures must not regenerate 10^6 rows per benchmark).
#ifndef LPOE_BENCHMARKS_BENCHMARK_DATA_H_
#define LPOE_BENCHMARKS_BENCHMARK_DATA_H_

#include <cstdint>
#include <vector>

#include "lpoe/measurements/measurements.h"
#include "lpoe/model/robot_model.h"

namespace lpoe {
namespace bench {

// Configurations cycled through by the per-pose benchmarks (random in [-pi, pi]^n, so sin/cos see
// realistic arguments and no branch is trained on one value).
constexpr int kConfigurationPool = 1024;

// `count` random configurations of `model`, row-major (count x num_joints).
std::vector<double> RandomConfigurations(const RobotModel& model, int count, uint64_t seed);

// Position data of the paper's section 4 on cobot6 (Table 2 errors, 0.03 mm noise), `rows` rows,
// generated on first use and cached for the process.
const MeasurementSet& Cobot6Data(int rows);

}  // namespace bench
}  // namespace lpoe

#endif  // LPOE_BENCHMARKS_BENCHMARK_DATA_H_
