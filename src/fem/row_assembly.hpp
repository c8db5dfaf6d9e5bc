// Assembly of A = mass_scale M + stiffness_scale K(R) straight into the CSR
// arrays of a MATAIJ matrix, owner computes: every rank runs over all elements
// that touch one of its own vertices and adds only the rows it owns, so the
// refill sends no matrix entries (the elements on a partition boundary are
// computed by both neighbours; their force and energy count once).
//
// Per element and refill: deformation gradient F (from edge vectors), rotation
// R = RotationOfDeformation(F) (corotational; R = I in linear mode), rotated
// shape gradients h_a = R g_a, and the 16 blocks of R K_e R^T,
//     R K_ab R^T = V [ l h_a h_b^T + s m h_b h_a^T + s m (h_a . h_b) I
//                      + (2 m - 2 s m) R diag(g_a o g_b) R^T ]
// (element.hpp, the last term vanishes for the standard shear scale s = 1),
// each added at an offset into A's values computed once at set-up (block rows
// of a vertex share one column pattern, so a block is three runs of three
// values). No COO triplets, no per-entry index arrays, no communication of
// matrix values: the refill costs the element arithmetic and one pass over A.
#pragma once

#include <petscmat.h>

#include <array>
#include <cstdint>
#include <vector>

#include "fem/element.hpp"
#include "fem/partition.hpp"
#include "io/scene.hpp"

namespace softbody {

class RowAssembler {
 public:
  RowAssembler() = default;
  RowAssembler(const RowAssembler &) = delete;
  RowAssembler &operator=(const RowAssembler &) = delete;
  ~RowAssembler();

  // Collective. The elements of the free bodies that touch a vertex this rank
  // owns, their rest data and the gather plan for their vertices. rest_positions
  // is a PETSc-ordered DOF vector (block size 3).
  PetscErrorCode Setup(MPI_Comm comm, const Scene &scene, const DofLayout &layout,
                       double shear_scale, Vec rest_positions);

  // Collective. A new MATAIJ matrix (block size 3) with one 3 x 3 block per pair
  // of vertices sharing a tet (the diagonal included), all values zero, and the
  // offsets of this rank's element blocks in it. Every matrix passed to Fill
  // must come from here (or be a MatDuplicate of one). plain_products: PETSc's
  // plain CSR product instead of its "inode" variant, a third faster on these
  // rows (3.0 against 4.1 ms at 1e5 tets) but summing in another order.
  PetscErrorCode CreateMatrix(Mat *matrix, bool plain_products = false);

  // Corotated stiffness damping (integrator.hpp): the displacement gradients
  // H_e = sum_a y_a g_a^T of y_a = R^T x_a - X_a (9 per element, this object's
  // element order), and, given H_e at the start of the step, the force and
  // energy of the increments y_e - y_e,start, through which K_e acts:
  //     force = sum_e R K_e (y_e - y_e,start)  (owned rows, N),
  //     energy = sum_e |y_e - y_e,start|_K_e^2 / 2  (J, summed over ranks).
  struct IncrementDamping {
    std::vector<double> *gradients = nullptr;    // out: H_e
    const std::vector<double> *start = nullptr;  // in: H_e at the step's start, or null
    Vec force = nullptr;                         // out when start
    PetscReal energy = 0;                        // out when start
  };

  // Collective. matrix = stiffness_scale K + mass_scale diag(lumped_mass), K the
  // rest stiffness (rotated = false) or the corotated sum_e R K_e R^T at
  // positions x (rotated = true). With rotated, also the elastic force term
  // force = sum_e R K_e (R^T x_e - X_e) (owned rows, N; may be null), the
  // strain energy sum_e y_e^T K_e y_e / 2 (J, summed over ranks; may be null)
  // and the damping terms (may be null). lumped_mass may be null (no mass
  // term). x is ignored unless rotated.
  PetscErrorCode Fill(Mat matrix, bool rotated, Vec x, double stiffness_scale, Vec lumped_mass,
                      double mass_scale, Vec force, PetscReal *energy,
                      IncrementDamping *damping = nullptr);

  // Not collective. From now on, every rotated Fill also computes one rotation per
  // owned vertex: the polar rotation of the volume-weighted sum of the
  // deformation gradients of its tets (for the warp preconditioner).
  void ComputeVertexRotations(bool on) { vertex_rotations_requested_ = on; }
  bool vertex_rotations_requested() const { return vertex_rotations_requested_; }
  // 9 per owned vertex (row-major); empty unless requested and filled.
  const std::vector<double> &vertex_rotations() const { return vertex_rotations_; }

  // Elements this rank computes (owned plus those shared with a neighbour).
  size_t num_elements() const { return elements_.size(); }
  // Bytes this rank keeps per element (element data and offsets).
  static constexpr size_t kBytesPerElement = 4 * 4 + 18 * 8 + 8 + 4 + 4 + 16 * 4;

 private:
  struct Element {
    std::array<int32_t, 4> vertex;   // index into the halo vertices
    std::array<double, 9> gradient;  // rows grad N_1, grad N_2, grad N_3 (1/m)
    std::array<double, 9>
        rest_gradient;  // sum_a (X_a - X_0) grad N_a^T (= I up to round-off), row-major
    double volume;      // |V| (m^3)
    int32_t material;   // index into lame_
    uint32_t owned;     // bit a: vertex a is owned; bit 4: the energy counts here
    // Offsets of the blocks a, b (16): entry (3a, 3b) in the values of the
    // diagonal part when b is owned, else of the off-diagonal part; -1 when a is
    // not owned.
    std::array<int32_t, 16> offset;
  };

  MPI_Comm comm_ = MPI_COMM_NULL;
  double shear_scale_ = 1;
  PetscInt begin_ = 0, count_ = 0;  // owned PETSc vertices [begin, begin + count)
  std::vector<Element> elements_;
  std::vector<Lame> lame_;
  std::vector<PetscInt> halo_vertices_;  // PETSc vertex indices, increasing
  VecScatter halo_scatter_ = nullptr;
  Vec x_halo_ = nullptr;
  int32_t first_owned_halo_ = 0;  // halo index of PETSc vertex begin_
  // Row lengths of the owned vertices' rows in both parts of the matrix, and the
  // diagonal entries of the owned rows.
  std::vector<int32_t> row_length_diagonal_, row_length_off_;
  std::vector<int32_t> diagonal_offset_;
  PetscInt pattern_nonzeros_diagonal_ = -1, pattern_nonzeros_off_ = -1;
  bool vertex_rotations_requested_ = false;
  std::vector<double> vertex_rotations_;
};

}  // namespace softbody
