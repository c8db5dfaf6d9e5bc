#include "common/number_format.hpp"

#include <cstdio>

namespace softbody {

std::string FormatNumber(double value, int significant_digits) {
  char text[32];  // %.17g of any double fits
  std::snprintf(text, sizeof(text), "%.*g", significant_digits, value);
  return text;
}

}  // namespace softbody
