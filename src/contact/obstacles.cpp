#include "contact/obstacles.hpp"

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <numeric>

#include "common/held_bytes.hpp"

namespace softbody {

namespace {

// Where an entry search starts: beyond the segment's fraction range [0, 1].
constexpr double kNoCrossing = 2;
// Closest triangles whose distances differ by less than this fraction of the
// obstacle's mean boundary edge are a tie, broken by the lower index: a point
// near an edge of the obstacle is nearly as close to both faces, and which one
// round-off (1e-16 relative: another rank count, another summation order) makes
// closer must not decide its normal. 1e-9: far above round-off in positions of
// order 1-100 m, far below any geometric difference that matters.
constexpr double kTieOfEdge = 1e-9;
// ContactOnBody blends the normal only for a point at most this many of its
// body's mean boundary edges from the face (a resting contact): the blend
// reads the triangles around the face's vertices, which a deep point's halo
// (-contact_halo_reach) need not hold on every rank count.
constexpr double kBlendReach = 0.1;

}  // namespace

void Obstacles::SetupGround(const Scene &scene, FreeState &state, bool ground, double ground_y,
                            double ground_margin) {
  scene_ = &scene;
  state_ = &state;
  ground_ = ground;
  ground_y_ = ground_y;
  ground_margin_ = ground_margin;
}

int64_t Obstacles::SceneBytes() const {
  return (fixed_tets_ ? fixed_tets_->HeldBytes() : 0) + HeldBytes(fixed_triangles_) +
         free_items_.HeldBytes();
}

void Obstacles::SetupBodies(bool track_free, const ContactMeshes &meshes) {
  size_t count = 0;  // exact size: the list is allocated once
  for (size_t b = 0; b < scene_->bodies.size(); ++b)
    if (scene_->bodies[b].fixed) count += meshes.boundary(b).rows();
  fixed_triangles_.reserve(count);
  for (size_t b = 0; b < scene_->bodies.size(); ++b)
    if (scene_->bodies[b].fixed) AddFixedTriangles(b, meshes.boundary(b));
  BuildFixedBodyBoxes();
  fixed_triangles_bin_.base = fixed_triangles_.data();
  BinItems(fixed_triangles_.size(), &fixed_triangles_bin_);
  if (track_free) state_->AttachItems(&free_items_);
}

void Obstacles::SetFixedTets(const FixedTets &fixed) {
  fixed_tets_ = &fixed;
  fixed_tets_bin_.base = fixed.held().data();
  BinItems(fixed.held().size(), &fixed_tets_bin_);
}

void Obstacles::AddFixedTriangles(size_t b, const ContactMeshes::Triangles &boundary) {
  const int32_t first = scene_->bodies[b].first_vertex, body_id = static_cast<int32_t>(b);
  for (Eigen::Index f = 0; f < boundary.rows(); ++f)
    fixed_triangles_.push_back(
        {-1,
         static_cast<int32_t>(fixed_triangles_.size()),
         {first + boundary(f, 0), first + boundary(f, 1), first + boundary(f, 2), body_id}});
}

void Obstacles::MoveFreeBodies() {
  for (size_t b = 0; b < scene_->bodies.size(); ++b)
    if (!scene_->bodies[b].fixed) body_box_[b] = state_->body_box(b);
  ++pass_;
}

void Obstacles::BuildFixedBodyBoxes() {
  body_box_.resize(scene_->bodies.size());
  for (size_t b = 0; b < scene_->bodies.size(); ++b)
    if (scene_->bodies[b].fixed) body_box_[b] = state_->body_box(b);
}

template <class Item>
void Obstacles::BinItems(size_t count, Binned<Item> *bin) const {
  bin->boxes.assign(count, Box());
  for (size_t slot = 0; slot < count; ++slot) {
    const Item &item = bin->at(slot).item;
    for (size_t a = 0; a + 1 < item.size(); ++a) bin->boxes[slot].Extend(WorldPoint(item[a]));
  }
  bin->grid.Build(bin->boxes);
}

template <class Item, class ForEachOf>
void Obstacles::BinCurrent(const std::vector<IndexedItem<Item>> &static_items,
                           ForEachOf for_each_of, Binned<Item> *bin) const {
  if (bin->listed && bin->listed_generation == free_items_.generation() &&
      bin->listed_current == state_->current_free()) {
    BinItems(bin->items.size(), bin);
    return;
  }
  auto all_current = [&](const IndexedItem<Item> &i) {
    return std::all_of(i.item.begin(), i.item.end() - 1,
                       [&](int32_t m) { return state_->current(m); });
  };
  // Counted first, so that the list is allocated once at its size.
  size_t count = static_items.size();
  for (const int32_t n : state_->current_free())
    for_each_of(n, [&](const IndexedItem<Item> &i) { count += all_current(i); });
  auto &items = bin->items;
  items.clear();
  items.shrink_to_fit();
  items.reserve(count);
  for (const IndexedItem<Item> &i : static_items) items.push_back(&i);
  for (const int32_t n : state_->current_free())
    for_each_of(n, [&](const IndexedItem<Item> &i) {
      if (all_current(i)) items.push_back(&i);
    });
  std::sort(items.begin(), items.end(), [](auto a, auto b) { return a->id < b->id; });
  items.erase(
      std::unique(items.begin(), items.end(), [](auto a, auto b) { return a->id == b->id; }),
      items.end());
  bin->listed = true;
  bin->listed_generation = free_items_.generation();
  bin->listed_current = state_->current_free();
  BinItems(items.size(), bin);
}

bool Obstacles::FreeGridCurrent(const FreeGridStamp &stamp) const {
  return stamp.valid && stamp.pass == pass_ && stamp.generation == free_items_.generation();
}

void Obstacles::StampFreeGrid(FreeGridStamp *stamp) const {
  *stamp = {true, pass_, free_items_.generation()};
  if (!FreeGridCurrent(counted_stamp_)) ++free_grid_builds_;
  counted_stamp_ = *stamp;
}

void Obstacles::EnsureFreeTets() const {
  if (FreeGridCurrent(tets_stamp_)) return;
  BinCurrent(
      free_items_.static_tets(), [&](int32_t n, auto visit) { free_items_.ForEachTetOf(n, visit); },
      &free_tets_bin_);
  StampFreeGrid(&tets_stamp_);
}

void Obstacles::EnsureFreeTriangles() const {
  if (FreeGridCurrent(triangles_stamp_)) return;
  BinCurrent(
      free_items_.static_triangles(),
      [&](int32_t n, auto visit) { free_items_.ForEachTriangleOf(n, visit); },
      &free_triangles_bin_);
  StampFreeGrid(&triangles_stamp_);
}

void Obstacles::SetHit(const Point &point, const Point &normal, const Eigen::Vector3d &w,
                       const FreeTriangle &tri, int32_t t, SurfaceHit *hit) const {
  hit->point = point;
  hit->normal = normal.normalized();
  hit->velocity = w[0] * state_->velocity(tri[0]) + w[1] * state_->velocity(tri[1]) +
                  w[2] * state_->velocity(tri[2]);
  hit->inverse_mass = w[0] * state_->inverse_mass(tri[0]) + w[1] * state_->inverse_mass(tri[1]) +
                      w[2] * state_->inverse_mass(tri[2]);
  hit->body = tri[3];
  hit->triangle = t;
  hit->weights = w;
  hit->face = tri;
}

bool Obstacles::ClosestOnBody(const Point &p, int32_t obstacle, SurfaceHit *hit) const {
  if (obstacle < 0) {  // the ground
    *hit = {Point(p[0], ground_y_, p[2]), Point(0, 1, 0), Point::Zero(), 0.0, -1, -1,
            Eigen::Vector3d::Zero()};
    return true;
  }
  const bool fixed_part = scene_->bodies[obstacle].fixed;
  if (!fixed_part) EnsureFreeTriangles();
  const Binned<FreeTriangle> &bin = fixed_part ? fixed_triangles_bin_ : free_triangles_bin_;
  const UniformGrid &grid = bin.grid;
  if (grid.empty()) return false;
  const double limit = (grid.bounds().upper - grid.bounds().lower).norm() +
                       (grid.bounds().upper - p).norm() + (grid.bounds().lower - p).norm();
  double best = kUnbounded;
  int32_t chosen = -1;
  const double tie = kTieOfEdge * state_->edge(obstacle);
  // Growing neighbourhoods until the closest point found lies within the one
  // searched: every triangle nearer than it meets that neighbourhood.
  for (double radius = grid.cell_size(), searched = 0; best > searched && searched < 2 * limit;
       searched = radius, radius *= 2)
    bin.ForEachNear(p, radius, [&](int32_t t, const FreeTriangle &tri, const Box &) {
      if (tri[3] != obstacle) return;
      const Point a = WorldPoint(tri[0]), b = WorldPoint(tri[1]), c = WorldPoint(tri[2]);
      Eigen::Vector3d w;
      const Point q = ClosestPointOnTriangle(p, a, b, c, &w);
      const double distance = (q - p).norm();
      const Point normal = (b - a).cross(c - a);
      if (distance > best + tie || (distance >= best - tie && t >= chosen) || !(normal.norm() > 0))
        return;
      best = distance;
      chosen = t;
      SetHit(q, normal, w, tri, t, hit);
    });
  return best < kUnbounded;
}

bool Obstacles::InsideBody(const Point &p, int32_t obstacle) const {
  const bool fixed_part = scene_->bodies[obstacle].fixed;
  if (!fixed_part) EnsureFreeTets();
  if (fixed_part) CountOutsideRegion(p);
  bool inside = false;
  (fixed_part ? fixed_tets_bin_ : free_tets_bin_)
      .ForEachNear(p, 0.0, [&](int32_t, const FreeTet &tet, const Box &box) {
        if (inside || tet[4] != obstacle) return;
        inside = TetHolds(p, box, WorldPoint(tet[0]), WorldPoint(tet[1]), WorldPoint(tet[2]),
                          WorldPoint(tet[3]));
      });
  return inside;
}

bool Obstacles::LocateInFreeBody(const Point &p, int32_t body, double margin,
                                 Point *velocity) const {
  EnsureFreeTets();
  bool found = false;
  free_tets_bin_.ForEachNear(p, 0.0, [&](int32_t, const FreeTet &tet, const Box &box) {
    if (found || tet[4] != body || !box.Contains(p, kBoxMargin)) return;
    const Eigen::Vector4d w = Barycentric(p, WorldPoint(tet[0]), WorldPoint(tet[1]),
                                          WorldPoint(tet[2]), WorldPoint(tet[3]));
    if (!(w.minCoeff() > margin)) return;
    found = true;
    *velocity = Point::Zero();
    for (int k = 0; k < 4; ++k) *velocity += w[k] * state_->velocity(tet[k]);
  });
  return found;
}

bool Obstacles::EntryOnBody(const Point &start, const Point &end, int32_t obstacle,
                            SurfaceHit *hit) const {
  const bool fixed_part = scene_->bodies[obstacle].fixed;
  if (!fixed_part) EnsureFreeTriangles();
  const Binned<FreeTriangle> &bin = fixed_part ? fixed_triangles_bin_ : free_triangles_bin_;
  const Point direction = end - start;
  double first = kNoCrossing;
  int32_t chosen = -1;
  bin.ForEachNear(0.5 * (start + end), 0.5 * direction.cwiseAbs().maxCoeff(),
                  [&](int32_t t, const FreeTriangle &tri, const Box &) {
                    if (tri[3] != obstacle) return;
                    const Point a = WorldPoint(tri[0]), b = WorldPoint(tri[1]),
                                c = WorldPoint(tri[2]);
                    const Point normal = (b - a).cross(c - a);
                    double along;
                    Eigen::Vector3d w;
                    if (normal.dot(direction) >= 0 ||
                        !SegmentCrossesTriangle(start, end, a, b, c, &along, &w) || along > first ||
                        (along == first && t >= chosen))
                      return;
                    first = along;
                    chosen = t;
                    SetHit(start + along * direction, normal, w, tri, t, hit);
                  });
  return first <= 1;
}

bool Obstacles::FindPenetration(const Point &p, int32_t body, const VertexObstacles &skip,
                                SurfaceHit *hit, int32_t natural) const {
  if (ground_ && p[1] < ground_y_ + ground_margin_ * state_->edge(body) && !skip.Has(-1))
    return ClosestOnBody(p, -1, hit);
  // Broad phase: only bodies whose box holds p.
  bool near_fixed = false, near_free = false;
  for (size_t b = 0; b < body_box_.size(); ++b)
    if (static_cast<int32_t>(b) != body && body_box_[b].Contains(p))
      (scene_->bodies[b].fixed ? near_fixed : near_free) = true;
  if (!near_fixed && !near_free) return natural >= 0 && NearFreeBody(p, natural, skip, hit);
  if (near_free) EnsureFreeTets();
  for (const bool fixed_part : {true, false}) {
    if (!(fixed_part ? near_fixed : near_free)) continue;
    const int32_t inside = BodyContaining(p, fixed_part, body, skip);
    if (inside >= 0)
      return fixed_part || natural < 0 ? ClosestOnBody(p, inside, hit)
                                       : ContactOnBody(p, natural, inside, hit);
  }
  return natural >= 0 && NearFreeBody(p, natural, skip, hit);
}

// The lowest free body other than the vertex's whose surface lies within the
// margin outside p (the ground's margin, in the vertex's body's edges), facing it.
bool Obstacles::NearFreeBody(const Point &p, int32_t natural, const VertexObstacles &skip,
                             SurfaceHit *hit) const {
  const int32_t body = state_->body_of(natural);
  const double margin = ground_margin_ * state_->edge(body);
  for (size_t b = 0; b < body_box_.size(); ++b) {
    const int32_t other = static_cast<int32_t>(b);
    if (other == body || scene_->bodies[b].fixed || skip.Has(other) || Separating(body, other) ||
        !body_box_[b].Contains(p, margin))
      continue;
    SurfaceHit near;
    if (ContactOnBody(p, natural, other, &near) && (near.point - p).norm() < margin &&
        near.normal.dot(p - near.point) >= 0) {
      *hit = near;
      return true;
    }
  }
  return false;
}

// sum_t angle_t n_t over the current free triangles t at `natural` whose
// normal n_t satisfies keep(n_t), in increasing triangle order. The ring comes
// from the triangle grid (a triangle's box holds its corners): the index by
// vertex lists each triangle under one corner only.
template <class Keep>
Point Obstacles::AngleWeightedNormal(int32_t natural, Keep keep) const {
  Point sum = Point::Zero();
  if (!state_->current(natural)) return sum;
  EnsureFreeTriangles();
  std::vector<std::pair<int32_t, const FreeTriangle *>> ring;  // (index, triangle)
  free_triangles_bin_.ForEachNear(
      WorldPoint(natural), 0, [&](int32_t t, const FreeTriangle &tri, const Box &) {
        if (std::find(tri.begin(), tri.begin() + 3, natural) != tri.begin() + 3)
          ring.push_back({t, &tri});
      });
  std::sort(ring.begin(), ring.end(),
            [](const auto &a, const auto &b) { return a.first < b.first; });
  ring.erase(std::unique(ring.begin(), ring.end(),
                         [](const auto &a, const auto &b) { return a.first == b.first; }),
             ring.end());
  for (const auto &[t, triangle] : ring) {
    const FreeTriangle &tri = *triangle;
    const int k = tri[0] == natural ? 0 : tri[1] == natural ? 1 : 2;
    const Point a = WorldPoint(tri[k]), b = WorldPoint(tri[(k + 1) % 3]),
                c = WorldPoint(tri[(k + 2) % 3]);
    const Point normal = (b - a).cross(c - a);
    if (normal.norm() > 0 && keep(Point(normal.normalized())))
      sum += std::atan2(normal.norm(), (b - a).dot(c - a)) * normal.normalized();
  }
  return sum;
}

Point Obstacles::VertexNormal(int32_t natural) const {
  const Point sum = AngleWeightedNormal(natural, [](const Point &) { return true; });
  return sum.norm() > 0 ? Point(sum.normalized()) : Point(Point::Zero());
}

// The normal at the hit's point: each face vertex's normal over its faces
// that face `own`, blended by the hit's weights (continuous over the
// surface, and the same whichever of the faces at a vertex or edge the hit
// took); the face's normal when that vanishes.
void Obstacles::BlendFacingNormal(const Point &own, SurfaceHit *hit) const {
  const FreeTriangle &tri = hit->face;
  Point blend = Point::Zero();
  for (int k = 0; k < 3; ++k) {
    if (!(hit->weights[k] > 0)) continue;
    const Point node = AngleWeightedNormal(tri[k], [&](const Point &n) { return n.dot(own) < 0; });
    if (node.norm() > 0) blend += hit->weights[k] * node.normalized();
  }
  if (blend.norm() > 0) hit->normal = blend.normalized();
}

// The closest face first; then, within its distance plus the slack, the
// closest facing one (ties to the lower index, as in ClosestOnBody).
bool Obstacles::ContactOnBody(const Point &p, int32_t natural, int32_t obstacle,
                              SurfaceHit *hit) const {
  if (!ClosestOnBody(p, obstacle, hit)) return false;
  if (obstacle < 0 || scene_->bodies[obstacle].fixed) return true;
  const Point own = VertexNormal(natural);
  if (!(own.norm() > 0)) return true;
  const double edge = state_->edge(state_->body_of(natural));
  const bool shallow = (hit->point - p).norm() <= kBlendReach * edge;
  if (hit->normal.dot(own) < 0) {
    if (shallow) BlendFacingNormal(own, hit);
    return true;
  }
  const double reach =
      (hit->point - p).norm() + kFacingSlack * state_->edge(state_->body_of(natural));
  const double tie = kTieOfEdge * state_->edge(obstacle);
  double best = kUnbounded;
  int32_t chosen = -1;
  free_triangles_bin_.ForEachNear(p, reach, [&](int32_t t, const FreeTriangle &tri, const Box &) {
    if (tri[3] != obstacle) return;
    const Point a = WorldPoint(tri[0]), b = WorldPoint(tri[1]), c = WorldPoint(tri[2]);
    const Point normal = (b - a).cross(c - a);
    if (!(normal.norm() > 0) || !(normal.dot(own) < 0)) return;
    Eigen::Vector3d w;
    const Point q = ClosestPointOnTriangle(p, a, b, c, &w);
    const double distance = (q - p).norm();
    if (distance > reach || distance > best + tie || (distance >= best - tie && t >= chosen))
      return;
    best = distance;
    chosen = t;
    SetHit(q, normal, w, tri, t, hit);
  });
  if (shallow) BlendFacingNormal(own, hit);
  return true;
}

int32_t Obstacles::BodyContaining(const Point &p, bool fixed_part, int32_t body,
                                  const VertexObstacles &skip) const {
  int32_t first = -1, first_body = -1;  // the lowest tet holding p, its body
  if (fixed_part) CountOutsideRegion(p);
  (fixed_part ? fixed_tets_bin_ : free_tets_bin_)
      .ForEachNear(p, 0.0, [&](int32_t t, const FreeTet &tet, const Box &box) {
        if ((first >= 0 && t >= first) || tet[4] == body || skip.Has(tet[4]) ||
            (!fixed_part && Separating(body, tet[4])))
          return;
        if (TetHolds(p, box, WorldPoint(tet[0]), WorldPoint(tet[1]), WorldPoint(tet[2]),
                     WorldPoint(tet[3]))) {
          first = t;
          first_body = tet[4];
        }
      });
  return first_body;
}

void Obstacles::CountOutsideRegion(const Point &p) const {
  if (fixed_tets_ && !fixed_tets_->InRegion(p)) ++outside_region_;
}

bool Obstacles::Separating(int32_t a, int32_t b) const {
  const std::pair<size_t, size_t> pair(std::min(a, b), std::max(a, b));
  return std::find(separating_.begin(), separating_.end(), pair) != separating_.end();
}

bool Obstacles::OnFixedSurface(const Point &x, const Point &direction, double min_cosine) const {
  if (ground_ && x[1] <= ground_y_ && direction[1] >= min_cosine) return true;
  for (size_t b = 0; b < scene_->bodies.size(); ++b) {
    SurfaceHit hit;
    const int32_t body = static_cast<int32_t>(b);
    if (scene_->bodies[b].fixed && body_box_[b].Contains(x, kBoxMargin) && InsideBody(x, body) &&
        ClosestOnBody(x, body, &hit) && hit.normal.dot(direction) >= min_cosine)
      return true;
  }
  return false;
}

}  // namespace softbody
