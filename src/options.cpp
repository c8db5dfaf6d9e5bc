#include "options.hpp"

#include <charconv>
#include <cmath>
#include <cstring>
#include <strings.h>
#include <string>

namespace softbody {

namespace {

bool ParsesAsReal(const char *text) {
  const char *begin = text + (text[0] == '+');
  const char *end = text + std::strlen(text);
  double value;
  const auto [stop, error] = std::from_chars(begin, end, value);
  return error == std::errc() && stop == end && std::isfinite(value);
}

bool ParsesAsInteger(const char *text) {
  const char *begin = text + (text[0] == '+');
  const char *end = text + std::strlen(text);
  long value;
  const auto [stop, error] = std::from_chars(begin, end, value);
  return error == std::errc() && stop == end;
}

bool IsChoice(const char *text, const char *const *choices) {
  // PetscOptionsEnum lists: names, then the enum's type name, prefix, nullptr.
  int count = 0;
  while (choices[count]) ++count;
  for (int i = 0; i < count - 2; ++i)
    if (strcasecmp(text, choices[i]) == 0) return true;  // as PetscOptionsEnum
  return false;
}

}  // namespace

PetscErrorCode CheckOptionSyntax(MPI_Comm comm, std::initializer_list<OptionSyntax> options) {
  PetscFunctionBeginUser;
  for (const OptionSyntax &option : options) {
    char value[PETSC_MAX_PATH_LEN];
    PetscBool set;
    PetscCall(PetscOptionsGetString(nullptr, nullptr, option.name, value, sizeof(value), &set));
    if (!set) continue;
    switch (option.kind) {
      case OptionSyntax::kReal:
        PetscCheck(ParsesAsReal(value), comm, PETSC_ERR_USER_INPUT,
                   "option %s: '%s' is not a finite number", option.name, value);
        break;
      case OptionSyntax::kInteger:
        PetscCheck(ParsesAsInteger(value), comm, PETSC_ERR_USER_INPUT,
                   "option %s: '%s' is not an integer", option.name, value);
        break;
      case OptionSyntax::kChoice: {
        std::string list;
        for (int i = 0; option.choices[i + 2]; ++i) list += std::string(" ") + option.choices[i];
        PetscCheck(IsChoice(value, option.choices), comm, PETSC_ERR_USER_INPUT,
                   "option %s: '%s' is not one of%s", option.name, value, list.c_str());
        break;
      }
    }
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
