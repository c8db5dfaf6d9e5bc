// The state that contact queries read, in natural vertex order: world
// positions (m) and velocities (m/s), inverse lumped masses (1/kg; 0 for fixed
// and stray vertices), each vertex's body, and per body its mean boundary edge
// length (m), total lumped mass (kg) and bounding box.
//
// Fixed vertices keep their rest positions and zero velocity and are always
// current; only the fixed bodies' surface vertices and the corners of the
// fixed tets a rank holds (fixed_tets.hpp) have them. Exchange writes this rank's own vertices and
// brings, when asked, two kinds of other ranks' vertices (nothing else is current; queries must
// read only current vertices, see current()):
// - the halo: the vertices of other bodies (and, with `same_body` on, of its
//   own bodies) that lie within reach of this rank's own vertices of a body.
//   Each rank's per-body boxes at x + dt v are gathered (a few boxes per rank,
//   halo.hpp); each rank sends its vertices inside another's boxes, grown by
//   the vertex's body's reach, point to point (neighbour_exchange.hpp), so the
//   messages follow the contact zone, not the mesh;
// - the fixed set (SetupFixedSet): vertices every rank reads whenever asked,
//   e.g. the distance constraints' (a scatter of just them);
// - the ring set (SetupRingSet): per rank, the other ranks' vertices of the
//   boundary triangles at its own surface vertices (a scatter of just them;
//   O(the rank's part's boundary)).
// The reach of a body is -contact_halo_reach (contact_options.hpp) times its
// longest rest tet edge: every tet and boundary triangle of another body that
// meets this rank's box, and is stretched less than that, comes whole.
//
// Positions, velocities and inverse masses are kept per slot: for this rank's
// own vertices, those it received, the free bodies' vertices without unknowns
// and the fixed vertices above (rest positions fetched at set-up,
// contact_meshes.hpp), O(local + halo + fixed surface + fixed region); the map from
// natural vertex to slot stays natural-indexed on every rank (4 B per scene
// vertex, SceneBytes); a vertex's body is found from the bodies' first vertices,
// and whether it moves from the layout's numbering; the messages are O(halo).
// The free bodies' tets and triangles that the obstacles' grids need travel
// with the halo's vertices (AttachItems, free_items.hpp).
#pragma once

#include <petscvec.h>

#include <algorithm>
#include <cstdint>
#include <limits>
#include <vector>

#include "common/neighbour_exchange.hpp"
#include "contact/free_items.hpp"
#include "contact/geometry.hpp"
#include "fem/partition.hpp"
#include "io/scene.hpp"

namespace softbody {

struct HaloPlan;
class ContactMeshes;

// What an Exchange brings besides this rank's own vertices.
struct StateNeeds {
  bool halo = false;       // other ranks' vertices near this rank's
  bool fixed_set = false;  // the vertices of SetupFixedSet
  bool rings = false;      // the vertices of SetupRingSet
};

class FreeState {
 public:
  FreeState() = default;
  FreeState(const FreeState &) = delete;
  FreeState &operator=(const FreeState &) = delete;
  ~FreeState();

