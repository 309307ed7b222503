// The one CPU dispatch of the kernels (lpoe/kinematics/kernels.h).
#include <atomic>
#include <cstdlib>
#include <cstring>

#include <glog/logging.h>

#include "lpoe/kinematics/kernels.h"

namespace lpoe {
namespace kernels {
namespace {

Path Detect() {
  const char* env = std::getenv("LPOE_KERNELS");
  if (env != nullptr && std::strcmp(env, "reference") == 0) return Path::kReference;
  if (env != nullptr && env[0] != '\0' && std::strcmp(env, "auto") != 0) {
    LOG(WARNING) << "LPOE_KERNELS=" << env << " is neither 'reference' nor 'auto': using 'auto'";
  }
  return ProcessorHasAvx2Fma() ? Path::kAvx2Fma : Path::kReference;
}

std::atomic<int>& Current() {
  static std::atomic<int> path{static_cast<int>(Detect())};
  return path;
}

}  // namespace

bool ProcessorHasAvx2Fma() {
#if defined(__x86_64__) && defined(__GNUC__)
  static const bool have = __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
  return have;
#else
  return false;
#endif
}

Path Active() { return static_cast<Path>(Current().load(std::memory_order_relaxed)); }

Path SetForTesting(Path path) {
  if (path == Path::kAvx2Fma && !ProcessorHasAvx2Fma()) path = Path::kReference;
  return static_cast<Path>(Current().exchange(static_cast<int>(path)));
}

}  // namespace kernels
}  // namespace lpoe
