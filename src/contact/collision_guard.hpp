// The collision guard: after everything else in a step, no surface primitive
// crosses another during the step (the straight motion from the step's start
// to its end positions), so no surface ends the step crossing another or its
// own, at any speed.
//
// Each round finds the pairs that would come closer than the separation
// (surface_collisions.hpp: vertex-triangle and edge-edge of two bodies or,
// with self-contact, of one body; vertices against the ground) and merges
// their vertices into rigid impact zones (impact_zones.hpp) that move rigidly
// or, touching something immobile, stay where they started; rounds repeat on
// the pairs the zones moved until none collides. Every round merges zones or
// freezes one, so the loop ends; a pair that started the step apart ends it
// at least `separation` apart. Pairs already closer than that at the start
// (bodies placed touching or overlapping) are counted and left to the contact
// constraints until they part.
//
// The separation is a quarter of -contact_gap times the smallest free body's
// mean boundary edge: contact constraints end contacts a full gap apart, so
// resting contacts sit outside the guard's reach.
//
// Parallel model: each rank holds its own surface vertices' start and end
// positions and a halo of the other ranks' within reach of its boxes
// (halo.hpp: -contact_halo_reach longest tet edges), and tests the pairs whose
// lowest moving surface vertex it owns. Each round's colliding pairs, with
// their vertices' positions, are gathered on every rank (few: the pairs, not
// the surface) and sorted, so every rank merges and moves the same zones in
// the same order whatever the rank count; each writes its own vertices: a
// vertex a zone moved gets x = its zone position and v = (x - x0) / dt.
#pragma once

#include <petscvec.h>

#include <string>
#include <utility>
#include <vector>

#include "common/held_bytes.hpp"
#include "common/neighbour_exchange.hpp"
#include "contact/contact_options.hpp"
#include "contact/contact_surface.hpp"
#include "contact/impact_zones.hpp"
#include "contact/surface_collisions.hpp"
#include "fem/partition.hpp"
#include "io/scene.hpp"

namespace softbody {

struct GuardStatistics {
  PetscInt passes_guarded = 0;  // detection passes (several per step) in which some pair collided
  PetscInt collisions = 0;      // colliding pairs found, all rounds and steps
  PetscInt rounds = 0, max_rounds = 0;  // detection rounds with collisions
  PetscInt zone_vertices = 0;           // surface vertices the zones moved, all steps
  PetscInt frozen_vertices = 0;         // of them, in immobile zones
  PetscInt close_pairs = 0;             // pairs closer than the separation at a step's start
  PetscInt initial_close_pairs =
      0;                         // of them, at the scene's start (placed touching or overlapping)
  PetscInt candidates = 0;       // pairs tested by CCD
  PetscInt rebuilds = 0;         // self-contact candidate lists built, summed over ranks
  PetscInt static_rebuilds = 0;  // candidate lists against fixed or resting bodies, summed
  PetscInt probes = 0;           // Probe calls
  PetscInt repeated = 0;         // of them, on the positions of the last probe, which moved nothing
  PetscLogDouble seconds = 0;
};

class CollisionGuard {
 public:
  CollisionGuard() = default;
  CollisionGuard(const CollisionGuard &) = delete;
  CollisionGuard &operator=(const CollisionGuard &) = delete;

  // Collective. scene and layout (replicated numbering) must outlive the
  // guard; meshes (contact_meshes.hpp: every body's boundary, the rest
  // positions of the free bodies' surface vertices) is read here only;
  // lumped_mass per DOF (kg), PETSc order; min_edge: the smallest free body's
  // mean boundary edge (m); reach: the halo's reach per body (m).
  PetscErrorCode Setup(MPI_Comm comm, const Scene &scene, const ContactMeshes &meshes,
                       const DofLayout &layout, Vec lumped_mass, const ContactOptions &options,
                       bool self_contact, double min_edge, const std::vector<double> &reach);
  // Collective. Detection and zones on the motion from x0 (the step's start
  // positions) to x (its end positions), PETSc order; nothing written.
  // *moved: zones moved vertices (the same on every rank). When the last probe
  // moved nothing and every rank's surface vertices start and end where they
  // did then, its answer stands without detection (the contact step probes the
  // last solve's end positions, and the step's end probes them again unless
  // the response changed them).
  PetscErrorCode Probe(Vec x0, Vec x, bool *moved);
  // Not collective. After Probe: this rank's vertices the zones moved, as
  // (local vertex, the zone's end position).
  struct MovedVertex {
    PetscInt local;
    Point end;
    bool frozen;  // its zone touched something immobile and stayed where it started
  };
  std::vector<MovedVertex> MovedEnds() const;
  // Collective. Probe, then the moved vertices written: x = the zone's end
  // position, v = (x - x0) / dt; *changed as Probe's *moved.
  PetscErrorCode Apply(Vec x0, Vec x, Vec v, PetscReal dt, bool *changed);