  // Not collective. Bodies, boundary edges and reaches (reach_in_edges: the
  // halo's, in longest rest tet edges). `meshes` (contact_meshes.hpp) is read
  // until EndSetup: the rest positions of the owned vertices and of those
  // without unknowns, and the free tets and triangles (AttachItems).
  void SetupBodies(const Scene &scene, const ContactMeshes &meshes, double reach_in_edges);
  // Not collective. The set-up is over: the meshes are no longer read.
  void EndSetup() { meshes_ = nullptr; }
  // Collective. Owned vertices, their inverse masses, the body masses; the halo
  // exchange when `halo`, bringing other ranks' vertices of this rank's own
  // bodies too when `same_body` (sharp-edge points meet a body's own tets).
  PetscErrorCode SetupMasses(MPI_Comm comm, const DofLayout &layout, Vec lumped_mass, bool halo,
                             bool same_body);
  // Collective. The vertices (natural) that every Exchange with needs.fixed_set
  // brings to every rank; their inverse masses fetched now.
  PetscErrorCode SetupFixedSet(Vec lumped_mass, const std::vector<int32_t> &naturals);
  // Collective. The vertices (natural) that every Exchange with needs.rings
  // brings to this rank (each rank its own list): the other corners of the
  // boundary triangles at its own surface vertices, so that a vertex's normal
  // reads its whole ring on any rank count; their inverse masses fetched now.
  PetscErrorCode SetupRingSet(Vec lumped_mass, const std::vector<int32_t> &naturals);
  // Not collective, after SetupMasses and SetupFixedSet, before EndSetup. Sets up *items
  // (free_items.hpp: the items listed under this rank's own, the fixed set's and the ring set's
  // vertices; SetupRingSet after it sets them up again) and has every halo exchange bring the items
  // of the vertices it brings.
  void AttachItems(FreeItems *items);
  // Collective. This rank's vertices at x + dt v (dt = 0: at x) and velocities
  // v, the free bodies' boxes there, and what `needs` asks for.
  PetscErrorCode Exchange(Vec x, Vec v, PetscReal dt, const StateNeeds &needs);
  // Not collective. Writes this rank's vertices of the world arrays into x and v.
  PetscErrorCode WriteOwned(Vec x, Vec v) const;

  // A vertex that was never current on this rank has no position (NaN), zero
  // velocity and zero inverse mass.
  Point position(int32_t natural) const {
    const int32_t s = slot_[natural];
    return s < 0 ? Point::Constant(kNoPosition) : Point(&x_[3 * s]);
  }
  Point velocity(int32_t natural) const {
    const int32_t s = slot_[natural];
    return s < 0 ? Point::Zero() : Point(&v_[3 * s]);
  }
  Eigen::Map<Point> position_ref(int32_t natural) {
    return Eigen::Map<Point>(&x_[3 * Slot(natural)]);
  }
  Eigen::Map<Point> velocity_ref(int32_t natural) {
    return Eigen::Map<Point>(&v_[3 * Slot(natural)]);
  }
  double inverse_mass(int32_t natural) const {
    const int32_t s = slot_[natural];
    return s < 0 ? 0.0 : inverse_mass_[s];
  }
  int32_t body_of(int32_t natural) const {
    return static_cast<int32_t>(std::upper_bound(body_first_.begin(), body_first_.end(), natural) -
                                body_first_.begin()) -
           1;
  }
  double edge(size_t body) const { return body_edge_[body]; }
  double mass(size_t body) const { return body_mass_[body]; }
  // The halo's reach for the body's vertices (m).
  double reach(size_t body) const { return body_reach_[body]; }
  // Whether the vertex has unknowns (moves).
  bool is_free(int32_t natural) const { return layout_->PetscVertexOfNatural(natural) >= 0; }
  // Whether the arrays hold the vertex's state of the last Exchange (fixed
  // vertices always).
  bool current(int32_t natural) const {
    return !is_free(natural) || (slot_[natural] >= 0 && stamp_[slot_[natural]] == stamp_now_);
  }
  // The free vertices the last Exchange brought or wrote, owned first.
  const std::vector<int32_t> &current_free() const { return current_free_; }
  // A free body's box at the last Exchange's positions (all ranks' vertices).
  const Box &body_box(size_t body) const { return body_box_[body]; }
  // Bytes this rank sent in exchanges (halo records, boxes, fixed set), all calls.
  PetscInt64 bytes_sent() const { return bytes_sent_; }
  // Not collective. A fixed body's vertex at rest at x (the fixed tets'
  // corners as they arrive, fixed_tets.hpp).
  void PlaceFixed(int32_t natural, const Point &x) { position_ref(natural) = x; }
  // Local vertex -> natural vertex.
  const std::vector<int32_t> &owned_natural() const { return owned_natural_; }
  // Bytes of the natural-indexed arrays (O(scene vertices) on every rank).
  int64_t SceneBytes() const;
  PetscInt local_count() const { return static_cast<PetscInt>(owned_natural_.size()); }

