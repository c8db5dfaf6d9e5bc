// A supernodal Cholesky factor in the layout its two triangular sweeps stream,
// and the solve x = A^-1 b with it, in the precision Real (double, or float:
// half the bytes, for a preconditioner), one rank's factor or a rank's piece
// of the split factor. Not collective.
//
// CHOLMOD's factor L of P A P^T, A = P^T L L^T P (supernode k: columns
// [first, first + columns) of L, `height` rows each, the diagonal block on top,
// then the rows below it listed in `rows`), is copied panel by panel: the
// columns of a supernode in panels of kPanel = 4, each panel stored as
// 4 x 4 tiles (rows i..i+3 of its four columns, one column after another) from
// its diagonal tile down to the supernode's last row, the last tile padded
// with zero rows; the supernode's last columns % 4 columns follow as plain
// columns, each from its diagonal down. So
// - the forward sweep reads the factor as one ascending stream: per tile, four
//   aligned vector loads (four Reals each) and four multiply-adds with the panel's four solved
//   values into four rows of the supernode's gathered right-hand side;
// - the backward sweep reads it as one descending stream (supernodes last to
//   first, panels last to first, tiles bottom to top): per tile, four
//   multiply-adds into the panel's four dot products.
// A supernode's rows are gathered from the permuted vector y into a dense work
// vector before its columns and scattered back after them, the only indirect
// accesses; the vectors (n Reals) stay in cache while the factor streams
// from memory, and while a supernode's rows are gathered its first lines of
// the factor are prefetched, so that memory does not idle between supernodes.
// The forward sweep skips a supernode whose own rows are zero when it comes to
// it (exact: it would add zeros), so a sparse right-hand side streams only the
// supernodes on its rows' paths up the elimination tree. A solve allocates
// nothing.
//
// The sweeps can stop at a column `limit` (the interior of a split factor,
// supernodal.cpp's Split): a supernode that straddles it is stored as two, its
// columns before the limit and those after (with the rows below them).
#pragma once

#include <cholmod.h>

#include <cstddef>
#include <limits>
#include <vector>

#include "common/large_array.hpp"

namespace softbody {

template <typename Real>
class TiledFactor {
 public:
  // Columns per panel, and rows per tile: one vector of four Reals (32 bytes
  // in double, a cache line per tile; 16 and half a line in float).
  static constexpr int kPanel = 4;

  // Copies CHOLMOD's factor L (supernodal, real, double; its values present),
  // with a supernode boundary at column `limit` (none when limit >= n).
  void From(const cholmod_factor *L, int limit = std::numeric_limits<int>::max());
  // From, consuming L's values: the whole pages of L->x are returned to the
  // system behind the copy (release_pages.hpp), so the copy's peak is about one
  // factor, not two. L's values must not be read afterwards: the caller drops
  // them (CHOLMOD_PATTERN).
  void MoveFrom(cholmod_factor *L, int limit = std::numeric_limits<int>::max());
  // x = A^-1 b (b and x of size n, in A's order; they may be the same array;
  // rounded to Real and back).
  void Solve(const double *b, double *x);
  // x_j = A^-1 b_j for the columns j < count of b (column-major, leading
  // dimension ldb) into those of x (ldx), four at a time: the factor streams
  // once per four columns, and each column is Solve's result bit for bit.
  // The first call allocates the four columns' vectors (4 n Reals and a
  // supernode's rows, each rounded up to 2 MB).
  void SolveColumns(int count, const double *b, size_t ldb, double *x, size_t ldx);
  // Restricts SolveColumns to the rows `rows` of x (A's order; empty: every
  // row, the default): its backward sweep then visits only the supernodes on
  // those rows' paths up the elimination tree, which is all their values
  // depend on, and x's other rows are left unspecified. The target rows' values
  // are the unrestricted solve's, bit for bit. Holds until the next call or From.
  void SetSolveTargets(const std::vector<int> &rows);
  // On y() (the permuted vector, size n): y <- L^-1 y over the columns
  // j < limit (their updates reach every row), and y <- L^-T y over the
  // columns j < limit with the others' y taken as known; limit must be n or
  // the limit given to From.
  void Forward(int limit);
  void Backward(int limit);
  Real *y() { return y_.data(); }
  // L's permutation: y[i] is row permutation()[i] of A's vectors.
  const int *permutation() const { return permutation_.data(); }
  // Entries a pair of sweeps streams (with the tiles' zeros): the factor's bytes / sizeof(Real).
  double StoredEntries() const { return static_cast<double>(values_.size()); }
  // CHOLMOD's entries (explicit zeros included, tiles' padding not) of the
  // columns before `limit`, each from its diagonal down.
  double EntriesBefore(int limit) const;
  int size() const { return n_; }

 private:
  // Entries of the panels of a supernode (columns, height), without its plain columns.
  static size_t PanelEntries(int columns, int height);
  static size_t SupernodeEntries(int columns, int height);
  int SupernodeOfColumn(int column) const;  // the stored supernode holding a (permuted) column
  void Copy(const cholmod_factor *L, int limit, bool release);
  void CopySupernode(const double *x, int stride, int k);
  // One supernode's part of a sweep on the permuted vector y, gathering its
  // rows into z; Row: Real, or four Reals in one vector (SolveColumns).
  template <typename Row>
  void ForwardSupernode(int k, Row *y, Row *z);
  template <typename Row>
  void BackwardSupernode(int k, Row *y, Row *z);

  int n_ = 0, supernodes_ = 0;
  // CHOLMOD's Perm, and its super, pi and s with straddling supernodes split at the limit.
  std::vector<int> permutation_, first_column_, row_start_, rows_;
  std::vector<size_t> value_start_;  // per supernode: its first value, a multiple of kPanel
  // Per supernode: the supernode of its first row below its columns (its
  // parent in the elimination tree), -1 for a root.
  std::vector<int> parent_;
  std::vector<char> needed_;  // per supernode (SetSolveTargets): on a target's path; empty: all
  LargeArray<Real> values_;
  std::vector<Real> inverse_diagonal_;  // per column: 1 / L_jj
  std::vector<Real> y_;                 // the permuted right-hand side, then solution
  std::vector<Real> work_;              // a supernode's rows, gathered (largest height + kPanel)
  // The same for four columns (SolveColumns): four Reals per row, row-major,
  // aligned for whole-vector access.
  LargeArray<Real> y4_, work4_;
};

extern template class TiledFactor<double>;
extern template class TiledFactor<float>;

}  // namespace softbody
