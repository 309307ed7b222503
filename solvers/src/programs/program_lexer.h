// Tokens of a robot program, shared by the language parsers (program_*.cc). Internal.
#ifndef LPOE_SOLVERS_PROGRAM_LEXER_H_
#define LPOE_SOLVERS_PROGRAM_LEXER_H_

#include <string>
#include <string_view>
#include <vector>

#include "lpoe/program.h"
#include "lpoe/status.h"

namespace lpoe {
namespace program_internal {

struct Token {
  enum Kind { kIdent, kNumber, kString, kPunct };
  Kind kind = kPunct;
  size_t begin = 0, end = 0;  // bytes of the text
  int line = 0;
  double value = 0;  // kNumber
  int match = -1;    // brackets: index of the matching bracket token
};

struct LexerOptions {
  char comment = '#';          // to the end of the line
  bool single_quotes = false;  // '...' strings too
};

// Splits `text` into tokens (comments and spaces dropped). Checks the size, UTF-8 and that
// brackets ( [ { are balanced; errors name the line.
Status Tokenize(std::string_view text, const LexerOptions& options, std::vector<Token>* tokens);

// Helpers on a token list.
class TokenView {
 public:
  TokenView(std::string_view text, const std::vector<Token>& tokens) : text_(text), t_(tokens) {}
  int size() const { return static_cast<int>(t_.size()); }
  const Token& operator[](int i) const { return t_[i]; }
  std::string_view Text(int i) const {
    return i < size() ? text_.substr(t_[i].begin, t_[i].end - t_[i].begin) : std::string_view();
  }
  // The source text of tokens [a, b).
  std::string_view Span(int a, int b) const {
    if (a >= b) return std::string_view();
    return text_.substr(t_[a].begin, t_[b - 1].end - t_[a].begin);
  }
  // Span(a, b) for a name or message: at most kExcerptBytes bytes (cut at a UTF-8 character
  // boundary, then "..."), so that a record never copies a large span of the text.
  static constexpr size_t kExcerptBytes = 80;
  std::string Excerpt(int a, int b) const {
    std::string_view s = Span(a, b);
    if (s.size() <= kExcerptBytes) return std::string(s);
    size_t cut = kExcerptBytes;
    while (cut > 0 && (static_cast<unsigned char>(s[cut]) & 0xC0) == 0x80) --cut;
    return std::string(s.substr(0, cut)) + "...";
  }
  bool Is(int i, std::string_view s) const { return i < size() && Text(i) == s; }
  // Case-insensitive (RAPID keywords and names).
  bool IsNoCase(int i, std::string_view s) const;
  bool IsIdent(int i) const { return i < size() && t_[i].kind == Token::kIdent; }
  // A (signed) number at i: fills `n` and returns the index after it, or -1.
  int Number(int i, ProgramNumber* n, int decimals) const;
  // End (exclusive) of the expression starting at i: the next ',' ';' or closing bracket at depth
  // 0, or `limit`.
  int ExpressionEnd(int i, int limit) const;
  // Comma-separated items of the bracket at `open` (its contents, [begin, end) per item).
  std::vector<std::pair<int, int>> Items(int open) const;

 private:
  std::string_view text_;
  const std::vector<Token>& t_;
};

std::string Lower(std::string_view s);

// Where a motion instruction uses a target: the work object (feature) and tool (TCP) in effect,
// the controller's seed (URScript qnear; empty: none), and the use's order and line.
struct TargetUse {
  SE3d frame, tcp;
  bool stationary = false;  // ProgramTarget::stationary_tool
  std::string frame_name, tcp_name;
  std::vector<double> qnear;
  int order = 0, line = 0;
};

// The language's names for what a target is used with, and whether a joint target depends on the
// frame it is used in (URScript features: yes; RAPID work objects: no).
struct TargetUseRules {
  const char* tcps;    // "tools", "TCPs"
  const char* frames;  // "work objects", "features"
  bool joint_targets_use_frame = false;
};

// The first of `uses` (non-empty) becomes t's use (used, order, frame, tcp, their names, qnear).
// A later use in another frame (a Cartesian target, or any with rules.joint_targets_use_frame) or
// with another TCP (a Cartesian target) makes a compensable t not compensable: "used with different
// <frames or tcps> (lines a and b)".
void ApplyTargetUses(const std::vector<TargetUse>& uses, const TargetUseRules& rules,
                     ProgramTarget* t);

}  // namespace program_internal

// The parsers (one per language).
Status ParseUrScriptProgram(std::string_view text, ParsedProgram* program);
Status ParseRapidProgram(std::string_view text, ParsedProgram* program);

}  // namespace lpoe

#endif  // LPOE_SOLVERS_PROGRAM_LEXER_H_
