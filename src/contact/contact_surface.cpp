#include "contact/contact_surface.hpp"

#include <algorithm>
#include <unordered_map>

#include "contact/contact_meshes.hpp"

namespace softbody {

void ContactSurface::Build(const Scene &scene, const ContactMeshes &meshes) {
  for (size_t b = 0; b < scene.bodies.size(); ++b) {
    const Body &body = scene.bodies[b];
    const auto &faces = meshes.boundary(b);
    std::unordered_map<int32_t, int32_t> surface_of;  // body-local vertex -> surface vertex
    auto surface_vertex = [&](int32_t local) {
      const auto [at, added] = surface_of.emplace(local, num_vertices());
      if (added) {
        global.push_back(num_vertices());
        natural.push_back(body.first_vertex + local);
        this->body.push_back(static_cast<int32_t>(b));
      }
      return at->second;
    };
    std::vector<std::array<int32_t, 2>> body_edges;
    for (Eigen::Index f = 0; f < faces.rows(); ++f) {
      const std::array<int32_t, 3> t = {surface_vertex(faces(f, 0)), surface_vertex(faces(f, 1)),
                                        surface_vertex(faces(f, 2))};
      triangle_id.push_back(static_cast<int32_t>(triangles.size()));
      triangles.push_back(t);
      for (int k = 0; k < 3; ++k)
        body_edges.push_back({std::min(t[k], t[(k + 1) % 3]), std::max(t[k], t[(k + 1) % 3])});
    }
    std::sort(body_edges.begin(), body_edges.end());
    body_edges.erase(std::unique(body_edges.begin(), body_edges.end()), body_edges.end());
    edges.insert(edges.end(), body_edges.begin(), body_edges.end());
    vertex_start.push_back(num_vertices());
    triangle_start.push_back(static_cast<int32_t>(triangles.size()));
    edge_start.push_back(static_cast<int32_t>(edges.size()));
  }
}

}  // namespace softbody
