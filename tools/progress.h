// Progress of long runs on stderr: after ~2 s, a line updated in place when stderr is a terminal
// (stage, iteration, cost, max error, elapsed, time left at most), else a plain line every 10 s.
// Silent with `quiet`.
#ifndef LPOE_TOOLS_PROGRESS_H_
#define LPOE_TOOLS_PROGRESS_H_

#include <chrono>
#include <string>

#include "lpoe/calibration.h"

namespace lpoe {
namespace tools {

class Progress {
 public:
  // `max_iterations`: bound of the time-left estimate.
  Progress(bool quiet, int max_iterations);
  ~Progress();  // ends an in-place line
  // After reading the inputs.
  void Rows(const std::string& what, long rows);
  void Iteration(const std::string& stage, const IterationRecord& r);
  // A stage without iterations (registration, analysis).
  void Stage(const std::string& stage);

 private:
  using Clock = std::chrono::steady_clock;
  bool Due();
  void Emit(const std::string& text);
  bool quiet_, tty_;
  int max_iterations_;
  Clock::time_point start_ = Clock::now(), stage_start_ = Clock::now(), last_ = Clock::now();
  std::string stage_;
  bool shown_ = false;
  bool first_ = true;
};

}  // namespace tools
}  // namespace lpoe

#endif  // LPOE_TOOLS_PROGRESS_H_
