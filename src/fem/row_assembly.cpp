#include "fem/row_assembly.hpp"

// PetscObjectStateIncrease: A's values are written in place, so its state must
// change for the preconditioner to notice (PETSc's note: "a developer need only
// call it after explicit access to an object's internals").
#include <petsc/private/petscimpl.h>

#include <algorithm>
#include <cstring>

#ifdef __AVX2__
#include <immintrin.h>
#endif

namespace softbody {

RowAssembler::~RowAssembler() {
  VecScatterDestroy(&halo_scatter_);
  VecDestroy(&x_halo_);
}

namespace {

// Row-major 3 x 3 matrices stored as 9 doubles.
using RowMajor3 = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;

// The lowest PETSc vertex of an element owns it: its energy is counted there.
constexpr int kEnergyCountsHereBit = 4;

// A rank's values of A from which on the element pass prefetches the rows it
// adds to (kPrefetchElementsAhead): below, they stay in the core's own caches
// and the prefetches only cost instructions (the 10 080-tet beam, 2 MB of
// values: the refill 10-15 % slower with them; the 99 840-tet beam and the
// 104k-tet TetGen mesh, about 20 MB: 7-12 % faster). Four times a 1 MB L2.
constexpr size_t kPrefetchMinimumBytes = size_t{4} << 20;

bool VertexIsOwned(uint32_t owned, int a) {
  return owned >> a & 1u;
}

// Position of `value` in the increasing list (which contains it).
int32_t PositionIn(const std::vector<PetscInt> &list, PetscInt value) {
  return static_cast<int32_t>(std::lower_bound(list.begin(), list.end(), value) - list.begin());
}

}  // namespace

RowAssembler::Element RowAssembler::MakeElement(const TetPositions &X, int32_t material,
                                                uint32_t owned) {
  const ShapeGradients g = ComputeShapeGradients(X);
  Element element;
  for (int a = 1; a < 4; ++a)
    for (int c = 0; c < 3; ++c) element.gradient[3 * (a - 1) + c] = g(a, c);
  // sum_a (X_a - X_0) g_a^T: the identity up to round-off, kept exactly so
  // that the corotated strain R^T F - this is the one of the edge vectors.
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) {
      double sum = 0;
      for (int a = 1; a < 4; ++a) sum += (X(a, i) - X(0, i)) * g(a, j);
      element.rest_gradient[3 * i + j] = sum;
    }
  element.volume = std::abs(SignedVolume(X));
  element.material = material;
  element.owned = owned;
  return element;
}

void RowAssembler::CollectElements(const Scene &scene, const DofLayout &layout,
                                   const LocalTets &tets) {
  elements_.clear();
  lame_.clear();
  std::vector<int32_t> material_of_body(scene.bodies.size(), -1);
  for (size_t b = 0; b < scene.bodies.size(); ++b) {
    if (scene.bodies[b].fixed) continue;
    material_of_body[b] = static_cast<int32_t>(lame_.size());
    lame_.push_back(
        LameFromYoungPoisson(scene.bodies[b].material.young, scene.bodies[b].material.poisson));
  }
  for (size_t t = 0; t < tets.size(); ++t) {
    const std::array<PetscInt, 4> &p = tets.vertices[t];
    uint32_t owned = 0;
    for (int a = 0; a < 4; ++a)
      if (layout.OwnsPetscVertex(p[a])) owned |= 1u << a;
    if (layout.OwnsPetscVertex(*std::min_element(p.begin(), p.end())))
      owned |= 1u << kEnergyCountsHereBit;
    elements_.push_back(MakeElement(tets.rest[t], material_of_body[tets.body[t]], owned));
  }
}

