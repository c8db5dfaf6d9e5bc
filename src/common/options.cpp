#include "common/options.hpp"

#include <strings.h>

#include <cmath>
#include <cstring>
#include <string>

#include "common/text_reader.hpp"

namespace softbody {

namespace {

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
    double real;
    long integer;
    PetscCall(PetscOptionsGetString(nullptr, nullptr, option.name, value, sizeof(value), &set));
    if (!set) continue;
    switch (option.kind) {
      case OptionSyntax::kReal:
        PetscCheck(ParseNumber(value, &real) && std::isfinite(real), comm, PETSC_ERR_USER_INPUT,
                   "option %s: '%s' is not a finite number", option.name, value);
        break;
      case OptionSyntax::kRealList: {
        bool ok = true;
        for (std::string_view rest = value; ok;) {
          const size_t comma = rest.find(',');
          ok = ParseNumber(rest.substr(0, comma), &real) && std::isfinite(real);
          if (comma == std::string_view::npos) break;
          rest.remove_prefix(comma + 1);
        }
        PetscCheck(ok, comm, PETSC_ERR_USER_INPUT,
                   "option %s: '%s' is not a list of finite numbers", option.name, value);
        break;
      }
      case OptionSyntax::kInteger:
        PetscCheck(ParseNumber(value, &integer), comm, PETSC_ERR_USER_INPUT,
                   "option %s: '%s' is not an integer", option.name, value);
        break;
      case OptionSyntax::kBool: {  // PetscOptionsBool's spellings; no value means true
        static const char *const kBools[] = {"",   "1",  "0",   "true", "false", "yes",
                                             "no", "on", "off", "bool", "",      nullptr};
        PetscCheck(IsChoice(value, kBools), comm, PETSC_ERR_USER_INPUT,
                   "option %s: '%s' is not true or false", option.name, value);
        break;
      }
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
