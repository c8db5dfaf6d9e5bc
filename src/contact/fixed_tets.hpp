// The fixed bodies' tets, which tell the obstacles whether a point lies inside
// a fixed body; no rank holds them all.
//
// Each rank keeps its share of the scene's fixed tets (its part of the tets'
// even share, mesh_share.hpp) and their corners' rest positions for the whole
// run: O(fixed tets / P), and the only copy (44 B per tet, 24 B per corner,
// and a grid over their boxes). The obstacles of a rank hold the fixed tets
// whose boxes meet its region, a few boxes around where its own free vertices
// are and will be, or everything once its region held most of them
// (ContactSolver keeps it; on one rank the share is fetched whole once and
// then released): Fetch brings them from the shares. The sharp features' flush test asks whether
// fixed tets hold points anywhere in the scene: Covered answers on every rank from every rank's
// share.
//
// Tets are named by their index in the scene's list of fixed tets (bodies in
// order, each body's tets in mesh order), the same on every rank, so that a
// query breaks ties as it would over the whole list. Fixed bodies do not move:
// positions are their placed rest positions (m).
#pragma once

#include <petscsys.h>

#include <array>
#include <cstdint>
#include <functional>
#include <vector>

#include "contact/free_items.hpp"
#include "contact/geometry.hpp"

namespace softbody {

// A rank's share of the fixed tets: the tets, each corner's index in `rest`,
// and the corners' positions (each vertex once).
struct FixedTetShare {
  std::vector<IndexedItem<FreeTet>> tets;
  std::vector<std::array<int32_t, 4>> corners;
  std::vector<Point> rest;
};

// A fixed tet with its corners' positions (x, y, z of each corner in turn), as
// it travels.
struct FixedTetRecord {
  IndexedItem<FreeTet> tet;  // key -1
  double corners[12];
  Point corner(int k) const {
    return Point(corners[3 * k], corners[3 * k + 1], corners[3 * k + 2]);
  }
};

class FixedTets {
 public:
  // Not collective. This rank's share (any order) and the scene's count of fixed tets.
  void Setup(MPI_Comm comm, FixedTetShare share, int64_t scene_count);

  // Collective. held(): the tets of all ranks' shares whose boxes meet one of
  // this rank's `region` boxes (each rank its own), id increasing. The tets
  // held before that still meet it are kept (held_box(tet): its box, from the
  // corners placed), the others come from their shares: place(n, x) for each
  // of their corners (natural vertex, position; repeats possible). *changed:
  // held() is not what it was.
  using HeldBox = std::function<Box(const FreeTet &)>;
  using Place = std::function<void(int32_t, const Point &)>;
  PetscErrorCode Fetch(const std::vector<Box> &region, const HeldBox &held_box, const Place &place,
                       bool *changed);
  // Collective; points and bodies the same on every rank. (*covered)[i], the
  // same on every rank: a fixed tet of a body other than bodies[i] holds
  // points[i] (TetHolds).
  PetscErrorCode Covered(const std::vector<Point> &points, const std::vector<int32_t> &bodies,
                         std::vector<char> *covered) const;

  const std::vector<IndexedItem<FreeTet>> &held() const { return held_; }
  // The boxes of the last Fetch.
  const std::vector<Box> &region() const { return region_; }
  // Not collective. Frees the share once no Fetch or Covered will read it.
  void ReleaseShare();
  // Whether p lies in a box of the region.
  bool InRegion(const Point &p) const;
  int64_t scene_count() const { return scene_count_; }
  // How often Fetch ran.
  PetscInt fetches() const { return fetches_; }
  // Bytes this rank holds: its share's tets and corners, and the held tets
  // (the grids not counted).
  int64_t HeldBytes() const;

 private:
  // A tet of the share with its corners' positions, and its box.
  FixedTetRecord Record(size_t t) const;
  Box BoxOf(size_t t) const;
  // Of held_, those whose boxes meet `region` (all of them, unread, when
  // each box of the last region lies in one of region's).
  void KeepMeeting(const std::vector<Box> &region, const HeldBox &held_box);
  // A region box with the rank it is for.
  struct RegionBox {
    PetscMPIInt rank;
    Box box;
  };

  MPI_Comm comm_ = MPI_COMM_NULL;
  FixedTetShare share_;
  UniformGrid share_grid_;
  int64_t scene_count_ = 0;
  std::vector<IndexedItem<FreeTet>> held_;
  std::vector<Box> region_;
  std::vector<RegionBox> all_regions_;  // every rank's at the last Fetch
  PetscInt fetches_ = 0;
};

}  // namespace softbody
