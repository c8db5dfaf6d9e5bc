// User-prescribed deformations (-deform): at a given time, a body's positions are
// scaled about its mass-weighted centroid c by S = diag(sx, sy, sz),
//     x <- c + S (x - c),
// velocities unchanged; the elastic forces then pull it back. A negative factor
// mirrors the body, which inverts every one of its tets.
#pragma once

#include <petscvec.h>

#include <vector>

#include "fem/partition.hpp"
#include "io/scene.hpp"

namespace softbody {

struct Deformation {
  PetscInt body;
  PetscReal time;  // s
  Eigen::Vector3d scale;
  bool applied = false;
};

// Collective. Reads -deform "body:time:sx,sy,sz[;body:time:sx,sy,sz...]" ("" if unset).
PetscErrorCode ProcessDeformationOptions(MPI_Comm comm, std::string *text);

// Collective. Parses the -deform text and checks it against the scene (body
// index, not fixed, time >= 0, factors non-zero).
PetscErrorCode ParseDeformations(MPI_Comm comm, const std::string &text, const Scene &scene,
                                 std::vector<Deformation> *deformations);

// Collective. Applies every deformation due at `time` (time >= its time, up to
// half a step of round-off) not applied before; *changed tells whether any was.
PetscErrorCode ApplyDueDeformations(const Scene &scene, const DofLayout &layout, PetscReal time,
                                    PetscReal tolerance, Vec lumped_mass, Vec positions,
                                    std::vector<Deformation> *deformations, bool *changed);

}  // namespace softbody
