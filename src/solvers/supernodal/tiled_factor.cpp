#include "solvers/supernodal/tiled_factor.hpp"

#include <algorithm>
#include <cstddef>
#include <cstring>

#include "common/release_pages.hpp"

namespace softbody {

namespace {

constexpr int kPanel = TiledFactor<double>::kPanel;
static_assert(TiledFactor<float>::kPanel == kPanel);
constexpr int kTile = kPanel * kPanel;  // entries of a tile

// Four Reals in one vector register (GCC/Clang vector extension: AVX for
// double, SSE for float); loaded and stored by memcpy, which compiles to one
// vector move. The helpers are internal and inlined, so GCC's note that such
// arguments change the ABI without AVX does not concern them.
#pragma GCC diagnostic ignored "-Wpsabi"
template <typename Real>
struct Lanes;
template <>
struct Lanes<double> {
  typedef double Vector __attribute__((vector_size(kPanel * sizeof(double))));
};
template <>
struct Lanes<float> {
  typedef float Vector __attribute__((vector_size(kPanel * sizeof(float))));
};
template <typename Real>
using Vector4 = typename Lanes<Real>::Vector;

template <typename Real>
inline Vector4<Real> Load(const Real *p) {
  Vector4<Real> v;
  std::memcpy(&v, p, sizeof(v));
  return v;
}
template <typename Real>
inline void Store(Real *p, const Vector4<Real> &v) {
  std::memcpy(p, &v, sizeof(v));
}
template <typename Real>
inline Vector4<Real> Broadcast(Real a) {
  return Vector4<Real>{a, a, a, a};
}

// Tiles of a panel whose diagonal is `rows_below` rows above the supernode's end.
inline int Tiles(int rows_below) {
  return (rows_below + kPanel - 1) / kPanel;
}

// A cache line's bytes: the unit of the prefetches below.
constexpr std::ptrdiff_t kCacheLine = 64;
// Rows gathered per line of the factor prefetched. A gathered row is an indexed
// load from the vector, in cache, and takes about as long as memory needs for
// half a line at the triad's rate. Measured on the 103 k-tet TetGen rung (one
// rank, interleaved runs): solves about 5 % faster than without prefetching;
// a line per row or per four rows no better than per two.
constexpr int kRowsPerPrefetch = 2;

// z[i] = y[rows[i]] for i < height, prefetching meanwhile the factor's bytes
// [begin, end) that the sweep reads first after the gather: from begin upwards
// (ascending) or from end downwards (descending). Without it memory idles
// while a supernode's rows are gathered, until the tile loop asks for its lines.
template <typename Row>
void GatherAndPrefetch(const Row *y, const int *rows, int height, Row *z, const void *begin,
                       const void *end, bool ascending) {
  const char *first = static_cast<const char *>(begin), *last = static_cast<const char *>(end);
  const std::ptrdiff_t lines = (last - first) / kCacheLine;
  const char *line = ascending ? first : last - kCacheLine;
  const std::ptrdiff_t step = ascending ? kCacheLine : -kCacheLine;
  std::ptrdiff_t fetched = 0;
  for (int i = 0; i < height; ++i) {
    z[i] = y[rows[i]];
    if (i % kRowsPerPrefetch == 0 && fetched < lines) {
      __builtin_prefetch(line + fetched * step, 0, 0);
      ++fetched;
    }
  }
}

// Whether rows [0, count) of y are zero (every lane of a vector row). A
// supernode whose own rows are zero when the forward sweep reaches it solves
// zeros (0 / L_jj) and subtracts zero products from the rows below, which
// leaves them as they are: skipping it is exact. With a sparse right-hand
// side (a vertex's columns J^T, the constraint correction's A^-1 e) only the
// supernodes on the paths from its rows up the elimination tree are nonzero,
// so the forward sweep streams those alone; with a dense one the test stops
// at its first row.
inline bool IsZero(double a) {
  return a == 0.0;
}
inline bool IsZero(float a) {
  return a == 0.0f;
}
template <typename Vector>
bool IsZeroVector(const Vector &v) {
  for (int l = 0; l < kPanel; ++l)
    if (v[l] != 0) return false;
  return true;
}
inline bool IsZero(const Vector4<double> &v) {
  return IsZeroVector(v);
}
inline bool IsZero(const Vector4<float> &v) {
  return IsZeroVector(v);
}
template <typename Row>
bool AllZero(const Row *y, int count) {
  for (int i = 0; i < count; ++i)
    if (!IsZero(y[i])) return false;
  return true;
}

// z[0..3] are the panel's rows on its diagonal tile c (c[q * 4 + r]: row r,
// column q); z[4..) the rows below, `tiles` - 1 more tiles. Solves the panel's
// four values and subtracts their contributions from the rows below.
template <typename Real>
void ForwardPanel(const Real *c, int tiles, const Real *inverse, Real *z) {
  for (int q = 0; q < kPanel; ++q) {
    z[q] *= inverse[q];
    for (int r = q + 1; r < kPanel; ++r) z[r] -= c[q * kPanel + r] * z[q];
  }
  const Vector4<Real> v0 = Broadcast(z[0]), v1 = Broadcast(z[1]), v2 = Broadcast(z[2]),
                      v3 = Broadcast(z[3]);
  for (int t = 1; t < tiles; ++t) {
    const Real *tile = c + t * kTile;
    Real *out = z + t * kPanel;
    Store(out, Load(out) - (Load(tile) * v0 + Load(tile + 4) * v1 + Load(tile + 8) * v2 +
                            Load(tile + 12) * v3));
  }
}

// The same panel backward: the dot products of its columns with the solved
// rows below (tiles bottom to top), then its four values from the triangle.
template <typename Real>
void BackwardPanel(const Real *c, int tiles, const Real *inverse, Real *z) {
  Vector4<Real> s0 = Broadcast(Real(0)), s1 = s0, s2 = s0, s3 = s0;
  for (int t = tiles - 1; t >= 1; --t) {
    const Real *tile = c + t * kTile;
    const Vector4<Real> rows = Load(z + t * kPanel);
    s0 += Load(tile) * rows;
    s1 += Load(tile + 4) * rows;
    s2 += Load(tile + 8) * rows;
    s3 += Load(tile + 12) * rows;
  }
  const Real sums[kPanel] = {s0[0] + s0[1] + s0[2] + s0[3], s1[0] + s1[1] + s1[2] + s1[3],
                             s2[0] + s2[1] + s2[2] + s2[3], s3[0] + s3[1] + s3[2] + s3[3]};
  for (int q = kPanel - 1; q >= 0; --q) {
    Real sum = sums[q];
    for (int r = q + 1; r < kPanel; ++r) sum += c[q * kPanel + r] * z[r];
    z[q] = (z[q] - sum) * inverse[q];
  }
}

// sum_i a[i] b[i] over i < count, in four vector lanes and four independent sums.
template <typename Real>
Real Dot(const Real *a, const Real *b, int count) {
  Vector4<Real> s0 = Broadcast(Real(0)), s1 = s0;
  int i = 0;
  for (; i + 8 <= count; i += 8) {
    s0 += Load(a + i) * Load(b + i);
    s1 += Load(a + i + 4) * Load(b + i + 4);
  }
  if (i + 4 <= count) {
    s0 += Load(a + i) * Load(b + i);
    i += 4;
  }
  s0 += s1;
  Real sum = (s0[0] + s0[1]) + (s0[2] + s0[3]);
  for (; i < count; ++i) sum += a[i] * b[i];
  return sum;
}

// Four right-hand sides at once: row i's four values are one vector, z[i]
// (lane l: right-hand side l), and every operation acts on each lane alone, so
// a column's result does not depend on the others solved with it. The factor
// streams once for four columns. The products are the single-column kernels';
// their sums run in another order (to round-off: a tile's rows are summed in
// two partial sums per column here, in a vector's lanes there).

// ForwardPanel for four columns: z[0..3] the panel's rows, z[4..) the rows below.
template <typename Real>
void ForwardPanel(const Real *c, int tiles, const Real *inverse, Vector4<Real> *z) {
  for (int q = 0; q < kPanel; ++q) {
    z[q] *= Broadcast(inverse[q]);
    for (int r = q + 1; r < kPanel; ++r) z[r] -= Broadcast(c[q * kPanel + r]) * z[q];
  }
  const Vector4<Real> v0 = z[0], v1 = z[1], v2 = z[2], v3 = z[3];  // held in registers
  for (int t = 1; t < tiles; ++t) {
    const Real *tile = c + t * kTile;
    Vector4<Real> *out = z + t * kPanel;
    for (int r = 0; r < kPanel; ++r)
      out[r] -= Broadcast(tile[r]) * v0 + Broadcast(tile[4 + r]) * v1 +
                Broadcast(tile[8 + r]) * v2 + Broadcast(tile[12 + r]) * v3;
  }
}

// BackwardPanel for four columns: per panel column q two partial sums (the tile's
// even and odd rows), for a short chain of dependent additions.
template <typename Real>
void BackwardPanel(const Real *c, int tiles, const Real *inverse, Vector4<Real> *z) {
  Vector4<Real> total[kPanel];
  for (int q = 0; q < kPanel; q += 2) {  // two columns at a time: 4 sums and 4 rows in registers
    Vector4<Real> even0 = Broadcast(Real(0)), odd0 = even0, even1 = even0, odd1 = even0;
    for (int t = tiles - 1; t >= 1; --t) {
      const Real *tile = c + t * kTile;
      const Vector4<Real> *rows = z + t * kPanel;
      even0 += Broadcast(tile[q * kPanel]) * rows[0] + Broadcast(tile[q * kPanel + 2]) * rows[2];
      odd0 += Broadcast(tile[q * kPanel + 1]) * rows[1] + Broadcast(tile[q * kPanel + 3]) * rows[3];
      even1 += Broadcast(tile[(q + 1) * kPanel]) * rows[0] +
               Broadcast(tile[(q + 1) * kPanel + 2]) * rows[2];
      odd1 += Broadcast(tile[(q + 1) * kPanel + 1]) * rows[1] +
              Broadcast(tile[(q + 1) * kPanel + 3]) * rows[3];
    }
    total[q] = even0 + odd0;
    total[q + 1] = even1 + odd1;
  }
  for (int q = kPanel - 1; q >= 0; --q) {
    Vector4<Real> sum = total[q];
    for (int r = q + 1; r < kPanel; ++r) sum += Broadcast(c[q * kPanel + r]) * z[r];
    z[q] = (z[q] - sum) * Broadcast(inverse[q]);
  }
}

// Dot for four columns: sum_i a[i] b[i] with b's rows vectors, in two partial sums.
template <typename Real>
Vector4<Real> Dot(const Real *a, const Vector4<Real> *b, int count) {
  Vector4<Real> even = Broadcast(Real(0)), odd = even;
  int i = 0;
  for (; i + 2 <= count; i += 2) {
    even += Broadcast(a[i]) * b[i];
    odd += Broadcast(a[i + 1]) * b[i + 1];
  }
  if (i < count) even += Broadcast(a[i]) * b[i];
  return even + odd;
}

}  // namespace

template <typename Real>
size_t TiledFactor<Real>::PanelEntries(int columns, int height) {
  size_t entries = 0;
  for (int j = 0; j + kPanel <= columns; j += kPanel)
    entries += static_cast<size_t>(kTile) * Tiles(height - j);
  return entries;
}

template <typename Real>
size_t TiledFactor<Real>::SupernodeEntries(int columns, int height) {
  size_t entries = PanelEntries(columns, height);
  for (int j = columns / kPanel * kPanel; j < columns; ++j) entries += height - j;
  return (entries + kPanel - 1) / kPanel * kPanel;  // the next supernode's panels stay aligned
}

template <typename Real>
void TiledFactor<Real>::From(const cholmod_factor *L, int limit) {
  Copy(L, limit, false);
}

template <typename Real>
void TiledFactor<Real>::MoveFrom(cholmod_factor *L, int limit) {
  Copy(L, limit, true);
}

template <typename Real>
void TiledFactor<Real>::Copy(const cholmod_factor *L, int limit, bool release) {
  n_ = static_cast<int>(L->n);
  const int *perm = static_cast<const int *>(L->Perm), *super = static_cast<const int *>(L->super),
            *pi = static_cast<const int *>(L->pi), *s = static_cast<const int *>(L->s),
            *px = static_cast<const int *>(L->px);
  const double *x = static_cast<const double *>(L->x);
  permutation_.assign(perm, perm + n_);
  first_column_.assign(1, 0);
  row_start_.assign(1, 0);
  rows_.clear();
  // Per stored supernode: its first value in CHOLMOD's x and CHOLMOD's height.
  std::vector<size_t> source;
  std::vector<int> stride;
  for (size_t k = 0; k < L->nsuper; ++k) {
    const int height = pi[k + 1] - pi[k];
    const int cut = super[k] < limit && limit < super[k + 1] ? limit : super[k + 1];
    for (int first = super[k]; first < super[k + 1];) {
      const int last = first < cut ? cut : super[k + 1], skip = first - super[k];
      first_column_.push_back(last);
      rows_.insert(rows_.end(), s + pi[k] + skip, s + pi[k + 1]);
      row_start_.push_back(static_cast<int>(rows_.size()));
      source.push_back(px[k] + static_cast<size_t>(skip) * height + skip);
      stride.push_back(height);
      first = last;
    }
  }
  supernodes_ = static_cast<int>(source.size());
  value_start_.resize(supernodes_ + 1);
  size_t entries = 0;
  int largest = 0;
  for (int k = 0; k < supernodes_; ++k) {
    const int height = row_start_[k + 1] - row_start_[k];
    value_start_[k] = entries;
    entries += SupernodeEntries(first_column_[k + 1] - first_column_[k], height);
    largest = std::max(largest, height);
  }
  value_start_[supernodes_] = entries;
  parent_.assign(supernodes_, -1);
  for (int k = 0; k < supernodes_; ++k) {
    const int columns = first_column_[k + 1] - first_column_[k];
    if (row_start_[k] + columns < row_start_[k + 1])
      parent_[k] = SupernodeOfColumn(rows_[row_start_[k] + columns]);
  }
  needed_.clear();
  values_.resize(entries);
  inverse_diagonal_.resize(n_);
  // The stored supernodes read x in increasing order: below source[k + 1] is done.
  ReleaseBehind behind(x, release);
  for (int k = 0; k < supernodes_; ++k) {
    CopySupernode(x + source[k], stride[k], k);
    if (k + 1 < supernodes_) behind.Consumed(x + source[k + 1]);
  }
  y_.assign(n_, Real(0));
  work_.assign(largest + kPanel, Real(0));
  y4_.resize(0);  // SolveColumns sizes them on its first call
  work4_.resize(0);
}

template <typename Real>
int TiledFactor<Real>::SupernodeOfColumn(int column) const {
  return static_cast<int>(std::upper_bound(first_column_.begin(), first_column_.end(), column) -
                          first_column_.begin()) -
         1;
}

template <typename Real>
void TiledFactor<Real>::SetSolveTargets(const std::vector<int> &rows) {
  needed_.clear();
  if (rows.empty()) return;
  std::vector<int> position(n_);  // A's row -> its place in the permuted order
  for (int i = 0; i < n_; ++i) position[permutation_[i]] = i;
  needed_.assign(supernodes_, 0);
  for (const int row : rows)
    for (int k = SupernodeOfColumn(position[row]); k >= 0 && !needed_[k]; k = parent_[k])
      needed_[k] = 1;
}

template <typename Real>
double TiledFactor<Real>::EntriesBefore(int limit) const {
  double entries = 0;
  for (int k = 0; k < supernodes_ && first_column_[k] < limit; ++k) {
    const int columns = std::min(first_column_[k + 1], limit) - first_column_[k];
    const int height = row_start_[k + 1] - row_start_[k];
    for (int j = 0; j < columns; ++j) entries += height - j;
  }
  return entries;
}

// Stored supernode k's values from CHOLMOD's column-major block: x[j * stride +
// i] is its entry (i, j), row i of its rows, column j of its columns.
template <typename Real>
void TiledFactor<Real>::CopySupernode(const double *x, int stride, int k) {
  const int columns = first_column_[k + 1] - first_column_[k],
            height = row_start_[k + 1] - row_start_[k];
  // The entry (i, j), zero above the diagonal and below the last row.
  auto entry = [&](int i, int j) {
    return i >= j && i < height ? x[static_cast<size_t>(j) * stride + i] : 0.0;
  };
  for (int j = 0; j < columns; ++j)
    inverse_diagonal_[first_column_[k] + j] = static_cast<Real>(1.0 / entry(j, j));
  Real *out = values_.data() + value_start_[k];
  int j = 0;
  for (; j + kPanel <= columns; j += kPanel)
    for (int t = 0; t < Tiles(height - j); ++t)
      for (int q = 0; q < kPanel; ++q)
        for (int r = 0; r < kPanel; ++r)
          *out++ = static_cast<Real>(entry(j + t * kPanel + r, j + q));
  for (; j < columns; ++j)
    for (int i = j; i < height; ++i) *out++ = static_cast<Real>(entry(i, j));
  std::fill(out, values_.data() + value_start_[k + 1], Real(0));
}

// y <- L_k^-1 y over supernode k's columns (y's rows of the supernode updated);
// Row: Real (one column; z the work vector) or a vector of four (SolveColumns).
template <typename Real>
template <typename Row>
void TiledFactor<Real>::ForwardSupernode(int k, Row *y, Row *z) {
  const int first = first_column_[k], columns = first_column_[k + 1] - first,
            height = row_start_[k + 1] - row_start_[k];
  if (AllZero(y + first, columns)) return;  // it would solve zeros and subtract them
  const int *rows = rows_.data() + row_start_[k];
  const Real *c = values_.data() + value_start_[k];
  GatherAndPrefetch(y, rows, height, z, c, values_.data() + value_start_[k + 1], true);
  std::fill(z + height, z + height + kPanel, Row{});  // the last tile's padding rows
  const Real *inverse = inverse_diagonal_.data() + first;
  int j = 0;
  for (; j + kPanel <= columns; j += kPanel) {
    ForwardPanel(c, Tiles(height - j), inverse + j, z + j);
    c += static_cast<size_t>(kTile) * Tiles(height - j);
  }
  for (; j < columns; ++j) {  // plain columns: c[i - j] is row i
    const Row v = z[j] * inverse[j];
    z[j] = v;
    for (int i = j + 1; i < height; ++i) z[i] -= c[i - j] * v;
    c += height - j;
  }
  for (int i = 0; i < height; ++i) y[rows[i]] = z[i];
}

// y <- L_k^-T y over supernode k's columns (the rows below them solved already).
template <typename Real>
template <typename Row>
void TiledFactor<Real>::BackwardSupernode(int k, Row *y, Row *z) {
  const int first = first_column_[k], columns = first_column_[k + 1] - first,
            height = row_start_[k + 1] - row_start_[k];
  const int *rows = rows_.data() + row_start_[k];
  GatherAndPrefetch(y, rows, height, z, values_.data() + value_start_[k],
                    values_.data() + value_start_[k + 1], false);
  std::fill(z + height, z + height + kPanel, Row{});
  const Real *inverse = inverse_diagonal_.data() + first;
  const int panels = columns / kPanel;
  const Real *panels_end = values_.data() + value_start_[k] + PanelEntries(columns, height);
  const Real *c = panels_end;
  for (int j = panels * kPanel; j < columns; ++j) c += height - j;
  for (int j = columns - 1; j >= panels * kPanel; --j) {  // plain columns, last first
    c -= height - j;
    z[j] = (z[j] - Dot(c + 1, z + j + 1, height - j - 1)) * inverse[j];
  }
  c = panels_end;
  for (int j = (panels - 1) * kPanel; j >= 0; j -= kPanel) {
    c -= static_cast<size_t>(kTile) * Tiles(height - j);
    BackwardPanel(c, Tiles(height - j), inverse + j, z + j);
  }
  for (int i = 0; i < columns; ++i) y[first + i] = z[i];
}

template <typename Real>
void TiledFactor<Real>::SolveColumns(int count, const double *b, size_t ldb, double *x,
                                     size_t ldx) {
  if (y4_.size() == 0) {
    y4_.resize(static_cast<size_t>(kPanel) * n_);
    work4_.resize(static_cast<size_t>(kPanel) * work_.size());
  }
  for (int first = 0; first < count; first += kPanel) {
    const int lanes = std::min(kPanel, count - first);
    for (int i = 0; i < n_; ++i)
      for (int l = 0; l < kPanel; ++l)
        y4_[kPanel * i + l] =
            l < lanes ? static_cast<Real>(b[(first + l) * ldb + permutation_[i]]) : Real(0);
    Vector4<Real> *y = reinterpret_cast<Vector4<Real> *>(y4_.data());
    Vector4<Real> *z = reinterpret_cast<Vector4<Real> *>(work4_.data());
    for (int k = 0; k < supernodes_; ++k) ForwardSupernode(k, y, z);
    for (int k = supernodes_ - 1; k >= 0; --k)
      if (needed_.empty() || needed_[k]) BackwardSupernode(k, y, z);
    for (int i = 0; i < n_; ++i)
      for (int l = 0; l < lanes; ++l) x[(first + l) * ldx + permutation_[i]] = y4_[kPanel * i + l];
  }
}

template <typename Real>
void TiledFactor<Real>::Forward(int limit) {
  for (int k = 0; k < supernodes_ && first_column_[k] < limit; ++k)
    ForwardSupernode(k, y_.data(), work_.data());
}

template <typename Real>
void TiledFactor<Real>::Backward(int limit) {
  for (int k = supernodes_ - 1; k >= 0; --k)
    if (first_column_[k] < limit) BackwardSupernode(k, y_.data(), work_.data());
}

template <typename Real>
void TiledFactor<Real>::Solve(const double *b, double *x) {
  for (int i = 0; i < n_; ++i) y_[i] = static_cast<Real>(b[permutation_[i]]);
  Forward(n_);
  Backward(n_);
  for (int i = 0; i < n_; ++i) x[permutation_[i]] = y_[i];
}

template class TiledFactor<double>;
template class TiledFactor<float>;

}  // namespace softbody
