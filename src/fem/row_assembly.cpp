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

PetscErrorCode RowAssembler::Setup(MPI_Comm comm, const Scene &scene, const DofLayout &layout,
                                   double shear_scale, Vec rest_positions) {
  PetscFunctionBeginUser;
  comm_ = comm;
  shear_scale_ = shear_scale;
  begin_ = layout.local_begin();
  count_ = layout.local_count();
  const PetscInt end = begin_ + count_;
  elements_.clear();
  lame_.clear();
  std::vector<std::array<PetscInt, 4>> vertices;  // PETSc vertex indices per element
  for (const Body &body : scene.bodies) {
    if (body.fixed) continue;
    const int32_t material = static_cast<int32_t>(lame_.size());
    lame_.push_back(LameFromYoungPoisson(body.material.young, body.material.poisson));
    for (int32_t t = 0; t < body.mesh.num_tets(); ++t) {
      std::array<PetscInt, 4> p;
      uint32_t owned = 0;
      for (int a = 0; a < 4; ++a) {
        p[a] =
            layout.petsc_of_free[layout.free_of_natural[body.first_vertex + body.mesh.tets(t, a)]];
        if (p[a] >= begin_ && p[a] < end) owned |= 1u << a;
      }
      if (!owned) continue;
      const PetscInt lowest = *std::min_element(p.begin(), p.end());
      if (lowest >= begin_ && lowest < end) owned |= 1u << 4;
      TetPositions X;
      for (int a = 0; a < 4; ++a) X.row(a) = body.mesh.vertices.row(body.mesh.tets(t, a));
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
      elements_.push_back(element);
      vertices.push_back(p);
    }
  }
  halo_vertices_.clear();
  halo_vertices_.reserve(4 * vertices.size());
  for (const auto &p : vertices) halo_vertices_.insert(halo_vertices_.end(), p.begin(), p.end());
  std::sort(halo_vertices_.begin(), halo_vertices_.end());
  halo_vertices_.erase(std::unique(halo_vertices_.begin(), halo_vertices_.end()),
                       halo_vertices_.end());
  PetscCheck(halo_vertices_.size() < (size_t(1) << 31) / 3, PETSC_COMM_SELF, PETSC_ERR_SUP,
             "too many vertices on one rank for 32-bit halo indices");
  // The owned vertices are one contiguous run of the (increasing) halo.
  first_owned_halo_ =
      static_cast<int32_t>(std::lower_bound(halo_vertices_.begin(), halo_vertices_.end(), begin_) -
                           halo_vertices_.begin());
  for (size_t e = 0; e < elements_.size(); ++e)
    for (int a = 0; a < 4; ++a)
      elements_[e].vertex[a] = static_cast<int32_t>(
          std::lower_bound(halo_vertices_.begin(), halo_vertices_.end(), vertices[e][a]) -
          halo_vertices_.begin());

  // Gather plan for the positions of the halo vertices.
  const PetscInt halo = static_cast<PetscInt>(halo_vertices_.size());
  IS from;
  PetscCall(
      ISCreateBlock(PETSC_COMM_SELF, 3, halo, halo_vertices_.data(), PETSC_COPY_VALUES, &from));
  PetscCall(VecCreateSeq(PETSC_COMM_SELF, 3 * halo, &x_halo_));
  PetscCall(VecScatterCreate(rest_positions, from, x_halo_, nullptr, &halo_scatter_));
  PetscCall(ISDestroy(&from));
  PetscCall(
      VecScatterBegin(halo_scatter_, rest_positions, x_halo_, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecScatterEnd(halo_scatter_, rest_positions, x_halo_, INSERT_VALUES, SCATTER_FORWARD));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode RowAssembler::CreateMatrix(Mat *matrix, bool plain_products) {
  PetscFunctionBeginUser;
  // Neighbours (halo indices, increasing) of every owned vertex: CSR by vertex.
  std::vector<PetscInt> start(count_ + 1, 0);
  for (const Element &e : elements_)
    for (int a = 0; a < 4; ++a)
      if (e.owned >> a & 1u) start[halo_vertices_[e.vertex[a]] - begin_ + 1] += 4;
  for (PetscInt v = 0; v < count_; ++v) start[v + 1] += start[v];
  std::vector<int32_t> neighbours(start[count_]);
  {
    std::vector<PetscInt> next(start.begin(), start.end() - 1);
    for (const Element &e : elements_)
      for (int a = 0; a < 4; ++a)
        if (e.owned >> a & 1u) {
          PetscInt &n = next[halo_vertices_[e.vertex[a]] - begin_];
          for (int b = 0; b < 4; ++b) neighbours[n++] = e.vertex[b];
        }
  }
  std::vector<PetscInt> degree(count_);
  for (PetscInt v = 0; v < count_; ++v) {
    auto first = neighbours.begin() + start[v], last = neighbours.begin() + start[v + 1];
    std::sort(first, last);
    degree[v] = std::unique(first, last) - first;
  }
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
  {
    std::vector<PetscScalar> zeros(columns.size(), 0.0);
    PetscCall(MatCreate(comm_, matrix));
    PetscCall(MatSetSizes(*matrix, 3 * count_, 3 * count_, PETSC_DETERMINE, PETSC_DETERMINE));
    PetscCall(MatSetBlockSize(*matrix, 3));
    PetscCall(MatSetType(*matrix, MATAIJ));
    PetscCall(
        MatSeqAIJSetPreallocationCSR(*matrix, row_start.data(), columns.data(), zeros.data()));
    PetscCall(
        MatMPIAIJSetPreallocationCSR(*matrix, row_start.data(), columns.data(), zeros.data()));
    if (plain_products) {  // the option takes effect at the next assembly
      PetscCall(MatSetOption(*matrix, MAT_USE_INODES, PETSC_FALSE));
      PetscCall(MatAssemblyBegin(*matrix, MAT_FINAL_ASSEMBLY));
      PetscCall(MatAssemblyEnd(*matrix, MAT_FINAL_ASSEMBLY));
    }
    PetscCall(MatSetOption(*matrix, MAT_NEW_NONZERO_LOCATION_ERR, PETSC_TRUE));
  }
  std::vector<PetscInt>().swap(columns);
  std::vector<int32_t>().swap(neighbours);

  // Offsets of the element blocks in the values of the diagonal and the
  // off-diagonal part (MPIAIJ: columns of the off-diagonal part are positions
  // in garray, the increasing global columns it has).
  PetscMPIInt size;
  PetscCallMPI(MPI_Comm_size(comm_, &size));
  Mat diagonal_part = *matrix, off_part = nullptr;
  const PetscInt *garray = nullptr;
  if (size > 1) PetscCall(MatMPIAIJGetSeqAIJ(*matrix, &diagonal_part, &off_part, &garray));
  PetscInt rows;
  const PetscInt *di, *dj, *oi = nullptr, *oj = nullptr;
  PetscBool done;
  PetscCall(MatGetRowIJ(diagonal_part, 0, PETSC_FALSE, PETSC_FALSE, &rows, &di, &dj, &done));
  PetscCheck(done && rows == 3 * count_, PETSC_COMM_SELF, PETSC_ERR_PLIB,
             "no CSR access to the matrix");
  PetscInt off_columns = 0;
  if (off_part) {
    PetscCall(MatGetRowIJ(off_part, 0, PETSC_FALSE, PETSC_FALSE, &rows, &oi, &oj, &done));
    PetscCheck(done, PETSC_COMM_SELF, PETSC_ERR_PLIB, "no CSR access to the matrix");
    PetscCall(MatGetSize(off_part, nullptr, &off_columns));
  }
  pattern_nonzeros_diagonal_ = di[3 * count_];
  pattern_nonzeros_off_ = oi ? oi[3 * count_] : 0;
  PetscCheck(pattern_nonzeros_diagonal_ < INT32_MAX && pattern_nonzeros_off_ < INT32_MAX,
             PETSC_COMM_SELF, PETSC_ERR_SUP, "more than 2^31 matrix entries on one rank");
  row_length_diagonal_.resize(count_);
  row_length_off_.resize(count_);
  for (PetscInt v = 0; v < count_; ++v) {
    row_length_diagonal_[v] = static_cast<int32_t>(di[3 * v + 1] - di[3 * v]);
    row_length_off_[v] = oi ? static_cast<int32_t>(oi[3 * v + 1] - oi[3 * v]) : 0;
  }
  auto find = [](const PetscInt *j, PetscInt first, PetscInt last, PetscInt column) {
    const PetscInt *p = std::lower_bound(j + first, j + last, column);
    return p < j + last && *p == column ? static_cast<int32_t>(p - j) : -1;
  };
  bool complete = true;
  for (size_t e = 0; e < elements_.size(); ++e) {
    Element &element = elements_[e];
    for (int a = 0; a < 4; ++a)
      for (int b = 0; b < 4; ++b) {
        int32_t &offset = element.offset[4 * a + b];
        offset = -1;
        if (!(element.owned >> a & 1u)) continue;
        const PetscInt row = 3 * (halo_vertices_[element.vertex[a]] - begin_);
        const PetscInt column_vertex = halo_vertices_[element.vertex[b]];
        if (element.owned >> b & 1u) {
          offset = find(dj, di[row], di[row + 1], 3 * (column_vertex - begin_));
        } else {
          const PetscInt *g = std::lower_bound(garray, garray + off_columns, 3 * column_vertex);
          if (g < garray + off_columns && *g == 3 * column_vertex)
            offset = find(oj, oi[row], oi[row + 1], g - garray);
        }
        complete = complete && offset >= 0;
      }
  }
  diagonal_offset_.resize(3 * count_);
  for (PetscInt i = 0; i < 3 * count_; ++i) {
    diagonal_offset_[i] = find(dj, di[i], di[i + 1], i);
    complete = complete && diagonal_offset_[i] >= 0;
  }
  PetscCall(MatRestoreRowIJ(diagonal_part, 0, PETSC_FALSE, PETSC_FALSE, &rows, &di, &dj, &done));
  if (off_part)
    PetscCall(MatRestoreRowIJ(off_part, 0, PETSC_FALSE, PETSC_FALSE, &rows, &oi, &oj, &done));
  PetscCheck(complete, PETSC_COMM_SELF, PETSC_ERR_PLIB,
             "an element block is missing from the pattern");
  PetscFunctionReturn(PETSC_SUCCESS);
}

namespace {

struct FillContext {
  const double *x_halo;
  int32_t first_owned;           // halo index of the first owned vertex (owned: contiguous)
  PetscScalar *values[2];        // [0] off-diagonal part, [1] diagonal part
  const int32_t *row_length[2];  // same order
  double stiffness_scale, shear_scale;
  PetscScalar *force;             // owned rows, may be null
  double *vertex_deformation;     // 9 per owned vertex: sum of V F, may be null
  double *gradients;              // damping: H per element (out), may be null
  const double *gradients_start;  // damping: H per element at the step's start, may be null
  PetscScalar *damping_force;     // owned rows, when gradients_start
  double *damping_energy;         // when gradients_start
};

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
// Adds the three rows of the block wl h_a h_b^T + wsm h_b h_a^T + diagonal I at
// p (rows `stride` apart) as four lanes, the fourth zero and masked off: row i
// is p_a[i] h_b + q_b[i] h_a + diagonal e_i with p = wl h, q = wsm h.
inline void AddBlockRows(const double *p_a, const double *q_b, __m256d h_a, __m256d h_b,
                         __m256d diagonal, PetscScalar *p, int32_t stride) {
  const __m256i mask = _mm256_set_epi64x(0, -1, -1, -1);
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
  _mm256_maskstore_pd(p, mask, _mm256_add_pd(_mm256_maskload_pd(p, mask), r0));
  _mm256_maskstore_pd(p + stride, mask, _mm256_add_pd(_mm256_maskload_pd(p + stride, mask), r1));
  _mm256_maskstore_pd(p + 2 * stride, mask,
                      _mm256_add_pd(_mm256_maskload_pd(p + 2 * stride, mask), r2));
}
#endif

}  // namespace

// The element pass. Plain arrays (and AVX2 rows where available) rather than
// Eigen expressions: this loop is the corotational refill's whole cost (see
// row_assembly.hpp for the formulas).
template <bool kRotated, bool kStandardShear, typename Element, typename Lame_>
static double FillElements(const std::vector<Element> &elements, const std::vector<Lame_> &lame,
                           const FillContext &c) {
  double energy = 0;
  // Rotated: the deformation gradients of four elements at a time, their
  // rotations together (RotationOfDeformation4), then each element.
  Mat3 batch_F[4], batch_R[4];
  for (size_t e = 0; e < elements.size(); ++e) {
    const Element &el = elements[e];
    if constexpr (kRotated) {
      if (e % 4 == 0) {
        const size_t count = std::min<size_t>(4, elements.size() - e);
        for (size_t k = 0; k < count; ++k) {
          const Element &other = elements[e + k];
          const double *x0 = c.x_halo + 3 * other.vertex[0];
          double d[3][3];  // edge vectors x_a - x_0, a = 1..3
          for (int a = 1; a < 4; ++a) {
            const double *xa = c.x_halo + 3 * other.vertex[a];
            for (int i = 0; i < 3; ++i) d[a - 1][i] = xa[i] - x0[i];
          }
          const double *g = other.gradient.data();  // rows grad N_1..3
          for (int i = 0; i < 3; ++i)               // F = sum_a d_a g_a^T
            for (int j = 0; j < 3; ++j)
              batch_F[k](i, j) = d[0][i] * g[j] + d[1][i] * g[3 + j] + d[2][i] * g[6 + j];
        }
        for (size_t k = count; k < 4; ++k) batch_F[k] = Mat3::Identity();
        RotationOfDeformation4(batch_F, batch_R);
      }
    }
    double g[4][3];  // shape gradients
    for (int k = 0; k < 3; ++k) {
      g[1][k] = el.gradient[k];
      g[2][k] = el.gradient[3 + k];
      g[3][k] = el.gradient[6 + k];
      g[0][k] = -(g[1][k] + g[2][k] + g[3][k]);
    }
    const double l = lame[el.material].lambda, m = lame[el.material].mu, sm = c.shear_scale * m;
    int32_t owned_row[4];  // valid for owned vertices
    for (int a = 0; a < 4; ++a) owned_row[a] = el.vertex[a] - c.first_owned;
    double R[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    double h[4][3];  // rotated gradients R g_a
    if constexpr (kRotated) {
      const Mat3 &F = batch_F[e % 4], &rotation = batch_R[e % 4];
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) R[i][j] = rotation(i, j);
      if (c.vertex_deformation) {
        const Eigen::Matrix<double, 3, 3, Eigen::RowMajor> VF = el.volume * F;
        for (int a = 0; a < 4; ++a)
          if (el.owned >> a & 1u) {
            double *sum = c.vertex_deformation + 9 * owned_row[a];
            for (int k = 0; k < 9; ++k) sum[k] += VF.data()[k];
          }
      }
      // Displacement gradient of y_a = R^T x_a - X_a: H = R^T F - sum_a (X_a - X_0) g_a^T.
      double H[3][3];
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
          H[i][j] = R[0][i] * F(0, j) + R[1][i] * F(1, j) + R[2][i] * F(2, j) -
                    el.rest_gradient[3 * i + j];
      double S[3][3];
      Stress(H, l, m, sm, S);
      if (el.owned >> 4 & 1u) energy += StrainEnergy(H, S, el.volume);
      if (c.force) AddStressForces(R, S, el.volume, g, el.owned, owned_row, c.force);
      if (c.gradients) {
        std::copy(&H[0][0], &H[0][0] + 9, c.gradients + 9 * e);
        if (c.gradients_start) {  // the increment since the step's start
          double dH[3][3], dS[3][3];
          for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) dH[i][j] = H[i][j] - c.gradients_start[9 * e + 3 * i + j];
          Stress(dH, l, m, sm, dS);
          if (el.owned >> 4 & 1u) *c.damping_energy += StrainEnergy(dH, dS, el.volume);
          AddStressForces(R, dS, el.volume, g, el.owned, owned_row, c.damping_force);
        }
      }
      for (int a = 0; a < 4; ++a)
        for (int i = 0; i < 3; ++i)
          h[a][i] = R[i][0] * g[a][0] + R[i][1] * g[a][1] + R[i][2] * g[a][2];
    } else {
      for (int a = 0; a < 4; ++a)
        for (int i = 0; i < 3; ++i) h[a][i] = g[a][i];
    }
    // Blocks a <= b: B = wl h_a h_b^T + wsm h_b h_a^T + wsm (h_a . h_b) I [+ R diag(.) R^T].
    const double w = c.stiffness_scale * el.volume, wl = w * l, wsm = w * sm;
    double p[4][3], q[4][3];  // wl h_a, wsm h_a
    for (int a = 0; a < 4; ++a)
      for (int i = 0; i < 3; ++i) {
        p[a][i] = wl * h[a][i];
        q[a][i] = wsm * h[a][i];
      }
    const std::array<int32_t, 16> &offset = el.offset;
#ifdef __AVX2__
    if constexpr (kStandardShear) {
      __m256d hv[4];
      for (int a = 0; a < 4; ++a) hv[a] = _mm256_set_pd(0.0, h[a][2], h[a][1], h[a][0]);
      double diagonal[4][4];
      for (int a = 0; a < 4; ++a)
        for (int b = a; b < 4; ++b)
          diagonal[a][b] = q[a][0] * h[b][0] + q[a][1] * h[b][1] + q[a][2] * h[b][2];
      if ((el.owned & 15u) == 15u) {  // every row owned, every column in the diagonal part
        PetscScalar *values = c.values[1];
        int32_t stride[4];
        for (int a = 0; a < 4; ++a) stride[a] = c.row_length[1][owned_row[a]];
        for (int a = 0; a < 4; ++a) {
          AddBlockRows(p[a], q[a], hv[a], hv[a], _mm256_set1_pd(diagonal[a][a]),
                       values + offset[5 * a], stride[a]);
          for (int b = a + 1; b < 4; ++b) {
            const __m256d dv = _mm256_set1_pd(diagonal[a][b]);
            AddBlockRows(p[a], q[b], hv[a], hv[b], dv, values + offset[4 * a + b], stride[a]);
            AddBlockRows(p[b], q[a], hv[b], hv[a], dv, values + offset[4 * b + a], stride[b]);
          }
        }
        continue;
      }
      for (int a = 0; a < 4; ++a) {
        const bool a_owned = el.owned >> a & 1u;
        for (int b = a; b < 4; ++b) {
          const bool b_owned = el.owned >> b & 1u;
          const __m256d dv = _mm256_set1_pd(diagonal[a][b]);
          if (a_owned)
            AddBlockRows(p[a], q[b], hv[a], hv[b], dv, c.values[b_owned] + offset[4 * a + b],
                         c.row_length[b_owned][owned_row[a]]);
          if (b_owned && b != a)
            AddBlockRows(p[b], q[a], hv[b], hv[a], dv, c.values[a_owned] + offset[4 * b + a],
                         c.row_length[a_owned][owned_row[b]]);
        }
      }
      continue;
    }
#endif
    for (int a = 0; a < 4; ++a) {
      const bool a_owned = el.owned >> a & 1u;
      for (int b = a; b < 4; ++b) {
        const bool b_owned = el.owned >> b & 1u;
        if (!a_owned && !b_owned) continue;
        double B[3][3];
        const double diagonal = q[a][0] * h[b][0] + q[a][1] * h[b][1] + q[a][2] * h[b][2];
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j) B[i][j] = p[a][i] * h[b][j] + q[b][i] * h[a][j];
        for (int i = 0; i < 3; ++i) B[i][i] += diagonal;
        if constexpr (!kStandardShear) {
          double t[3];  // (2m - 2sm) w (g_a o g_b)
          for (int k = 0; k < 3; ++k) t[k] = (2.0 * m - 2.0 * sm) * w * g[a][k] * g[b][k];
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
  return energy;
}

PetscErrorCode RowAssembler::Fill(Mat matrix, bool rotated, Vec x, double stiffness_scale,
                                  Vec lumped_mass, double mass_scale, Vec force, PetscReal *energy,
                                  IncrementDamping *damping) {
  PetscFunctionBeginUser;
  PetscMPIInt size;
  PetscCallMPI(MPI_Comm_size(comm_, &size));
  Mat diagonal_part = matrix, off_part = nullptr;
  if (size > 1) PetscCall(MatMPIAIJGetSeqAIJ(matrix, &diagonal_part, &off_part, nullptr));
  {
    MatInfo info;
    PetscCall(MatGetInfo(diagonal_part, MAT_LOCAL, &info));
    PetscCheck(static_cast<PetscInt>(info.nz_used) == pattern_nonzeros_diagonal_, PETSC_COMM_SELF,
               PETSC_ERR_ARG_WRONG,
               "RowAssembler::Fill: the matrix does not come from CreateMatrix");
  }
  PetscScalar *diagonal_values, *off_values = nullptr;
  PetscCall(MatSeqAIJGetArray(diagonal_part, &diagonal_values));
  if (off_part) PetscCall(MatSeqAIJGetArray(off_part, &off_values));
  if (diagonal_values)
    std::memset(diagonal_values, 0, sizeof(PetscScalar) * pattern_nonzeros_diagonal_);
  if (off_values) std::memset(off_values, 0, sizeof(PetscScalar) * pattern_nonzeros_off_);

  FillContext context;
  context.first_owned = first_owned_halo_;
  context.values[0] = off_values;
  context.values[1] = diagonal_values;
  context.row_length[0] = row_length_off_.data();
  context.row_length[1] = row_length_diagonal_.data();
  context.stiffness_scale = stiffness_scale;
  context.shear_scale = shear_scale_;
  context.force = nullptr;
  context.x_halo = nullptr;
  context.vertex_deformation = nullptr;
  context.gradients = nullptr;
  context.gradients_start = nullptr;
  context.damping_force = nullptr;
  double local_damping_energy = 0;
  context.damping_energy = &local_damping_energy;
  if (rotated && vertex_rotations_requested_) {
    vertex_rotations_.assign(9 * count_, 0.0);
    context.vertex_deformation = vertex_rotations_.data();
  }
  const bool standard_shear = shear_scale_ == 1.0;
  double local_energy = 0;
  if (rotated) {
    PetscCall(VecScatterBegin(halo_scatter_, x, x_halo_, INSERT_VALUES, SCATTER_FORWARD));
    PetscCall(VecScatterEnd(halo_scatter_, x, x_halo_, INSERT_VALUES, SCATTER_FORWARD));
    const PetscScalar *x_halo;
    PetscCall(VecGetArrayRead(x_halo_, &x_halo));
    context.x_halo = x_halo;
    if (force) {
      PetscCall(VecSet(force, 0.0));
      PetscCall(VecGetArray(force, &context.force));
    }
    if (damping) {
      damping->gradients->resize(9 * elements_.size());
      context.gradients = damping->gradients->data();
      if (damping->start) {
        PetscCheck(damping->start->size() == damping->gradients->size(), PETSC_COMM_SELF,
                   PETSC_ERR_ARG_SIZ,
                   "RowAssembler::Fill: the damping's start gradients do not match the elements");
        context.gradients_start = damping->start->data();
        PetscCall(VecSet(damping->force, 0.0));
        PetscCall(VecGetArray(damping->force, &context.damping_force));
      }
    }
    local_energy = standard_shear ? FillElements<true, true>(elements_, lame_, context)
                                  : FillElements<true, false>(elements_, lame_, context);
    if (force) PetscCall(VecRestoreArray(force, &context.force));
    if (context.damping_force) PetscCall(VecRestoreArray(damping->force, &context.damping_force));
    if (context.vertex_deformation)  // four vertices at a time, as the elements' rotations
      for (PetscInt v = 0; v < count_; v += 4) {
        Mat3 F[4], R[4];
        const PetscInt batch = std::min<PetscInt>(4, count_ - v);
        for (PetscInt k = 0; k < 4; ++k)
          F[k] = k < batch ? Mat3(Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(
                                 context.vertex_deformation + 9 * (v + k)))
                           : Mat3::Identity();
        RotationOfDeformation4(F, R);
        for (PetscInt k = 0; k < batch; ++k)
          Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(context.vertex_deformation +
                                                                   9 * (v + k)) = R[k];
      }
    PetscCall(VecRestoreArrayRead(x_halo_, &x_halo));
  } else {
    if (standard_shear)
      FillElements<false, true>(elements_, lame_, context);
    else
      FillElements<false, false>(elements_, lame_, context);
  }
  if (lumped_mass) {
    const PetscScalar *mass;
    PetscCall(VecGetArrayRead(lumped_mass, &mass));
    for (PetscInt i = 0; i < 3 * count_; ++i)
      diagonal_values[diagonal_offset_[i]] += mass_scale * mass[i];
    PetscCall(VecRestoreArrayRead(lumped_mass, &mass));
  }
  PetscCall(MatSeqAIJRestoreArray(diagonal_part, &diagonal_values));
  if (off_part) PetscCall(MatSeqAIJRestoreArray(off_part, &off_values));
  PetscCall(PetscObjectStateIncrease((PetscObject)matrix));
  if (damping && damping->start) {
    const double local[2] = {local_energy, local_damping_energy};
    double global[2];
    PetscCall(MPIU_Allreduce(local, global, 2, MPIU_REAL, MPIU_SUM, comm_));
    if (energy) *energy = global[0];
    damping->energy = global[1];
  } else if (energy) {
    PetscCall(MPIU_Allreduce(&local_energy, energy, 1, MPIU_REAL, MPIU_SUM, comm_));
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
