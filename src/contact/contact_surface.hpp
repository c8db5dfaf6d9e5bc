// The bodies' boundary surfaces as the collision guard sees them: the surface
// vertices of every body (fixed ones too), their triangles and their edges,
// numbered by surface vertex. Built from the bodies' boundary triangles
// (contact_meshes.hpp). Not collective.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include "io/scene.hpp"

namespace softbody {

class ContactMeshes;

struct ContactSurface {
  std::vector<int32_t> natural;  // surface vertex -> natural vertex
  std::vector<int32_t> body;     // surface vertex -> body
  // surface vertex -> its index in the whole surface (increasing; the identity
  // on the whole surface, held_surface.hpp's part of it otherwise)
  std::vector<int32_t> global;
  std::vector<std::array<int32_t, 3>> triangles;  // surface vertices, outward orientation
  std::vector<std::array<int32_t, 2>> edges;      // surface vertices, each edge once
  // Each triangle's index in the whole surface's list (as global; the edges
  // are sorted by their vertices, each body's after the previous body's).
  std::vector<int32_t> triangle_id;
  // Per body b, its vertices, triangles and edges are the ranges
  // [x_start[b], x_start[b + 1]) of the lists above (size bodies + 1).
  std::vector<int32_t> vertex_start = {0}, triangle_start = {0}, edge_start = {0};

  // Surface vertices numbered in the order the boundary triangles first name them.
  void Build(const Scene &scene, const ContactMeshes &meshes);
  int32_t num_vertices() const { return static_cast<int32_t>(natural.size()); }
  size_t num_bodies() const { return vertex_start.size() - 1; }
};

}  // namespace softbody
