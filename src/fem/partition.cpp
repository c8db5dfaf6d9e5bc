#include "fem/partition.hpp"

#include <petscis.h>

#include <algorithm>
#include <numeric>

namespace softbody {

int MarkBodiesAtRest(const MotionSources &sources, Scene *scene) {
  if (sources.gravity || sources.ground || sources.constraints) return 0;
  const size_t n = scene->bodies.size();
  std::vector<Eigen::Vector3d> lo(n), hi(n);
  for (size_t b = 0; b < n; ++b) {
    const Body &body = scene->bodies[b];
    if (body.fixed) {
      if (body.mesh.num_vertices() == 0) continue;
    } else {
      if (b < sources.deformed.size() && sources.deformed[b]) return 0;
      for (int32_t v = 0; v < body.mesh.num_vertices(); ++v)
        if (scene->initial_velocities.row(body.first_vertex + v).squaredNorm() != 0)
          return 0;  // it moves
    }
    lo[b] = body.mesh.vertices.colwise().minCoeff().transpose();
    hi[b] = body.mesh.vertices.colwise().maxCoeff().transpose();
  }
  // Everything is still: a free body at rest unless its box meets another's.
  std::vector<bool> alone(n, true);
  for (size_t a = 0; a < n; ++a)
    for (size_t b = a + 1; b < n; ++b) {
      if (scene->bodies[a].mesh.num_vertices() == 0 || scene->bodies[b].mesh.num_vertices() == 0)
        continue;
      if ((lo[a].array() <= hi[b].array()).all() && (lo[b].array() <= hi[a].array()).all())
        alone[a] = alone[b] = false;
    }
  int marked = 0;
  for (size_t b = 0; b < n; ++b) {
    Body &body = scene->bodies[b];
    if (body.fixed || !alone[b]) continue;
    body.fixed = body.at_rest = true;
    ++marked;
  }
  return marked;
}

PetscErrorCode ProcessPartitionOptions(MPI_Comm comm, PartitionOptions *options) {
  PetscFunctionBeginUser;
  static const char *const kNames[] = {"auto", "metis", "ptscotch", "Partitioner", "", nullptr};
  PetscEnum chosen = static_cast<PetscEnum>(options->partitioner);
  PetscOptionsBegin(comm, nullptr, "Partition of the free vertices over the ranks", nullptr);
  PetscCall(PetscOptionsEnum("-partitioner",
                             "auto (METIS on up to 2 ranks, else PT-Scotch), metis (the whole "
                             "graph on rank 0) or ptscotch (on the distributed graph)",
                             nullptr, kNames, chosen, &chosen, nullptr));
  PetscOptionsEnd();
  options->partitioner = static_cast<Partitioner>(chosen);
  PetscFunctionReturn(PETSC_SUCCESS);
}

const char *PartitionerName(Partitioner partitioner) {
  switch (partitioner) {
    case Partitioner::kMetis:
      return "metis";
    case Partitioner::kPtScotch:
      return "ptscotch";
    default:
      return "auto";
  }
}

namespace {

// Free vertices in natural order: layout->free_of_natural and natural_of_free.
void NumberFreeVertices(const Scene &scene, DofLayout *layout) {
  std::vector<char> in_free_tet(scene.num_vertices(), 0);
  for (const Body &body : scene.bodies)
    if (!body.fixed)
      for (int32_t t = 0; t < body.mesh.num_tets(); ++t)
        for (int a = 0; a < 4; ++a) in_free_tet[body.first_vertex + body.mesh.tets(t, a)] = 1;
  layout->free_of_natural.assign(scene.num_vertices(), -1);
  layout->natural_of_free.clear();
  for (PetscInt v = 0; v < scene.num_vertices(); ++v)
    if (in_free_tet[v]) {
      layout->free_of_natural[v] = layout->num_free();
      layout->natural_of_free.push_back(v);
    }
}

// PETSc numbers from the parts of this rank's graph rows: part by part, natural
// order inside a part (ISPartitioningToNumbering). Sets vertex_start, and the
// PETSc vertex of every free vertex (gathered to every rank while the rest of the
// program reads the scene whole).
PetscErrorCode NumberByPart(MPI_Comm comm, const std::vector<PetscInt> &part, DofLayout *layout) {
  PetscFunctionBeginUser;
  IS parts, numbers;
  PetscCall(ISCreateGeneral(comm, static_cast<PetscInt>(part.size()), part.data(),
                            PETSC_USE_POINTER, &parts));
  PetscCall(ISPartitioningToNumbering(parts, &numbers));
  std::vector<PetscInt> counts(layout->size);
  PetscCall(ISPartitioningCount(parts, layout->size, counts.data()));
  layout->vertex_start.assign(layout->size + 1, 0);
  for (PetscMPIInt q = 0; q < layout->size; ++q)
    layout->vertex_start[q + 1] = layout->vertex_start[q] + counts[q];
  const PetscInt *mine;
  PetscCall(ISGetIndices(numbers, &mine));
  std::vector<int> rows(layout->size), offsets(layout->size + 1, 0);
  const int my_rows = static_cast<int>(part.size());
  PetscCallMPI(MPI_Allgather(&my_rows, 1, MPI_INT, rows.data(), 1, MPI_INT, comm));
  for (PetscMPIInt q = 0; q < layout->size; ++q) offsets[q + 1] = offsets[q] + rows[q];
  layout->petsc_of_free.resize(layout->num_free());
  PetscCallMPI(MPI_Allgatherv(mine, my_rows, MPIU_INT, layout->petsc_of_free.data(), rows.data(),
                              offsets.data(), MPIU_INT, comm));
  PetscCall(ISRestoreIndices(numbers, &mine));
  PetscCall(ISDestroy(&numbers));
  PetscCall(ISDestroy(&parts));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace

PetscErrorCode BuildDofLayout(MPI_Comm comm, const Scene &scene, const PartitionOptions &options,
                              DofLayout *layout) {
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(comm, &layout->rank));
  PetscCallMPI(MPI_Comm_size(comm, &layout->size));
  NumberFreeVertices(scene, layout);
  VertexGraphRows graph;
  PetscCall(BuildVertexGraphRows(comm, scene, layout->free_of_natural, layout->num_free(), &graph));
  std::vector<PetscInt> part;
  PetscCall(PartitionVertexGraph(comm, &graph, options.partitioner, &part, &layout->partitioner));
  graph = VertexGraphRows();
  PetscCall(NumberByPart(comm, part, layout));
  layout->natural_of_owned.resize(layout->local_count());
  for (PetscInt f = 0; f < layout->num_free(); ++f) {
    const PetscInt local = layout->LocalOfFree(f);
    if (local >= 0) layout->natural_of_owned[local] = layout->natural_of_free[f];
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

std::vector<int32_t> OwnedVertexBodies(const Scene &scene, const DofLayout &layout) {
  std::vector<int32_t> body_of_natural(scene.num_vertices());
  for (size_t b = 0; b < scene.bodies.size(); ++b)
    std::fill_n(body_of_natural.begin() + scene.bodies[b].first_vertex,
                scene.bodies[b].mesh.num_vertices(), static_cast<int32_t>(b));
  std::vector<int32_t> owned(layout.local_count());
  for (PetscInt f = 0; f < layout.num_free(); ++f) {
    const PetscInt local = layout.LocalOfFree(f);
    if (local >= 0) owned[local] = body_of_natural[layout.natural_of_free[f]];
  }
  return owned;
}

}  // namespace softbody
