// The progress display (tools/common/progress.h) on a simulated clock: nothing before the delay, then plain
// lines at most once per period (stderr not a terminal) or one line updated in place (a terminal),
// a new stage shown at once, nothing at all with --quiet.
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "common/progress.h"

namespace lpoe {
namespace tools {
namespace {
namespace progress_test {

struct Fake {
  double now = 0;
  std::ostringstream out;
  ProgressOptions Options(bool terminal) {
    ProgressOptions o;
    o.out = &out;
    o.terminal = terminal ? 1 : 0;
    o.clock = [this] { return now; };
    return o;
  }
};

IterationRecord Record(int iteration) {
  IterationRecord r;
  r.iteration = iteration;
  r.cost = 100.0 / (iteration + 1);
  r.max_error = 1.5;
  return r;
}

// Drives a 40 s run: rows read at 0.5 s, then one iteration per 0.1 s from 1 s on, a stage change
// at 30 s.
void Drive(Fake* f, Progress* p) {
  f->now = 0.5;
  p->Rows("points.csv", 123456);
  for (int it = 1; it <= 390; ++it) {
    f->now = 1.0 + 0.1 * it;
    if (it == 290) p->Stage("analysing");
    p->Iteration(it < 290 ? "calibrating" : "fold 1", Record(it < 290 ? it : it - 290));
  }
}

std::vector<std::string> Lines(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) lines.push_back(line);
  return lines;
}

TEST(Progress, PlainLinesAfterTheDelayAtMostOncePerPeriod) {
  Fake f;
  {
    Progress p(false, 300, f.Options(false));
    Drive(&f, &p);
  }
  const std::vector<std::string> lines = Lines(f.out.str());
  // Rows at 0.5 s: before the 2 s delay, not shown. Then 2.0 s (first), 12 s, 22 s, 30 s (the new
  // stage is shown at once), 30 s (its first iteration is within the period: not shown), 40 s.
  ASSERT_EQ(lines.size(), 5u) << f.out.str();
  EXPECT_EQ(lines[0].rfind("calibrating: iteration 10, cost ", 0), 0u) << lines[0];
  // The stage started at 1.1 s: 0.09 s per iteration, 290 left.
  EXPECT_NE(lines[0].find("max error 1.5 mm, 2.0 s elapsed, at most 26 s left"), std::string::npos)
      << lines[0];
  EXPECT_EQ(lines[1].rfind("calibrating: iteration 110,", 0), 0u) << lines[1];
  EXPECT_EQ(lines[2].rfind("calibrating: iteration 210,", 0), 0u) << lines[2];
  EXPECT_EQ(lines[3], "analysing, 30.0 s elapsed");
  EXPECT_EQ(lines[4].rfind("fold 1: iteration 100,", 0), 0u) << lines[4];
  EXPECT_EQ(f.out.str().find('\r'), std::string::npos);
}

TEST(Progress, TerminalLineIsUpdatedInPlaceAndEnded) {
  Fake f;
  {
    Progress p(false, 300, f.Options(true));
    Drive(&f, &p);
  }
  const std::string text = f.out.str();
  size_t updates = 0;
  for (size_t at = text.find('\r'); at != std::string::npos; at = text.find('\r', at + 1)) {
    ++updates;
  }
  // From 2.0 s to 40 s, at least 0.2 s apart and at most 0.3 s (iterations come every 0.1 s, plus
  // the new stage at once): between 127 and 191 updates, each cleared to the end of the line.
  EXPECT_GE(updates, 127u);
  EXPECT_LE(updates, 191u);
  size_t clears = 0;
  for (size_t at = text.find("\x1b[K"); at != std::string::npos; at = text.find("\x1b[K", at + 1)) {
    ++clears;
  }
  EXPECT_EQ(clears, updates);
  // One line in all: a single newline, at the end.
  EXPECT_EQ(text.find('\n'), text.size() - 1);
}

TEST(Progress, RowsAreShownOnceTheRunIsLong) {
  Fake f;
  Progress p(false, 30, f.Options(false));
  f.now = 3.0;
  p.Rows("big.csv", 5000000);
  EXPECT_EQ(f.out.str(), "read 5000000 rows of big.csv, 3.0 s\n");
}

TEST(Progress, QuietShowsNothing) {
  Fake f;
  {
    Progress p(true, 300, f.Options(true));
    Drive(&f, &p);
  }
  EXPECT_EQ(f.out.str(), "");
}

TEST(Progress, ShortRunsShowNothing) {
  Fake f;
  {
    Progress p(false, 300, f.Options(true));
    for (int it = 1; it <= 19; ++it) {
      f.now = 0.1 * it;
      p.Iteration("calibrating", Record(it));
    }
  }
  EXPECT_EQ(f.out.str(), "");
}

}  // namespace progress_test
}  // namespace
}  // namespace tools
}  // namespace lpoe
