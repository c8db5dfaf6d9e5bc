// The options of collisions, friction and distance constraints.
#pragma once

#include <petscsys.h>

#include <string>

namespace softbody {

struct ContactOptions {
  PetscBool ground = PETSC_FALSE;
  PetscReal ground_y = 0;     // m
  PetscReal restitution = 0;  // e in [0, 1]
  PetscReal friction = 0;     // Coulomb coefficient mu >= 0
  PetscReal gravity = 0;      // |g| (m/s^2), set by the caller: no bounce below 2 |g| dt
  PetscBool impulse_spreading = PETSC_FALSE;
  PetscBool sharp_edges = PETSC_TRUE;  // fixed bodies' edges and corners against free faces
  std::string constraints_path;        // "" = none
  PetscBool edge_bounds = PETSC_FALSE;
  PetscReal edge_lower = 1, edge_upper = 1;  // x rest length
  // The collision guard (collision_guard.hpp): contacts end this fraction of the
  // body's mean boundary edge outside the obstacle, and no surface pair comes
  // closer than a quarter of it.
  PetscBool guard = PETSC_TRUE;
  PetscReal gap = 1e-4;
  // A probe on the positions of the last one, which moved nothing, keeps its
  // answer without detection (the same result, bit for bit; off: tests compare).
  PetscBool guard_reuse = PETSC_TRUE;
  // A body's surface against its own (non-adjacent) faces and edges: on with any
  // other contact unless -self_contact 0; -self_contact 1 also guards a lone body.
  PetscBool self_contact = PETSC_TRUE;
  PetscBool self_contact_set = PETSC_FALSE;
  // The free state's halo (free_state.hpp): a rank receives other ranks'
  // vertices within this many of their body's longest rest tet edge of its
  // own. 3: a tet stretched less than threefold comes whole; a huge value
  // sends every vertex near any box (what tests compare the halo with).
  PetscReal halo_reach = 3;
  // Every rank holds the fixed bodies' tets whole when they would take at most
  // this many MB on a rank (fixed_tets.hpp; contact.cpp's kHeldBytesPerFixedTet,
  // 140 B each with their boxes and grid), else each holds those near its own
  // vertices. 64 MB (about 4.6e5 tets): small beside what a rank holds anyway,
  // and a small fixed scene is cheaper held whole than fetched as the free
  // bodies move (the stairway's 362 175: 35-60 % more contact time by region).
  PetscReal fixed_replicate_mb = 64;
};

// Collective. Reads -ground -restitution -friction -sharp_edges -impulse_spreading -constraints
// -edge_bounds -contact_guard -contact_guard_reuse -contact_gap -self_contact
// -contact_halo_reach -contact_fixed_replicate_mb.
PetscErrorCode ProcessContactOptions(MPI_Comm comm, ContactOptions *options);

// Not collective. Whether contact may run (ContactSolver builds its structures
// from the ranks' shares): with a ground, distance constraints
// or edge bounds, with more than one body (obstacles), or with -self_contact 1.
inline bool ContactMayRun(const ContactOptions &options, size_t num_bodies) {
  return options.ground || !options.constraints_path.empty() || options.edge_bounds ||
         num_bodies > 1 || (options.self_contact_set && options.self_contact && options.guard);
}

}  // namespace softbody
