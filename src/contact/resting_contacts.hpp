// The resting contacts carried from one step into the next: a contact stays
// constrained while the obstacle pushes it (normal impulse lambda >= 0) and does
// not bounce; it is released when it would pull. Checkpoints store them as
// (natural vertex, obstacle), the obstacle a body index, -1 the ground, or
// -2 - f for sharp-edge feature point f, with each one's reaction (N s: the
// next step's two-sided row starts its multiplier there).
#pragma once

#include <petscsys.h>

#include <array>
#include <cstdint>
#include <utility>
#include <vector>

#include "contact/contact_constraints.hpp"
#include "contact/sharp_features.hpp"
#include "fem/partition.hpp"

namespace softbody {

class RestingContacts {
 public:
  // The obstacles of this run, to drop restored entries it does not have.
  struct Known {
    bool ground;        // the ground is an obstacle
    bool bodies;        // bodies are obstacles
    size_t num_bodies;  // of the scene
  };
  using Entry = std::pair<PetscInt, Contact>;  // (local vertex, contact)

  void Clear() { entries_.clear(); }
  void Add(PetscInt local, const Contact &contact) { entries_.push_back({local, contact}); }
  const std::vector<Entry> &entries() const { return entries_; }
  // Not collective. Whether this rank rests a sharp-edge feature contact.
  bool any_feature() const;

  // Collective: every rank's entries in rank order, on rank 0 (empty elsewhere),
  // and their reactions.
  PetscErrorCode Gather(MPI_Comm comm, std::vector<std::array<int32_t, 2>> *all,
                        std::vector<double> *reactions) const;
  // Not collective: keeps this rank's own vertices' entries in the list's order.
  // reactions: one per entry of `all`, or empty (none known: zero).
  void Restore(const std::vector<std::array<int32_t, 2>> &all, const std::vector<double> &reactions,
               const DofLayout &layout, const SharpFeatures &features, const Known &known);

 private:
  std::vector<Entry> entries_;
};

}  // namespace softbody
