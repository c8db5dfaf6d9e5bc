// The obstacles a vertex can meet, and the geometric queries on them: the
// ground half-space y < y0, and the bodies' tets (they tell inside) and
// boundary triangles (they give the closest surface point and its outward
// normal), binned in uniform grids so that no query visits all pairs.
//
// Broad phase: each body's bounding box. The fixed bodies' grids are built
// once; the free bodies' boxes follow them (MoveFreeBodies) and their grids
// are rebuilt lazily, when a query first needs them, so that a step whose
// bodies' boxes stay apart builds none. Positions and velocities are read
// from FreeState (world coordinates). The fixed bodies' triangles are held
// whole on every rank (O(fixed surface)); of their tets a rank holds those
// that meet its region (fixed_tets.hpp), which must hold every point asked
// about inside a fixed body (outside_region() counts the queries it did not).
// Of the free bodies' tets and triangles a rank holds only those listed under
// its own, its halo's and the fixed and ring sets' vertices (free_items.hpp:
// they travel with the halo), and the free grids bin the items whose vertices
// are all current, so the lists and a rebuild are O(local + halo). Queries break
// ties of distance by the lower triangle or tet index (the item's index in the
// scene's list), so that answers do not depend on which items a rank's grid
// holds. Not collective.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <utility>
#include <vector>

#include "contact/contact_meshes.hpp"
#include "contact/fixed_tets.hpp"
#include "contact/free_items.hpp"
#include "contact/free_state.hpp"
#include "contact/geometry.hpp"
#include "io/scene.hpp"

namespace softbody {

// Where a point meets an obstacle: closest surface point, outward normal, the
// surface's velocity and inverse mass there (0: fixed or ground), the obstacle
// (-1: the ground).
struct SurfaceHit {
  Point point, normal, velocity;
  double inverse_mass;
  int32_t body;
  int32_t triangle = -1;  // index into the obstacle's triangle list (-1: the ground)
  Eigen::Vector3d weights = Eigen::Vector3d::Zero();  // barycentric coordinates of point in it
  FreeTriangle face = {-1, -1, -1, -1};               // the triangle's natural vertices and body
};

// A vertex against a free body meets the closest of the body's faces that
// face it (outward normal at an obtuse angle to the vertex's own outward
// normal) when that face lies at most this fraction of the vertex's body's mean
// boundary edge farther than the closest face. A vertex on the edge of one of
// two aligned stacked blocks is as close to the other block's side face as to
// the face it rests on, and the side face's normal would push it sideways. A
// tenth of an edge: the most a step's constraint takes a vertex out
// (kMaxRecoveryPerStep), well above a resting step's sinking.
constexpr double kFacingSlack = 0.1;

// The obstacles constraining one vertex in a step (-1: the ground); at most
// three (a corner).
struct VertexObstacles {
  static constexpr int kMax = 3;
  int count = 0;
  int32_t obstacle[kMax];
  bool Has(int32_t o) const { return std::find(obstacle, obstacle + count, o) != obstacle + count; }
  bool full() const { return count == kMax; }
};

class Obstacles {
 public:
  // First: the scene, the state the queries read, and the ground (an obstacle
  // when `ground`, at height ground_y in m; a point less than ground_margin of
  // its body's mean boundary edge above it counts as inside). The state's
  // halo exchanges bring the free items (SetupBodies).
  void SetupGround(const Scene &scene, FreeState &state, bool ground, double ground_y,
                   double ground_margin);
  // During contact's set-up (meshes: its boundaries). The bodies: fixed ones
  // always, free ones when `track_free` (they are obstacles to each other or
  // meet sharp edges; their items then travel with the state's halo); builds
  // the fixed triangles' grid.
  void SetupBodies(bool track_free, const ContactMeshes &meshes);
  // The fixed tets that `fixed` holds now (after each of its Fetches; the
  // state holds their corners): bins them. `fixed` must outlive this object.
  void SetFixedTets(const FixedTets &fixed);

  // The free bodies moved (FreeState holds their new positions and boxes):
  // their boxes follow, their grids are stale.
  void MoveFreeBodies();
  // Pairs of free bodies (a, b) that are not obstacles to each other
  // (OverlapSeparation moves them apart); replaces the last list.
  void SetSeparating(const std::vector<std::pair<size_t, size_t>> &pairs) { separating_ = pairs; }

