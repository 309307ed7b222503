// The checks shared by the program parsers' libFuzzer targets (fuzz_urscript.cc, fuzz_rapid.cc):
// no crash; errors are "line N: ..." messages; every number of every target record lies in the
// text, no two overlap, and the text there reads back as the value; rewriting every record with
// other values and parsing the result gives the same records with those values (to the decimals
// each is rewritten with).
#ifndef LPOE_FUZZ_FUZZ_PROGRAM_H_
#define LPOE_FUZZ_FUZZ_PROGRAM_H_

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "fuzz_common.h"
#include "lpoe/program.h"

namespace lpoe {
namespace fuzz {

inline void CheckLineError(const Status& s) {
  const std::string& m = s.message();
  if (m.compare(0, 5, "line ") != 0) Fail("program error without 'line N: '", m);
  size_t k = 5;
  while (k < m.size() && m[k] >= '0' && m[k] <= '9') ++k;
  if (k == 5 || k >= m.size() || m[k] != ':' || m[5] == '0') {
    Fail("program error without a line number", m);
  }
}

// The number written at [n.begin, n.end) of `text`.
inline double ReadNumber(std::string_view text, const ProgramNumber& n) {
  if (n.begin >= n.end || n.end > text.size()) Fail("number range outside the text", "");
  std::string s;
  for (size_t i = n.begin; i < n.end; ++i) {
    const char c = text[i];
    if (c != ' ' && c != '\t' && c != '\r' && c != '\n' && c != '\f' && c != '\v' && c != '+') {
      s.push_back(c);
    }
  }
  double v = 0;
  const auto r = std::from_chars(s.data(), s.data() + s.size(), v);
  if (r.ec != std::errc() || r.ptr != s.data() + s.size()) Fail("no number at a range", s);
  return v;
}

inline void CheckRecords(std::string_view text, const ParsedProgram& p) {
  std::vector<std::pair<size_t, size_t>> spans;
  for (const ProgramTarget& t : p.targets) {
    if (t.line < 1) Fail("target without a line", t.name);
    for (const ProgramNumber& n : t.numbers) {
      if (ReadNumber(text, n) != n.value) Fail("number read back differs", t.name);
      spans.emplace_back(n.begin, n.end);
    }
    for (const auto& q : t.quadrants) {
      if (ReadNumber(text, q.number) != q.number.value) Fail("quadrant read back differs", t.name);
      spans.emplace_back(q.number.begin, q.number.end);
    }
    if (!t.compensable && t.reason.empty()) Fail("not compensable without a reason", t.name);
  }
  std::sort(spans.begin(), spans.end());
  for (size_t k = 1; k < spans.size(); ++k) {
    if (spans[k].first < spans[k - 1].second) Fail("overlapping number ranges", "");
  }
}

inline void FuzzProgram(const uint8_t* data, size_t size, ProgramLanguage language) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  ParsedProgram p;
  const Status s = ParseProgram(text, language, &p);
  if (!s.ok()) {
    CheckLineError(s);
    if (!p.targets.empty()) Fail("targets left after an error", s.message());
    return;
  }
  CheckRecords(text, p);
  // Rewrite every record with other values; the result parses into the same records.
  for (ProgramTarget& t : p.targets) {
    t.status = ProgramTargetStatus::kCompensated;
    t.new_values.clear();
    t.new_quadrants.clear();
    for (const ProgramNumber& n : t.numbers)
      t.new_values.push_back(std::round(n.value * 8) / 16 - 1);
    for (const auto& q : t.quadrants) t.new_quadrants.push_back(q.number.value > 0 ? -2 : 3);
  }
  const std::string out = RewriteProgram(text, p);
  ParsedProgram again;
  const Status s2 = ParseProgram(out, language, &again);
  if (!s2.ok()) Fail("the rewritten program does not parse", s2.message() + "\n" + out);
  if (again.targets.size() != p.targets.size())
    Fail("the rewritten program has other targets", out);
  CheckRecords(out, again);
  for (size_t k = 0; k < p.targets.size(); ++k) {
    const ProgramTarget& a = p.targets[k];
    const ProgramTarget& b = again.targets[k];
    if (a.name != b.name || a.numbers.size() != b.numbers.size() ||
        a.quadrants.size() != b.quadrants.size()) {
      Fail("a rewritten target differs", a.name + " / " + b.name);
    }
    // A number reads back as its new value to the decimals it is rewritten with (a number the new
    // value leaves the same to those decimals keeps its bytes: RewriteProgram).
    for (size_t i = 0; i < a.numbers.size(); ++i) {
      const double resolution = 0.5 * std::pow(10.0, -std::min(a.numbers[i].decimals, 20));
      if (!(std::abs(b.numbers[i].value - a.new_values[i]) <= resolution))
        Fail("a rewritten number reads back otherwise", a.name);
    }
    for (size_t i = 0; i < a.quadrants.size(); ++i) {
      if (b.quadrants[i].number.value != a.new_quadrants[i])
        Fail("a rewritten quadrant differs", a.name);
    }
  }
}

}  // namespace fuzz
}  // namespace lpoe

#endif  // LPOE_FUZZ_FUZZ_PROGRAM_H_
