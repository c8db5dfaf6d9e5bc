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
// Parallel model: each rank holds a part of the surfaces (held_surface.hpp:
// the fixed bodies', its own surface vertices with the triangles and edges at
// them, and a halo of the other ranks' vertices within reach of its boxes,
// halo.hpp: -contact_halo_reach longest tet edges, with the primitives keyed
// at them), and tests the pairs whose lowest moving surface vertex it owns.
// Each round's colliding pairs, with their vertices' positions, are gathered
// on every rank (few: the pairs, not the surface) and sorted; the zones are
// built over the vertices of the pairs shared so far, so every rank merges
// and moves the same zones in the same order whatever the rank count and
// whatever it holds; each writes its own vertices: a vertex a zone moved gets
// x = its zone position and v = (x - x0) / dt.
#pragma once

#include <petscvec.h>

#include <string>
#include <unordered_map>
#include <utility>
#include <vector>

#include "common/held_bytes.hpp"
#include "common/neighbour_exchange.hpp"
#include "contact/contact_options.hpp"
#include "contact/contact_surface.hpp"
#include "contact/halo.hpp"
#include "contact/held_surface.hpp"
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

  // Not collective. Marks (natural vertex) the vertices the last Apply moved,
  // the same on every rank (the zones' vertices; when the safety net stopped
  // every free vertex, every vertex of the free bodies).
  void MarkMoved(std::vector<char> *marked) const;

  const GuardStatistics &statistics() const { return stats_; }
  // Not collective. Bytes this rank sent (halo, boxes, its colliding pairs), all probes.
  PetscInt64 bytes_sent() const { return bytes_sent_; }
  // Bytes of what this rank holds of the surfaces and its arrays per held
  // surface vertex (O(fixed surface + own part + halo)).
  int64_t SceneBytes() const;
  double separation() const { return query_.tolerance.separation; }
  std::string Description() const;

 private:
  // A surface vertex in the halo (whole surface index).
  struct HaloVertex {
    int32_t whole, natural, body;
    double start[3], end[3], mass;
  };
  // A colliding pair as every rank receives it: its whole surface vertices,
  // their natural vertices and whether each moves (1) or not (0), and their
  // positions and masses.
  struct SharedCollision {
    int32_t vertices[4], natural[4], moving[4];
    int32_t count;
    double start[4][3], end[4][3], mass[4];
  };
  // A vertex of the zones (every rank has the same, in the same order).
  struct ZoneVertex {
    int32_t whole, natural;
    bool moving, moved;
  };
  // Collective, set-up only. The pairs closer than the separation at the
  // rest positions (stats_.initial_close_pairs).
  PetscErrorCode CountInitialClosePairs();
  // This rank's surface vertices' masses (the others' come with the halo and the pairs).
  PetscErrorCode FetchMasses(Vec lumped_mass);
  // This rank's surface vertices' start and end positions.
  PetscErrorCode WriteOwnedPositions(Vec x0, Vec x);
  // Collective. The other ranks' surface vertices near this rank's, with the
  // triangles and edges keyed at them; reassembles the held surface when they
  // changed.
  PetscErrorCode ExchangeHalo();
  // The held surface: of `before` (the whole surface at the set-up, else the
  // held one), the kept part, and received_ with the primitives keyed at them
  // (kept from before and pending_, and `primitives`, those that came with
  // the vertices new to the halo); positions, masses and usability carried
  // over by whole index from the held surface it replaces (zero and unusable
  // for new vertices); the per-vertex flags and owned_ redone.
  void Reassemble(const ContactSurface &before, const std::vector<char> &own,
                  const std::vector<char> &moving, const std::vector<SurfacePrimitive> &primitives);
  // This rank's primitives keyed at the halo's vertices it sends (plan: the
  // halo's ranks and owned_ items) that were not in that rank's halo at the
  // last exchange, by rank: *ranks and *counts as NeighbourExchange takes
  // them; sent_ becomes this exchange's.
  void KeyedPrimitives(const HaloPlan &plan, std::vector<SurfacePrimitive> *primitives,
                       std::vector<PetscMPIInt> *ranks, std::vector<PetscMPIInt> *counts);
  // The held index of whole surface vertex `whole` (-1: not held).
  int32_t HeldIndex(int32_t whole) const;
  // Collective. Every rank's colliding pairs of a round (`found`, held
  // indices), sorted by whole vertices, as *pairs of zone vertices; the held
  // ones' positions and masses written into start_, end_ and mass_.
  PetscErrorCode ShareCollisions(const std::vector<SurfaceCollision> &found,
                                 std::vector<SurfaceCollision> *pairs);
  // The zone vertex of a shared pair's k-th vertex, added when new.
  int32_t ZoneVertexOf(const SharedCollision &c, int k);
  // Collective. Detection and zones until no pair collides; *moved: per held
  // surface vertex, moved by the zones.
  PetscErrorCode Resolve(std::vector<char> *moved);
  // One round's colliding pairs (zone vertices) into the zones (immobile: the
  // ground, a vertex that does not move, or a mobile zone colliding with itself).
  void MergeZones(const std::vector<SurfaceCollision> &pairs);
  // The zones' vertices and the statistics of a Resolve.
  void CountZoneVertices(bool stopped_all);
  // This rank's vertices the last Probe moved: (local vertex, held surface vertex).
  std::vector<std::pair<PetscInt, int32_t>> OwnedMoved() const;
  PetscErrorCode WriteBack(Vec x, Vec v, PetscReal dt);
  // Not collective. This rank's surface vertices start and end where they did
  // at the last probe, which moved nothing.
  bool RepeatsCleanProbe() const;
  void RememberCleanProbe();

  MPI_Comm comm_ = MPI_COMM_NULL;
  const Scene *scene_ = nullptr;
  const DofLayout *layout_ = nullptr;
  bool parallel_ = false;  // more than one rank
  // The last probe moved nothing; its start and end positions of owned_.
  bool last_clean_ = false;
  bool reuse_ = true;  // ContactOptions::guard_reuse
  std::vector<Point> clean_start_, clean_end_;
  // The whole surface's counts and its moving vertices' (Description, statistics).
  int32_t whole_free_vertices_ = 0;
  size_t whole_triangles_ = 0, whole_edges_ = 0;
  ContactSurface surface_;               // what this rank holds (held_surface.hpp)
  std::vector<SurfaceVertex> received_;  // the halo's vertices in surface_, whole increasing
  // Primitives keyed at them with a vertex not held (held_surface.hpp).
  std::vector<SurfacePrimitive> pending_;
  std::vector<std::pair<PetscMPIInt, int32_t>> sent_;  // (rank, whole vertex) at the last exchange
  std::vector<std::pair<int32_t, PetscInt>> owned_;    // (held vertex, local vertex), held order
  std::vector<char> owned_mask_, usable_;              // per held surface vertex
  std::vector<double> reach_;                          // per body (m)
  std::vector<double> half_skin_;  // per body (m): the finder's, from the whole surface
  NeighbourExchange neighbours_;
  PetscInt64 bytes_sent_ = 0;
  std::vector<char> moving_;        // per held surface vertex
  std::vector<double> mass_;        // per held surface vertex (kg; 0 when it does not move)
  std::vector<Point> start_, end_;  // per held surface vertex
  std::vector<char> moved_;         // per held surface vertex: moved by the last Apply
  std::vector<char> frozen_;        // per held surface vertex: moved, in an immobile zone
  // The last Resolve: a vertex moved (the same on every rank); every free vertex stopped.
  bool moved_any_ = false, stopped_all_ = false;
  std::vector<ZoneVertex> zone_vertices_;
  std::unordered_map<int32_t, int32_t> zone_of_;  // whole surface vertex -> zone vertex
  std::vector<Point> zone_start_, zone_end_;      // per zone vertex
  std::vector<double> zone_mass_;
  CollisionQuery query_;
  SurfaceCollisionFinder finder_;
  ImpactZones zones_;
  GuardStatistics stats_;
};

}  // namespace softbody
