// Robot programs, the textual parts: tokens, the parsers' dispatch, the rewriter and
// the report. No inverse kinematics here (the fuzz targets link this without the solvers); the
// compensation step is program.cc, the parsers program_urscript.cc and program_rapid.cc.
#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <string>
#include <utility>
#include <vector>

#include "lpoe/program.h"

#include "re2/re2.h"
#include "programs/program_lexer.h"

namespace lpoe {
namespace program_internal {
namespace {

std::string LineError(int line, const std::string& what) {
  return "line " + std::to_string(line) + ": " + what;
}

// Length of the valid UTF-8 sequence at s[i], 0 when invalid.
int Utf8Length(std::string_view s, size_t i) {
  const unsigned char c = static_cast<unsigned char>(s[i]);
  if (c < 0x80) return 1;
  int n;
  unsigned int cp;
  if ((c & 0xE0) == 0xC0) {
    n = 2;
    cp = c & 0x1F;
  } else if ((c & 0xF0) == 0xE0) {
    n = 3;
    cp = c & 0x0F;
  } else if ((c & 0xF8) == 0xF0) {
    n = 4;
    cp = c & 0x07;
  } else
    return 0;
  if (i + n > s.size()) return 0;
  for (int k = 1; k < n; ++k) {
    const unsigned char d = static_cast<unsigned char>(s[i + k]);
    if ((d & 0xC0) != 0x80) return 0;
    cp = (cp << 6) | (d & 0x3F);
  }
  if ((n == 2 && cp < 0x80) || (n == 3 && cp < 0x800) || (n == 4 && cp < 0x10000) ||
      cp > 0x10FFFF || (cp >= 0xD800 && cp <= 0xDFFF)) {
    return 0;
  }
  return n;
}

bool IdentStart(unsigned char c) { return std::isalpha(c) || c == '_' || c >= 0x80; }
bool IdentChar(unsigned char c) { return std::isalnum(c) || c == '_' || c >= 0x80; }

}  // namespace

std::string Lower(std::string_view s) {
  std::string out(s);
  for (char& c : out) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return out;
}

void ApplyTargetUses(const std::vector<TargetUse>& uses, const TargetUseRules& rules,
                     ProgramTarget* t) {
  const TargetUse& u = uses.front();
  t->used = true;
  t->order = u.order;
  t->frame = u.frame;
  t->tcp = u.tcp;
  t->stationary_tool = u.stationary;
  t->frame_name = u.frame_name;
  t->tcp_name = u.tcp_name;
  t->qnear = u.qnear;
  const bool cartesian = t->kind == ProgramTargetKind::kCartesian;
  for (const TargetUse& w : uses) {
    const bool same_tcp = w.stationary == u.stationary && (w.tcp.t - u.tcp.t).norm() < 1e-9 &&
                          (w.tcp.R - u.tcp.R).norm() < 1e-12;
    const bool same_frame =
        (w.frame.t - u.frame.t).norm() < 1e-9 && (w.frame.R - u.frame.R).norm() < 1e-12;
    if (t->compensable && ((!same_frame && (cartesian || rules.joint_targets_use_frame)) ||
                           (!same_tcp && cartesian))) {
      t->compensable = false;
      t->reason = "used with different " + std::string(same_frame ? rules.tcps : rules.frames) +
                  " (lines " + std::to_string(u.line) + " and " + std::to_string(w.line) + ")";
    }
  }
}

namespace {

// Not valid UTF-8 at byte `at`.
Status InvalidUtf8(int line, size_t at) {
  return Status::Error(
      LineError(line, "the text is not valid UTF-8 (byte " + std::to_string(at) + ")"));
}

// A quoted string from its opening quote at *at to after its closing one (*at moved there): a
// backslash escapes the next character, a doubled quote stands for one; it ends on its line.
Status ScanQuotedText(std::string_view text, int line, size_t* at) {
  const size_t n = text.size();
  size_t i = *at;
  const char quote = text[i++];
  while (i < n && text[i] != '\n') {
    if (text[i] == '\\' && i + 1 < n && text[i + 1] != '\n') {
      i += 2;
      continue;
    }
    if (text[i] == quote) {
      if (i + 1 < n && text[i + 1] == quote) {  // "" inside a string
        i += 2;
        continue;
      }
      *at = i + 1;
      return Status::Ok();
    }
    const int len = Utf8Length(text, i);
    if (len == 0) return InvalidUtf8(line, i);
    i += len;
  }
  return Status::Error(LineError(line, "unterminated string"));
}

// A number from *at (digits, fraction, exponent; *at moved after it) and its finite value.
Status ScanNumberText(std::string_view text, int line, size_t* at, double* value) {
  const size_t n = text.size();
  const size_t b = *at;
  size_t i = b;
  while (i < n && std::isdigit(static_cast<unsigned char>(text[i]))) ++i;
  if (i < n && text[i] == '.') {
    ++i;
    while (i < n && std::isdigit(static_cast<unsigned char>(text[i]))) ++i;
  }
  if (i < n && (text[i] == 'e' || text[i] == 'E')) {
    size_t k = i + 1;
    if (k < n && (text[k] == '+' || text[k] == '-')) ++k;
    if (k < n && std::isdigit(static_cast<unsigned char>(text[k]))) {
      i = k;
      while (i < n && std::isdigit(static_cast<unsigned char>(text[i]))) ++i;
    }
  }
  if (i < n && IdentChar(static_cast<unsigned char>(text[i]))) {
    return Status::Error(
        LineError(line, "malformed number '" + std::string(text.substr(b, i + 1 - b)) + "'"));
  }
  *at = i;
  const auto r = std::from_chars(text.data() + b, text.data() + i, *value);
  if (r.ec != std::errc() || !std::isfinite(*value)) {
    return Status::Error(
        LineError(line, "number out of range '" + std::string(text.substr(b, i - b)) + "'"));
  }
  return Status::Ok();
}

}  // namespace

Status Tokenize(std::string_view text, const LexerOptions& options, std::vector<Token>* tokens) {
  tokens->clear();
  int line = 1;
  if (text.size() > kMaxProgramBytes) {
    size_t i = 0;
    for (; i < kMaxProgramBytes; ++i) line += text[i] == '\n';
    return Status::Error(LineError(line, "the program is larger than " +
                                             std::to_string(kMaxProgramBytes >> 20) +
                                             " MB (its size here exceeds the limit)"));
  }
  // Programs have about one token per three to four bytes (a number or name and its separator):
  // reserving one per two bytes once keeps the list from being copied as it grows (only a text
  // of mostly one-byte tokens grows it), and what a program leaves unfilled is address space the
  // system never backs with memory.
  tokens->reserve(text.size() / 2 + 16);
  std::vector<int> open;  // token indices of open brackets
  size_t i = 0;
  const size_t n = text.size();
  if (n >= 3 && text.compare(0, 3, "\xEF\xBB\xBF") == 0) i = 3;  // UTF-8 byte order mark
  auto push = [&](Token::Kind kind, size_t b, size_t e) {
    Token t;
    t.kind = kind;
    t.begin = b;
    t.end = e;
    t.line = line;
    tokens->push_back(t);
  };
  while (i < n) {
    const unsigned char c = static_cast<unsigned char>(text[i]);
    if (c == '\n') {
      ++line;
      ++i;
      continue;
    }
    if (c >= 0x80) {
      if (Utf8Length(text, i) == 0) return InvalidUtf8(line, i);
    } else if (c < 0x20 && c != '\t' && c != '\r' && c != '\f' && c != '\v') {
      return Status::Error(
          LineError(line, "control character " + std::to_string(c) + " in the program text"));
    }
    if (c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v') {
      ++i;
      continue;
    }
    if (c == static_cast<unsigned char>(options.comment)) {
      while (i < n && text[i] != '\n') {
        const int len = Utf8Length(text, i);
        if (len == 0) return InvalidUtf8(line, i);
        i += len;
      }
      continue;
    }
    if (c == '"' || (options.single_quotes && c == '\'')) {
      const size_t b = i;
      if (Status s = ScanQuotedText(text, line, &i); !s.ok()) return s;
      push(Token::kString, b, i);
      continue;
    }
    if (std::isdigit(c) ||
        (c == '.' && i + 1 < n && std::isdigit(static_cast<unsigned char>(text[i + 1])))) {
      const size_t b = i;
      double v = 0;
      if (Status s = ScanNumberText(text, line, &i, &v); !s.ok()) return s;
      push(Token::kNumber, b, i);
      tokens->back().value = v;
      continue;
    }
    if (IdentStart(c)) {
      const size_t b = i;
      while (i < n && IdentChar(static_cast<unsigned char>(text[i]))) {
        const int len = Utf8Length(text, i);
        if (len == 0) return InvalidUtf8(line, i);
        i += len;
      }
      push(Token::kIdent, b, i);
      continue;
    }
    push(Token::kPunct, i, i + 1);
    ++i;
    if (c == '(' || c == '[' || c == '{') {
      open.push_back(static_cast<int>(tokens->size()) - 1);
    } else if (c == ')' || c == ']' || c == '}') {
      if (open.empty()) {
        return Status::Error(LineError(
            line, std::string("'") + static_cast<char>(c) + "' without an opening bracket"));
      }
      Token& o = (*tokens)[open.back()];
      const char oc = text[o.begin];
      const char want = oc == '(' ? ')' : oc == '[' ? ']' : '}';
      if (want != static_cast<char>(c)) {
        return Status::Error(LineError(line, std::string("'") + static_cast<char>(c) +
                                                 "' does not close '" + oc + "' opened on line " +
                                                 std::to_string(o.line)));
      }
      o.match = static_cast<int>(tokens->size()) - 1;
      tokens->back().match = open.back();
      open.pop_back();
    }
  }
  if (!open.empty()) {
    const Token& o = (*tokens)[open.back()];
    return Status::Error(LineError(o.line, std::string("'") + text[o.begin] + "' is never closed"));
  }
  return Status::Ok();
}

bool TokenView::IsNoCase(int i, std::string_view s) const {
  if (i >= size()) return false;
  const std::string_view t = Text(i);
  if (t.size() != s.size()) return false;
  for (size_t k = 0; k < t.size(); ++k) {
    if (std::tolower(static_cast<unsigned char>(t[k])) !=
        std::tolower(static_cast<unsigned char>(s[k]))) {
      return false;
    }
  }
  return true;
}

int TokenView::Number(int i, ProgramNumber* n, int decimals) const {
  if (i >= size()) return -1;
  double sign = 1;
  const int first = i;
  if (Is(i, "-") || Is(i, "+")) {
    sign = Is(i, "-") ? -1 : 1;
    ++i;
  }
  if (i >= size() || t_[i].kind != Token::kNumber) return -1;
  // A sign apart from its digits ("- 5", a line break between) is not taken as a literal: the
  // rewritten number replaces sign and digits, and every other byte must stay.
  if (i != first && t_[i].begin != t_[first].end) return -1;
  n->begin = t_[first].begin;
  n->end = t_[i].end;
  n->value = sign * t_[i].value;
  n->decimals = decimals;
  return i + 1;
}

int TokenView::ExpressionEnd(int i, int limit) const {
  while (i < limit) {
    const Token& t = t_[i];
    if (t.kind == Token::kPunct) {
      const char c = text_[t.begin];
      if (c == ',' || c == ';' || c == ')' || c == ']' || c == '}') return i;
      if (t.match > i) {
        i = t.match + 1;
        continue;
      }
    }
    ++i;
  }
  return limit;
}

std::vector<std::pair<int, int>> TokenView::Items(int open) const {
  std::vector<std::pair<int, int>> items;
  const int close = t_[open].match;
  if (close == open + 1) return items;
  int a = open + 1;
  while (a <= close) {
    const int e = ExpressionEnd(a, close);
    items.emplace_back(a, e);
    if (e >= close) break;
    a = e + 1;
  }
  return items;
}

}  // namespace program_internal

namespace {

std::string FormatNumber(double x, int decimals) {
  if (std::abs(x) < 0.5 * std::pow(10.0, -decimals)) x = 0;
  char buf[64];
  if (!(std::abs(x) < 1e15)) {  // never a coordinate; exact, and short enough for the buffer
    std::snprintf(buf, sizeof(buf), "%.17g", x);
    return buf;
  }
  std::snprintf(buf, sizeof(buf), "%.*f", std::min(decimals, 20), x);
  std::string s(buf);
  if (s.find('.') != std::string::npos) {
    while (s.back() == '0') s.pop_back();
    if (s.back() == '.') s.push_back('0');
  }
  if (s == "-0.0") s = "0.0";
  return s;
}

void JsonString(std::string_view s, std::string* out) {
  out->push_back('"');
  for (const char c : s) {
    switch (c) {
      case '"':
        *out += "\\\"";
        break;
      case '\\':
        *out += "\\\\";
        break;
      case '\n':
        *out += "\\n";
        break;
      case '\r':
        *out += "\\r";
        break;
      case '\t':
        *out += "\\t";
        break;
      default:
        if (static_cast<unsigned char>(c) < 0x20) {
          char b[8];
          std::snprintf(b, sizeof(b), "\\u%04x", c);
          *out += b;
        } else {
          out->push_back(c);
        }
    }
  }
  out->push_back('"');
}

}  // namespace

const char* ProgramLanguageName(ProgramLanguage language) {
  return language == ProgramLanguage::kRapid ? "rapid" : "urscript";
}

bool ProgramLanguageFromName(std::string_view name, ProgramLanguage* language) {
  const std::string l = program_internal::Lower(name);
  if (l == "urscript")
    *language = ProgramLanguage::kUrScript;
  else if (l == "rapid")
    *language = ProgramLanguage::kRapid;
  else
    return false;
  return true;
}

bool ProgramLanguageFromPath(std::string_view path, ProgramLanguage* language) {
  const size_t dot = path.rfind('.');
  const size_t slash = path.find_last_of("/\\");
  if (dot == std::string_view::npos || (slash != std::string_view::npos && dot < slash)) {
    return false;
  }
  const std::string ext = program_internal::Lower(path.substr(dot + 1));
  if (ext == "script" || ext == "urscript")
    *language = ProgramLanguage::kUrScript;
  else if (ext == "mod" || ext == "modx" || ext == "prg")
    *language = ProgramLanguage::kRapid;
  else
    return false;
  return true;
}

const char* ProgramTargetStatusName(ProgramTargetStatus status) {
  switch (status) {
    case ProgramTargetStatus::kCompensated:
      return "compensated";
    case ProgramTargetStatus::kNotCompensated:
      return "not_compensated";
    case ProgramTargetStatus::kNotSelected:
      return "not_selected";
  }
  return "?";
}

Status ParseProgram(std::string_view text, ProgramLanguage language, ParsedProgram* program) {
  program->language = language;
  program->targets.clear();
  const Status s = language == ProgramLanguage::kRapid ? ParseRapidProgram(text, program)
                                                       : ParseUrScriptProgram(text, program);
  if (!s.ok()) program->targets.clear();
  return s;
}

std::string RewriteProgram(std::string_view text, const ParsedProgram& program) {
  struct Edit {
    size_t begin, end;
    std::string text;
  };
  std::vector<Edit> edits;
  for (const ProgramTarget& t : program.targets) {
    if (t.status != ProgramTargetStatus::kCompensated) continue;
    for (size_t k = 0; k < t.numbers.size() && k < t.new_values.size(); ++k) {
      // A number the compensation leaves the same (to the decimals it is written with) keeps
      // its bytes.
      if (std::abs(t.new_values[k] - t.numbers[k].value) <
          0.5 * std::pow(10.0, -std::min(t.numbers[k].decimals, 20))) {
        continue;
      }
      edits.push_back({t.numbers[k].begin, t.numbers[k].end,
                       FormatNumber(t.new_values[k], t.numbers[k].decimals)});
    }
    for (size_t k = 0; k < t.quadrants.size() && k < t.new_quadrants.size(); ++k) {
      if (t.new_quadrants[k] == t.quadrants[k].number.value) continue;  // unchanged: keep bytes
      edits.push_back({t.quadrants[k].number.begin, t.quadrants[k].number.end,
                       std::to_string(static_cast<long long>(t.new_quadrants[k]))});
    }
  }
  std::sort(edits.begin(), edits.end(),
            [](const Edit& a, const Edit& b) { return a.begin < b.begin; });
  std::string out;
  out.reserve(text.size() + 16 * edits.size());
  size_t at = 0;
  for (const Edit& e : edits) {
    if (e.begin < at) continue;  // overlapping (never made by the parsers)
    out.append(text.substr(at, e.begin - at));
    out += e.text;
    at = e.end;
  }
  out.append(text.substr(at));
  return out;
}

std::string FlangeRotationNote(const ParsedProgram& program) {
  char text[640];
  const double r = program.tcp_off_flange_axis_mm;
  if (program.flange_rotation_identified) {
    std::snprintf(text, sizeof(text),
                  "The flange's rotation about its axis (the last joint's zero) was identified: "
                  "the calibration held the tools %s at their known positions on the flange. The "
                  "compensated TCPs are up to %.3g mm off that axis.",
                  program.fixed_tools.c_str(), r);
  } else {
    std::snprintf(text, sizeof(text),
                  "The flange's rotation about its axis (the last joint's zero) was not "
                  "identified: without fixed tools (lpoe_calibrate --fixed_tools) it is a "
                  "convention traded against the SMR offsets, and the flange keeps its nominal "
                  "angle. The compensated TCPs are up to %.3g mm off that axis: each 0.1 deg of "
                  "error there moves such a TCP by %.3g mm (and turns every TCP by 0.1 deg).",
                  r, r * 0.1 * kPi / 180.0);
  }
  return text;
}

namespace {

std::string FlangeRotationNoteJson(const ParsedProgram& program) {
  char buf[160];
  std::snprintf(buf, sizeof(buf),
                "  \"tcp_off_flange_axis_mm\": %.6g,\n  \"flange_rotation_identified\": %s,\n"
                "  \"tcp_error_mm_per_0.1_deg\": %.6g,\n  \"flange_note\": ",
                program.tcp_off_flange_axis_mm,
                program.flange_rotation_identified ? "true" : "false",
                program.flange_rotation_identified
                    ? 0.0
                    : program.tcp_off_flange_axis_mm * 0.1 * kPi / 180.0);
  std::string out = buf;
  JsonString(FlangeRotationNote(program), &out);
  out += ",\n  \"frame\": ";
  JsonString(program.frame, &out);
  out += ",\n  \"flange\": ";
  JsonString(program.flange, &out);
  out += ",\n";
  return out;
}

}  // namespace

Status TargetNameFilter::Compile(const std::string& pattern) {
  re_.reset();
  if (pattern.empty()) return Status::Ok();
  re2::RE2::Options options;
  options.set_log_errors(false);
  auto re = std::make_shared<const re2::RE2>(pattern, options);
  if (!re->ok()) {
    return Status::Error("targets_only '" + pattern +
                         "' is not a regular expression (RE2 syntax): " + re->error());
  }
  re_ = std::move(re);
  return Status::Ok();
}

bool TargetNameFilter::Matches(std::string_view name) const {
  return re_ == nullptr ||
         re2::RE2::FullMatch(re2::StringPiece(name.data(), name.size()), *re_);
}

Status CheckTargetsOnly(const std::string& pattern) { return TargetNameFilter().Compile(pattern); }

std::string ProgramReportJson(const ParsedProgram& program) {
  int counts[3] = {};
  for (const ProgramTarget& t : program.targets) ++counts[static_cast<int>(t.status)];
  std::string out = "{\n  \"language\": \"";
  out += ProgramLanguageName(program.language);
  out +=
      "\",\n  \"targets\": " + std::to_string(program.targets.size()) + ",\n  \"status_counts\": {";
  for (int s = 0; s < 3; ++s) {
    out += s ? ", \"" : "\"";
    out += ProgramTargetStatusName(static_cast<ProgramTargetStatus>(s));
    out += "\": " + std::to_string(counts[s]);
  }
  out += "},\n";
  out += FlangeRotationNoteJson(program);
  out += "  \"rows\": [";
  for (size_t k = 0; k < program.targets.size(); ++k) {
    const ProgramTarget& t = program.targets[k];
    out += k ? ",\n    {" : "\n    {";
    out += "\"name\": ";
    JsonString(t.name, &out);
    out += ", \"line\": " + std::to_string(t.line) + ", \"kind\": \"";
    out += t.kind == ProgramTargetKind::kJoint ? "joint" : "cartesian";
    out += "\", \"status\": \"";
    out += ProgramTargetStatusName(t.status);
    out += "\", \"frame\": ";
    JsonString(t.frame_name, &out);
    out += ", \"tcp\": ";
    JsonString(t.tcp_name, &out);
    if (t.stationary_tool) out += ", \"stationary_tool\": true";
    out += ", \"reason\": ";
    JsonString(t.reason, &out);
    char buf[96];
    std::snprintf(buf, sizeof(buf), ", \"correction_mm\": %.6g, \"correction_deg\": %.6g}",
                  t.correction_mm, t.correction_deg);
    out += buf;
  }
  out += program.targets.empty() ? "]\n}\n" : "\n  ]\n}\n";
  return out;
}

}  // namespace lpoe
