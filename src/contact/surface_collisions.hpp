// The collision guard's detection: every pair of surface primitives that comes
// too close during a step, found by continuous collision detection (ccd.hpp)
// on the candidates of a uniform grid over the primitives' swept boxes.
//
// Pairs: a surface vertex against a triangle, an edge against an edge, of two
// bodies (free-free, free-fixed) or, with self-contact, of one body when they
// share no vertex; a free surface vertex against the ground plane y = y0.
// Pairs with no vertex that moves (both sides fixed or at rest) are skipped.
// Positions are per surface vertex (contact_surface.hpp); lengths in metres.
// Not collective.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <utility>
#include <vector>

#include "contact/geometry.hpp"

#include "contact/ccd.hpp"
#include "contact/contact_surface.hpp"

namespace softbody {

struct SurfaceCollision {
  std::array<int32_t, 4> vertices;  // surface vertices; count of them used
  int count;                        // 4: vertex-triangle or edge-edge; 1: vertex-ground
};

struct CollisionQuery {
  const ContactSurface *surface = nullptr;
  const std::vector<Point> *start = nullptr, *end = nullptr;  // per surface vertex
  const std::vector<char> *moving = nullptr;                  // per surface vertex: a free vertex
  CcdTolerance tolerance;
  bool self_contact = false;
  bool ground = false;
  double ground_y = 0;
  // Only pairs with a vertex marked here (null: all pairs).
  const std::vector<char> *changed = nullptr;
  // In parallel: only primitives whose vertices are all marked usable (their
  // positions current: a rank's own and its halo's), and only pairs whose
  // lowest moving vertex is marked owned (each pair tested by one rank). Null:
  // all.
  const std::vector<char> *usable = nullptr, *owned = nullptr;
};

struct CollisionCount {
  int64_t candidates = 0;  // pairs tested by CCD
  int64_t close = 0;       // pairs already closer than the separation at the start (not guarded)
  int64_t rebuilds = 0;    // self-contact candidate lists built
  int64_t static_rebuilds = 0;  // candidate lists against the static primitives built
};

// Boxes of listed surface vertices, triangles and edges.
struct PrimitiveBoxes {
  std::vector<Box> vertices, triangles, edges;
};

// Which items a query has visited, for item lists seen through a grid that
// lists an item in every cell it overlaps. The marks are kept between queries
// and told apart by a stamp, so a pass of a few moving boxes against a large
// static grid does not clear an array of the grid's size per query list (on
// the stairway scene, 5e8 marks in 800 steps: about a tenth of the guard's time).
class VisitMarks {
 public:
  // Starts a query over items [0, count).
  void Begin(size_t count) {
    if (marks_.size() < count) marks_.resize(count, 0);
    if (++stamp_ == 0) {  // wrapped: forget every mark
      std::fill(marks_.begin(), marks_.end(), 0);
      stamp_ = 1;
    }
  }
  // True the first time item j is seen in this query.
  bool First(int32_t j) {
    if (marks_[j] == stamp_) return false;
    marks_[j] = stamp_;
    return true;
  }

 private:
  std::vector<uint32_t> marks_;
  uint32_t stamp_ = 0;
};

// Finds the colliding pairs. The primitives that never move (fixed bodies,
// bodies at rest) are binned once; each call bins the moving ones in the world
// frame against the static ones and against other moving bodies (only those
// near another body's box). Self-contact: each moving body in the frame of its
// mean displacement, from a list of candidate pairs kept over steps (a Verlet
// list, as molecular dynamics keeps neighbour lists): built from the boxes
// grown by half a skin of kSkinOfEdge mean surface edges, and rebuilt when a
// vertex leaves its box at the build (relative to the body's mean start
// position) by more than half the skin, or the usable vertices change. Every
// pair whose boxes meet in a step is in the list, and the same box test as a
// fresh grid's picks the pairs CCD tests: the result is the same. The moving
// primitives against the static ones keep such a list too, in the world frame
// (a body resting on a fixed one keeps it; a falling one rebuilds it).
class SurfaceCollisionFinder {
 public:
  // query.start must hold the static vertices' positions. half_skin: per
  // body, half its skin (m; null: from the mean length of query's edges at
  // query.start).
  void Setup(const CollisionQuery &query, const std::vector<double> *half_skin = nullptr);
  // The query's surface was replaced by another part of the same whole
  // surface (held_surface.hpp) holding the same static primitives in the same
  // order: the lists are renumbered, the static grids kept, the candidates
  // dropped.
  void Renumber(const CollisionQuery &query);
  // Per body of s, half its skin (m) from its mean edge length at positions x.
  static std::vector<double> HalfSkins(const ContactSurface &s, const std::vector<Point> &x);
  // The colliding pairs (in an order that depends on the grids: callers that
  // need one sort them).
  std::vector<SurfaceCollision> Find(const CollisionQuery &query, CollisionCount *count) const;