  // The first obstacle other than `body` and those in `skip` that contains p
  // (the ground when p lies below it or within its margin), with its closest
  // surface point.
  // natural: the free vertex at p (-1: none); against a free body its contact
  // point is then ContactOnBody's, and a free body whose surface lies within
  // the ground's margin outside p counts too (its two-sided contact keeps the
  // pair apart before the collision guard's separation would be reached).
  bool FindPenetration(const Point &p, int32_t body, const VertexObstacles &skip, SurfaceHit *hit,
                       int32_t natural = -1) const;
  // The closest point to p on the obstacle's surface (-1: the ground).
  bool ClosestOnBody(const Point &p, int32_t obstacle, SurfaceHit *hit) const;
  // Where free vertex `natural` at p meets the obstacle: ClosestOnBody, but on
  // a free body the closest face facing the vertex when one lies within
  // kFacingSlack of its body's edge of the closest (a vertex of no surface: the
  // closest), and the normal there blended from the face vertices' normals
  // over their faces that face the vertex (BlendFacingNormal).
  bool ContactOnBody(const Point &p, int32_t natural, int32_t obstacle, SurfaceHit *hit) const;
  // A free surface vertex's outward normal (unit; angle-weighted mean of its
  // current boundary triangles' normals, Thuermer & Wuethrich 1998); zero for
  // a vertex of no boundary triangle.
  Point VertexNormal(int32_t natural) const;
  // Whether p lies in one of the obstacle body's tets (faces included).
  bool InsideBody(const Point &p, int32_t obstacle) const;
  // The free body's tet holding p with all barycentric coordinates above
  // `margin`, and the body's velocity there; false if none.
  bool LocateInFreeBody(const Point &p, int32_t body, double margin, Point *velocity) const;
  // Where the segment start -> end first enters the obstacle body through its
  // surface (a boundary triangle crossed against its outward normal).
  bool EntryOnBody(const Point &start, const Point &end, int32_t obstacle, SurfaceHit *hit) const;
  // Whether x lies in or on a fixed body (or the ground) whose surface there
  // faces direction within the angle of cosine min_cosine.
  bool OnFixedSurface(const Point &x, const Point &direction, double min_cosine) const;

  bool ground() const { return ground_; }
  double ground_y() const { return ground_y_; }
  const Box &body_box(size_t body) const { return body_box_[body]; }
  // The scene's fixed tets.
  int64_t num_fixed_tets() const { return fixed_tets_ ? fixed_tets_->scene_count() : 0; }
  // Queries about points inside fixed bodies outside the fixed tets' region
  // (their answer may have missed a tet): none when the region is kept right.
  PetscInt outside_region() const { return outside_region_; }
  size_t num_free_tets() const { return static_cast<size_t>(free_items_.num_tets()); }
  // Bytes of the bodies' item lists: the fixed bodies' triangles (O(fixed
  // surface) on every rank), the fixed tets' share and region (FixedTets) and
  // the free tets and triangles this rank holds (O(local + halo)); the grids and
  // their items' boxes are not counted.
  int64_t SceneBytes() const;
  // How often this rank built the free bodies' grids.
  PetscInt free_grid_builds() const { return free_grid_builds_; }

