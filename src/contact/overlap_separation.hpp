// Free bodies whose surfaces cross at the start of a run (placed
// overlapping) are moved apart rigidly over the first steps, until their
// surfaces no longer cross; from then on the contact constraints and the
// collision guard keep them apart.
//
// Pushing such bodies apart vertex by vertex along closest-point normals
// strains them without separating them when the overlap is deep (the normals
// point every way); a rigid translation strains nothing. After each step while
// a pair crosses, its two bodies are translated along the line between their
// mass centroids, d = (c_B - c_A) / |c_B - c_A|, by kSeparationPerStep times
// the finer body's mean boundary edge in all, body A by -M_B / (M_A + M_B) and
// body B by M_A / (M_A + M_B) of it: the pair's mass centroid stays, and no
// velocity changes (elastic forces do not see a translation). Meanwhile the
// vertex contact constraints between the two bodies are off
// (Obstacles::SetSeparating). A pair's surfaces cross when an edge of one
// crosses a triangle of the other (SegmentCrossesTriangle), or one body lies
// inside the other.
//
// Parallel model: the separating bodies' surface vertices are brought to
// every rank (an all-gather of their positions, only at the first step and
// while a pair separates) and their mass centroids reduced, so every rank takes
// the same decisions and writes its own vertices. It reads nothing of the free
// state but the bodies, masses and owned vertices. Collective where noted.
// The surfaces are released once no pair separates (at the start of most runs):
// FindOverlaps runs once, and nothing reads them afterwards.
#pragma once

#include <petscvec.h>

#include <array>
#include <cstdint>
#include <utility>
#include <vector>

#include "common/held_bytes.hpp"
#include "contact/free_state.hpp"
#include "contact/obstacles.hpp"
#include "fem/partition.hpp"
#include "io/scene.hpp"

namespace softbody {

class ContactMeshes;

// How far a separating pair moves apart per step, in mean boundary edges of
// its finer body: an overlap of depth D takes about D / edge steps, and the
// pair ends at most one edge further apart than needed (the crossing test runs
// once per step).
constexpr double kSeparationPerStep = 1.0;

class OverlapSeparation {
 public:
  // Not collective. The free bodies' surfaces from meshes (contact_meshes.hpp,
  // read here only); scene, state and obstacles must outlive this object.
  void Setup(MPI_Comm comm, const Scene &scene, const ContactMeshes &meshes, const FreeState &state,
             Obstacles *obstacles);

  // Collective, once. At positions x (PETSc order, this rank's vertices): the
  // pairs of free bodies whose surfaces cross become the separating pairs (the
  // start of the run); their vertex contacts are turned off. *found: how many.
  PetscErrorCode FindOverlaps(Vec x, size_t *found);
  bool active() const { return !pairs_.empty(); }
  // Collective. Translates the separating pairs that still cross at x (this
  // rank's vertices) and drops those that no longer do. *moved: any translation.
  PetscErrorCode Step(Vec x, bool *moved);

  // Steps taken while some pair was separating; pairs found at the start.
  PetscInt steps() const { return steps_; }
  // Bytes of the free bodies' surfaces (O(scene surface) on every rank, 0
  // once released).
  int64_t SceneBytes() const {
    return HeldBytes(edges_) + HeldBytes(triangles_) + HeldBytes(surface_) + HeldBytes(positions_);
  }
  size_t initial_pairs() const { return initial_pairs_; }

 private:
  // Collective. The surface vertices of `bodies` at x into positions_, and
  // their mass centroids into centroid_.
  PetscErrorCode Fetch(Vec x, const std::vector<char> &bodies);
  // Whether the surfaces of free bodies a and b cross (or one holds the other).
  bool Cross(size_t a, size_t b) const;
  // Whether an edge of body a crosses a triangle of body b.
  bool EdgeCrossesSurface(size_t a, size_t b) const;
  // Whether p lies inside body b's closed surface (parity of a ray's crossings).
  bool InsideSurface(const Point &p, size_t b) const;
  // The translation of each of the pair's bodies this step.
  std::pair<Point, Point> Translations(size_t a, size_t b) const;
  void NumberSurface();
  // Frees the surfaces: no pair separates any more.
  void ReleaseSurfaces();
  // The surface index of a natural vertex, -1 if not on a free body's surface.
  int32_t SurfaceIndex(int32_t natural) const;
  Point At(int32_t surface) const { return Point(&positions_[3 * surface]); }

  MPI_Comm comm_ = MPI_COMM_NULL;
  const Scene *scene_ = nullptr;
  const FreeState *state_ = nullptr;
  Obstacles *obstacles_ = nullptr;
  // Per body: its boundary edges and triangles (surface indices).
  std::vector<std::vector<std::pair<int32_t, int32_t>>> edges_;
  std::vector<std::vector<std::array<int32_t, 3>>> triangles_;
  std::vector<int32_t> surface_;                  // surface index -> natural vertex, increasing
  std::vector<double> positions_;                 // 3 per surface vertex: the fetched positions
  std::vector<Box> box_;                          // per body: its fetched surface's box
  std::vector<Point> centroid_;                   // per body: its mass centroid at the fetch
  std::vector<std::pair<size_t, size_t>> pairs_;  // separating (a < b)
  PetscInt steps_ = 0;
  size_t initial_pairs_ = 0;
};

}  // namespace softbody
