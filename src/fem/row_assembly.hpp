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
#include "fem/migration.hpp"
#include "fem/partition.hpp"
#include "io/scene.hpp"

namespace softbody {

namespace row_assembly_detail {
struct FillContext;  // the element pass's pointers and scales (row_assembly.cpp)
}

class RowAssembler {
 public:
  RowAssembler() = default;
  RowAssembler(const RowAssembler &) = delete;
  RowAssembler &operator=(const RowAssembler &) = delete;
  ~RowAssembler();

  // Collective. The elements of `tets` (MigrateTets: the free tets that touch a
  // vertex this rank owns; taken by value, so a caller that moves them in frees
  // them here) with their bodies' materials, their rest data and the gather plan
  // for their vertices. rest_positions is a PETSc-ordered DOF vector
  // (block size 3).
  PetscErrorCode Setup(MPI_Comm comm, const Scene &scene, const DofLayout &layout, LocalTets tets,
                       double shear_scale, Vec rest_positions);

  // How PETSc multiplies with the matrix: its default "inode" kernel, or the
  // plain CSR kernel, faster on these rows but summing in another order.
  enum class Products { kInode, kPlainCsr };

  // Collective. A new MATAIJ matrix (block size 3) with one 3 x 3 block per pair
  // of vertices sharing a tet (the diagonal included), all values zero, and the
  // offsets of this rank's element blocks in it. Every matrix passed to Fill
  // must come from here (or be a MatDuplicate of one).
  PetscErrorCode CreateMatrix(Mat *matrix, Products products = Products::kInode);

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

  // The terms of one Fill, named. Build with the setters, e.g.
  //     FillTerms().Stiffness(b dt + dt^2).Mass(lumped_mass, 1 + a dt).CorotatedAt(x)
  //         .ElasticForce(force).StrainEnergy(&energy)
  // Every output is optional; the force, energy and damping outputs need CorotatedAt.
  struct FillTerms {
    double stiffness_scale = 1;           // factor on K (or on sum_e R K_e R^T)
    Vec lumped_mass = nullptr;            // per DOF (kg); null: no mass term
    double mass_scale = 0;                // factor on diag(lumped_mass)
    Vec positions = nullptr;              // x (m): the corotated K(R) at x; null: the rest K
    Vec force = nullptr;                  // out: sum_e R K_e (R^T x_e - X_e), owned rows (N)
    PetscReal *energy = nullptr;          // out: sum_e y_e^T K_e y_e / 2 (J, all ranks)
    IncrementDamping *damping = nullptr;  // in/out: the increment damping terms

    FillTerms &Stiffness(double scale) {
      stiffness_scale = scale;
      return *this;
    }
    FillTerms &Mass(Vec lumped, double scale) {
      lumped_mass = lumped;
      mass_scale = scale;
      return *this;
    }
    FillTerms &CorotatedAt(Vec x) {
      positions = x;
      return *this;
    }
    FillTerms &ElasticForce(Vec out) {
      force = out;
      return *this;
    }
    FillTerms &StrainEnergy(PetscReal *out) {
      energy = out;
      return *this;
    }
    FillTerms &Damping(IncrementDamping *terms) {
      damping = terms;
      return *this;
    }
  };

  // Collective. matrix = stiffness_scale K + mass_scale diag(lumped_mass), K the
  // rest stiffness (no positions) or the corotated sum_e R K_e R^T at positions
  // x, with y_e = R^T x_e - X_e; with positions, also the requested outputs of
  // `terms` (FillTerms). matrix must come from CreateMatrix.
  PetscErrorCode Fill(Mat matrix, const FillTerms &terms);

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
    // sum_a (X_a - X_0) grad N_a^T (= I up to round-off), row-major
    std::array<double, 9> rest_gradient;
    double volume;     // |V| (m^3)
    int32_t material;  // index into lame_
    uint32_t owned;    // bit a: vertex a is owned; bit 4: the energy counts here
    // Offsets of the blocks a, b (16): entry (3a, 3b) in the values of the
    // diagonal part when b is owned, else of the off-diagonal part; -1 when a is
    // not owned.
    std::array<int32_t, 16> offset;
  };

  struct MatrixParts;   // CSR structure of the matrix's two parts (set-up)
  struct MatrixValues;  // their value arrays (a fill)
  using FillContext = row_assembly_detail::FillContext;

  // Setup's steps: the elements touching an owned vertex (and their PETSc
  // vertices), the halo indices of those vertices, the gather plan.
  static Element MakeElement(const TetPositions &X, int32_t material, uint32_t owned);
  void CollectElements(const Scene &scene, const DofLayout &layout, const LocalTets &tets);
  PetscErrorCode IndexHalo(const std::vector<std::array<PetscInt, 4>> &vertices);
  PetscErrorCode CreateHaloScatter(Vec rest_positions);
  PetscErrorCode GatherHalo(Vec x);  // x_halo_ = the halo vertices' entries of x
  // CreateMatrix's steps: per owned vertex its neighbours (CSR by vertex:
  // start, halo indices, their count), the preallocated pattern, the offsets of
  // the element blocks and diagonal entries in it (false when one is missing).
  void OwnedNeighbours(std::vector<PetscInt> *start, std::vector<int32_t> *neighbours,
                       std::vector<PetscInt> *degree) const;
  PetscErrorCode CreatePattern(Mat *matrix, Products products) const;
  bool LocateBlocks(const MatrixParts &parts);
  // Fill's steps.
  PetscErrorCode OpenValues(Mat matrix, MatrixValues *values) const;  // and zero them
  PetscErrorCode CloseValues(Mat matrix, MatrixValues *values) const;
  PetscErrorCode FillRotated(const FillTerms &terms, FillContext *context, double *local_energy);
  void RotateVertexDeformations();
  PetscErrorCode AddMassTerm(const FillTerms &terms, PetscScalar *diagonal_values);
  PetscErrorCode SumEnergies(const FillTerms &terms, double local_energy,
                             double local_damping_energy);

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
