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
};

// Collective. Reads -ground -restitution -friction -sharp_edges -impulse_spreading -constraints
// -edge_bounds.
PetscErrorCode ProcessContactOptions(MPI_Comm comm, ContactOptions *options);

// Not collective. Whether contact may need the bodies' whole meshes on every
// rank (ContactSolver reads them when it is active): with a ground, distance
// constraints or edge bounds, or with more than one body (obstacles).
inline bool ContactMayNeedWholeMeshes(const ContactOptions &options, size_t num_bodies) {
  return options.ground || !options.constraints_path.empty() || options.edge_bounds ||
         num_bodies > 1;
}

}  // namespace softbody
