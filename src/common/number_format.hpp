// Numbers in messages for people.
//
// PetscPrintf's %g marks a value that looks like an integer with a trailing
// dot ("1.", "2."), as a C literal of type double would be. Summaries and
// warnings print numbers plainly instead ("shear scale 1", "t = 2 s"): format
// them here and print the text with %s.
#pragma once

#include <string>

namespace softbody {

// Not collective. `value` as C's printf prints %.<significant_digits>g:
// FormatNumber(1) == "1", FormatNumber(0.02) == "0.02", FormatNumber(2.5e-7) ==
// "2.5e-07", FormatNumber(3.14159, 3) == "3.14".
std::string FormatNumber(double value, int significant_digits = 6);

}  // namespace softbody
