#include "contact/free_state.hpp"

#include <algorithm>

#include "common/held_bytes.hpp"
#include "contact/contact_meshes.hpp"
#include "contact/halo.hpp"

namespace softbody {

FreeState::~FreeState() {
  for (ScatteredSet *set : {&fixed_set_, &ring_set_}) {
    VecScatterDestroy(&set->scatter);
    VecDestroy(&set->x);
    VecDestroy(&set->v);
  }
}

int64_t FreeState::SceneBytes() const {
  return HeldBytes(slot_);
}

int32_t FreeState::Slot(int32_t natural) {
  int32_t &s = slot_[natural];
  if (s >= 0) return s;
  s = static_cast<int32_t>(stamp_.size());
  x_.insert(x_.end(), 3, kNoPosition);
  v_.insert(v_.end(), 3, 0.0);
  inverse_mass_.push_back(0.0);
  stamp_.push_back(0);
  return s;
}

Point FreeState::RestPosition(int32_t natural) const {
  return meshes_->rest(natural);
}

void FreeState::SetupBodies(const Scene &scene, const ContactMeshes &meshes,
                            double reach_in_edges) {
  const int32_t V = scene.num_vertices();
  scene_ = &scene;
  meshes_ = &meshes;
  num_bodies_ = scene.bodies.size();
  body_first_.resize(num_bodies_);
  slot_.assign(V, -1);
  body_edge_.assign(num_bodies_, 0.0);
  body_reach_.assign(num_bodies_, 0.0);
  for (size_t b = 0; b < num_bodies_; ++b) {
    const Body &body = scene.bodies[b];
    body_first_[b] = body.first_vertex;
    double length = 0;
    const int32_t first = body.first_vertex;
    const auto edges = BoundaryEdges(meshes.boundary(b));
    for (const auto &[a, c] : edges)
      length += (meshes.rest_row(first + c) - meshes.rest_row(first + a)).norm();
    body_edge_[b] = edges.empty() ? 1.0 : length / edges.size();
    body_reach_[b] = reach_in_edges * meshes.longest_edge(b);
  }
}

PetscErrorCode FreeState::SetupMasses(MPI_Comm comm, const DofLayout &layout, Vec lumped_mass,
                                      bool halo, bool same_body) {
  PetscFunctionBeginUser;
  comm_ = comm;
  layout_ = &layout;
  same_body_ = same_body;
  owned_natural_.assign(layout.natural_of_owned.begin(), layout.natural_of_owned.end());
  PlaceStaticVertices();
  for (const int32_t n : owned_natural_) position_ref(n) = RestPosition(n);
  body_box_ = static_box_;
  PetscCall(OwnInverseMasses(layout, lumped_mass));
  PetscCall(SumBodyMasses(comm));
  if (halo) PetscCall(neighbours_.Setup(comm));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// A fixed body's surface vertices (its tets' other vertices come with them,
// PlaceFixed) and its box, and the free bodies' vertices without unknowns.
void FreeState::PlaceStaticVertices() {
  static_box_.assign(num_bodies_, Box());
  for (size_t b = 0; b < num_bodies_; ++b) {
    const Body &body = scene_->bodies[b];
    if (body.fixed) {
      static_box_[b] = meshes_->fixed_box(b);
      const auto &boundary = meshes_->boundary(b);
      for (Eigen::Index k = 0; k < boundary.size(); ++k)
        PlaceFixed(body.first_vertex + boundary.data()[k],
                   RestPosition(body.first_vertex + boundary.data()[k]));
      continue;
    }
    for (int32_t n = body.first_vertex; n < body.first_vertex + body.num_vertices(); ++n) {
      if (is_free(n)) continue;
      position_ref(n) = RestPosition(n);
      static_box_[b].Extend(position(n));
    }
  }
}

// This rank's own vertices' inverse masses.
PetscErrorCode FreeState::OwnInverseMasses(const DofLayout &layout, Vec lumped_mass) {
  PetscFunctionBeginUser;
  const PetscScalar *mass;
  PetscCall(VecGetArrayRead(lumped_mass, &mass));
  for (PetscInt local = 0; local < layout.local_count(); ++local)
    inverse_mass_[Slot(layout.natural_of_owned[local])] = 1.0 / mass[3 * local];
  PetscCall(VecRestoreArrayRead(lumped_mass, &mass));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Body masses: the owned vertices' lumped masses, summed over ranks.
PetscErrorCode FreeState::SumBodyMasses(MPI_Comm comm) {
  PetscFunctionBeginUser;
  std::vector<double> owned_mass(num_bodies_, 0.0);
  for (const int32_t natural : owned_natural_)
    owned_mass[body_of(natural)] += 1.0 / inverse_mass(natural);
  body_mass_.resize(num_bodies_);
  PetscCallMPI(MPI_Allreduce(owned_mass.data(), body_mass_.data(),
                             static_cast<int>(owned_mass.size()), MPI_DOUBLE, MPI_SUM, comm));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode FreeState::SetupFixedSet(Vec lumped_mass, const std::vector<int32_t> &naturals) {
  PetscFunctionBeginUser;
  PetscCall(SetupScatteredSet(lumped_mass, naturals, &fixed_set_));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode FreeState::SetupRingSet(Vec lumped_mass, const std::vector<int32_t> &naturals) {
  PetscFunctionBeginUser;
  PetscCall(SetupScatteredSet(lumped_mass, naturals, &ring_set_));
  if (items_) SetupItems();
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode FreeState::SetupScatteredSet(Vec lumped_mass, const std::vector<int32_t> &naturals,
                                            ScatteredSet *set) {
  PetscFunctionBeginUser;
  for (const int32_t n : naturals)
    if (is_free(n)) set->naturals.push_back(n);
  std::sort(set->naturals.begin(), set->naturals.end());
  set->naturals.erase(std::unique(set->naturals.begin(), set->naturals.end()), set->naturals.end());
  std::vector<PetscInt> dofs;
  for (const int32_t n : set->naturals)
    for (int c = 0; c < 3; ++c) dofs.push_back(3 * layout_->PetscVertexOfNatural(n) + c);
  IS from;
  PetscCall(ISCreateGeneral(PETSC_COMM_SELF, static_cast<PetscInt>(dofs.size()), dofs.data(),
                            PETSC_COPY_VALUES, &from));
  PetscCall(VecCreateSeq(PETSC_COMM_SELF, static_cast<PetscInt>(dofs.size()), &set->x));
  PetscCall(VecDuplicate(set->x, &set->v));
  PetscCall(VecScatterCreate(lumped_mass, from, set->x, nullptr, &set->scatter));
  PetscCall(ISDestroy(&from));
  PetscCall(VecScatterBegin(set->scatter, lumped_mass, set->x, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecScatterEnd(set->scatter, lumped_mass, set->x, INSERT_VALUES, SCATTER_FORWARD));
  const PetscScalar *mass;
  PetscCall(VecGetArrayRead(set->x, &mass));
  for (size_t k = 0; k < set->naturals.size(); ++k) {
    position_ref(set->naturals[k]) = RestPosition(set->naturals[k]);
    inverse_mass_[Slot(set->naturals[k])] = 1.0 / mass[3 * k];
  }
  PetscCall(VecRestoreArrayRead(set->x, &mass));
  PetscFunctionReturn(PETSC_SUCCESS);
}

void FreeState::AttachItems(FreeItems *items) {
  items_ = items;
  SetupItems();
}

void FreeState::SetupItems() {
  std::vector<int32_t> kept(owned_natural_);
  for (const ScatteredSet *set : {&fixed_set_, &ring_set_})
    kept.insert(kept.end(), set->naturals.begin(), set->naturals.end());
  std::sort(kept.begin(), kept.end());
  items_->Setup(
      *scene_, *meshes_, [&](int32_t n) { return is_free(n); },
      [&](int32_t n) { return std::binary_search(kept.begin(), kept.end(), n); });
}

PetscErrorCode FreeState::Exchange(Vec x, Vec v, PetscReal dt, const StateNeeds &needs) {
  PetscFunctionBeginUser;
  ++stamp_now_;
  current_free_.clear();
  std::vector<Box> owned_boxes;
  PetscCall(WriteOwnedState(x, v, dt, &owned_boxes));
  PetscCall(ReduceBodyBoxes(owned_boxes));
  if (needs.halo) PetscCall(ExchangeHalo(owned_boxes));
  if (needs.fixed_set) PetscCall(FetchScatteredSet(x, v, dt, fixed_set_));
  if (needs.rings) PetscCall(FetchScatteredSet(x, v, dt, ring_set_));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode FreeState::WriteOwnedState(Vec x, Vec v, PetscReal dt, std::vector<Box> *boxes) {
  PetscFunctionBeginUser;
  boxes->assign(num_bodies_, Box());
  const PetscScalar *ax, *av;
  PetscCall(VecGetArrayRead(x, &ax));
  PetscCall(VecGetArrayRead(v, &av));
  for (size_t p = 0; p < owned_natural_.size(); ++p) {
    const int32_t n = owned_natural_[p], s = Slot(n);
    for (int c = 0; c < 3; ++c) {
      x_[3 * s + c] = ax[3 * p + c] + dt * av[3 * p + c];
      v_[3 * s + c] = av[3 * p + c];
    }
    (*boxes)[body_of(n)].Extend(position(n));
    MarkCurrent(n);
  }
  PetscCall(VecRestoreArrayRead(x, &ax));
  PetscCall(VecRestoreArrayRead(v, &av));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// MPI_MAX over (-lower, upper) of every rank's boxes.
PetscErrorCode FreeState::ReduceBodyBoxes(const std::vector<Box> &owned_boxes) {
  PetscFunctionBeginUser;
  std::vector<double> bounds(6 * num_bodies_);
  for (size_t b = 0; b < num_bodies_; ++b)
    for (int c = 0; c < 3; ++c) {
      bounds[6 * b + c] = -owned_boxes[b].lower[c];
      bounds[6 * b + 3 + c] = owned_boxes[b].upper[c];
    }
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, bounds.data(), static_cast<int>(bounds.size()),
                             MPI_DOUBLE, MPI_MAX, comm_));
  for (size_t b = 0; b < num_bodies_; ++b) {
    body_box_[b] = static_box_[b];
    Box moving;
    moving.lower = -Point(&bounds[6 * b]);
    moving.upper = Point(&bounds[6 * b + 3]);
    if (!moving.Empty()) body_box_[b].Extend(moving);
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode FreeState::ExchangeHalo(const std::vector<Box> &owned_boxes) {
  PetscFunctionBeginUser;
  HaloPlan plan;
  PetscCall(PlanHalo(
      comm_, owned_boxes, owned_natural_.size(),
      [&](int32_t p, const RankBox &box) {
        const int32_t n = owned_natural_[p], body = body_of(n);
        return (same_body_ || box.body != body) &&
               box.box().Contains(position(n), body_reach_[body]);
      },
      &plan, &bytes_sent_));
  std::vector<HaloVertex> records, received;
  for (const int32_t p : plan.items) {
    const int32_t n = owned_natural_[p], s = slot_[n];
    HaloVertex h{n, {}, {}, inverse_mass_[s]};
    std::copy(&x_[3 * s], &x_[3 * s] + 3, h.x);
    std::copy(&v_[3 * s], &v_[3 * s] + 3, h.v);
    records.push_back(h);
  }
  PetscInt64 bytes;
  PetscCall(neighbours_.Exchange(plan.ranks, plan.counts, records, &received, &bytes));
  bytes_sent_ += bytes;
  if (items_) PetscCall(ExchangeItems(plan, records, received));
  for (const HaloVertex &h : received) {
    const int32_t n = h.natural, s = Slot(n);
    std::copy(h.x, h.x + 3, &x_[3 * s]);
    std::copy(h.v, h.v + 3, &v_[3 * s]);
    inverse_mass_[s] = h.inverse_mass;
    MarkCurrent(n);
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

// The items of the halo's vertices (AttachItems), along the same ranks.
PetscErrorCode FreeState::ExchangeItems(const HaloPlan &plan, const std::vector<HaloVertex> &sent,
                                        const std::vector<HaloVertex> &received) {
  PetscFunctionBeginUser;
  std::vector<int32_t> sent_naturals, received_naturals;
  for (const HaloVertex &h : sent) sent_naturals.push_back(h.natural);
  for (const HaloVertex &h : received) received_naturals.push_back(h.natural);
  PetscInt64 bytes;
  PetscCall(items_->Exchange(neighbours_, plan.ranks, plan.counts, sent_naturals, received_naturals,
                             &bytes));
  bytes_sent_ += bytes;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode FreeState::FetchScatteredSet(Vec x, Vec v, PetscReal dt, const ScatteredSet &set) {
  PetscFunctionBeginUser;
  if (!set.scatter) PetscFunctionReturn(PETSC_SUCCESS);
  for (auto [from, to] : {std::pair<Vec, Vec>(x, set.x), std::pair<Vec, Vec>(v, set.v)}) {
    PetscCall(VecScatterBegin(set.scatter, from, to, INSERT_VALUES, SCATTER_FORWARD));
    PetscCall(VecScatterEnd(set.scatter, from, to, INSERT_VALUES, SCATTER_FORWARD));
  }
  const PetscScalar *ax, *av;
  PetscCall(VecGetArrayRead(set.x, &ax));
  PetscCall(VecGetArrayRead(set.v, &av));
  for (size_t k = 0; k < set.naturals.size(); ++k) {
    const int32_t n = set.naturals[k], s = Slot(n);
    for (int c = 0; c < 3; ++c) {
      x_[3 * s + c] = ax[3 * k + c] + dt * av[3 * k + c];
      v_[3 * s + c] = av[3 * k + c];
    }
    MarkCurrent(n);
  }
  PetscCall(VecRestoreArrayRead(set.x, &ax));
  PetscCall(VecRestoreArrayRead(set.v, &av));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode FreeState::WriteOwned(Vec x, Vec v) const {
  PetscFunctionBeginUser;
  PetscScalar *lx, *lv;
  PetscCall(VecGetArray(x, &lx));
  PetscCall(VecGetArray(v, &lv));
  for (PetscInt p = 0; p < local_count(); ++p)
    for (int c = 0; c < 3; ++c) {
      lx[3 * p + c] = x_[3 * slot_[owned_natural_[p]] + c];
      lv[3 * p + c] = v_[3 * slot_[owned_natural_[p]] + c];
    }
  PetscCall(VecRestoreArray(x, &lx));
  PetscCall(VecRestoreArray(v, &lv));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
