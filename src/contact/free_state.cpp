#include "contact/free_state.hpp"

namespace softbody {

FreeState::~FreeState() {
  VecScatterDestroy(&to_all_);
  VecDestroy(&all_x_);
  VecDestroy(&all_v_);
}

void FreeState::SetupBodies(const Scene &scene) {
  const int32_t V = scene.num_vertices();
  num_bodies_ = scene.bodies.size();
  body_of_.resize(V);
  x_.resize(3 * static_cast<size_t>(V));
  v_.assign(3 * static_cast<size_t>(V), 0.0);
  body_edge_.assign(scene.bodies.size(), 0.0);
  for (size_t b = 0; b < scene.bodies.size(); ++b) {
    const Body &body = scene.bodies[b];
    for (int32_t v = 0; v < body.mesh.num_vertices(); ++v) {
      body_of_[body.first_vertex + v] = static_cast<int32_t>(b);
      for (int c = 0; c < 3; ++c) x_[3 * (body.first_vertex + v) + c] = body.mesh.vertices(v, c);
    }
    double length = 0;
    const auto edges = BoundaryEdges(body.mesh);
    for (const auto &[a, c] : edges)
      length += (body.mesh.vertices.row(c) - body.mesh.vertices.row(a)).norm();
    body_edge_[b] = edges.empty() ? 1.0 : length / edges.size();
  }
}

PetscErrorCode FreeState::SetupMasses(MPI_Comm comm, const DofLayout &layout, Vec lumped_mass,
                                      bool gather) {
  PetscFunctionBeginUser;
  layout_ = &layout;
  owned_natural_.assign(layout.natural_of_owned.begin(), layout.natural_of_owned.end());
  inverse_mass_.assign(body_of_.size(), 0.0);
  if (gather)
    PetscCall(GatherInverseMasses(layout, lumped_mass));
  else
    PetscCall(OwnInverseMasses(layout, lumped_mass));
  PetscCall(SumBodyMasses(comm));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Every free vertex's inverse mass on every rank; also creates the scatter Gather uses.
PetscErrorCode FreeState::GatherInverseMasses(const DofLayout &layout, Vec lumped_mass) {
  PetscFunctionBeginUser;
  PetscCall(VecScatterCreateToAll(lumped_mass, &to_all_, &all_x_));
  PetscCall(VecDuplicate(all_x_, &all_v_));
  PetscCall(VecScatterBegin(to_all_, lumped_mass, all_x_, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecScatterEnd(to_all_, lumped_mass, all_x_, INSERT_VALUES, SCATTER_FORWARD));
  const PetscScalar *mass;
  PetscCall(VecGetArrayRead(all_x_, &mass));
  for (PetscInt f = 0; f < layout.num_free(); ++f)
    inverse_mass_[layout.natural_of_free[f]] = 1.0 / mass[3 * layout.petsc_of_free[f]];
  PetscCall(VecRestoreArrayRead(all_x_, &mass));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// This rank's own vertices' inverse masses.
PetscErrorCode FreeState::OwnInverseMasses(const DofLayout &layout, Vec lumped_mass) {
  PetscFunctionBeginUser;
  const PetscScalar *mass;
  PetscCall(VecGetArrayRead(lumped_mass, &mass));
  for (PetscInt local = 0; local < layout.local_count(); ++local)
    inverse_mass_[layout.natural_of_owned[local]] = 1.0 / mass[3 * local];
  PetscCall(VecRestoreArrayRead(lumped_mass, &mass));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Body masses: the owned vertices' lumped masses, summed over ranks.
PetscErrorCode FreeState::SumBodyMasses(MPI_Comm comm) {
  PetscFunctionBeginUser;
  std::vector<double> owned_mass(num_bodies_, 0.0);
  for (const int32_t natural : owned_natural_)
    owned_mass[body_of_[natural]] += 1.0 / inverse_mass_[natural];
  body_mass_.resize(num_bodies_);
  PetscCallMPI(MPI_Allreduce(owned_mass.data(), body_mass_.data(),
                             static_cast<int>(owned_mass.size()), MPI_DOUBLE, MPI_SUM, comm));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode FreeState::Gather(Vec x, Vec v, PetscReal dt) {
  PetscFunctionBeginUser;
  for (auto [from, to] : {std::pair<Vec, Vec>(x, all_x_), std::pair<Vec, Vec>(v, all_v_)}) {
    PetscCall(VecScatterBegin(to_all_, from, to, INSERT_VALUES, SCATTER_FORWARD));
    PetscCall(VecScatterEnd(to_all_, from, to, INSERT_VALUES, SCATTER_FORWARD));
  }
  const PetscScalar *ax, *av;
  PetscCall(VecGetArrayRead(all_x_, &ax));
  PetscCall(VecGetArrayRead(all_v_, &av));
  for (PetscInt f = 0; f < layout_->num_free(); ++f) {
    const PetscInt n = layout_->natural_of_free[f], p = layout_->petsc_of_free[f];
    for (int c = 0; c < 3; ++c) {
      x_[3 * n + c] = ax[3 * p + c] + dt * av[3 * p + c];
      v_[3 * n + c] = av[3 * p + c];
    }
  }
  PetscCall(VecRestoreArrayRead(all_x_, &ax));
  PetscCall(VecRestoreArrayRead(all_v_, &av));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode FreeState::WriteOwned(Vec x, Vec v) const {
  PetscFunctionBeginUser;
  PetscScalar *lx, *lv;
  PetscCall(VecGetArray(x, &lx));
  PetscCall(VecGetArray(v, &lv));
  for (PetscInt p = 0; p < local_count(); ++p)
    for (int c = 0; c < 3; ++c) {
      lx[3 * p + c] = x_[3 * owned_natural_[p] + c];
      lv[3 * p + c] = v_[3 * owned_natural_[p] + c];
    }
  PetscCall(VecRestoreArray(x, &lx));
  PetscCall(VecRestoreArray(v, &lv));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
