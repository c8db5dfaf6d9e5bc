// The stiffness K of a box for the unit tests of K's storage and products: the
// box's scene, its shares on this rank, the layout, the state and the row
// assembler that fills K (MATAIJ, block size 3) with the stiffness alone.
// Collective on PETSC_COMM_WORLD.
#pragma once

#include <petscmat.h>

#include "box_mesh.hpp"
#include "fem/assembly.hpp"
#include "fem/partition.hpp"
#include "fem/row_assembly.hpp"
#include "io/scene.hpp"

namespace softbody {

struct BoxStiffness {
  Scene scene;
  MeshShare share;
  DofLayout layout;
  State state;
  RowAssembler assembler;
  Mat K = nullptr;

  // nx x ny x nz cells of 0.1 m; E = 1 MPa, nu = 0.3.
  BoxStiffness(int nx, int ny, int nz) {
    Body body;
    body.material = {1000.0, 1e6, 0.3};
    body.fixed = false;
    body.mesh = BoxMesh(nx, ny, nz, 0.1);
    body.first_vertex = 0;
    scene.bodies.push_back(body);
    PetscMPIInt rank, size;
    MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
    MPI_Comm_size(PETSC_COMM_WORLD, &size);
    share = ShareScene(scene, rank, size);
    LocalTets tets;
    BuildDofLayout(PETSC_COMM_WORLD, PartitionOptions(), &share, &layout);
    MigrateTets(PETSC_COMM_WORLD, share, layout, &tets);
    const LocalElements elements = CollectLocalElements(scene, layout, tets);
    CreateState(PETSC_COMM_WORLD, share, layout, elements, &state);
    assembler.Setup(PETSC_COMM_WORLD, scene, layout, std::move(tets), 1.0, state.rest_positions);
    assembler.CreateMatrix(&K);
    assembler.Fill(K, RowAssembler::FillTerms().Stiffness(1.0));
  }
  ~BoxStiffness() { MatDestroy(&K); }
  BoxStiffness(const BoxStiffness &) = delete;
  BoxStiffness &operator=(const BoxStiffness &) = delete;
};

}  // namespace softbody
