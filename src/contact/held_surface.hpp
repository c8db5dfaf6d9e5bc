// The part of the bodies' surfaces that one rank holds for the collision
// guard (collision_guard.hpp): a ContactSurface whose vertices, triangles and
// edges are a subsequence of the whole surface's (contact_surface.hpp), in
// the same order, so that comparing two held indices compares the whole ones
// (the guard's "lowest moving vertex" picks the same rank whatever each holds).
//
// A rank keeps for the whole run the static primitives (the fixed bodies':
// they never move, and the guard bins them once) and the closure of its own
// surface vertices: every triangle and edge at one of them, with their
// vertices. The halo brings the other ranks' vertices, and with a vertex new
// to a rank's halo the triangles and edges keyed at it (a primitive's key is
// its lowest vertex, whose owner keeps it in its closure and sends it); the
// rank keeps them while the key stays in its halo: in the held surface when
// all their vertices are held, else pending (a primitive at the edge of the
// halo, tested once its other vertices arrive). So a rank holds O(fixed
// surface + own closure + halo), not the scene's surface, and a primitive
// crosses to a rank once per visit of its key. Indices named `whole` are the
// whole surface's. Not collective.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "contact/contact_surface.hpp"

namespace softbody {

// A surface vertex as the halo brings it.
struct SurfaceVertex {
  int32_t whole, natural, body;
};

// A triangle, or an edge (vertices[2] == kNoSurfaceVertex), as whole
// vertices; a triangle's index in the whole surface's list of triangles (an
// edge's is its vertices: the whole list is sorted by them).
constexpr int32_t kNoSurfaceVertex = -1;
struct SurfacePrimitive {
  int32_t id;
  std::array<int32_t, 3> vertices;
  bool edge() const { return vertices[2] == kNoSurfaceVertex; }
};

// *held: of `before` (the whole surface, or the held part it replaces) the
// kept primitives (vertices all static (!moving) or one own) with their
// vertices, the static and own vertices, the `received` vertices (whole
// increasing), and of `before`'s other primitives, *pending and `primitives`
// (those that came with vertices new to the halo) the ones keyed at a received
// vertex whose vertices are all held; *pending becomes those keyed at a
// received vertex with a vertex not held. own and moving: per vertex of `before`.
void AssembleHeldSurface(const ContactSurface &before, const std::vector<char> &own,
                         const std::vector<char> &moving,
                         const std::vector<SurfaceVertex> &received,
                         const std::vector<SurfacePrimitive> &primitives,
                         std::vector<SurfacePrimitive> *pending, ContactSurface *held);

}  // namespace softbody
