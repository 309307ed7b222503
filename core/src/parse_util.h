// Internal helpers shared by the file readers and writers (model YAML, measurement CSV, URDF): one
// number parser, one number formatter, and one format for every input error,
//   "<file>:<line>: <what is wrong>; expected <what>".
// The interface is meant to stay small and stable; everything here is locale-independent.
#ifndef LPOE_CORE_SRC_PARSE_UTIL_H_
#define LPOE_CORE_SRC_PARSE_UTIL_H_

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "lpoe/status.h"

namespace lpoe {
namespace internal {

// The error of an input file at a 1-based line (lines below 1 are reported as line 1). Lines are
// 64-bit: a measurement file may have more than 2^31 lines.
Status LineError(const std::string& source, int64_t line, const std::string& what,
                 const std::string& expected);

// `s` in single quotes for a message: control bytes escaped, long junk cut after `max_shown`
// characters so that a message stays one readable line.
std::string Quote(std::string_view s, size_t max_shown = 40);

// `s` without leading and trailing blanks (spaces and tabs).
std::string_view Trim(std::string_view s);

// The comma-separated fields of one CSV line, each trimmed (no quoting: the joint and plan files
// have none). An empty line gives one empty field.
std::vector<std::string_view> SplitFields(std::string_view line);

// The `separator`-separated numbers of a flag or option value ("2500,0,800", a box, a TCP
// offset), each item trimmed and read by ParseNumber (below): false when an item is not a finite
// number (an empty item included); `*values` then holds the items before it. The one reader of
// such lists (the tools' --tracker, --box, --keep_out lines, --joint_ranges items, --tcp).
bool ParseNumberList(std::string_view text, char separator, std::vector<double>* values);

// Result of ParseNumber.
enum class NumberParse {
  kOk,
  kNotANumber,  // empty, junk, trailing characters, two signs
  kNonFinite,   // nan, inf, infinity (any case, signed), YAML's .inf / .nan
  kOutOfRange,  // a decimal number whose magnitude overflows a double (1e999)
};

// Parses the whole of `text` (no blanks; call Trim first) as a decimal double: an optional sign
// ('+' accepted), digits, an optional fraction and exponent. Values below the smallest subnormal
// round to zero. `*out` is written only on kOk.
NumberParse ParseNumber(std::string_view text, double* out);

// The fast path of the CSV readers for the common spelling of a number, "[+-]digits[.digits]"
// with at most 18 digits in all: parses it from `first` and returns the character after it, or
// null when the text there is not such a number or its value cannot be rounded here with certainty
// (the caller then takes ParseNumber). The value is ParseNumber's, bit for bit: the digits are an
// exact integer m < 10^18 and the value m / 10^k is divided in x87 extended precision (64-bit
// mantissa, itself exact for m and 10^k, k <= 27) and rounded to double, which is the correctly
// rounded value unless the extended quotient lies exactly halfway between two doubles (then null).
// Only where long double has a 64-bit mantissa (x86-64); null everywhere else.
const char* ParsePlainDecimal(const char* first, const char* last, double* out);

// The shortest decimal text that reads back as exactly `v` (std::to_chars), with -0 written as 0.
// Non-finite values are written as nan / inf / -inf.
void AppendNumber(double v, std::string* out);
std::string FormatNumber(double v);

// A number for a message: 6 significant digits.
std::string ShortNumber(double v);

// `s` double-quoted with YAML escapes (\" \\ and \xNN for control bytes); reads back as `s`.
std::string YamlDoubleQuoted(std::string_view s);

}  // namespace internal
}  // namespace lpoe

#endif  // LPOE_CORE_SRC_PARSE_UTIL_H_
