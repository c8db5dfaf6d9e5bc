// The sharp features of the fixed bodies, sampled as points: a free vertex
// cannot enter a fixed face, but a fixed body's edge or corner can cut into a
// free body between its vertices. A sharp edge is a boundary edge whose two
// faces' outward normals differ by more than kFeatureAngle (or that borders one
// face or more than two); its end points and points along it at most
// kFeatureSpacing x the finest free body's mean edge length apart are kept when
// the edge is a real edge of the fixed bodies together (both of its faces free
// of other fixed bodies there: a cube's top edge flush with its neighbour's top
// face is none). World coordinates (fixed bodies do not move). Not collective.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <map>
#include <utility>
#include <vector>

#include "contact/contact_meshes.hpp"
#include "contact/fixed_tets.hpp"
#include "contact/free_state.hpp"
#include "contact/geometry.hpp"
#include "contact/obstacles.hpp"
#include "io/scene.hpp"

namespace softbody {

// Faces meeting at more than this angle form a sharp edge; a fixed surface
// facing within it of a feature's push holds a vertex along nearly that push.
// 30 degrees: a box's or a step's edges (90) count, while neighbouring facets
// of a finely meshed smooth surface meet at far less.
constexpr double kFeatureAngle = 30.0 * M_PI / 180.0;

class SharpFeatures {
 public:
  // A sampled point with the face normals of each edge it lies on (one pair
  // per edge; an edge with one face or more than two: each face's normal twice).
  struct Candidate {
    Point point;
    std::vector<std::pair<Point, Point>> edges;
  };
  // Per fixed body, its candidates.
  using Candidates = std::map<size_t, std::vector<Candidate>>;

  // Not collective. The fixed bodies' sharp-edge points, before the flush
  // test, from their boundaries and rest positions (contact's set-up).
  static Candidates Sample(const Scene &scene, const FreeState &state, const ContactMeshes &meshes);
  // Collective (the same candidates on every rank). Keeps the candidates on
  // real edges, asking the fixed tets of every rank's share.
  PetscErrorCode Keep(const Candidates &candidates, const Scene &scene, const FreeState &state,
                      const FixedTets &fixed);

  bool empty() const { return point_.empty(); }
  size_t size() const { return point_.size(); }
  const Point &point(int32_t feature) const { return point_[feature]; }
  // Body b's points are [begin(b), end(b)); none for a free body.
  int32_t begin(size_t body) const { return begin_[body]; }
  int32_t end(size_t body) const { return begin_[body + 1]; }
  bool on_body(size_t body) const { return begin_[body] < begin_[body + 1]; }
  size_t num_bodies() const { return begin_.empty() ? 0 : begin_.size() - 1; }
  // The fixed body that feature point `feature` lies on.
  int32_t body_of(int32_t feature) const {
    return static_cast<int32_t>(std::upper_bound(begin_.begin(), begin_.end(), feature) -
                                begin_.begin() - 1);
  }

 private:
  std::vector<Point> point_;
  std::vector<int32_t> begin_;
};

}  // namespace softbody
