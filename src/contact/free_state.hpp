// The state that contact queries read, in natural vertex order on every rank:
// world positions (m) and velocities (m/s) of all vertices, inverse lumped
// masses (1/kg; 0 for fixed and stray vertices), each vertex's body, and per
// body its mean boundary edge length (m) and total lumped mass (kg).
//
// Fixed vertices keep their rest positions and zero velocity. Free vertices
// are filled by Gather, which brings every rank's free vertices to every rank;
// without gathering, only this rank's own vertices are read (the ground and
// fixed bodies need no more).
#pragma once

#include <petscvec.h>

#include <cstdint>
#include <vector>

#include "contact/geometry.hpp"
#include "fem/partition.hpp"
#include "io/scene.hpp"

namespace softbody {

class FreeState {
 public:
  FreeState() = default;
  FreeState(const FreeState &) = delete;
  FreeState &operator=(const FreeState &) = delete;
  ~FreeState();

  // Not collective. Bodies, rest positions and mean boundary edge lengths.
  void SetupBodies(const Scene &scene);
  // Collective. Owned vertices, inverse masses (all free vertices' when
  // `gather`, which also prepares Gather; else this rank's own) and body masses.
  PetscErrorCode SetupMasses(MPI_Comm comm, const DofLayout &layout, Vec lumped_mass, bool gather);
  // Collective. Free vertices at x + dt v (dt = 0: at x), velocities v, from all ranks.
  PetscErrorCode Gather(Vec x, Vec v, PetscReal dt);
  // Not collective. Writes this rank's vertices of the world arrays into x and v.
  PetscErrorCode WriteOwned(Vec x, Vec v) const;

  Point position(int32_t natural) const { return Point(&x_[3 * natural]); }
  Point velocity(int32_t natural) const { return Point(&v_[3 * natural]); }
  Eigen::Map<Point> position_ref(int32_t natural) { return Eigen::Map<Point>(&x_[3 * natural]); }
  Eigen::Map<Point> velocity_ref(int32_t natural) { return Eigen::Map<Point>(&v_[3 * natural]); }
  double inverse_mass(int32_t natural) const { return inverse_mass_[natural]; }
  int32_t body_of(int32_t natural) const { return body_of_[natural]; }
  double edge(size_t body) const { return body_edge_[body]; }
  double mass(size_t body) const { return body_mass_[body]; }
  // Local vertex -> natural vertex.
  const std::vector<int32_t> &owned_natural() const { return owned_natural_; }
  PetscInt local_count() const { return static_cast<PetscInt>(owned_natural_.size()); }

 private:
  PetscErrorCode GatherInverseMasses(const DofLayout &layout, Vec lumped_mass);
  PetscErrorCode OwnInverseMasses(const DofLayout &layout, Vec lumped_mass);
  PetscErrorCode SumBodyMasses(MPI_Comm comm);

  const DofLayout *layout_ = nullptr;
  size_t num_bodies_ = 0;
  std::vector<int32_t> body_of_;        // natural vertex -> body
  std::vector<int32_t> owned_natural_;  // local vertex -> natural vertex
  std::vector<double> inverse_mass_;    // natural vertex (0: fixed or stray)
  std::vector<double> x_, v_;           // natural, 3 per vertex (free ones gathered)
  std::vector<double> body_edge_;       // mean boundary edge length per body
  std::vector<double> body_mass_;       // total lumped mass per body (kg)
  VecScatter to_all_ = nullptr;
  Vec all_x_ = nullptr, all_v_ = nullptr;
};

}  // namespace softbody
