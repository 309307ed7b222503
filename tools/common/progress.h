// Progress of long runs on stderr: after ~2 s, a line updated in place when stderr is a terminal
// (stage, iteration, cost, max error, elapsed, time left at most), else a plain line every 10 s.
// Silent with `quiet`.
#ifndef LPOE_TOOLS_PROGRESS_H_
#define LPOE_TOOLS_PROGRESS_H_

#include <functional>
#include <iosfwd>
#include <string>

#include "lpoe/calibration.h"

namespace lpoe {
namespace tools {

struct ProgressOptions {
  double delay_seconds = 2.0;     // shorter runs show nothing
  double terminal_period = 0.2;   // seconds between in-place updates on a terminal
  double plain_period = 10.0;     // seconds between plain lines otherwise
  std::ostream* out = nullptr;    // null: std::cerr
  int terminal = -1;              // 1 / 0: whether `out` is a terminal; -1: isatty(2)
  std::function<double()> clock;  // seconds; empty: std::chrono::steady_clock
};

class Progress {
 public:
  // `max_iterations`: bound of the time-left estimate.
  Progress(bool quiet, int max_iterations, ProgressOptions options = ProgressOptions());
  ~Progress();  // ends an in-place line
  // After reading the inputs.
  void Rows(const std::string& what, long rows);
  void Iteration(const std::string& stage, const IterationRecord& r);
  // A stage without iterations (registration, analysis).
  void Stage(const std::string& stage);

 private:
  double Now() const;
  bool Due();
  void Emit(const std::string& text);
  bool quiet_;
  int max_iterations_;
  ProgressOptions options_;
  std::ostream& out_;
  bool tty_;
  double start_, stage_start_, last_;
  std::string stage_;
  bool shown_ = false;
  bool first_ = true;
};

}  // namespace tools
}  // namespace lpoe

#endif  // LPOE_TOOLS_PROGRESS_H_
