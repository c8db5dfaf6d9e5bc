// The halo's plan, shared by the free state (free_state.hpp) and the collision
// guard (collision_guard.hpp): each rank's boxes of its own vertices, one per
// body, are gathered on every rank (a few boxes per rank: O(P) small records,
// the one all-ranks step), and each rank then sends its vertices that lie
// within reach of another rank's box to that rank alone, point to point
// (common/neighbour_exchange.hpp). Lengths in metres. Collective where said.
#pragma once

#include <petscsys.h>

#include <cstdint>
#include <vector>

#include "contact/geometry.hpp"

namespace softbody {

// Another rank's box of its own vertices of one body.
struct RankBox {
  PetscMPIInt rank;
  int32_t body;
  double lower[3], upper[3];  // plain numbers: records travel as bytes
  Box box() const {
    Box b;
    b.lower = Point(lower);
    b.upper = Point(upper);
    return b;
  }
};

// Collective. The other ranks' non-empty boxes, in rank order, from this
// rank's `mine` (per body; empty boxes are not sent). *bytes_sent grows by
// this rank's share.
PetscErrorCode GatherRankBoxes(MPI_Comm comm, const std::vector<Box> &mine,
                               std::vector<RankBox> *others, PetscInt64 *bytes_sent);

// Not collective. For each rank with a box that `wants(item, box)` for some of
// this rank's items 0 .. num_items - 1: the rank, how many items, and the
// items (grouped by rank, ranks increasing, each item at most once per rank).
template <class Wants>
void SelectForRanks(const std::vector<RankBox> &others, size_t num_items, Wants wants,
                    std::vector<PetscMPIInt> *ranks, std::vector<PetscMPIInt> *counts,
                    std::vector<int32_t> *items) {
  for (size_t first = 0, last; first < others.size(); first = last) {
    for (last = first; last < others.size() && others[last].rank == others[first].rank;) ++last;
    const size_t before = items->size();
    for (size_t i = 0; i < num_items; ++i)
      for (size_t b = first; b < last; ++b)
        if (wants(static_cast<int32_t>(i), others[b])) {
          items->push_back(static_cast<int32_t>(i));
          break;
        }
    if (items->size() == before) continue;
    ranks->push_back(others[first].rank);
    counts->push_back(static_cast<PetscMPIInt>(items->size() - before));
  }
}

// Collective. The halo's plan in one call: GatherRankBoxes with this rank's
// boxes `mine`, then SelectForRanks over its num_items items.
struct HaloPlan {
  std::vector<PetscMPIInt> ranks, counts;
  std::vector<int32_t> items;
};
template <class Wants>
PetscErrorCode PlanHalo(MPI_Comm comm, const std::vector<Box> &mine, size_t num_items, Wants wants,
                        HaloPlan *plan, PetscInt64 *bytes_sent) {
  PetscFunctionBeginUser;
  std::vector<RankBox> others;
  PetscCall(GatherRankBoxes(comm, mine, &others, bytes_sent));
  SelectForRanks(others, num_items, wants, &plan->ranks, &plan->counts, &plan->items);
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