 private:
  // A vertex travelling in the halo.
  struct HaloVertex {
    int32_t natural;
    double x[3], v[3], inverse_mass;
  };
  void PlaceStaticVertices();
  PetscErrorCode OwnInverseMasses(const DofLayout &layout, Vec lumped_mass);
  PetscErrorCode SumBodyMasses(MPI_Comm comm);
  // Writes the owned vertices; *boxes: their box per body.
  PetscErrorCode WriteOwnedState(Vec x, Vec v, PetscReal dt, std::vector<Box> *boxes);
  // Collective. body_box_: every rank's boxes joined, and the non-free vertices'.
  PetscErrorCode ReduceBodyBoxes(const std::vector<Box> &owned_boxes);
  PetscErrorCode ExchangeHalo(const std::vector<Box> &owned_boxes);
  // items_->Setup for this rank's own, fixed-set and ring-set vertices.
  void SetupItems();
  PetscErrorCode ExchangeItems(const HaloPlan &plan, const std::vector<HaloVertex> &sent,
                               const std::vector<HaloVertex> &received);
  // The vertex's slot in the per-slot arrays, given on first use (position
  // NaN, velocity and inverse mass 0 until written).
  int32_t Slot(int32_t natural);
  void MarkCurrent(int32_t natural) {
    const int32_t s = Slot(natural);
    if (stamp_[s] != stamp_now_) current_free_.push_back(natural);
    stamp_[s] = stamp_now_;
  }
  // The rest position of a vertex (set-up only: from meshes_).
  Point RestPosition(int32_t natural) const;

  static constexpr double kNoPosition = std::numeric_limits<double>::quiet_NaN();
  MPI_Comm comm_ = MPI_COMM_NULL;
  const DofLayout *layout_ = nullptr;
  const Scene *scene_ = nullptr;
  const ContactMeshes *meshes_ = nullptr;  // set-up only (SetupBodies to EndSetup)
  size_t num_bodies_ = 0;
  bool same_body_ = false;
  std::vector<int32_t> body_first_;     // per body: its first natural vertex
  std::vector<int32_t> owned_natural_;  // local vertex -> natural vertex
  // Per-slot state: only the vertices this rank owns, has received or reads
  // whatever the exchange (those without unknowns, the fixed set) have a slot.
  std::vector<int32_t> slot_;         // natural vertex -> slot, -1: none yet
  std::vector<double> inverse_mass_;  // per slot (0: fixed or stray)
  std::vector<double> x_, v_;         // per slot, 3 each
  std::vector<uint32_t> stamp_;       // per slot: the exchange that wrote it
  uint32_t stamp_now_ = 1;
  std::vector<int32_t> current_free_;
  std::vector<double> body_edge_;   // mean boundary edge length per body
  std::vector<double> body_reach_;  // halo reach per body (m)
  std::vector<double> body_mass_;   // total lumped mass per body (kg)
  std::vector<Box> body_box_;       // per body, at the last exchange
  std::vector<Box> static_box_;     // per body, its vertices without unknowns
  NeighbourExchange neighbours_;
  FreeItems *items_ = nullptr;  // AttachItems
  PetscInt64 bytes_sent_ = 0;
  // Vertices fetched by a scatter of just them: their free vertices (natural)
  // and their DOFs gathered.
  struct ScatteredSet {
    std::vector<int32_t> naturals;
    VecScatter scatter = nullptr;
    Vec x = nullptr, v = nullptr;
  };
  PetscErrorCode SetupScatteredSet(Vec lumped_mass, const std::vector<int32_t> &naturals,
                                   ScatteredSet *set);
  PetscErrorCode FetchScatteredSet(Vec x, Vec v, PetscReal dt, const ScatteredSet &set);
  ScatteredSet fixed_set_;  // SetupFixedSet's, the same on every rank
  ScatteredSet ring_set_;   // SetupRingSet's, this rank's own
};

}  // namespace softbody
