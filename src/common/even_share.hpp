// Even shares of a range among ranks: the one split every distributed piece uses
// (the vertex graph's rows and tets, mesh-file slabs, result-file slabs), so that
// share r of one is share r of another.
#pragma once

#include <cstdint>

namespace softbody {

// First index of part `part` when `count` items are split into `parts` parts:
// floor(count part / parts), computed without forming count part (no overflow for
// count < 2^63). Part sizes differ by at most one, earlier parts never larger.
constexpr int64_t EvenShareBegin(int64_t count, int parts, int part) {
  return (count / parts) * part + (count % parts) * part / parts;
}

}  // namespace softbody
