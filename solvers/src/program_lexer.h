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

}  // namespace program_internal

// The parsers (one per language).
Status ParseUrScriptProgram(std::string_view text, ParsedProgram* program);
Status ParseRapidProgram(std::string_view text, ParsedProgram* program);

}  // namespace lpoe

#endif  // LPOE_SOLVERS_PROGRAM_LEXER_H_