  // Not collective. Marks (natural vertex) the vertices the last Apply moved.
  void MarkMoved(std::vector<char> *marked) const;

  const GuardStatistics &statistics() const { return stats_; }
  // Not collective. Bytes this rank sent (halo, boxes, its colliding pairs), all probes.
  PetscInt64 bytes_sent() const { return bytes_sent_; }
  // Bytes of the per-surface-vertex arrays (every body's surface, on every rank).
  int64_t SceneBytes() const {
    return HeldBytes(surface_.natural) + HeldBytes(surface_.body) + HeldBytes(surface_.triangles) +
           HeldBytes(surface_.edges) + HeldBytes(owned_mask_) + HeldBytes(usable_) +
           HeldBytes(moving_) + HeldBytes(mass_) + HeldBytes(rest_) + HeldBytes(start_) +
           HeldBytes(end_) + HeldBytes(moved_) + HeldBytes(frozen_);
  }
  double separation() const { return query_.tolerance.separation; }
  std::string Description() const;

 private:
  // A surface vertex in the halo.
  struct HaloVertex {
    int32_t vertex;
    double start[3], end[3], mass;
  };
  // A colliding pair as every rank receives it: its vertices and their positions.
  struct SharedCollision {
    int32_t vertices[4];
    int32_t count;
    double start[4][3], end[4][3], mass[4];
  };
  // This rank's surface vertices' masses (the others' come with the halo and the pairs).
  PetscErrorCode FetchMasses(Vec lumped_mass);
  // This rank's surface vertices' start and end positions.
  PetscErrorCode WriteOwnedPositions(Vec x0, Vec x);
  // Collective. The other ranks' surface vertices near this rank's.
  PetscErrorCode ExchangeHalo();
  // Collective. Every rank's colliding pairs of a round, sorted; their
  // vertices' positions and masses written into start_, end_ and mass_.
  PetscErrorCode ShareCollisions(std::vector<SurfaceCollision> *collisions);
  // Collective. Detection and zones until no pair collides; *moved: per
  // surface vertex, moved by the zones.
  PetscErrorCode Resolve(std::vector<char> *moved);
  // One round's colliding pairs into the zones (immobile: the ground, a vertex
  // that does not move, or a mobile zone colliding with itself).
  void MergeZones(const std::vector<SurfaceCollision> &collisions);
  // This rank's vertices the last Probe moved: (local vertex, surface vertex).
  std::vector<std::pair<PetscInt, int32_t>> OwnedMoved() const;
  PetscErrorCode WriteBack(Vec x, Vec v, PetscReal dt);
  // Not collective. This rank's surface vertices start and end where they did
  // at the last probe, which moved nothing.
  bool RepeatsCleanProbe() const;
  void RememberCleanProbe();

  MPI_Comm comm_ = MPI_COMM_NULL;
  bool parallel_ = false;  // more than one rank
  // The last probe moved nothing; its start and end positions of owned_.
  bool last_clean_ = false;
  bool reuse_ = true;  // ContactOptions::guard_reuse
  std::vector<Point> clean_start_, clean_end_;
  ContactSurface surface_;
  std::vector<std::pair<int32_t, PetscInt>> owned_;  // (surface vertex, local vertex), this rank's
  std::vector<char> owned_mask_, usable_;            // per surface vertex
  std::vector<double> reach_;                        // per body (m)
  NeighbourExchange neighbours_;
  PetscInt64 bytes_sent_ = 0;
  std::vector<int32_t> free_vertices_;  // surface vertices that move, surface order
  std::vector<char> moving_;            // per surface vertex
  std::vector<double> mass_;            // per surface vertex (kg; 0 when it does not move)
  std::vector<Point> rest_, start_, end_;
  std::vector<char> moved_;   // per surface vertex: moved by the last Apply
  std::vector<char> frozen_;  // per surface vertex: moved, in an immobile zone
  CollisionQuery query_;
  SurfaceCollisionFinder finder_;
  ImpactZones zones_;
  GuardStatistics stats_;
};

}  // namespace softbody
