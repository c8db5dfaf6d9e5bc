#include "fem/assembly.hpp"

#include <petscsf.h>

#include <algorithm>
#include <unordered_map>
#include <vector>

namespace softbody {

LocalElements CollectLocalElements(const Scene &scene, const DofLayout &layout,
                                   const LocalTets &tets) {
  LocalElements elements;
  for (size_t t = 0; t < tets.size(); ++t) {
    const std::array<PetscInt, 4> &vertices = tets.vertices[t];
    // The lowest PETSc vertex's owner owns the element.
    if (!layout.OwnsPetscVertex(*std::min_element(vertices.begin(), vertices.end()))) continue;
    const Material &material = scene.bodies[tets.body[t]].material;
    elements.vertices.push_back(vertices);
    elements.gradients.push_back(ComputeShapeGradients(tets.rest[t]));
    elements.volumes.push_back(std::abs(SignedVolume(tets.rest[t])));
    elements.lame.push_back(LameFromYoungPoisson(material.young, material.poisson));
    elements.densities.push_back(material.density);
  }
  elements.touched_vertices.reserve(4 * elements.size());
  for (const auto &v : elements.vertices)
    elements.touched_vertices.insert(elements.touched_vertices.end(), v.begin(), v.end());
  auto &touched = elements.touched_vertices;
  std::sort(touched.begin(), touched.end());
  touched.erase(std::unique(touched.begin(), touched.end()), touched.end());
  for (const auto &v : elements.vertices) {
    std::array<PetscInt, 4> index;
    for (int a = 0; a < 4; ++a)
      index[a] = std::lower_bound(touched.begin(), touched.end(), v[a]) - touched.begin();
    elements.touched_index.push_back(index);
  }
  return elements;
}

PetscErrorCode CreateElasticMatrix(MPI_Comm comm, const DofLayout &layout,
                                   const LocalElements &elements, Mat *matrix) {
  PetscFunctionBeginUser;
  const PetscInt local_dofs = 3 * layout.local_count();
  const PetscCount entries = 144 * static_cast<PetscCount>(elements.size());
  std::vector<PetscInt> rows, cols;
  rows.reserve(entries);
  cols.reserve(entries);
  for (const auto &v : elements.vertices)
    for (int a = 0; a < 4; ++a)
      for (int ca = 0; ca < 3; ++ca)
        for (int b = 0; b < 4; ++b)
          for (int cb = 0; cb < 3; ++cb) {
            rows.push_back(3 * v[a] + ca);
            cols.push_back(3 * v[b] + cb);
          }
  PetscCall(MatCreate(comm, matrix));
  PetscCall(MatSetSizes(*matrix, local_dofs, local_dofs, PETSC_DETERMINE, PETSC_DETERMINE));
  PetscCall(MatSetBlockSize(*matrix, 3));
  PetscCall(MatSetType(*matrix, MATAIJ));
  PetscCall(MatSetPreallocationCOO(*matrix, entries, rows.data(), cols.data()));
  PetscFunctionReturn(PETSC_SUCCESS);
}

void LinearStiffnessValues(const LocalElements &elements, double shear_scale,
                           double stiffness_scale, CooValues *values) {
  PetscScalar *out = values->data();
  for (size_t e = 0; e < elements.size(); ++e) {
    const Mat12 K =
        ElementStiffness(elements.gradients[e], elements.volumes[e], elements.lame[e], shear_scale);
    // Row-major, as the pattern: entry (3a+ca, 3b+cb).
    for (int i = 0; i < 12; ++i)
      for (int j = 0; j < 12; ++j) *out++ = stiffness_scale * K(i, j);
  }
}

TetPositions ElementPositions(const LocalElements &elements, size_t e, const PetscScalar *touched) {
  TetPositions x;
  for (int a = 0; a < 4; ++a)
    for (int c = 0; c < 3; ++c) x(a, c) = touched[3 * elements.touched_index[e][a] + c];
  return x;
}

double LinearStrainEnergy(const LocalElements &elements, double shear_scale,
                          const PetscScalar *x_touched, const PetscScalar *X_touched) {
  double energy = 0;
  for (size_t e = 0; e < elements.size(); ++e) {
    TetPositions force;
    double element_energy;
    ElasticForceAndEnergy(
        elements.gradients[e], elements.volumes[e], elements.lame[e], shear_scale,
        ElementPositions(elements, e, x_touched) - ElementPositions(elements, e, X_touched), &force,
        &element_energy);
    energy += element_energy;
  }
  return energy;
}

PetscErrorCode SetElasticMatrixValues(const CooValues &values, Mat matrix) {
  PetscFunctionBeginUser;
  PetscCall(MatSetValuesCOO(matrix, values.data(), INSERT_VALUES));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode CreateStiffnessMatrix(MPI_Comm comm, const DofLayout &layout,
                                     const LocalElements &elements, double shear_scale, Mat *K) {
  PetscFunctionBeginUser;
  PetscCall(CreateElasticMatrix(comm, layout, elements, K));
  CooValues values(144 * elements.size());
  LinearStiffnessValues(elements, shear_scale, 1.0, &values);
  PetscCall(SetElasticMatrixValues(values, *K));
  PetscFunctionReturn(PETSC_SUCCESS);
}

namespace {

// owned[index] += sent[i] for every entry i sent to (rank, index): each owner
// adds the senders' entries in the order of their ranks, a sum formed in one
// order whatever the timing of the messages. (VecAssembly adds stashed values
// as the messages arrive, so with three or more ranks a vertex's mass could
// differ in its last bit from run to run.)
PetscErrorCode AddSentMasses(MPI_Comm comm, std::vector<PetscSFNode> *destination,
                             const std::vector<PetscScalar> &sent,
                             std::vector<PetscScalar> *owned) {
  PetscFunctionBeginUser;
  PetscSF sf;
  PetscCall(PetscSFCreate(comm, &sf));
  PetscCall(PetscSFSetGraph(sf, static_cast<PetscInt>(owned->size()),
                            static_cast<PetscInt>(sent.size()), nullptr, PETSC_COPY_VALUES,
                            destination->data(), PETSC_COPY_VALUES));
  PetscCall(PetscSFSetUp(sf));
  PetscCall(PetscSFReduceBegin(sf, MPIU_SCALAR, sent.data(), owned->data(), MPI_SUM));
  PetscCall(PetscSFReduceEnd(sf, MPIU_SCALAR, sent.data(), owned->data(), MPI_SUM));
  PetscCall(PetscSFDestroy(&sf));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace

PetscErrorCode AssembleLumpedMass(MPI_Comm comm, const DofLayout &layout,
                                  const LocalElements &elements, Vec *lumped_mass) {
  PetscFunctionBeginUser;
  PetscCall(VecCreate(comm, lumped_mass));
  PetscCall(VecSetSizes(*lumped_mass, 3 * layout.local_count(), PETSC_DETERMINE));
  PetscCall(VecSetBlockSize(*lumped_mass, 3));
  PetscCall(VecSetType(*lumped_mass, VECMPI));
  // Rank r owns the PETSc vertices [starts[r], starts[r + 1]).
  const std::vector<PetscInt> &starts = layout.vertex_start;
  std::vector<PetscScalar> owned(layout.local_count(), 0.0), sent;
  std::vector<PetscSFNode> destination;           // per entry of sent: owner rank, its vertex there
  std::unordered_map<PetscInt, size_t> entry_of;  // another rank's vertex -> its entry
  for (size_t e = 0; e < elements.size(); ++e) {
    const double m = LumpedVertexMass(elements.densities[e], elements.volumes[e]);
    for (const PetscInt vertex : elements.vertices[e]) {
      if (layout.OwnsPetscVertex(vertex)) {
        owned[vertex - layout.local_begin()] += m;
        continue;
      }
      const auto [entry, added] = entry_of.emplace(vertex, sent.size());
      if (added) {
        const PetscInt owner =
            std::upper_bound(starts.begin(), starts.end(), vertex) - starts.begin() - 1;
        destination.push_back({owner, vertex - starts[owner]});
        sent.push_back(0.0);
      }
      sent[entry->second] += m;
    }
  }
  PetscCall(AddSentMasses(comm, &destination, sent, &owned));
  PetscScalar *values;
  PetscCall(VecGetArrayWrite(*lumped_mass, &values));
  for (size_t v = 0; v < owned.size(); ++v)
    values[3 * v] = values[3 * v + 1] = values[3 * v + 2] = owned[v];
  PetscCall(VecRestoreArrayWrite(*lumped_mass, &values));
  PetscFunctionReturn(PETSC_SUCCESS);
}

State::~State() {
  VecDestroy(&rest_positions);
  VecDestroy(&positions);
  VecDestroy(&velocities);
  VecDestroy(&lumped_mass);
}

PetscErrorCode CreateState(MPI_Comm comm, const MeshShare &share, const DofLayout &layout,
                           const LocalElements &elements, State *state) {
  PetscFunctionBeginUser;
  PetscCall(AssembleLumpedMass(comm, layout, elements, &state->lumped_mass));
  PetscCall(VecDuplicate(state->lumped_mass, &state->rest_positions));
  PetscCall(VecDuplicate(state->lumped_mass, &state->velocities));
  PetscSF sf;
  PetscCall(CreateSlabSF(comm, share, layout.natural_of_owned, &sf));
  PetscScalar *X, *v;
  PetscCall(VecGetArray(state->rest_positions, &X));
  PetscCall(VecGetArray(state->velocities, &v));
  PetscCall(FetchFromSlabs(sf, MPI_DOUBLE, 3, share.rest.data(), X));
  PetscCall(FetchFromSlabs(sf, MPI_DOUBLE, 3, share.velocities.data(), v));
  PetscCall(VecRestoreArray(state->rest_positions, &X));
  PetscCall(VecRestoreArray(state->velocities, &v));
  PetscCall(PetscSFDestroy(&sf));
  PetscCall(VecDuplicate(state->rest_positions, &state->positions));
  PetscCall(VecCopy(state->rest_positions, state->positions));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
