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

#include <array>
#include <cstdint>
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
};

// Finds the colliding pairs. The primitives that never move (fixed bodies,
// bodies at rest) are binned once; each call bins the moving ones: in the
// world frame against the static ones and other moving bodies, and each
// moving body in the frame of its mean displacement for self-contact.
class SurfaceCollisionFinder {
 public:
  // query.start must hold the static vertices' positions.
  void Setup(const CollisionQuery &query);
  // The colliding pairs (in an order that depends on the grids: callers that
  // need one sort them).
  std::vector<SurfaceCollision> Find(const CollisionQuery &query, CollisionCount *count) const;

 private:
  struct Binned {
    std::vector<int32_t> vertices, triangles, edges;  // surface indices
    std::vector<Box> vertex_boxes, triangle_boxes, edge_boxes;
    UniformGrid vertex_grid, triangle_grid, edge_grid;
  };
  std::vector<int32_t> moving_vertices_, moving_triangles_, moving_edges_;
  std::vector<size_t> moving_bodies_;
  Binned static_;
};

}  // namespace softbody
