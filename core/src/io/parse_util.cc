#include "io/parse_util.h"

#include <charconv>
#include <cstdint>
#include <cstring>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <system_error>

namespace lpoe {
namespace internal {

Status LineError(const std::string& source, int64_t line, const std::string& what,
                 const std::string& expected) {
  std::string msg = source;
  msg += ':';
  msg += std::to_string(line < 1 ? 1 : line);
  msg += ": ";
  msg += what;
  msg += "; expected ";
  msg += expected;
  return Status::Error(std::move(msg));
}

std::string Quote(std::string_view s, size_t max_shown) {
  std::string out = "'";
  for (size_t i = 0; i < s.size() && i < max_shown; ++i) {
    const unsigned char c = static_cast<unsigned char>(s[i]);
    if (c < 0x20 || c == 0x7f) {
      char buf[8];
      std::snprintf(buf, sizeof(buf), "\\x%02x", c);
      out += buf;
    } else {
      out += static_cast<char>(c);
    }
  }
  if (s.size() > max_shown) out += "...";
  out += "'";
  return out;
}

std::string_view Trim(std::string_view s) {
  size_t b = 0, e = s.size();
  while (b < e && (s[b] == ' ' || s[b] == '\t')) ++b;
  while (e > b && (s[e - 1] == ' ' || s[e - 1] == '\t')) --e;
  return s.substr(b, e - b);
}

std::vector<std::string_view> SplitFields(std::string_view line) {
  std::vector<std::string_view> out;
  size_t start = 0;
  while (true) {
    const size_t comma = line.find(',', start);
    out.push_back(Trim(line.substr(start, comma - start)));
    if (comma == std::string_view::npos) return out;
    start = comma + 1;
  }
}

bool ParseNumberList(std::string_view text, char separator, std::vector<double>* values) {
  values->clear();
  while (true) {
    const size_t end = text.find(separator);
    double v = 0;
    if (ParseNumber(Trim(text.substr(0, end)), &v) != NumberParse::kOk) return false;
    values->push_back(v);
    if (end == std::string_view::npos) return true;
    text.remove_prefix(end + 1);
  }
}

namespace {

char Lower(char c) { return c >= 'A' && c <= 'Z' ? static_cast<char>(c - 'A' + 'a') : c; }

bool EqualsLower(std::string_view s, std::string_view lower) {
  if (s.size() != lower.size()) return false;
  for (size_t i = 0; i < s.size(); ++i) {
    if (Lower(s[i]) != lower[i]) return false;
  }
  return true;
}

}  // namespace

NumberParse ParseNumber(std::string_view text, double* out) {
  if (text.empty()) return NumberParse::kNotANumber;
  const char* first = text.data();
  const char* last = text.data() + text.size();
  bool negate = false;
  if (*first == '+' || *first == '-') {
    negate = *first == '-';
    ++first;
    if (first == last || *first == '+' || *first == '-') return NumberParse::kNotANumber;
  }
  // Spellings of NaN and infinity: C's (what trackers export for a lost beam) and YAML's.
  const std::string_view word(first, static_cast<size_t>(last - first));
  if (word.size() <= 9 && (EqualsLower(word, "nan") || EqualsLower(word, "inf") ||
                           EqualsLower(word, "infinity") || EqualsLower(word, ".inf") ||
                           EqualsLower(word, ".nan"))) {
    return NumberParse::kNonFinite;
  }
  // from_chars would accept these spellings too; anything else that is not a digit or '.' at the
  // start is junk (from_chars also accepts "nan(...)").
  if (!((*first >= '0' && *first <= '9') || *first == '.')) return NumberParse::kNotANumber;
  double v = 0;
  const std::from_chars_result r = std::from_chars(first, last, v, std::chars_format::general);
  if (r.ptr != last) return NumberParse::kNotANumber;
  if (r.ec == std::errc::result_out_of_range) {
    // from_chars reports underflow and overflow alike: tell them apart by the exponent's sign
    // (a mantissa of zeros, "0e999", parses fine and never gets here).
    bool negative_exponent = false;
    for (const char* p = first; p < last; ++p) {
      if (*p == 'e' || *p == 'E') {
        negative_exponent = p + 1 < last && p[1] == '-';
        break;
      }
    }
    // Without a negative exponent the digits can only overflow; otherwise let strtod decide
    // (a rare path: underflow to zero or a subnormal, or absurdly many digits).
    if (!negative_exponent) return NumberParse::kOutOfRange;
    const std::string copy(first, last);
    v = std::strtod(copy.c_str(), nullptr);
  } else if (r.ec != std::errc()) {
    return NumberParse::kNotANumber;
  }
  if (!std::isfinite(v)) return NumberParse::kOutOfRange;
  *out = negate ? -v : v;
  return NumberParse::kOk;
}

const char* ParsePlainDecimal(const char* first, const char* last, double* out) {
  // from_chars (libstdc++ 12: the Eisel-Lemire algorithm of fast_float, correctly rounded) reads
  // up to the first character that cannot continue the number; a leading '+', "inf" and "nan" are
  // left to ParseNumber, so only a digit (after an optional '-') may start the number here.
  const char* digit = first < last && *first == '-' ? first + 1 : first;
  if (digit >= last || static_cast<unsigned>(*digit - '0') >= 10) return nullptr;
  double v = 0;
  const std::from_chars_result r = std::from_chars(first, last, v, std::chars_format::general);
  if (r.ec != std::errc()) return nullptr;  // out of range: ParseNumber says which way
  *out = v;
  return r.ptr;
}

void AppendNumber(double v, std::string* out) {
  if (v == 0) v = 0;  // no "-0"
  char buf[32];
  const std::to_chars_result r = std::to_chars(buf, buf + sizeof(buf), v);
  out->append(buf, r.ptr);
}

std::string FormatNumber(double v) {
  std::string out;
  AppendNumber(v, &out);
  return out;
}

std::string ShortNumber(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.6g", v);
  return buf;
}

std::string YamlDoubleQuoted(std::string_view s) {
  std::string out = "\"";
  for (const char c : s) {
    const unsigned char u = static_cast<unsigned char>(c);
    if (c == '"' || c == '\\') {
      out += '\\';
      out += c;
    } else if (u < 0x20 || u == 0x7f) {
      char buf[8];
      std::snprintf(buf, sizeof(buf), "\\x%02x", u);
      out += buf;
    } else {
      out += c;
    }
  }
  out += '"';
  return out;
}

}  // namespace internal
}  // namespace lpoe
