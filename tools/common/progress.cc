#include "common/progress.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <iostream>
#include <utility>

#include <unistd.h>

namespace lpoe {
namespace tools {

Progress::Progress(bool quiet, int max_iterations, ProgressOptions options)
    : quiet_(quiet),
      max_iterations_(max_iterations),
      options_(std::move(options)),
      out_(options_.out ? *options_.out : std::cerr),
      tty_(options_.terminal >= 0 ? options_.terminal == 1 : ::isatty(2) == 1),
      start_(Now()),
      stage_start_(start_),
      last_(start_) {}

Progress::~Progress() {
  if (shown_ && tty_) out_ << "\n" << std::flush;
}

double Progress::Now() const {
  if (options_.clock) return options_.clock();
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

bool Progress::Due() {
  if (quiet_) return false;
  const double now = Now();
  if (now - start_ < options_.delay_seconds) return false;
  const double period = tty_ ? options_.terminal_period : options_.plain_period;
  if (!first_ && now - last_ < period) return false;
  first_ = false;
  last_ = now;
  return true;
}

void Progress::Emit(const std::string& text) {
  shown_ = true;
  if (tty_) {
    out_ << "\r" << text << "\x1b[K" << std::flush;
  } else {
    out_ << text << "\n" << std::flush;
  }
}

void Progress::Rows(const std::string& what, long rows) {
  if (!Due()) return;
  const double t = Now() - start_;
  char line[256];
  std::snprintf(line, sizeof(line), "read %ld rows of %s, %.1f s", rows, what.c_str(), t);
  Emit(line);
}

void Progress::Iteration(const std::string& stage, const IterationRecord& r) {
  if (stage != stage_) {
    stage_ = stage;
    stage_start_ = Now();
  }
  if (!Due()) return;
  const double now = Now();
  const double t = now - start_;
  const double in_stage = now - stage_start_;
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
  stage_start_ = Now();
  first_ = true;  // a new stage is shown at once (once the run is past the quiet period)
  if (!Due()) return;
  char line[256];
  std::snprintf(line, sizeof(line), "%s, %.1f s elapsed", stage.c_str(), Now() - start_);
  Emit(line);
}

}  // namespace tools
}  // namespace lpoe
