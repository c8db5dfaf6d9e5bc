#include "common/text_reader.hpp"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "common/errors.hpp"

namespace softbody {

TextReader::TextReader(std::string path) : path_(std::move(path)) {
  std::error_code error;
  if (std::filesystem::exists(path_, error) && !std::filesystem::is_regular_file(path_, error))
    throw InputError(Where(path_, 0, "not a regular file"));
  std::ifstream in(path_, std::ios::binary);
  if (!in) throw InputError(Where(path_, 0, "cannot open file"));
  std::ostringstream buffer;
  buffer << in.rdbuf();
  text_ = buffer.str();
}

void TextReader::SkipBlanksAndComments(bool stop_at_newline) {
  while (pos_ < text_.size()) {
    const char c = text_[pos_];
    if (c == '\n') {
      if (stop_at_newline) return;
      ++line_;
      ++pos_;
    } else if (c == ' ' || c == '\t' || c == '\r' || c == '\f' || c == '\v') {
      ++pos_;
    } else if (c == '#') {
      while (pos_ < text_.size() && text_[pos_] != '\n') ++pos_;
    } else {
      return;
    }
  }
}

bool TextReader::NextToken(std::string_view *token) {
  SkipBlanksAndComments(false);
  if (pos_ >= text_.size()) return false;
  const size_t start = pos_;
  token_line_ = line_;
  while (pos_ < text_.size() && !std::isspace(static_cast<unsigned char>(text_[pos_])) &&
         text_[pos_] != '#')
    ++pos_;
  *token = std::string_view(text_).substr(start, pos_ - start);
  return true;
}

std::string_view TextReader::ExpectToken(const char *what) {
  std::string_view token;
  if (!NextToken(&token)) Fail(std::string("expected ") + what + ", found end of file");
  return token;
}

bool TextReader::NextLine(std::vector<std::string_view> *tokens) {
  tokens->clear();
  SkipBlanksAndComments(false);
  if (pos_ >= text_.size()) return false;
  std::string_view token;
  while (true) {
    SkipBlanksAndComments(true);
    if (pos_ >= text_.size() || text_[pos_] == '\n') break;
    NextToken(&token);
    tokens->push_back(token);
  }
  return true;
}

double TextReader::ParseReal(std::string_view token, const char *what) const {
  double value = 0;
  if (!ParseNumber(token, &value))
    Fail(std::string(what) + ": '" + std::string(token) + "' is not a number");
  if (!std::isfinite(value))
    Fail(std::string(what) + ": '" + std::string(token) + "' is not finite");
  return value;
}

long TextReader::ParseInteger(std::string_view token, const char *what) const {
  long value = 0;
  if (!ParseNumber(token, &value))
    Fail(std::string(what) + ": '" + std::string(token) + "' is not an integer");
  return value;
}

void TextReader::Fail(const std::string &what) const {
  throw InputError(Where(path_, token_line_, what));
}

}  // namespace softbody
