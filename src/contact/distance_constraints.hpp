// Distance constraints: pairs of vertices kept within [lower, upper] of each
// other (-constraints FILE), and every boundary edge of the free bodies within
// [lo, hi] x its rest length (-edge_bounds lo,hi).
//
// Resolved after the step on the world arrays of FreeState, identically on
// every rank: Gauss-Seidel sweeps of mass-weighted projections. For a
// constraint a-b with inverse masses w_a, w_b (0: fixed or stray), length
// l = |x_b - x_a|, unit direction n = (x_b - x_a) / l and target
// t = clamp(l, lower, upper):
//   x_a += w_a / (w_a + w_b) (l - t) n,   x_b -= w_b / (w_a + w_b) (l - t) n,
// and when the relative velocity s = n . (v_b - v_a) points further out of the
// bounds (s > 0 at the upper bound, s < 0 at the lower one) it is removed the
// same way. Sweeps stop once every constraint holds to kConstraintTolerance
// relative to its upper bound, or after kMaxConstraintSweeps.
#pragma once

#include <petscsys.h>

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "contact/contact_options.hpp"
#include "contact/free_state.hpp"
#include "contact/geometry.hpp"
#include "io/scene.hpp"

namespace softbody {

// A distance constraint between natural vertices a and b: lower <= |x_b - x_a| <= upper (m).
struct DistanceConstraint {
  int32_t a, b;
  double lower, upper;
};

// One line of a constraints file: its vertices (natural), its bounds as
// multiples of the rest distance, and its line number.
struct ConstraintLine {
  int32_t a = 0, b = 0;
  double lo = 1, hi = 1;
  long line = 0;
};

// Parses a constraints file: n, then n lines "m1 v1 m2 v2" (rest distance
// kept) or "m1 v1 m2 v2 lo hi" (within [lo, hi] x rest distance), 0-based mesh
// and vertex indices, checked against the bodies' counts (no mesh read). Not
// collective; throws InputError naming file and line.
std::vector<ConstraintLine> ParseConstraints(const std::string &path, const Scene &scene);

// The constraints of the parsed lines, given the vertices' rest positions (m).
// Not collective; throws InputError naming the file and line of a constraint
// whose two vertices coincide.
std::vector<DistanceConstraint> RestDistances(const std::string &path,
                                              const std::vector<ConstraintLine> &lines,
                                              const std::function<Point(int32_t)> &rest);

// ParseConstraints and RestDistances from the scene's whole meshes (held by
// the caller). Not collective; throws InputError naming file and line.
std::vector<DistanceConstraint> ReadConstraints(const std::string &path, const Scene &scene);

class DistanceConstraints {
 public:
  // What one resolution did: its sweeps and the largest relative violation left.
  struct Resolution {
    PetscInt sweeps;
    double violation;
  };
  // Collective (an unreadable file is an error on comm). The file's
  // constraints (their vertices' rest positions fetched into *meshes), then
  // the edge bounds of each free body's boundary edges (their rest positions
  // fetched before, contact_meshes.hpp).
  PetscErrorCode Setup(MPI_Comm comm, const Scene &scene, ContactMeshes *meshes,
                       const ContactOptions &options);
  bool empty() const { return constraints_.empty(); }
  size_t size() const { return constraints_.size(); }
  // The constrained vertices (natural, with repeats): what Resolve reads and writes.
  std::vector<int32_t> vertices() const {
    std::vector<int32_t> ends;
    for (const DistanceConstraint &c : constraints_) ends.insert(ends.end(), {c.a, c.b});
    return ends;
  }
  // Not collective; every rank must call it on the same gathered state.
  // pinned (natural vertex; null: none): vertices that do not move, as if fixed.
  Resolution Resolve(FreeState *state, const std::vector<char> *pinned = nullptr) const;

 private:
  // One Gauss-Seidel sweep; returns the largest relative violation met.
  double Sweep(FreeState *state, const std::vector<char> *pinned) const;

  std::vector<DistanceConstraint> constraints_;
};

}  // namespace softbody
