#include "fem/share_boundary.hpp"

#include <algorithm>

#include "common/even_share.hpp"
#include "common/exchange.hpp"
#include "fem/element.hpp"

namespace softbody {

namespace {

// A tet's face on its way to the owner of its smallest vertex's slab.
struct FaceRecord {
  std::array<PetscInt, 3> key;       // sorted natural vertices
  std::array<PetscInt, 3> oriented;  // outward order
};

// Faces of a positively oriented tet (0,1,2,3) with outward normals, as in
// BoundaryTriangles (mesh.cpp).
constexpr int kFaces[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};

// Collective. Whether each of the share's tets has a positive signed volume at rest.
PetscErrorCode PositiveTets(MPI_Comm comm, const MeshShare &share, std::vector<char> *positive) {
  PetscFunctionBeginUser;
  std::vector<PetscInt> naturals;
  naturals.reserve(4 * share.tets.size());
  for (const auto &tet : share.tets) naturals.insert(naturals.end(), tet.begin(), tet.end());
  std::vector<std::array<double, 12>> rest(share.tets.size());
  PetscSF sf;
  PetscCall(CreateSlabSF(comm, share, naturals, &sf));
  PetscCall(FetchFromSlabs(sf, MPI_DOUBLE, 3, share.rest.data(), rest.data()));
  PetscCall(PetscSFDestroy(&sf));
  positive->resize(share.tets.size());
  for (size_t t = 0; t < rest.size(); ++t)
    (*positive)[t] = SignedVolume(Eigen::Map<const Eigen::Matrix<double, 4, 3, Eigen::RowMajor>>(
                         rest[t].data())) > 0;
  PetscFunctionReturn(PETSC_SUCCESS);
}

// The share's faces, grouped by the rank whose slab holds their smallest vertex.
std::vector<FaceRecord> FacesBySlabOwner(const MeshShare &share, const std::vector<char> &positive,
                                         PetscMPIInt size, std::vector<int> *counts) {
  std::vector<FaceRecord> faces;
  faces.reserve(4 * share.tets.size());
  for (size_t t = 0; t < share.tets.size(); ++t)
    for (const auto &f : kFaces) {
      FaceRecord face;
      for (int k = 0; k < 3; ++k) face.oriented[k] = share.tets[t][f[k]];
      if (!positive[t]) std::swap(face.oriented[1], face.oriented[2]);
      face.key = face.oriented;
      std::sort(face.key.begin(), face.key.end());
      faces.push_back(face);
    }
  std::sort(faces.begin(), faces.end(),
            [](const FaceRecord &a, const FaceRecord &b) { return a.key < b.key; });
  counts->assign(size, 0);
  PetscMPIInt q = 0;
  for (const FaceRecord &face : faces) {
    while (face.key[0] >= EvenShareBegin(share.num_vertices, size, q + 1)) ++q;
    ++(*counts)[q];
  }
  return faces;
}

}  // namespace

PetscErrorCode ShareBoundaryTriangles(MPI_Comm comm, const MeshShare &share,
                                      std::vector<std::array<PetscInt, 3>> *triangles) {
  PetscFunctionBeginUser;
  PetscMPIInt size;
  PetscCallMPI(MPI_Comm_size(comm, &size));
  std::vector<FaceRecord> received;
  {
    std::vector<char> positive;
    PetscCall(PositiveTets(comm, share, &positive));
    std::vector<int> counts;
    const std::vector<FaceRecord> faces = FacesBySlabOwner(share, positive, size, &counts);
    PetscCall(ExchangeRecords(comm, faces, counts, &received));
  }
  std::sort(received.begin(), received.end(),
            [](const FaceRecord &a, const FaceRecord &b) { return a.key < b.key; });
  triangles->clear();
  for (size_t i = 0; i < received.size();) {
    size_t j = i + 1;
    while (j < received.size() && received[j].key == received[i].key) ++j;
    if (j - i == 1) triangles->push_back(received[i].oriented);
    i = j;
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