 private:
  // A fixed body's boundary triangles (body-local rows), as natural vertices
  // + body, indexed in the scene's list of fixed triangles.
  void AddFixedTriangles(size_t b, const ContactMeshes::Triangles &boundary);
  void CountOutsideRegion(const Point &p) const;
  void BuildFixedBodyBoxes();
  // The free bodies' tet and triangle grids at the current positions and
  // items, each built only when a query needs it (a pass that locates sharp
  // edges in a free body needs only the tets).
  void EnsureFreeTets() const;
  void EnsureFreeTriangles() const;
  // When a free grid was built: MoveFreeBodies' pass and free_items_'s generation.
  struct FreeGridStamp {
    bool valid = false;
    uint64_t pass = 0, generation = 0;
  };
  bool FreeGridCurrent(const FreeGridStamp &stamp) const;
  // Stamps a grid just built; counts the passes in which a free grid was built.
  void StampFreeGrid(FreeGridStamp *stamp) const;
  // Items (tets or triangles: vertices and the body) binned in a uniform grid
  // over their boxes: the grid holds slots, at(slot) the item (from `base`,
  // slot = index, or `items`: free grids hold only the current items, O(local +
  // halo), pointers into FreeItems' lists) and boxes[slot] its box.
  template <class Item>
  struct Binned {
    const IndexedItem<Item> *base = nullptr;
    std::vector<const IndexedItem<Item> *> items;  // id increasing
    std::vector<Box> boxes;
    UniformGrid grid;
    // What `items` was listed from (free grids): free_items_'s generation and
    // the free state's current vertices; while both stay, only boxes and grid
    // change with the positions.
    bool listed = false;
    uint64_t listed_generation = 0;
    std::vector<int32_t> listed_current;
    const IndexedItem<Item> &at(size_t slot) const { return base ? base[slot] : *items[slot]; }
    // visit(id, item, box) for the items whose cells meet the box around p of half-width radius.
    template <typename Visit>
    void ForEachNear(const Point &p, double radius, Visit visit) const {
      grid.ForEachNear(p, radius, [&](int32_t slot) {
        const IndexedItem<Item> &i = at(slot);
        visit(i.id, i.item, boxes[slot]);
      });
    }
  };
  // The bin's boxes at the world positions and its grid, for its `count` items.
  template <class Item>
  void BinItems(size_t count, Binned<Item> *bin) const;
  // The free items whose vertices are all current, binned: those under the
  // current free vertices (for_each_of: free_items_'s ForEachTetOf or
  // ForEachTriangleOf) and the static ones.
  template <class Item, class ForEachOf>
  void BinCurrent(const std::vector<IndexedItem<Item>> &static_items, ForEachOf for_each_of,
                  Binned<Item> *bin) const;
  // The first body other than `body` and those in `skip` in whose tets of the
  // fixed or free part p lies; -1 if none.
  int32_t BodyContaining(const Point &p, bool fixed_part, int32_t body,
                         const VertexObstacles &skip) const;
  // FindPenetration's last resort for free vertex `natural` at p.
  bool NearFreeBody(const Point &p, int32_t natural, const VertexObstacles &skip,
                    SurfaceHit *hit) const;
  template <class Keep>
  Point AngleWeightedNormal(int32_t natural, Keep keep) const;
  void BlendFacingNormal(const Point &own, SurfaceHit *hit) const;
  // The hit at `point` on free or fixed triangle t (`tri`, its body tri[3]) with
  // barycentric weights w: the triangle's unit normal from `normal` (its
  // unnormalised (b - a) x (c - a)), velocity and inverse mass interpolated by w.
  void SetHit(const Point &point, const Point &normal, const Eigen::Vector3d &w,
              const FreeTriangle &tri, int32_t t, SurfaceHit *hit) const;
  // Whether free bodies a and b are a separating pair.
  bool Separating(int32_t a, int32_t b) const;
  Point WorldPoint(int32_t n) const { return state_->position(n); }

  const Scene *scene_ = nullptr;
  FreeState *state_ = nullptr;  // read by the queries; its halo brings free_items_
  bool ground_ = false;
  double ground_y_ = 0;
  double ground_margin_ = 0;               // in mean boundary edges of the point's body
  const FixedTets *fixed_tets_ = nullptr;  // the fixed bodies' (SetFixedTets)
  mutable PetscInt outside_region_ = 0;
  std::vector<IndexedItem<FreeTriangle>> fixed_triangles_;
  Binned<FreeTet> fixed_tets_bin_;
  Binned<FreeTriangle> fixed_triangles_bin_;
  FreeItems free_items_;
  mutable Binned<FreeTet> free_tets_bin_;
  mutable Binned<FreeTriangle> free_triangles_bin_;
  uint64_t pass_ = 0;  // MoveFreeBodies calls
  mutable FreeGridStamp tets_stamp_, triangles_stamp_, counted_stamp_;
  mutable PetscInt free_grid_builds_ = 0;
  std::vector<std::pair<size_t, size_t>> separating_;  // (a < b), SetSeparating
  std::vector<Box> body_box_;  // broad phase: each obstacle body's bounding box
};

}  // namespace softbody
