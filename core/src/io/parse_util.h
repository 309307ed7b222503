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

// The fast path of the CSV readers: the number that starts at `first` ("[-]digit...", with any
// fraction and exponent std::from_chars reads), parsed up to where it ends, which is returned; null
// when the text there does not start with a digit or '-' and a digit, or the value is out of range
// (the caller then takes ParseNumber, which accepts '+', names non-finite spellings and tells
// overflow from underflow). The value is ParseNumber's, bit for bit (both are std::from_chars,
// correctly rounded: libstdc++ 12 implements it with fast_float's algorithm).
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