PetscErrorCode RowAssembler::IndexHalo(const std::vector<std::array<PetscInt, 4>> &vertices) {
  PetscFunctionBeginUser;
  halo_vertices_.clear();
  halo_vertices_.reserve(4 * vertices.size());
  for (const auto &p : vertices) halo_vertices_.insert(halo_vertices_.end(), p.begin(), p.end());
  std::sort(halo_vertices_.begin(), halo_vertices_.end());
  halo_vertices_.erase(std::unique(halo_vertices_.begin(), halo_vertices_.end()),
                       halo_vertices_.end());
  PetscCheck(halo_vertices_.size() < (size_t(1) << 31) / 3, PETSC_COMM_SELF, PETSC_ERR_SUP,
             "too many vertices on one rank for 32-bit halo indices");
  // The owned vertices are one contiguous run of the (increasing) halo.
  first_owned_halo_ = PositionIn(halo_vertices_, begin_);
  for (size_t e = 0; e < elements_.size(); ++e)
    for (int a = 0; a < 4; ++a) elements_[e].vertex[a] = PositionIn(halo_vertices_, vertices[e][a]);
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode RowAssembler::CreateHaloScatter(Vec rest_positions) {
  PetscFunctionBeginUser;
  const PetscInt halo = static_cast<PetscInt>(halo_vertices_.size());
  IS from;
  PetscCall(
      ISCreateBlock(PETSC_COMM_SELF, 3, halo, halo_vertices_.data(), PETSC_COPY_VALUES, &from));
  PetscCall(VecCreateSeq(PETSC_COMM_SELF, 3 * halo, &x_halo_));
  PetscCall(VecScatterCreate(rest_positions, from, x_halo_, nullptr, &halo_scatter_));
  PetscCall(ISDestroy(&from));
  PetscCall(GatherHalo(rest_positions));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode RowAssembler::GatherHalo(Vec x) {
  PetscFunctionBeginUser;
  PetscCall(VecScatterBegin(halo_scatter_, x, x_halo_, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecScatterEnd(halo_scatter_, x, x_halo_, INSERT_VALUES, SCATTER_FORWARD));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode RowAssembler::Setup(MPI_Comm comm, const Scene &scene, const DofLayout &layout,
                                   LocalTets tets, double shear_scale, Vec rest_positions) {
  PetscFunctionBeginUser;
  comm_ = comm;
  shear_scale_ = shear_scale;
  begin_ = layout.local_begin();
  count_ = layout.local_count();
  CollectElements(scene, layout, tets);
  PetscCall(IndexHalo(tets.vertices));
  PetscCall(CreateHaloScatter(rest_positions));
  PetscFunctionReturn(PETSC_SUCCESS);
}

void RowAssembler::OwnedNeighbours(std::vector<PetscInt> *start, std::vector<int32_t> *neighbours,
                                   std::vector<PetscInt> *degree) const {
  start->assign(count_ + 1, 0);
  for (const Element &e : elements_)
    for (int a = 0; a < 4; ++a)
      if (VertexIsOwned(e.owned, a)) (*start)[halo_vertices_[e.vertex[a]] - begin_ + 1] += 4;
  for (PetscInt v = 0; v < count_; ++v) (*start)[v + 1] += (*start)[v];
  neighbours->resize((*start)[count_]);
  std::vector<PetscInt> next(start->begin(), start->end() - 1);
  for (const Element &e : elements_)
    for (int a = 0; a < 4; ++a)
      if (VertexIsOwned(e.owned, a)) {
        PetscInt &n = next[halo_vertices_[e.vertex[a]] - begin_];
        for (int b = 0; b < 4; ++b) (*neighbours)[n++] = e.vertex[b];
      }
  degree->resize(count_);
  for (PetscInt v = 0; v < count_; ++v) {
    auto first = neighbours->begin() + (*start)[v], last = neighbours->begin() + (*start)[v + 1];
    std::sort(first, last);
    (*degree)[v] = std::unique(first, last) - first;
  }
}

PetscErrorCode RowAssembler::CreatePattern(Mat *matrix, Products products) const {
  PetscFunctionBeginUser;
  std::vector<PetscInt> start, degree;
  std::vector<int32_t> neighbours;  // halo indices, increasing per owned vertex
  OwnedNeighbours(&start, &neighbours, &degree);
  // DOF rows: row 3v + c has the columns 3w + d of the neighbours w.
  std::vector<PetscInt> row_start(3 * count_ + 1, 0), columns;
  for (PetscInt v = 0; v < count_; ++v)
    for (int c = 0; c < 3; ++c) row_start[3 * v + c + 1] = row_start[3 * v + c] + 3 * degree[v];
  columns.reserve(row_start.back());
  for (PetscInt v = 0; v < count_; ++v)
    for (int c = 0; c < 3; ++c)
      for (PetscInt k = 0; k < degree[v]; ++k)
        for (int d = 0; d < 3; ++d)
          columns.push_back(3 * halo_vertices_[neighbours[start[v] + k]] + d);
  std::vector<PetscScalar> zeros(columns.size(), 0.0);
  PetscCall(MatCreate(comm_, matrix));
  PetscCall(MatSetSizes(*matrix, 3 * count_, 3 * count_, PETSC_DETERMINE, PETSC_DETERMINE));
  PetscCall(MatSetBlockSize(*matrix, 3));
  PetscCall(MatSetType(*matrix, MATAIJ));
  PetscCall(MatSeqAIJSetPreallocationCSR(*matrix, row_start.data(), columns.data(), zeros.data()));
  PetscCall(MatMPIAIJSetPreallocationCSR(*matrix, row_start.data(), columns.data(), zeros.data()));
  if (products == Products::kPlainCsr) {  // the option takes effect at the next assembly
    PetscCall(MatSetOption(*matrix, MAT_USE_INODES, PETSC_FALSE));
    PetscCall(MatAssemblyBegin(*matrix, MAT_FINAL_ASSEMBLY));
    PetscCall(MatAssemblyEnd(*matrix, MAT_FINAL_ASSEMBLY));
  }
  PetscCall(MatSetOption(*matrix, MAT_NEW_NONZERO_LOCATION_ERR, PETSC_TRUE));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Read access to the CSR structure of an MPIAIJ (or, on one rank, SeqAIJ)
// matrix's diagonal and off-diagonal parts (the off-diagonal part's columns are
// positions in garray, the increasing global columns it has).
struct RowAssembler::MatrixParts {
  Mat diagonal = nullptr, off = nullptr;
  const PetscInt *garray = nullptr;
  PetscInt off_columns = 0;
  const PetscInt *di = nullptr, *dj = nullptr, *oi = nullptr, *oj = nullptr;

  PetscErrorCode Open(Mat matrix, MPI_Comm comm, PetscInt rows_expected) {
    PetscFunctionBeginUser;
    PetscMPIInt size;
    PetscCallMPI(MPI_Comm_size(comm, &size));
    diagonal = matrix;
    if (size > 1) PetscCall(MatMPIAIJGetSeqAIJ(matrix, &diagonal, &off, &garray));
    PetscInt rows;
    PetscBool done;
    PetscCall(MatGetRowIJ(diagonal, 0, PETSC_FALSE, PETSC_FALSE, &rows, &di, &dj, &done));
    PetscCheck(done && rows == rows_expected, PETSC_COMM_SELF, PETSC_ERR_PLIB,
               "no CSR access to the matrix");
    if (off) {
      PetscCall(MatGetRowIJ(off, 0, PETSC_FALSE, PETSC_FALSE, &rows, &oi, &oj, &done));
      PetscCheck(done, PETSC_COMM_SELF, PETSC_ERR_PLIB, "no CSR access to the matrix");
      PetscCall(MatGetSize(off, nullptr, &off_columns));
    }
    PetscFunctionReturn(PETSC_SUCCESS);
  }
  PetscErrorCode Close() {
    PetscFunctionBeginUser;
    PetscInt rows;
    PetscBool done;
    PetscCall(MatRestoreRowIJ(diagonal, 0, PETSC_FALSE, PETSC_FALSE, &rows, &di, &dj, &done));
    if (off) PetscCall(MatRestoreRowIJ(off, 0, PETSC_FALSE, PETSC_FALSE, &rows, &oi, &oj, &done));
    PetscFunctionReturn(PETSC_SUCCESS);
  }
};

namespace {

// Position of `column` in j[first, last) (increasing), or -1.
int32_t FindColumn(const PetscInt *j, PetscInt first, PetscInt last, PetscInt column) {
  const PetscInt *p = std::lower_bound(j + first, j + last, column);
  return p < j + last && *p == column ? static_cast<int32_t>(p - j) : -1;
}

}  // namespace

bool RowAssembler::LocateBlocks(const MatrixParts &m) {
  bool complete = true;
  for (Element &element : elements_)
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b) {
        int32_t &offset = element.offset[4 * a + b];
        offset = -1;
        if (!VertexIsOwned(element.owned, a)) continue;
        const PetscInt row = 3 * (halo_vertices_[element.vertex[a]] - begin_);
        const PetscInt column_vertex = halo_vertices_[element.vertex[b]];
        if (VertexIsOwned(element.owned, b)) {
          offset = FindColumn(m.dj, m.di[row], m.di[row + 1], 3 * (column_vertex - begin_));
        } else {
          const PetscInt *g =
              std::lower_bound(m.garray, m.garray + m.off_columns, 3 * column_vertex);
          if (g < m.garray + m.off_columns && *g == 3 * column_vertex)
            offset = FindColumn(m.oj, m.oi[row], m.oi[row + 1], g - m.garray);
        }
        complete = complete && offset >= 0;
      }
  diagonal_offset_.resize(3 * count_);
  for (PetscInt i = 0; i < 3 * count_; ++i) {
    diagonal_offset_[i] = FindColumn(m.dj, m.di[i], m.di[i + 1], i);
    complete = complete && diagonal_offset_[i] >= 0;
  }
  return complete;
}

PetscErrorCode RowAssembler::CreateMatrix(Mat *matrix, Products products) {
  PetscFunctionBeginUser;
  PetscCall(CreatePattern(matrix, products));
  MatrixParts parts;
  PetscCall(parts.Open(*matrix, comm_, 3 * count_));
  pattern_nonzeros_diagonal_ = parts.di[3 * count_];
  pattern_nonzeros_off_ = parts.oi ? parts.oi[3 * count_] : 0;
  PetscCheck(pattern_nonzeros_diagonal_ < INT32_MAX && pattern_nonzeros_off_ < INT32_MAX,
             PETSC_COMM_SELF, PETSC_ERR_SUP, "more than 2^31 matrix entries on one rank");
  row_length_diagonal_.resize(count_);
  row_length_off_.resize(count_);
  for (PetscInt v = 0; v < count_; ++v) {
    row_length_diagonal_[v] = static_cast<int32_t>(parts.di[3 * v + 1] - parts.di[3 * v]);
    row_length_off_[v] = parts.oi ? static_cast<int32_t>(parts.oi[3 * v + 1] - parts.oi[3 * v]) : 0;
  }
  const bool complete = LocateBlocks(parts);
  PetscCall(parts.Close());
  PetscCheck(complete, PETSC_COMM_SELF, PETSC_ERR_PLIB,
             "an element block is missing from the pattern");
  PetscFunctionReturn(PETSC_SUCCESS);
}

namespace row_assembly_detail {

struct FillContext {
  const double *x_halo;
  int32_t first_owned;           // halo index of the first owned vertex (owned: contiguous)
  PetscScalar *values[2];        // [0] off-diagonal part, [1] diagonal part
  const int32_t *row_length[2];  // same order
  bool prefetch_rows;            // the element pass prefetches A's rows (kPrefetchMinimumBytes)
  double stiffness_scale, shear_scale;
  PetscScalar *force;             // owned rows, may be null
  double *vertex_deformation;     // 9 per owned vertex: sum of V F, may be null
  double *gradients;              // damping: H per element (out), may be null
  const double *gradients_start;  // damping: H per element at the step's start, may be null
  PetscScalar *damping_force;     // owned rows, when gradients_start
  double *damping_energy;         // when gradients_start
};

}  // namespace row_assembly_detail

namespace {

using row_assembly_detail::FillContext;

// Linear-elastic stress of a displacement gradient H (symmetric):
// S = l tr(H) I + 2 m sym(H) on the diagonal, s m (H + H^T) off it (s: shear scale).
inline void Stress(const double (&H)[3][3], double l, double m, double sm, double (&S)[3][3]) {
  const double trace = H[0][0] + H[1][1] + H[2][2];
  for (int i = 0; i < 3; ++i) {
    S[i][i] = l * trace + 2.0 * m * H[i][i];
    for (int j = i + 1; j < 3; ++j) S[i][j] = S[j][i] = sm * (H[i][j] + H[j][i]);
  }
}

// Strain energy V H : S / 2 (J).
inline double StrainEnergy(const double (&H)[3][3], const double (&S)[3][3], double volume) {
  return 0.5 * volume *
         (H[0][0] * S[0][0] + H[1][1] * S[1][1] + H[2][2] * S[2][2] +
          (H[0][1] + H[1][0]) * S[0][1] + (H[1][2] + H[2][1]) * S[1][2] +
          (H[2][0] + H[0][2]) * S[2][0]);
}

// The element's nodal forces f_a = V R S g_a (f_0 = -f_1 - f_2 - f_3) added to
// the owned rows of out.
inline void AddStressForces(const double (&R)[3][3], const double (&S)[3][3], double volume,
                            const double (&g)[4][3], uint32_t owned, const int32_t (&owned_row)[4],
                            PetscScalar *out) {
  double P[3][3];  // V R S
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      P[i][j] = volume * (R[i][0] * S[0][j] + R[i][1] * S[1][j] + R[i][2] * S[2][j]);
  double f[4][3];
  for (int a = 1; a < 4; ++a)
    for (int i = 0; i < 3; ++i) f[a][i] = P[i][0] * g[a][0] + P[i][1] * g[a][1] + P[i][2] * g[a][2];
  for (int i = 0; i < 3; ++i) f[0][i] = -(f[1][i] + f[2][i] + f[3][i]);
  for (int a = 0; a < 4; ++a)
    if (owned >> a & 1u) {
      PetscScalar *row = out + 3 * owned_row[a];
      row[0] += f[a][0];
      row[1] += f[a][1];
      row[2] += f[a][2];
    }
}

// p[r * stride + c] += B[r][c] (or B[c][r]): a 3 x 3 block into rows `stride` apart.
template <bool kTransposed>
inline void AddBlock(const double (&B)[3][3], PetscScalar *p, int32_t stride) {
  for (int r = 0; r < 3; ++r, p += stride)
    for (int c = 0; c < 3; ++c) p[c] += kTransposed ? B[c][r] : B[r][c];
}

#ifdef __AVX2__
// p[0 .. 2] += the first three lanes of r. Two lanes and a scalar rather than a
// masked load and store: AMD's processors (Zen 2 to 4) take several times
// longer over a masked store than over a plain one (the refill ran at 3.3 M
// tets/s per rank on an EPYC with them, against 6.5 M on an Intel core).
inline void AddThreeLanes(__m256d r, PetscScalar *p) {
  _mm_storeu_pd(p, _mm_add_pd(_mm_loadu_pd(p), _mm256_castpd256_pd128(r)));
  p[2] += _mm_cvtsd_f64(_mm256_extractf128_pd(r, 1));
}

// Adds the three rows of the block wl h_a h_b^T + wsm h_b h_a^T + diagonal I at
// p (rows `stride` apart) as four lanes, the fourth unused: row i is
// p_a[i] h_b + q_b[i] h_a + diagonal e_i with p = wl h, q = wsm h.
inline void AddBlockRows(const double *p_a, const double *q_b, __m256d h_a, __m256d h_b,
                         __m256d diagonal, PetscScalar *p, int32_t stride) {
  const __m256d e0 = _mm256_set_pd(0, 0, 0, 1), e1 = _mm256_set_pd(0, 0, 1, 0),
                e2 = _mm256_set_pd(0, 1, 0, 0);
  __m256d r0 = _mm256_fmadd_pd(
      _mm256_broadcast_sd(q_b + 0), h_a,
      _mm256_fmadd_pd(diagonal, e0, _mm256_mul_pd(_mm256_broadcast_sd(p_a + 0), h_b)));
  __m256d r1 = _mm256_fmadd_pd(
      _mm256_broadcast_sd(q_b + 1), h_a,
      _mm256_fmadd_pd(diagonal, e1, _mm256_mul_pd(_mm256_broadcast_sd(p_a + 1), h_b)));
  __m256d r2 = _mm256_fmadd_pd(
      _mm256_broadcast_sd(q_b + 2), h_a,
      _mm256_fmadd_pd(diagonal, e2, _mm256_mul_pd(_mm256_broadcast_sd(p_a + 2), h_b)));
  AddThreeLanes(r0, p);
  AddThreeLanes(r1, p + stride);
  AddThreeLanes(r2, p + 2 * stride);
}
#endif

}  // namespace

namespace {

// The helpers of the element pass are always inlined: the pass must compile to
// one loop body, for its speed and for the same floating-point contractions
// (fused multiply-adds) as one function.
#define SOFTBODY_ELEMENT_STEP [[gnu::always_inline]] inline

// F_k = sum_a (x_a - x_0) g_a^T of elements first .. first + 3 (the identity
// past the end) and their rotations R_k = RotationOfDeformation(F_k), four at a
// time (RotationOfDeformation4).
template <typename Element>
SOFTBODY_ELEMENT_STEP void RotationsOfBatch(const std::vector<Element> &elements, size_t first,
                                            const double *x_halo, Mat3 (&F)[4], Mat3 (&R)[4]) {
  const size_t count = std::min<size_t>(4, elements.size() - first);
  for (size_t k = 0; k < count; ++k) {
    const Element &other = elements[first + k];
    const double *x0 = x_halo + 3 * other.vertex[0];
    double d[3][3];  // edge vectors x_a - x_0, a = 1..3
    for (int a = 1; a < 4; ++a) {
      const double *xa = x_halo + 3 * other.vertex[a];
      for (int i = 0; i < 3; ++i) d[a - 1][i] = xa[i] - x0[i];
    }
    const double *g = other.gradient.data();  // rows grad N_1..3
    for (int i = 0; i < 3; ++i)               // F = sum_a d_a g_a^T
      for (int j = 0; j < 3; ++j)
        F[k](i, j) = d[0][i] * g[j] + d[1][i] * g[3 + j] + d[2][i] * g[6 + j];
  }
  for (size_t k = count; k < 4; ++k) F[k] = Mat3::Identity();
  RotationOfDeformation4(F, R);
}

// g_0 .. g_3 from the stored g_1 .. g_3 (g_0 = -(g_1 + g_2 + g_3)).
SOFTBODY_ELEMENT_STEP void ExpandShapeGradients(const std::array<double, 9> &gradient,
                                                double (&g)[4][3]) {
  for (int k = 0; k < 3; ++k) {
    g[1][k] = gradient[k];
    g[2][k] = gradient[3 + k];
    g[3][k] = gradient[6 + k];
    g[0][k] = -(g[1][k] + g[2][k] + g[3][k]);
  }
}

// The material constants of an element: l = lambda, m = mu, sm = s mu (Pa).
struct ElementMaterial {
  double l, m, sm;
};

// The corotated element's force, energy, damping terms and its share of the
// per-vertex deformation sums, at deformation gradient F and rotation R.
template <typename Element>
SOFTBODY_ELEMENT_STEP void CorotatedElementTerms(const Element &el, size_t e, const Mat3 &F,
                                                 const double (&R)[3][3], const double (&g)[4][3],
                                                 const ElementMaterial &k,
                                                 const int32_t (&owned_row)[4],
                                                 const FillContext &c, double &energy) {
  const bool counts_energy = el.owned >> kEnergyCountsHereBit & 1u;
  if (c.vertex_deformation) {
    const RowMajor3 VF = el.volume * F;
    for (int a = 0; a < 4; ++a)
      if (VertexIsOwned(el.owned, a)) {
        double *sum = c.vertex_deformation + 9 * owned_row[a];
        for (int q = 0; q < 9; ++q) sum[q] += VF.data()[q];
      }
  }
  // Displacement gradient of y_a = R^T x_a - X_a: H = R^T F - sum_a (X_a - X_0) g_a^T.
  double H[3][3];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      H[i][j] =
          R[0][i] * F(0, j) + R[1][i] * F(1, j) + R[2][i] * F(2, j) - el.rest_gradient[3 * i + j];
  double S[3][3];
  Stress(H, k.l, k.m, k.sm, S);
  if (counts_energy) energy += StrainEnergy(H, S, el.volume);
  if (c.force) AddStressForces(R, S, el.volume, g, el.owned, owned_row, c.force);
  if (!c.gradients) return;
  std::copy(&H[0][0], &H[0][0] + 9, c.gradients + 9 * e);
  if (!c.gradients_start) return;
  double dH[3][3], dS[3][3];  // the increment since the step's start
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) dH[i][j] = H[i][j] - c.gradients_start[9 * e + 3 * i + j];
  Stress(dH, k.l, k.m, k.sm, dS);
  if (counts_energy) *c.damping_energy += StrainEnergy(dH, dS, el.volume);
  AddStressForces(R, dS, el.volume, g, el.owned, owned_row, c.damping_force);
}

// The factors of the blocks B_ab = p_a h_b^T + q_b h_a^T + (q_a . h_b) I [+ ...]:
// p_a = w l h_a, q_a = w s m h_a with w = stiffness_scale V (returned). Plain
// arrays, not a struct: GCC vectorises the pass less well with the struct.
SOFTBODY_ELEMENT_STEP double BlockFactors(double stiffness_scale, double volume,
                                          const ElementMaterial &k, const double (&h)[4][3],
                                          double (&p)[4][3], double (&q)[4][3]) {
  const double w = stiffness_scale * volume, wl = w * k.l, wsm = w * k.sm;
  for (int a = 0; a < 4; ++a)
    for (int i = 0; i < 3; ++i) {
      p[a][i] = wl * h[a][i];
      q[a][i] = wsm * h[a][i];
    }
  return w;
}

#ifdef __AVX2__
// The blocks of a standard-shear element (s = 1) in AVX2 rows.
SOFTBODY_ELEMENT_STEP void AddBlocksAvx2(uint32_t owned, const std::array<int32_t, 16> &offset,
                                         const double (&h)[4][3], const double (&p)[4][3],
                                         const double (&q)[4][3], const int32_t (&owned_row)[4],
                                         const FillContext &c) {
  __m256d hv[4];
  for (int a = 0; a < 4; ++a) hv[a] = _mm256_set_pd(0.0, h[a][2], h[a][1], h[a][0]);
  double diagonal[4][4];
  for (int a = 0; a < 4; ++a)
    for (int b = a; b < 4; ++b)
      diagonal[a][b] = q[a][0] * h[b][0] + q[a][1] * h[b][1] + q[a][2] * h[b][2];
  if ((owned & 15u) == 15u) {  // every row owned, every column in the diagonal part
    PetscScalar *values = c.values[1];
    int32_t stride[4];
    for (int a = 0; a < 4; ++a) stride[a] = c.row_length[1][owned_row[a]];
    for (int a = 0; a < 4; ++a) {
      AddBlockRows(p[a], q[a], hv[a], hv[a], _mm256_set1_pd(diagonal[a][a]), values + offset[5 * a],
                   stride[a]);
      for (int b = a + 1; b < 4; ++b) {
        const __m256d dv = _mm256_set1_pd(diagonal[a][b]);
        AddBlockRows(p[a], q[b], hv[a], hv[b], dv, values + offset[4 * a + b], stride[a]);
        AddBlockRows(p[b], q[a], hv[b], hv[a], dv, values + offset[4 * b + a], stride[b]);
      }
    }
    return;
  }
  for (int a = 0; a < 4; ++a) {
    const bool a_owned = VertexIsOwned(owned, a);
    for (int b = a; b < 4; ++b) {
      const bool b_owned = VertexIsOwned(owned, b);
      const __m256d dv = _mm256_set1_pd(diagonal[a][b]);
      if (a_owned)
        AddBlockRows(p[a], q[b], hv[a], hv[b], dv, c.values[b_owned] + offset[4 * a + b],
                     c.row_length[b_owned][owned_row[a]]);
      if (b_owned && b != a)
        AddBlockRows(p[b], q[a], hv[b], hv[a], dv, c.values[a_owned] + offset[4 * b + a],
                     c.row_length[a_owned][owned_row[b]]);
    }
  }
}
#endif

// The blocks of an element, 3 x 3 at a time (any shear scale; with s != 1 the
// term (2m - 2sm) w R diag(g_a o g_b) R^T).
template <bool kStandardShear>
SOFTBODY_ELEMENT_STEP void AddBlocks(uint32_t owned, const std::array<int32_t, 16> &offset,
                                     const double (&g)[4][3], const double (&h)[4][3],
                                     const double (&R)[3][3], const ElementMaterial &k, double w,
                                     const double (&p)[4][3], const double (&q)[4][3],
                                     const int32_t (&owned_row)[4], const FillContext &c) {
  for (int a = 0; a < 4; ++a) {
    const bool a_owned = VertexIsOwned(owned, a);
    for (int b = a; b < 4; ++b) {
      const bool b_owned = VertexIsOwned(owned, b);
      if (!a_owned && !b_owned) continue;
      double B[3][3];
      const double diagonal = q[a][0] * h[b][0] + q[a][1] * h[b][1] + q[a][2] * h[b][2];
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) B[i][j] = p[a][i] * h[b][j] + q[b][i] * h[a][j];
      for (int i = 0; i < 3; ++i) B[i][i] += diagonal;
      if constexpr (!kStandardShear) {
        double t[3];  // (2m - 2sm) w (g_a o g_b)
        for (int q = 0; q < 3; ++q) t[q] = (2.0 * k.m - 2.0 * k.sm) * w * g[a][q] * g[b][q];
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j)
            B[i][j] +=
                R[i][0] * t[0] * R[j][0] + R[i][1] * t[1] * R[j][1] + R[i][2] * t[2] * R[j][2];
      }
      if (a_owned)
        AddBlock<false>(B, c.values[b_owned] + offset[4 * a + b],
                        c.row_length[b_owned][owned_row[a]]);
      if (b_owned && b != a)
        AddBlock<true>(B, c.values[a_owned] + offset[4 * b + a],
                       c.row_length[a_owned][owned_row[b]]);
    }
  }
}

// Elements ahead whose rows of A the element pass prefetches. The pass's
// adds into A wait on A's values when they are not in the core's caches (20 MB
// on the 104k-tet TetGen rung: from L3); asking for an element's rows a few
// elements early overlaps those waits with the work in between. Measured on
// that rung (corotational refill, 1 rank, AMD EPYC, 2026-11-25): none
// 4.3-5.2 M tets/s, 2 ahead 4.7-5.8, 6 ahead 5.6-5.8, 12 and 20 ahead 5.2-5.7.
constexpr size_t kPrefetchElementsAhead = 6;

// Prefetches (for writing) the first entry of each block row element `el` adds
// to: its owned vertices' three rows at each of its four column blocks.
template <typename Element>
SOFTBODY_ELEMENT_STEP void PrefetchElementRows(const Element &el, const FillContext &c) {
  const bool all_owned = (el.owned & 15u) == 15u;
  for (int a = 0; a < 4; ++a) {
    if (!VertexIsOwned(el.owned, a)) continue;
    const int32_t row = el.vertex[a] - c.first_owned;
    for (int b = 0; b < 4; ++b) {
      const bool b_owned = all_owned || VertexIsOwned(el.owned, b);
      const PetscScalar *first = c.values[b_owned] + el.offset[4 * a + b];
      const int32_t stride = c.row_length[b_owned][row];
      for (int r = 0; r < 3; ++r) __builtin_prefetch(first + r * stride, 1, 3);
    }
  }
}

#undef SOFTBODY_ELEMENT_STEP

// The element pass: per element its rotation (corotational), its force and
// energy terms, then its blocks into the owned rows (row_assembly.hpp for the
// formulas). Plain arrays (and AVX2 rows where available) rather than Eigen
// expressions: this loop is the corotational refill's whole cost. Returns the
// local strain energy (J).
template <bool kRotated, bool kStandardShear, typename Element, typename Lame_>
double FillElements(const std::vector<Element> &elements, const std::vector<Lame_> &lame,
                    const FillContext &c) {
  double energy = 0;
  Mat3 batch_F[4], batch_R[4];  // rotated: four elements' F and R at a time
  for (size_t e = 0; e < elements.size(); ++e) {
    const Element &el = elements[e];
    if (c.prefetch_rows && e + kPrefetchElementsAhead < elements.size())
      PrefetchElementRows(elements[e + kPrefetchElementsAhead], c);
    if constexpr (kRotated)
      if (e % 4 == 0) RotationsOfBatch(elements, e, c.x_halo, batch_F, batch_R);
    double g[4][3];  // shape gradients
    ExpandShapeGradients(el.gradient, g);
    const ElementMaterial k{lame[el.material].lambda, lame[el.material].mu,
                            c.shear_scale * lame[el.material].mu};
    int32_t owned_row[4];  // valid for owned vertices
    for (int a = 0; a < 4; ++a) owned_row[a] = el.vertex[a] - c.first_owned;
    double R[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    double h[4][3];  // rotated gradients R g_a
    if constexpr (kRotated) {
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) R[i][j] = batch_R[e % 4](i, j);
      CorotatedElementTerms(el, e, batch_F[e % 4], R, g, k, owned_row, c, energy);
      for (int a = 0; a < 4; ++a)
        for (int i = 0; i < 3; ++i)
          h[a][i] = R[i][0] * g[a][0] + R[i][1] * g[a][1] + R[i][2] * g[a][2];
    } else {
      for (int a = 0; a < 4; ++a)
        for (int i = 0; i < 3; ++i) h[a][i] = g[a][i];
    }
    double p[4][3], q[4][3];  // w l h_a, w s m h_a
    const double w = BlockFactors(c.stiffness_scale, el.volume, k, h, p, q);
#ifdef __AVX2__
    if constexpr (kStandardShear) {
      AddBlocksAvx2(el.owned, el.offset, h, p, q, owned_row, c);
      continue;
    }
#endif
    AddBlocks<kStandardShear>(el.owned, el.offset, g, h, R, k, w, p, q, owned_row, c);
  }
  return energy;
}

}  // namespace

struct RowAssembler::MatrixValues {
  Mat diagonal_part = nullptr, off_part = nullptr;
  PetscScalar *diagonal_values = nullptr, *off_values = nullptr;
};

PetscErrorCode RowAssembler::OpenValues(Mat matrix, MatrixValues *m) const {
  PetscFunctionBeginUser;
  PetscMPIInt size;
  PetscCallMPI(MPI_Comm_size(comm_, &size));
  m->diagonal_part = matrix;
  m->off_part = nullptr;
  if (size > 1) PetscCall(MatMPIAIJGetSeqAIJ(matrix, &m->diagonal_part, &m->off_part, nullptr));
  MatInfo info;
  PetscCall(MatGetInfo(m->diagonal_part, MAT_LOCAL, &info));
  PetscCheck(static_cast<PetscInt>(info.nz_used) == pattern_nonzeros_diagonal_, PETSC_COMM_SELF,
             PETSC_ERR_ARG_WRONG, "RowAssembler::Fill: the matrix does not come from CreateMatrix");
  m->off_values = nullptr;
  PetscCall(MatSeqAIJGetArray(m->diagonal_part, &m->diagonal_values));
  if (m->off_part) PetscCall(MatSeqAIJGetArray(m->off_part, &m->off_values));
  if (m->diagonal_values)
    std::memset(m->diagonal_values, 0, sizeof(PetscScalar) * pattern_nonzeros_diagonal_);
  if (m->off_values) std::memset(m->off_values, 0, sizeof(PetscScalar) * pattern_nonzeros_off_);
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode RowAssembler::CloseValues(Mat matrix, MatrixValues *m) const {
  PetscFunctionBeginUser;
  PetscCall(MatSeqAIJRestoreArray(m->diagonal_part, &m->diagonal_values));
  if (m->off_part) PetscCall(MatSeqAIJRestoreArray(m->off_part, &m->off_values));
  // The values were written in place: the new state tells the preconditioner.
  PetscCall(PetscObjectStateIncrease((PetscObject)matrix));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// The per-vertex sums of V F (9 per owned vertex) replaced by their rotations,
// four vertices at a time as the elements' rotations.
void RowAssembler::RotateVertexDeformations() {
  for (PetscInt v = 0; v < count_; v += 4) {
    Mat3 F[4], R[4];
    const PetscInt batch = std::min<PetscInt>(4, count_ - v);
    for (PetscInt k = 0; k < 4; ++k)
      F[k] = k < batch ? Mat3(Eigen::Map<RowMajor3>(vertex_rotations_.data() + 9 * (v + k)))
                       : Mat3::Identity();
    RotationOfDeformation4(F, R);
    for (PetscInt k = 0; k < batch; ++k)
      Eigen::Map<RowMajor3>(vertex_rotations_.data() + 9 * (v + k)) = R[k];
  }
}

PetscErrorCode RowAssembler::FillRotated(const FillTerms &terms, FillContext *context,
                                         double *local_energy) {
  PetscFunctionBeginUser;
  if (vertex_rotations_requested_) {
    vertex_rotations_.assign(9 * count_, 0.0);
    context->vertex_deformation = vertex_rotations_.data();
  }
  PetscCall(GatherHalo(terms.positions));
  const PetscScalar *x_halo;
  PetscCall(VecGetArrayRead(x_halo_, &x_halo));
  context->x_halo = x_halo;
  if (terms.force) {
    PetscCall(VecSet(terms.force, 0.0));
    PetscCall(VecGetArray(terms.force, &context->force));
  }
  IncrementDamping *damping = terms.damping;
  if (damping) {
    damping->gradients->resize(9 * elements_.size());
    context->gradients = damping->gradients->data();
    if (damping->start) {
      PetscCheck(damping->start->size() == damping->gradients->size(), PETSC_COMM_SELF,
                 PETSC_ERR_ARG_SIZ,
                 "RowAssembler::Fill: the damping's start gradients do not match the elements");
      context->gradients_start = damping->start->data();
      PetscCall(VecSet(damping->force, 0.0));
      PetscCall(VecGetArray(damping->force, &context->damping_force));
    }
  }
  *local_energy = shear_scale_ == 1.0 ? FillElements<true, true>(elements_, lame_, *context)
                                      : FillElements<true, false>(elements_, lame_, *context);
  if (terms.force) PetscCall(VecRestoreArray(terms.force, &context->force));
  if (context->damping_force) PetscCall(VecRestoreArray(damping->force, &context->damping_force));
  if (context->vertex_deformation) RotateVertexDeformations();
  PetscCall(VecRestoreArrayRead(x_halo_, &x_halo));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode RowAssembler::AddMassTerm(const FillTerms &terms, PetscScalar *diagonal_values) {
  PetscFunctionBeginUser;
  const PetscScalar *mass;
  PetscCall(VecGetArrayRead(terms.lumped_mass, &mass));
  for (PetscInt i = 0; i < 3 * count_; ++i)
    diagonal_values[diagonal_offset_[i]] += terms.mass_scale * mass[i];
  PetscCall(VecRestoreArrayRead(terms.lumped_mass, &mass));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode RowAssembler::SumEnergies(const FillTerms &terms, double local_energy,
                                         double local_damping_energy) {
  PetscFunctionBeginUser;
  if (terms.damping && terms.damping->start) {
    const double local[2] = {local_energy, local_damping_energy};
    double global[2];
    PetscCall(MPIU_Allreduce(local, global, 2, MPIU_REAL, MPIU_SUM, comm_));
    if (terms.energy) *terms.energy = global[0];
    terms.damping->energy = global[1];
  } else if (terms.energy) {
    PetscCall(MPIU_Allreduce(&local_energy, terms.energy, 1, MPIU_REAL, MPIU_SUM, comm_));
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode RowAssembler::Fill(Mat matrix, const FillTerms &terms) {
  PetscFunctionBeginUser;
  MatrixValues values;
  PetscCall(OpenValues(matrix, &values));
  FillContext context{};
  context.first_owned = first_owned_halo_;
  context.values[0] = values.off_values;
  context.values[1] = values.diagonal_values;
  context.row_length[0] = row_length_off_.data();
  context.row_length[1] = row_length_diagonal_.data();
  context.prefetch_rows =
      sizeof(PetscScalar) * (pattern_nonzeros_diagonal_ + pattern_nonzeros_off_) >=
      kPrefetchMinimumBytes;
  context.stiffness_scale = terms.stiffness_scale;
  context.shear_scale = shear_scale_;
  double local_energy = 0, local_damping_energy = 0;
  context.damping_energy = &local_damping_energy;
  if (terms.positions) {
    PetscCall(FillRotated(terms, &context, &local_energy));
  } else if (shear_scale_ == 1.0) {
    FillElements<false, true>(elements_, lame_, context);
  } else {
    FillElements<false, false>(elements_, lame_, context);
  }
  if (terms.lumped_mass) PetscCall(AddMassTerm(terms, values.diagonal_values));
  PetscCall(CloseValues(matrix, &values));
  PetscCall(SumEnergies(terms, local_energy, local_damping_energy));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