 private:
  struct Binned {
    std::vector<int32_t> vertices, triangles, edges;  // surface indices
    std::vector<Box> vertex_boxes, triangle_boxes, edge_boxes;
    UniformGrid vertex_grid, triangle_grid, edge_grid;
  };
  // One moving body's self-contact candidates (surface indices).
  struct SelfCandidates {
    bool valid = false;
    std::vector<int32_t> vertices;  // the body's usable vertices at the build
    // Per vertex of `vertices`: its positions at the step's start and end
    // (less the shift) at the build, relative to the mean start position.
    std::vector<Box> vertex_boxes;
    std::vector<std::array<int32_t, 2>> vertex_triangle, edge_edge;
    // Per pair: its distance at the build (start positions), and per surface
    // vertex of the body those positions: a pair whose vertices have moved
    // relative to each other by less than that distance less the separation
    // stays apart (SurfaceCollisionFinder::StaysApart).
    std::vector<double> vertex_triangle_distance, edge_edge_distance;
    std::vector<Point> built;
  };
  // The moving primitives' candidates among the static ones: pairs (index in
  // the build's list of moving vertices, triangles or edges; index in static_'s
  // list of triangles, vertices or edges).
  struct StaticCandidates {
    bool valid = false;
    std::vector<int32_t> vertices, triangles, edges;  // the usable moving ones at the build
    std::vector<Box> vertex_boxes;  // per vertex of `vertices`: its start and end at the build
    std::vector<std::array<int32_t, 2>> vertex_triangle, triangle_vertex, edge_edge;
  };
  void StaticPass(const CollisionQuery &query, const std::vector<int32_t> &vertices,
                  const std::vector<int32_t> &triangles, const std::vector<int32_t> &edges,
                  const PrimitiveBoxes &moving, std::vector<SurfaceCollision> *out,
                  CollisionCount *count) const;
  bool StaticCandidatesHold(const CollisionQuery &query, const std::vector<int32_t> &vertices,
                            const std::vector<int32_t> &triangles,
                            const std::vector<int32_t> &edges) const;
  void BuildStaticCandidates(const CollisionQuery &query, const std::vector<int32_t> &vertices,
                             const std::vector<int32_t> &triangles,
                             const std::vector<int32_t> &edges) const;
  void SelfPass(const CollisionQuery &query, size_t body, const std::vector<int32_t> &vertices,
                std::vector<SurfaceCollision> *out, CollisionCount *count) const;
  bool StaysApart(const CollisionQuery &query, const SelfCandidates &c, int32_t first_vertex,
                  const std::array<int32_t, 4> &v, int on_a, double distance) const;
  void MeasureSelfCandidates(const CollisionQuery &query, size_t body) const;
  void SelfStepBoxes(const CollisionQuery &query, size_t body, const std::vector<int32_t> &vertices,
                     const Point &shift) const;
  bool SelfCandidatesHold(const CollisionQuery &query, const SelfCandidates &c,
                          const std::vector<int32_t> &vertices, const Point &shift,
                          const Point &mean, double half_skin) const;
  void BuildSelfCandidates(const CollisionQuery &query, size_t body,
                           const std::vector<int32_t> &vertices, const Point &shift,
                           const Point &mean) const;

  // The moving and the static primitives, and the bodies with a moving one,
  // from the query's surface.
  void ListPrimitives(const CollisionQuery &query);

  std::vector<int32_t> moving_vertices_, moving_triangles_, moving_edges_;
  std::vector<size_t> moving_bodies_;
  Binned static_;
  std::vector<double> half_skin_;             // per body (m)
  mutable std::vector<SelfCandidates> self_;  // per body
  mutable StaticCandidates static_candidates_;
  // A self-contact pass's boxes over the step: per surface vertex, and per
  // triangle and edge of the body (vertex_box_ also the static lists' scratch).
  mutable std::vector<Box> vertex_box_, triangle_box_, edge_box_;
  mutable VisitMarks marks_;
};

}  // namespace softbody
