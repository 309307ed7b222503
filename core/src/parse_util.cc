#include "parse_util.h"

#include <cfloat>
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

#if defined(__x86_64__) && LDBL_MANT_DIG == 64
namespace {

inline uint64_t Load8(const char* p) {
  uint64_t v;
  std::memcpy(&v, p, 8);
  return v;  // little-endian: p[0] in the low byte
}

// The bytes that are not ASCII digits, as their high bits (SWAR). Only the lowest one set is
// exact (a carry or borrow runs upwards, and only out of a byte that is itself flagged): the first
// non-digit.
inline uint64_t NonDigits(uint64_t v) {
  return ((v + 0x4646464646464646ULL) | (v - 0x3030303030303030ULL)) & 0x8080808080808080ULL;
}
// The value of 8 ASCII digits (SWAR: 3 multiplications).
inline uint64_t EightDigitsValue(uint64_t v) {
  v -= 0x3030303030303030ULL;
  v = v * 10 + (v >> 8);
  return (((v & 0x000000FF000000FFULL) * (100 + (1000000ULL << 32))) +
          (((v >> 16) & 0x000000FF000000FFULL) * (1 + (10000ULL << 32)))) >>
         32;
}

constexpr uint64_t kPow10Int[] = {1,      10,      100,      1000,     10000,
                                  100000, 1000000, 10000000, 100000000};

// Digits from p into *m (which may wrap when there are more than 19: the caller counts them),
// eight bytes at a time while eight can be read: a run of fewer than eight digits is shifted to
// the top of its word, the bytes below filled with '0', and read the same way.
inline const char* Digits(const char* p, const char* last, uint64_t* m) {
  while (last - p >= 8) {
    const uint64_t v = Load8(p);
    const uint64_t non_digits = NonDigits(v);
    if (non_digits == 0) {
      *m = *m * 100000000ULL + EightDigitsValue(v);
      p += 8;
      continue;
    }
    const int n = __builtin_ctzll(non_digits) >> 3;  // leading digits, 0..7
    if (n > 0) {
      const uint64_t w = (v << (8 * (8 - n))) | (0x3030303030303030ULL >> (8 * n));
      *m = *m * kPow10Int[n] + EightDigitsValue(w);
    }
    return p + n;
  }
  while (p < last && static_cast<unsigned>(*p - '0') < 10) {
    *m = *m * 10 + static_cast<unsigned>(*p - '0');
    ++p;
  }
  return p;
}

constexpr long double kPow10[] = {1e0L,  1e1L,  1e2L,  1e3L,  1e4L,  1e5L,  1e6L,
                                  1e7L,  1e8L,  1e9L,  1e10L, 1e11L, 1e12L, 1e13L,
                                  1e14L, 1e15L, 1e16L, 1e17L, 1e18L, 1e19L, 1e20L,
                                  1e21L, 1e22L, 1e23L, 1e24L, 1e25L, 1e26L, 1e27L};

}  // namespace

const char* ParsePlainDecimal(const char* first, const char* last, double* out) {
  const char* p = first;
  bool negate = false;
  if (p < last && (*p == '-' || *p == '+')) {
    negate = *p == '-';
    ++p;
  }
  uint64_t m = 0;
  const char* int_begin = p;
  p = Digits(p, last, &m);
  const long int_digits = p - int_begin;
  long frac_digits = 0;
  if (int_digits == 0) return nullptr;
  if (p < last && *p == '.') {
    const char* frac_begin = ++p;
    p = Digits(p, last, &m);
    frac_digits = p - frac_begin;
    if (frac_digits == 0) return nullptr;
  }
  if (int_digits + frac_digits > 18) return nullptr;  // m < 10^18 < 2^63, k <= 17
  // Both operands exact; one correctly rounded division to 64 bits.
  const long double q = static_cast<long double>(static_cast<int64_t>(m)) / kPow10[frac_digits];
  uint64_t mantissa;
  std::memcpy(&mantissa, &q, 8);
  // Exactly halfway between two doubles (the 11 bits below the double's 53 are 100 0000 0000):
  // the true quotient may lie on either side.
  if ((mantissa & 0x7FF) == 0x400) return nullptr;
  const double v = static_cast<double>(q);
  *out = negate ? -v : v;
  return p;
}
#else
const char* ParsePlainDecimal(const char*, const char*, double*) { return nullptr; }
#endif

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
