#include "fem/partition.hpp"

#include <metis.h>

#include <algorithm>
#include <numeric>

namespace softbody {

namespace {

// METIS's random seed, fixed so that a scene is partitioned the same way at
// every run (results reproducible bit for bit); any fixed value would do.
constexpr idx_t kMetisSeed = 1;

// Rank 0 only: METIS k-way partition of the free-vertex adjacency graph.
PetscErrorCode PartitionFreeVertices(const Scene &scene, const DofLayout &layout, idx_t nparts,
                                     std::vector<idx_t> *part) {
  PetscFunctionBeginUser;
  const PetscInt n = layout.num_free();
  // Neighbour lists from the tets, then CSR without self loops or repeats.
  std::vector<std::vector<idx_t>> neighbours(n);
  for (const Body &body : scene.bodies) {
    if (body.fixed) continue;
    for (int32_t t = 0; t < body.mesh.num_tets(); ++t)
      for (int a = 0; a < 4; ++a)
        for (int b = 0; b < 4; ++b)
          if (a != b)
            neighbours[layout.free_of_natural[body.first_vertex + body.mesh.tets(t, a)]].push_back(
                static_cast<idx_t>(
                    layout.free_of_natural[body.first_vertex + body.mesh.tets(t, b)]));
  }
  std::vector<idx_t> xadj(n + 1, 0), adjncy;
  for (PetscInt v = 0; v < n; ++v) {
    auto &list = neighbours[v];
    std::sort(list.begin(), list.end());
    list.erase(std::unique(list.begin(), list.end()), list.end());
    adjncy.insert(adjncy.end(), list.begin(), list.end());
    xadj[v + 1] = static_cast<idx_t>(adjncy.size());
    std::vector<idx_t>().swap(list);
  }
  idx_t nvtxs = static_cast<idx_t>(n), ncon = 1, objval = 0;
  idx_t options[METIS_NOPTIONS];
  METIS_SetDefaultOptions(options);
  options[METIS_OPTION_SEED] = kMetisSeed;
  part->assign(n, 0);
  const int status =
      METIS_PartGraphKway(&nvtxs, &ncon, xadj.data(), adjncy.data(), nullptr, nullptr, nullptr,
                          &nparts, nullptr, nullptr, options, &objval, part->data());
  PetscCheck(status == METIS_OK, PETSC_COMM_SELF, PETSC_ERR_LIB, "METIS_PartGraphKway failed (%d)",
             status);
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace

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

PetscErrorCode BuildDofLayout(MPI_Comm comm, const Scene &scene, DofLayout *layout) {
  PetscFunctionBeginUser;
  PetscCallMPI(MPI_Comm_rank(comm, &layout->rank));
  PetscCallMPI(MPI_Comm_size(comm, &layout->size));

  // Free vertices in natural order.
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
  const PetscInt n = layout->num_free();

  // Part of every free vertex: METIS on rank 0 when there is more than one rank.
  std::vector<idx_t> part(n, 0);
  if (layout->size > 1 && n > 0) {
    if (layout->rank == 0) PetscCall(PartitionFreeVertices(scene, *layout, layout->size, &part));
    static_assert(sizeof(idx_t) == sizeof(int32_t), "METIS built with 32-bit indices expected");
    PetscCallMPI(MPI_Bcast(part.data(), static_cast<int>(n), MPI_INT32_T, 0, comm));
  }

  // Renumber part by part, natural order within a part.
  layout->vertex_start.assign(layout->size + 1, 0);
  for (PetscInt f = 0; f < n; ++f) ++layout->vertex_start[part[f] + 1];
  std::partial_sum(layout->vertex_start.begin(), layout->vertex_start.end(),
                   layout->vertex_start.begin());
  std::vector<PetscInt> next(layout->vertex_start.begin(), layout->vertex_start.end() - 1);
  layout->petsc_of_free.resize(n);
  for (PetscInt f = 0; f < n; ++f) layout->petsc_of_free[f] = next[part[f]]++;
  layout->natural_of_owned.resize(layout->local_count());
  for (PetscInt f = 0; f < n; ++f) {
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
