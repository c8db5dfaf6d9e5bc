// Rigid impact zones, the collision guard's fail-safe (Provot 1997; Bridson,
// Fedkiw, Anderson 2002, section 7.4): the vertices of each colliding pair are
// merged into a zone that moves rigidly over the step, so nothing inside a
// zone can collide; zones that still collide with others merge further. A zone
// that meets something immobile (a fixed body, the ground) stays where it
// started the step.
//
// A mobile zone keeps its mass-weighted mean displacement and the rotation
// that carries its angular momentum: with r_i = s_i - c0 (s the start
// positions, c0 the centre of mass),
//   theta = I^+ sum_i m_i r_i x (u_i - u_mean),  I = sum_i m_i (|r_i|^2 1 - r_i r_i^T),
//   e_i = c1 + R(theta) r_i,
// u_i = e_i - s_i the displacements over the step, c1 the centre at the end,
// R(theta) the rotation by |theta| about theta (I^+ the pseudo-inverse: a
// zone of two vertices has no inertia about their axis). This is the
// mass-weighted projection of the displacements on rigid motions, so it never
// adds kinetic energy; freezing a zone removes its motion.
//
// Units: metres, kilograms. Not collective.
#pragma once

#include <cstdint>
#include <vector>

#include "contact/geometry.hpp"

namespace softbody {

class ImpactZones {
 public:
  // Every vertex its own zone, mobile.
  void Reset(int32_t num_vertices);
  // One more vertex, its own zone, mobile; returns its index.
  int32_t Add();
  // Whether the vertices share one mobile zone: a pair found colliding while
  // it moves rigidly (only round-off can do that); the caller freezes it.
  bool InOneMobileZone(const int32_t *vertices, int count);
  // Merges the zones of a colliding pair's vertices. The merged zone is
  // immobile when `immobile` or when any of the zones was.
  void Merge(const int32_t *vertices, int count, bool immobile);
  // Moves every zone merged since the last call: end[v] for its vertices from
  // start and mass (kg; only read for mobile zones). Returns the vertices whose
  // end position changed.
  std::vector<int32_t> Move(const std::vector<Point> &start, const std::vector<double> &mass,
                            std::vector<Point> *end);
  bool immobile(int32_t vertex) { return immobile_[Find(vertex)]; }

 private:
  int32_t Find(int32_t vertex);
  void MoveRigidly(const std::vector<int32_t> &members, const std::vector<Point> &start,
                   const std::vector<double> &mass, std::vector<Point> *end) const;

  std::vector<int32_t> parent_;
  std::vector<char> immobile_;                 // per zone root
  std::vector<std::vector<int32_t>> members_;  // per zone root (empty: a lone vertex)
  std::vector<int32_t> touched_;               // roots merged since the last Move
};

}  // namespace softbody
