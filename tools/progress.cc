#include "progress.h"

#include <algorithm>
#include <cstdio>
#include <iostream>
#include <unistd.h>

namespace lpoe {
namespace tools {
namespace {
constexpr double kQuietSeconds = 2.0;       // shorter runs show nothing
constexpr double kTerminalPeriod = 0.2;     // seconds between in-place updates
constexpr double kPlainPeriod = 10.0;       // seconds between plain lines
}  // namespace

Progress::Progress(bool quiet, int max_iterations)
    : quiet_(quiet), tty_(::isatty(2) == 1), max_iterations_(max_iterations) {}

Progress::~Progress() {
  if (shown_ && tty_) std::cerr << "\n";
}

bool Progress::Due() {
  if (quiet_) return false;
  const Clock::time_point now = Clock::now();
  if (std::chrono::duration<double>(now - start_).count() < kQuietSeconds) return false;
  const double period = tty_ ? kTerminalPeriod : kPlainPeriod;
  if (!first_ && std::chrono::duration<double>(now - last_).count() < period) return false;
  first_ = false;
  last_ = now;
  return true;
}

void Progress::Emit(const std::string& text) {
  shown_ = true;
  if (tty_) {
    std::cerr << "\r" << text << "\x1b[K" << std::flush;
  } else {
    std::cerr << text << "\n";
  }
}

void Progress::Rows(const std::string& what, long rows) {
  if (!Due()) return;
  const double t = std::chrono::duration<double>(Clock::now() - start_).count();
  char line[256];
  std::snprintf(line, sizeof(line), "read %ld rows of %s, %.1f s", rows, what.c_str(), t);
  Emit(line);
}

void Progress::Iteration(const std::string& stage, const IterationRecord& r) {
  if (stage != stage_) {
    stage_ = stage;
    stage_start_ = Clock::now();
  }
  if (!Due()) return;
  const Clock::time_point now = Clock::now();
  const double t = std::chrono::duration<double>(now - start_).count();
  const double in_stage = std::chrono::duration<double>(now - stage_start_).count();
  const double per_iteration = r.iteration > 0 ? in_stage / r.iteration : 0;
  const double left = per_iteration * std::max(0, max_iterations_ - r.iteration);
  char line[256];
  std::snprintf(line, sizeof(line), "%s: iteration %d, cost %.6g, max error %.4g mm, %.1f s elapsed",
                stage.c_str(), r.iteration, r.cost, r.max_error, t);
  std::string text = line;
  if (r.iteration > 0) {
    std::snprintf(line, sizeof(line), ", at most %.0f s left", left);
    text += line;
  }
  Emit(text);
}

void Progress::Stage(const std::string& stage) {
  stage_ = stage;
  stage_start_ = Clock::now();
  first_ = true;  // a new stage is shown at once (once the run is past the quiet period)
  if (!Due()) return;
  char line[256];
  std::snprintf(line, sizeof(line), "%s, %.1f s elapsed", stage.c_str(),
                std::chrono::duration<double>(Clock::now() - start_).count());
  Emit(line);
}

}  // namespace tools
}  // namespace lpoe
