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
// Reads the free state gathered on every rank (FreeState::Gather): every rank
// takes the same decisions and writes its own vertices. Collective where noted.
#pragma once

#include <petscvec.h>

#include <array>
#include <cstdint>
#include <utility>
#include <vector>

#include "contact/free_state.hpp"
#include "contact/obstacles.hpp"
#include "fem/partition.hpp"
#include "io/scene.hpp"

namespace softbody {

// How far a separating pair moves apart per step, in mean boundary edges of
// its finer body: an overlap of depth D takes about D / edge steps, and the
// pair ends at most one edge further apart than needed (the crossing test runs
// once per step).
constexpr double kSeparationPerStep = 1.0;

class OverlapSeparation {
 public:
  void Setup(const Scene &scene, const FreeState &state, Obstacles *obstacles);

  // Not collective. On the gathered state: the pairs of free bodies whose
  // surfaces cross now become the separating pairs (the start of the run);
  // their vertex contacts are turned off. Returns how many.
  size_t FindOverlaps();
  bool active() const { return !pairs_.empty(); }
  // Collective (the state must be gathered at x first). Translates the
  // separating pairs that still cross (x: this rank's vertices; the gathered
  // state follows) and drops those that no longer do. *moved: any translation.
  PetscErrorCode Step(Vec x, FreeState *state, bool *moved);

  // Steps taken while some pair was separating; pairs found at the start.
  PetscInt steps() const { return steps_; }
  size_t initial_pairs() const { return initial_pairs_; }

 private:
  // Whether the surfaces of free bodies a and b cross (or one holds the other).
  bool Cross(size_t a, size_t b) const;
  // Whether an edge of body a crosses a triangle of body b.
  bool EdgeCrossesSurface(size_t a, size_t b) const;
  // The translation of each of the pair's bodies this step.
  std::pair<Point, Point> Translations(size_t a, size_t b) const;
  Point Centroid(size_t b) const;

  const Scene *scene_ = nullptr;
  const FreeState *state_ = nullptr;
  Obstacles *obstacles_ = nullptr;
  // Per body: its boundary edges and triangles (natural vertices).
  std::vector<std::vector<std::pair<int32_t, int32_t>>> edges_;
  std::vector<std::vector<std::array<int32_t, 3>>> triangles_;
  std::vector<std::pair<size_t, size_t>> pairs_;  // separating (a < b)
  PetscInt steps_ = 0;
  size_t initial_pairs_ = 0;
};

}  // namespace softbody
