// Reading whitespace-separated text files with line numbers for error messages.
// Everything after '#' on a line is a comment. Not collective; throws InputError.
#pragma once

#include <charconv>
#include <string>
#include <string_view>
#include <vector>

namespace softbody {

// Parses all of `text` (an optional leading '+', then what std::from_chars
// reads: decimal integers; reals in fixed or scientific notation, "nan", "inf").
// False when something is left over or nothing parses.
template <typename Number>
bool ParseNumber(std::string_view text, Number *value) {
  if (!text.empty() && text.front() == '+') text.remove_prefix(1);
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), *value);
  return error == std::errc() && end == text.data() + text.size();
}

class TextReader {
 public:
  // Reads the whole file; throws InputError "path: cannot open ..." when it cannot.
  explicit TextReader(std::string path);

  const std::string &path() const { return path_; }
  // Line of the token returned last (1-based).
  long line() const { return token_line_; }
  // Bytes not read yet: an upper bound for how many tokens can still follow.
  size_t remaining_bytes() const { return text_.size() - pos_; }

  // Next token; false at the end of the file.
  bool NextToken(std::string_view *token);
  // Next token, or InputError "expected <what>, found end of file" (at the line
  // of the last token).
  std::string_view ExpectToken(const char *what);
  // Tokens of the next line that holds any; false at the end of the file.
  bool NextLine(std::vector<std::string_view> *tokens);

  double ExpectReal(const char *what) { return ParseReal(ExpectToken(what), what); }
  long ExpectInteger(const char *what) { return ParseInteger(ExpectToken(what), what); }

  // Parse a whole token as a finite real / a decimal integer, or throw an
  // InputError at the current line naming `what`.
  double ParseReal(std::string_view token, const char *what) const;
  long ParseInteger(std::string_view token, const char *what) const;

  // InputError at the current line.
  [[noreturn]] void Fail(const std::string &what) const;

 private:
  void SkipBlanksAndComments(bool stop_at_newline);

  std::string path_;
  std::string text_;
  size_t pos_ = 0;
  long line_ = 1;        // line of the reading position
  long token_line_ = 1;  // line of the token returned last
};

}  // namespace softbody
