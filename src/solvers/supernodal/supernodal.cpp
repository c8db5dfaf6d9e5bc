#include "solvers/supernodal/supernodal.hpp"

// A new PC type is added as PETSc documents it (PCRegister with a creation
// routine that fills the PC's operations), which needs the PC's private header.
#include <petsc/private/pcimpl.h>

#include <cholmod.h>

#include <unistd.h>

#include <algorithm>
#include <cstring>
#include <limits>
#include <vector>

#include "common/exchange.hpp"
#include "common/large_array.hpp"
#include "common/release_pages.hpp"
#include "solvers/supernodal/tiled_factor.hpp"

// LAPACK / BLAS (Fortran interface): the separator's dense Schur complement.
extern "C" {
void dpotrf_(const char *uplo, const int *n, double *a, const int *lda, int *info);
void dsyrk_(const char *uplo, const char *trans, const int *n, const int *k, const double *alpha,
            const double *a, const int *lda, const double *beta, double *c, const int *ldc);
}

namespace softbody {

namespace {

static_assert(sizeof(PetscInt) == sizeof(int), "CHOLMOD is called with 32-bit indices");

const char *const kOrderings[] = {"best", "amd", "metis", "SupernodalOrdering", "", nullptr};
enum SupernodalOrdering { kOrderingBest, kOrderingAmd, kOrderingMetis };
const char *const kPrecisions[] = {"double", "single", "SupernodalPrecision", "", nullptr};
enum SupernodalPrecision { kDouble, kSingle };

// Entries of the separator's Schur complement summed to rank 0 by one MPI
// reduction: below INT_MAX (MPI's counts), and small enough that the buffer MPI
// may allocate for a reduction (128 MB) stays a fraction of the blocks themselves.
constexpr size_t kReduceChunk = size_t{1} << 24;
// CHOLMOD factorises in double precision, whatever the solves use.
constexpr double kCholmodBytesPerEntry = sizeof(double);
// The copy for the solves releases CHOLMOD's values behind it (MoveFrom), so the
// values peak at the larger of the two, over CHOLMOD's entries: the tiles' zero
// padding in double (3.9 % on the 104k-tet TetGen mesh, docs/performance.md)
// and one release batch above one factor.
constexpr double kCopyPeakOverFactor = 1.05;
// The default memory budget of the factor: three quarters of a rank's share of
// its node's physical memory. The factor dominates a direct run (5.8 KB per tet
// at 1e6 tets against about 1.1 KB for everything else, docs/performance.md);
// the rest is left to that state, MPI and the system.
constexpr double kBudgetShareOfMemory = 0.75;
constexpr double kBytesPerMB = 1024.0 * 1024.0;

// A dense Cholesky factor (lower, column-major) and its two sweeps.
template <typename Real>
struct DenseFactor {
  int n = 0;
  LargeArray<Real> values;

  void From(const std::vector<double> &lower, int size) {
    n = size;
    values.resize(static_cast<size_t>(n) * n);
    for (size_t i = 0; i < values.size(); ++i) values[i] = static_cast<Real>(lower[i]);
  }
  void Solve(Real *y) const {
    for (int j = 0; j < n; ++j) {
      const Real *column = values.data() + static_cast<size_t>(j) * n;
      const Real v = y[j] / column[j];
      y[j] = v;
#pragma omp simd
      for (int i = j + 1; i < n; ++i) y[i] -= column[i] * v;
    }
    for (int j = n - 1; j >= 0; --j) {
      const Real *column = values.data() + static_cast<size_t>(j) * n;
      Real sum = 0;
#pragma omp simd reduction(+ : sum)
      for (int i = j + 1; i < n; ++i) sum += column[i] * y[i];
      y[j] = (y[j] - sum) / column[j];
    }
  }
};

// More than one rank: the factor split at a separator. S = the owned DOFs that
// couple to a DOF of a higher rank; every rank's other DOFs (its interior I_r)
// then couple only to its own and to S. Rank r factors its piece
// M_r = A[I_r + S, I_r + S] with S ordered last (METIS/AMD order inside I_r); the
// trailing block of that factor gives C_r = A_SS - A_S,I_r A_I_r^-1 A_I_r,S, and
// rank 0 factors the separator's dense Schur complement
//     S = A_SS - sum_r A_S,I_r A_I_r^-1 A_I_r,S = sum_r C_r - (ranks - 1) A_SS.
// A solve: every rank sweeps forward over its interior (streaming its own part
// of the factor, all ranks at once), the separator's right-hand side
// b_S - sum_r L_S,I_r L_I_r^-1 b_I_r is summed on rank 0, solved with the dense
// factor and broadcast, and every rank sweeps backward over its interior.
struct Split {
  PetscInt interior = 0, separator = 0;
  std::vector<PetscInt> separator_dofs;   // global DOFs of S, increasing (the same on every rank)
  std::vector<PetscInt> local_dofs;       // global DOFs of M_r, increasing
  std::vector<PetscInt> owned_position;   // per local index: position among the owned DOFs, or -1
  std::vector<PetscInt> separator_local;  // per separator index k: local index in M_r
  Mat *local = nullptr;                   // M_r
  cholmod_factor *factor = nullptr;       // symbolic (values dropped after the copy)
  TiledFactor<float> single;              // split at the interior's end
  TiledFactor<double> full;               // the same in double
  DenseFactor<float> dense_single;        // rank 0
  DenseFactor<double> dense_full;
  std::vector<double> separator_values;  // n_S: right-hand side, then solution
  std::vector<double> local_b;           // per local index
};

struct Supernodal {
  cholmod_common common;
  bool started = false;
  cholmod_factor *factor = nullptr;     // one rank
  PetscObjectState pattern_state = -1;  // nonzero state of the factorised pattern
  SupernodalOrdering ordering = kOrderingBest;
  SupernodalPrecision precision = kDouble;
  SupernodalLimits limits;
  TiledFactor<float> single;  // one rank, single precision
  TiledFactor<double> full;   // one rank, double precision
  Split split;                // more than one rank
  double stored = 0, nonzeros = 0, flops = 0;
  std::vector<int> targets;  // PCSupernodalSetSolveTargets (one rank); empty: every row
  // The last set-up met a matrix that is not (numerically) positive definite:
  // decided on all ranks together; the PC then reports PC_FACTOR_NUMERIC_ZEROPIVOT
  // and its applications return NaN, so the KSP stops with DIVERGED_PC_FAILED
  // on every rank (no rank left waiting).
  bool failed = false;
};

PetscErrorCode ReleaseFactor(Supernodal *s) {
  PetscFunctionBeginUser;
  if (s->started) {
    cholmod_free_factor(&s->factor, &s->common);
    cholmod_free_factor(&s->split.factor, &s->common);
    cholmod_finish(&s->common);
    s->started = false;
  }
  if (s->split.local) PetscCall(MatDestroySubMatrices(1, &s->split.local));
  s->pattern_state = -1;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode PCReset_Supernodal(PC pc) {
  PetscFunctionBeginUser;
  PetscCall(ReleaseFactor(static_cast<Supernodal *>(pc->data)));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode PCDestroy_Supernodal(PC pc) {
  PetscFunctionBeginUser;
  PetscCall(PCReset_Supernodal(pc));
  delete static_cast<Supernodal *>(pc->data);
  pc->data = nullptr;
  PetscFunctionReturn(PETSC_SUCCESS);
}

// The default budget per rank: kBudgetShareOfMemory of the node's physical
// memory divided by the ranks on the node.
PetscErrorCode DefaultBudget(MPI_Comm comm, SupernodalLimits *limits) {
  PetscFunctionBeginUser;
  MPI_Comm node;
  PetscMPIInt ranks_on_node;
  PetscCallMPI(MPI_Comm_split_type(comm, MPI_COMM_TYPE_SHARED, 0, MPI_INFO_NULL, &node));
  PetscCallMPI(MPI_Comm_size(node, &ranks_on_node));
  PetscCallMPI(MPI_Comm_free(&node));
  const double physical =
      static_cast<double>(sysconf(_SC_PHYS_PAGES)) * static_cast<double>(sysconf(_SC_PAGESIZE));
  double budget = kBudgetShareOfMemory * physical / ranks_on_node / kBytesPerMB;
  // Ranks may see different nodes: all take the smallest, so they decide alike.
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &budget, 1, MPI_DOUBLE, MPI_MIN, comm));
  limits->budget_mb = budget;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode PCSetFromOptions_Supernodal(PC pc, PetscOptionItems *PetscOptionsObject) {
  PetscFunctionBeginUser;
  Supernodal *s = static_cast<Supernodal *>(pc->data);
  PetscOptionsHeadBegin(PetscOptionsObject, "Supernodal Cholesky (CHOLMOD) options");
  PetscCall(PetscOptionsEnum(
      "-pc_supernodal_ordering",
      "Fill-reducing ordering: best (CHOLMOD tries AMD, then METIS if AMD fills "
      "much, and keeps the better), amd or metis",
      nullptr, kOrderings, (PetscEnum)s->ordering, (PetscEnum *)&s->ordering, nullptr));
  PetscCall(PetscOptionsEnum(
      "-pc_supernodal_precision",
      "Precision of the factor in the solves: double, or single (half the memory traffic, "
      "about 1e-7 relative accuracy: for use as a preconditioner)",
      nullptr, kPrecisions, (PetscEnum)s->precision, (PetscEnum *)&s->precision, nullptr));
  if (s->limits.budget_mb <= 0)
    PetscCall(DefaultBudget(PetscObjectComm((PetscObject)pc), &s->limits));
  PetscCall(PetscOptionsReal(
      "-pc_supernodal_budget_mb",
      "Largest predicted memory per rank of the factor (MB): the factor in double (its copy "
      "for the solves replaces it) and, on several ranks, the separator's dense blocks; a default "
      "solver "
      "whose factor would need more switches to CG + GAMG (default: three quarters of the "
      "node's physical memory over the ranks on the node)",
      nullptr, s->limits.budget_mb, &s->limits.budget_mb, nullptr));
  PetscCall(PetscOptionsInt(
      "-pc_supernodal_max_separator",
      "Largest separator (DOFs) of the split factor on several ranks: rank 0 factorises it "
      "densely alone (n^3/3 flops) and solves with it at every application; above it the "
      "default solver switches to CG + GAMG",
      nullptr, s->limits.max_separator, &s->limits.max_separator, nullptr));
  PetscCheck(s->limits.budget_mb > 0 && s->limits.max_separator >= 0,
             PetscObjectComm((PetscObject)pc), PETSC_ERR_USER_INPUT,
             "option -pc_supernodal_budget_mb must be > 0 and -pc_supernodal_max_separator >= 0 "
             "(got %g and %" PetscInt_FMT ")",
             s->limits.budget_mb, s->limits.max_separator);
  PetscOptionsHeadEnd();
  PetscFunctionReturn(PETSC_SUCCESS);
}

// The upper triangle of a symmetric SeqAIJ matrix by rows is the lower triangle
// by columns: CHOLMOD reads the CSR arrays in place as a lower-stored CSC matrix.
cholmod_sparse LowerView(PetscInt n, const PetscInt *row_start, const PetscInt *columns,
                         const PetscScalar *values) {
  cholmod_sparse view;
  std::memset(&view, 0, sizeof(view));
  view.nrow = view.ncol = n;
  view.nzmax = row_start[n];
  view.p = const_cast<PetscInt *>(row_start);
  view.i = const_cast<PetscInt *>(columns);
  view.x = const_cast<PetscScalar *>(values);
  view.stype = -1;
  view.itype = CHOLMOD_INT;
  view.xtype = CHOLMOD_REAL;
  view.dtype = CHOLMOD_DOUBLE;
  view.sorted = 1;
  view.packed = 1;
  return view;
}

void StartCholmod(Supernodal *s) {
  if (s->started) return;
  cholmod_start(&s->common);
  s->common.supernodal = CHOLMOD_SUPERNODAL;
  s->common.print = 0;
  s->common.error_handler = nullptr;
  if (s->ordering == kOrderingAmd || s->ordering == kOrderingMetis) {
    s->common.nmethods = 1;
    s->common.method[0].ordering = s->ordering == kOrderingAmd ? CHOLMOD_AMD : CHOLMOD_METIS;
    s->common.postorder = 1;
  }
  s->started = true;
}

// The symbolic factor of the matrix `view`: in exactly the order user_order
// when given (one method, no postorder), else by CHOLMOD's own choice.
PetscErrorCode Analyse(Supernodal *s, cholmod_sparse *view, const std::vector<int> *user_order,
                       cholmod_factor **factor) {
  PetscFunctionBeginUser;
  PetscCall(PetscInfo(nullptr, "supernodal: analysing %d DOFs\n", static_cast<int>(view->nrow)));
  if (user_order) {
    const int methods = s->common.nmethods, postorder = s->common.postorder,
              ordering = s->common.method[0].ordering;
    s->common.nmethods = 1;
    s->common.method[0].ordering = CHOLMOD_GIVEN;
    s->common.postorder = 0;
    *factor =
        cholmod_analyze_p(view, const_cast<int *>(user_order->data()), nullptr, 0, &s->common);
    s->common.nmethods = methods;
    s->common.postorder = postorder;
    s->common.method[0].ordering = ordering;
  } else {
    *factor = cholmod_analyze(view, &s->common);
  }
  PetscCheck(*factor, PETSC_COMM_SELF, PETSC_ERR_LIB,
             "supernodal: CHOLMOD analysis failed (status %d)", s->common.status);
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Calls use(view) with a CHOLMOD view of the lower triangle of the SeqAIJ matrix A
// (no copy: valid during the call only).
template <typename Use>
PetscErrorCode WithLowerView(Mat A, Use use) {
  PetscFunctionBeginUser;
  PetscInt n;
  const PetscInt *row_start, *columns;
  PetscBool done;
  PetscCall(MatGetRowIJ(A, 0, PETSC_FALSE, PETSC_FALSE, &n, &row_start, &columns, &done));
  PetscCheck(done, PETSC_COMM_SELF, PETSC_ERR_SUP, "supernodal: no CSR access to the matrix");
  const PetscScalar *values;
  PetscCall(MatSeqAIJGetArrayRead(A, &values));
  cholmod_sparse view = LowerView(n, row_start, columns, values);
  PetscCall(use(&view));
  PetscCall(MatSeqAIJRestoreArrayRead(A, &values));
  PetscCall(MatRestoreRowIJ(A, 0, PETSC_FALSE, PETSC_FALSE, &n, &row_start, &columns, &done));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Analyses (when `*factor` is null: with `user_order`, given in full, if not
// null) and factorises the SeqAIJ matrix A into *factor; a matrix that is not
// positive definite sets s->failed.
PetscErrorCode Factorise(Supernodal *s, Mat A, const std::vector<int> *user_order,
                         cholmod_factor **factor) {
  PetscFunctionBeginUser;
  StartCholmod(s);
  int ok = 0;
  PetscCall(WithLowerView(A, [&](cholmod_sparse *view) -> PetscErrorCode {
    if (!*factor) PetscCall(Analyse(s, view, user_order, factor));
    PetscCall(PetscInfo(nullptr, "supernodal: factorising %d DOFs (%.4g entries)\n",
                        static_cast<int>(view->nrow), static_cast<double>((*factor)->xsize)));
    ok = cholmod_factorize(view, *factor, &s->common);
    return PETSC_SUCCESS;
  }));
  PetscCheck(ok && (s->common.status == CHOLMOD_OK || s->common.status == CHOLMOD_NOT_POSDEF),
             PETSC_COMM_SELF, PETSC_ERR_LIB, "supernodal: CHOLMOD factorisation failed (status %d)",
             s->common.status);
  if (s->common.status == CHOLMOD_NOT_POSDEF) {
    PetscCall(PetscInfo(nullptr, "supernodal: the matrix is not positive definite (column %d)\n",
                        (int)(*factor)->minor));
    s->failed = true;
    PetscFunctionReturn(PETSC_SUCCESS);
  }
  PetscCheck((*factor)->is_super && (*factor)->xtype == CHOLMOD_REAL, PETSC_COMM_SELF,
             PETSC_ERR_LIB, "supernodal: CHOLMOD did not return a real supernodal factor");
  PetscFunctionReturn(PETSC_SUCCESS);
}

// The symbolic factor of the SeqAIJ matrix A's pattern into *factor (in
// exactly user_order when not null, else CHOLMOD's choice).
PetscErrorCode AnalysePattern(Supernodal *s, Mat A, const std::vector<int> *user_order,
                              cholmod_factor **factor) {
  PetscFunctionBeginUser;
  StartCholmod(s);
  PetscCall(WithLowerView(A, [&](cholmod_sparse *view) -> PetscErrorCode {
    return Analyse(s, view, user_order, factor);
  }));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Keeps the symbolic factor (for refactorisations), frees CHOLMOD's values.
PetscErrorCode DropValues(Supernodal *s, cholmod_factor *factor) {
  PetscFunctionBeginUser;
  PetscCheck(cholmod_change_factor(CHOLMOD_PATTERN, 0, 1, 1, 1, factor, &s->common),
             PETSC_COMM_SELF, PETSC_ERR_LIB,
             "supernodal: CHOLMOD could not drop the factor's values");
  PetscFunctionReturn(PETSC_SUCCESS);
}

// One rank: the whole matrix.
PetscErrorCode SetUpOneRank(Supernodal *s, Mat A, bool new_pattern) {
  PetscFunctionBeginUser;
  if (new_pattern) cholmod_free_factor(&s->factor, &s->common);
  PetscCall(Factorise(s, A, nullptr, &s->factor));
  if (s->failed) PetscFunctionReturn(PETSC_SUCCESS);
  s->stored = static_cast<double>(s->factor->xsize);
  s->nonzeros = s->common.lnz;
  s->flops = s->common.fl;
  if (s->precision == kSingle)
    s->single.MoveFrom(s->factor);
  else
    s->full.MoveFrom(s->factor);
  PetscCall(DropValues(s, s->factor));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// This rank's separator DOFs (global, increasing): its owned DOFs coupled to a
// higher rank's DOF, i.e. to a column of the off-diagonal part beyond its rows.
PetscErrorCode OwnedSeparatorDofs(Mat A, PetscInt begin, PetscInt end,
                                  std::vector<PetscInt> *mine) {
  PetscFunctionBeginUser;
  Mat diagonal_part, off_part;
  const PetscInt *garray;
  PetscCall(MatMPIAIJGetSeqAIJ(A, &diagonal_part, &off_part, &garray));
  PetscInt rows;
  const PetscInt *oi, *oj;
  PetscBool done;
  PetscCall(MatGetRowIJ(off_part, 0, PETSC_FALSE, PETSC_FALSE, &rows, &oi, &oj, &done));
  PetscCheck(done, PETSC_COMM_SELF, PETSC_ERR_SUP, "supernodal: no CSR access to the matrix");
  mine->clear();
  for (PetscInt i = 0; i < end - begin; ++i)
    for (PetscInt k = oi[i]; k < oi[i + 1]; ++k)
      if (garray[oj[k]] >= end) {
        mine->push_back(begin + i);
        break;
      }
  PetscCall(MatRestoreRowIJ(off_part, 0, PETSC_FALSE, PETSC_FALSE, &rows, &oi, &oj, &done));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// The whole separator on every rank: the ranks' separator DOFs in rank order.
PetscErrorCode GatherSeparator(MPI_Comm comm, const std::vector<PetscInt> &mine, Split *p) {
  PetscFunctionBeginUser;
  PetscCall(AllGatherRecords(comm, mine, &p->separator_dofs));
  p->separator = static_cast<PetscInt>(p->separator_dofs.size());
  PetscFunctionReturn(PETSC_SUCCESS);
}

// M_r's DOFs (the owned interior and the whole separator, increasing), their
// owned positions and the separator's local indices; returns the interior's
// local indices.
std::vector<int> IndexLocalPiece(PetscInt begin, PetscInt end, const std::vector<PetscInt> &mine,
                                 Split *p) {
  p->local_dofs.clear();
  for (PetscInt g = begin; g < end; ++g)
    if (!std::binary_search(mine.begin(), mine.end(), g)) p->local_dofs.push_back(g);
  p->interior = static_cast<PetscInt>(p->local_dofs.size());
  p->local_dofs.insert(p->local_dofs.end(), p->separator_dofs.begin(), p->separator_dofs.end());
  std::sort(p->local_dofs.begin(), p->local_dofs.end());
  const PetscInt n = static_cast<PetscInt>(p->local_dofs.size());
  p->owned_position.assign(n, -1);
  p->separator_local.resize(p->separator);
  std::vector<int> interior_local;
  for (PetscInt l = 0; l < n; ++l) {
    const PetscInt g = p->local_dofs[l];
    if (g >= begin && g < end) p->owned_position[l] = g - begin;
    const auto k = std::lower_bound(p->separator_dofs.begin(), p->separator_dofs.end(), g);
    if (k != p->separator_dofs.end() && *k == g)
      p->separator_local[k - p->separator_dofs.begin()] = l;
    else
      interior_local.push_back(static_cast<int>(l));
  }
  return interior_local;
}

// M_r = A[local_dofs, local_dofs] (created, or refilled with `reuse`).
PetscErrorCode ExtractLocalPiece(Mat A, MatReuse reuse, Split *p) {
  PetscFunctionBeginUser;
  IS local;
  PetscCall(ISCreateGeneral(PETSC_COMM_SELF, static_cast<PetscInt>(p->local_dofs.size()),
                            p->local_dofs.data(), PETSC_USE_POINTER, &local));
  if (reuse == MAT_INITIAL_MATRIX && p->local) PetscCall(MatDestroySubMatrices(1, &p->local));
  PetscCall(MatCreateSubMatrices(A, 1, &local, &local, reuse, &p->local));
  PetscCall(ISDestroy(&local));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// CHOLMOD's fill-reducing order of A[I_r, I_r] (the interior of M_r), as
// local indices of M_r.
PetscErrorCode InteriorOrder(Supernodal *s, const std::vector<int> &interior_local,
                             std::vector<int> *order) {
  PetscFunctionBeginUser;
  Split &p = s->split;
  IS interior;
  Mat interior_matrix;
  PetscCall(ISCreateGeneral(PETSC_COMM_SELF, p.interior, interior_local.data(), PETSC_USE_POINTER,
                            &interior));
  PetscCall(
      MatCreateSubMatrix(p.local[0], interior, interior, MAT_INITIAL_MATRIX, &interior_matrix));
  PetscCall(ISDestroy(&interior));
  StartCholmod(s);
  PetscInt m;
  const PetscInt *row_start, *columns;
  PetscBool done;
  PetscCall(
      MatGetRowIJ(interior_matrix, 0, PETSC_FALSE, PETSC_FALSE, &m, &row_start, &columns, &done));
  const PetscScalar *values;
  PetscCall(MatSeqAIJGetArrayRead(interior_matrix, &values));
  cholmod_sparse view = LowerView(m, row_start, columns, values);
  cholmod_factor *symbolic = cholmod_analyze(&view, &s->common);
  PetscCall(MatSeqAIJRestoreArrayRead(interior_matrix, &values));
  PetscCall(MatRestoreRowIJ(interior_matrix, 0, PETSC_FALSE, PETSC_FALSE, &m, &row_start, &columns,
                            &done));
  PetscCheck(symbolic, PETSC_COMM_SELF, PETSC_ERR_LIB,
             "supernodal: CHOLMOD analysis failed (status %d)", s->common.status);
  const int *perm = static_cast<const int *>(symbolic->Perm);
  for (PetscInt i = 0; i < p.interior; ++i) order->push_back(interior_local[perm[i]]);
  cholmod_free_factor(&symbolic, &s->common);
  PetscCall(MatDestroy(&interior_matrix));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// The separator, the local piece M_r and its order (Split's comment), and the
// symbolic factor of M_r in that order (no values yet).
PetscErrorCode SplitStructure(Supernodal *s, Mat A) {
  PetscFunctionBeginUser;
  Split &p = s->split;
  MPI_Comm comm = PetscObjectComm((PetscObject)A);
  PetscMPIInt rank;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  const PetscInt *ranges;
  PetscCall(MatGetOwnershipRanges(A, &ranges));
  std::vector<PetscInt> mine;
  PetscCall(OwnedSeparatorDofs(A, ranges[rank], ranges[rank + 1], &mine));
  PetscCall(GatherSeparator(comm, mine, &p));
  const std::vector<int> interior_local = IndexLocalPiece(ranges[rank], ranges[rank + 1], mine, &p);
  PetscCall(ExtractLocalPiece(A, MAT_INITIAL_MATRIX, &p));
  // Order: the interior by CHOLMOD's fill-reducing ordering of A[I_r, I_r],
  // then the separator.
  std::vector<int> order;
  if (p.interior > 0) PetscCall(InteriorOrder(s, interior_local, &order));
  for (PetscInt k = 0; k < p.separator; ++k)
    order.push_back(static_cast<int>(p.separator_local[k]));
  cholmod_free_factor(&p.factor, &s->common);
  const PetscInt n = static_cast<PetscInt>(p.local_dofs.size());
  if (n > 0) {
    PetscCall(AnalysePattern(s, p.local[0], &order, &p.factor));
    PetscCheck(std::equal(order.begin(), order.end(), static_cast<const int *>(p.factor->Perm)),
               PETSC_COMM_SELF, PETSC_ERR_LIB, "supernodal: CHOLMOD changed the given order");
  }
  p.local_b.assign(n, 0.0);
  p.separator_values.assign(p.separator, 0.0);
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Every rank takes `failed` from `root` (root < 0: true when any rank's is).
PetscErrorCode AgreeOnFailure(MPI_Comm comm, int root, bool *failed) {
  PetscFunctionBeginUser;
  int value = *failed;
  if (root < 0)
    PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &value, 1, MPI_INT, MPI_LOR, comm));
  else
    PetscCallMPI(MPI_Bcast(&value, 1, MPI_INT, root, comm));
  *failed = value;
  PetscFunctionReturn(PETSC_SUCCESS);
}

// The trailing block L_SS of the factor L of M_r (the separator's columns,
// last), dense lower column-major, separator x separator.
std::vector<double> TrailingBlock(const cholmod_factor *L, int interior, int separator) {
  const int *super = static_cast<const int *>(L->super), *pi = static_cast<const int *>(L->pi),
            *px = static_cast<const int *>(L->px), *srow = static_cast<const int *>(L->s);
  const double *x = static_cast<const double *>(L->x);
  std::vector<double> trailing(static_cast<size_t>(separator) * separator, 0.0);
  for (size_t k = 0; k < L->nsuper; ++k) {
    const int first = super[k], last = super[k + 1], height = pi[k + 1] - pi[k];
    for (int j = std::max(first, interior); j < last; ++j)
      for (int q = j - first; q < height; ++q) {
        const int row = srow[pi[k] + q];
        trailing[static_cast<size_t>(j - interior) * separator + (row - interior)] =
            x[px[k] + static_cast<size_t>(j - first) * height + q];
      }
  }
  return trailing;
}

// This rank's part after a factorisation of M_r: the tiled copy of its factor
// (whose values CHOLMOD then drops), C_r = L_SS L_SS^T into schur (lower), and
// the entries and flops it contributes.
PetscErrorCode KeepLocalFactor(Supernodal *s, std::vector<double> *schur, double *entries,
                               double *flops) {
  PetscFunctionBeginUser;
  Split &p = s->split;
  const int interior = static_cast<int>(p.interior), separator = static_cast<int>(p.separator);
  const std::vector<double> trailing = TrailingBlock(p.factor, interior, separator);
  if (s->precision == kSingle) {
    p.single.MoveFrom(p.factor, interior);
    *entries = p.single.EntriesBefore(interior);
  } else {
    p.full.MoveFrom(p.factor, interior);
    *entries = p.full.EntriesBefore(interior);
  }
  *flops = s->common.fl;
  PetscCall(DropValues(s, p.factor));
  if (separator > 0) {
    const double one = 1.0, zero = 0.0;
    dsyrk_("L", "N", &separator, &separator, &one, trailing.data(), &separator, &zero,
           schur->data(), &separator);
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Rank 0: schur (the sum of the C_r) -= (ranks - 1) A_SS, giving the separator's
// Schur complement S, factorised in place by LAPACK (lower); sets s->failed when
// S is not positive definite.
PetscErrorCode FactoriseSeparator(Supernodal *s, PetscMPIInt ranks, std::vector<double> *schur) {
  PetscFunctionBeginUser;
  Split &p = s->split;
  const int separator = static_cast<int>(p.separator);
  PetscInt m;
  const PetscInt *row_start, *columns;
  PetscBool done;
  const PetscScalar *values;
  PetscCall(MatGetRowIJ(p.local[0], 0, PETSC_FALSE, PETSC_FALSE, &m, &row_start, &columns, &done));
  PetscCall(MatSeqAIJGetArrayRead(p.local[0], &values));
  std::vector<PetscInt> separator_index(m, -1);
  for (PetscInt k = 0; k < p.separator; ++k) separator_index[p.separator_local[k]] = k;
  for (PetscInt k = 0; k < p.separator; ++k) {
    const PetscInt l = p.separator_local[k];
    for (PetscInt e = row_start[l]; e < row_start[l + 1]; ++e) {
      const PetscInt c = separator_index[columns[e]];
      if (c >= 0 && c >= k)
        (*schur)[static_cast<size_t>(k) * separator + c] -= (ranks - 1) * values[e];
    }
  }
  PetscCall(MatSeqAIJRestoreArrayRead(p.local[0], &values));
  PetscCall(
      MatRestoreRowIJ(p.local[0], 0, PETSC_FALSE, PETSC_FALSE, &m, &row_start, &columns, &done));
  int info = 0;
  dpotrf_("L", &separator, schur->data(), &separator, &info);
  PetscCheck(info >= 0, PETSC_COMM_SELF, PETSC_ERR_LIB,
             "supernodal: LAPACK dpotrf failed (info %d)", info);
  if (info > 0) {
    PetscCall(PetscInfo(nullptr,
                        "supernodal: the separator's Schur complement is not positive definite\n"));
    s->failed = true;
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Rank 0: the separator's dense factor kept in the solves' precision; its
// entries and flops added.
void KeepSeparatorFactor(Supernodal *s, std::vector<double> *schur, double *entries,
                         double *flops) {
  Split &p = s->split;
  const int separator = static_cast<int>(p.separator);
  for (int j = 0; j < separator; ++j)  // dpotrf leaves the upper triangle as it was
    for (int i = 0; i < j; ++i) (*schur)[static_cast<size_t>(j) * separator + i] = 0.0;
  if (s->precision == kSingle)
    p.dense_single.From(*schur, separator);
  else
    p.dense_full.From(*schur, separator);
  *entries += 0.5 * separator * (separator + 1.0);
  *flops += separator * (double)separator * separator / 3.0;
}

// Rank 0's values[i] becomes the sum over the ranks of values[i], i < count
// (64-bit), in pieces of kReduceChunk entries (MPI counts are int).
PetscErrorCode ReduceSumToRoot(MPI_Comm comm, double *values, size_t count) {
  PetscFunctionBeginUser;
  PetscMPIInt rank;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  for (size_t first = 0; first < count; first += kReduceChunk) {
    const int piece = static_cast<int>(std::min(kReduceChunk, count - first));
    PetscCallMPI(MPI_Reduce(rank == 0 ? MPI_IN_PLACE : values + first, values + first, piece,
                            MPI_DOUBLE, MPI_SUM, 0, comm));
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode SetUpSplit(Supernodal *s, Mat A, bool new_pattern) {
  PetscFunctionBeginUser;
  Split &p = s->split;
  MPI_Comm comm = PetscObjectComm((PetscObject)A);
  PetscMPIInt rank, size;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  PetscCallMPI(MPI_Comm_size(comm, &size));
  if (new_pattern || !p.local)
    PetscCall(SplitStructure(s, A));
  else
    PetscCall(ExtractLocalPiece(A, MAT_REUSE_MATRIX, &p));
  if (!p.local_dofs.empty()) PetscCall(Factorise(s, p.local[0], nullptr, &p.factor));
  PetscCall(AgreeOnFailure(comm, -1, &s->failed));  // any local factorisation
  if (s->failed) PetscFunctionReturn(PETSC_SUCCESS);
  const int separator = static_cast<int>(p.separator);
  std::vector<double> schur(static_cast<size_t>(separator) * separator, 0.0);
  double entries = 0, flops = 0;
  if (!p.local_dofs.empty()) PetscCall(KeepLocalFactor(s, &schur, &entries, &flops));
  // Rank 0: S = sum_r C_r - (ranks - 1) A_SS, factorised densely.
  if (separator > 0) {
    PetscCall(ReduceSumToRoot(comm, schur.data(), schur.size()));
    if (rank == 0) PetscCall(FactoriseSeparator(s, size, &schur));
    PetscCall(AgreeOnFailure(comm, 0, &s->failed));  // rank 0's verdict on the separator
    if (s->failed) PetscFunctionReturn(PETSC_SUCCESS);
    if (rank == 0) KeepSeparatorFactor(s, &schur, &entries, &flops);
  }
  double sums[2] = {entries, flops};
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, sums, 2, MPI_DOUBLE, MPI_SUM, comm));
  s->stored = s->nonzeros = sums[0];
  s->flops = sums[1];
  PetscFunctionReturn(PETSC_SUCCESS);
}

template <typename Real>
PetscErrorCode ApplySplit(MPI_Comm comm, Split &p, TiledFactor<Real> &factor,
                          const DenseFactor<Real> &dense, const PetscScalar *b, PetscScalar *x) {
  PetscFunctionBeginUser;
  PetscMPIInt rank;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  const PetscInt n = static_cast<PetscInt>(p.local_dofs.size());
  const int interior = static_cast<int>(p.interior);
  Real *y = factor.y();
  const int *permutation = factor.permutation();
  for (PetscInt l = 0; l < n; ++l) p.local_b[l] = 0.0;
  for (PetscInt l = 0; l < n; ++l)
    if (p.owned_position[l] >= 0) p.local_b[l] = b[p.owned_position[l]];
  // Forward over the interior; the separator rows collect -L_S,I L_I^-1 b_I.
  if (n > 0) {
    for (PetscInt i = 0; i < interior; ++i) y[i] = static_cast<Real>(p.local_b[permutation[i]]);
    for (PetscInt i = interior; i < n; ++i) y[i] = 0;
    factor.Forward(interior);
  }
  for (PetscInt k = 0; k < p.separator; ++k) {
    const PetscInt l = p.separator_local[k];
    p.separator_values[k] = static_cast<double>(y[interior + k]) + p.local_b[l];  // b_S where owned
  }
  if (p.separator > 0) {
    PetscCallMPI(MPI_Reduce(rank == 0 ? MPI_IN_PLACE : p.separator_values.data(),
                            p.separator_values.data(), static_cast<int>(p.separator), MPI_DOUBLE,
                            MPI_SUM, 0, comm));
    if (rank == 0) {
      std::vector<Real> solved(p.separator_values.begin(), p.separator_values.end());
      dense.Solve(solved.data());
      std::copy(solved.begin(), solved.end(), p.separator_values.begin());
    }
    PetscCallMPI(
        MPI_Bcast(p.separator_values.data(), static_cast<int>(p.separator), MPI_DOUBLE, 0, comm));
  }
  if (n > 0) {
    for (PetscInt k = 0; k < p.separator; ++k)
      y[interior + k] = static_cast<Real>(p.separator_values[k]);
    factor.Backward(interior);
    for (PetscInt i = 0; i < n; ++i) {
      const PetscInt l = permutation[i];
      if (p.owned_position[l] >= 0) x[p.owned_position[l]] = y[i];
    }
  }
  for (PetscInt k = 0; k < p.separator; ++k) {  // the separator exactly as broadcast
    const PetscInt l = p.separator_local[k];
    if (p.owned_position[l] >= 0) x[p.owned_position[l]] = p.separator_values[k];
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode PCSetUp_Supernodal(PC pc) {
  PetscFunctionBeginUser;
  Supernodal *s = static_cast<Supernodal *>(pc->data);
  Mat A = pc->pmat;
  PetscObjectState pattern;
  PetscCall(MatGetNonzeroState(A, &pattern));
  const bool new_pattern = pattern != s->pattern_state;
  PetscMPIInt size;
  PetscCallMPI(MPI_Comm_size(PetscObjectComm((PetscObject)pc), &size));
  s->failed = false;
  if (size == 1)
    PetscCall(SetUpOneRank(s, A, new_pattern));
  else
    PetscCall(SetUpSplit(s, A, new_pattern));
  s->pattern_state = pattern;
  PetscCall(PCSetFailedReason(pc, s->failed ? PC_FACTOR_NUMERIC_ZEROPIVOT : PC_NOERROR));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode PCApply_Supernodal(PC pc, Vec b, Vec x) {
  PetscFunctionBeginUser;
  Supernodal *s = static_cast<Supernodal *>(pc->data);
  PetscMPIInt size;
  MPI_Comm comm = PetscObjectComm((PetscObject)pc);
  PetscCallMPI(MPI_Comm_size(comm, &size));
  if (s->failed) {  // the KSP sees NaN and stops on every rank
    PetscCall(VecSet(x, std::numeric_limits<PetscReal>::quiet_NaN()));
    PetscFunctionReturn(PETSC_SUCCESS);
  }
  const PetscScalar *rhs;
  PetscScalar *out;
  PetscCall(VecGetArrayRead(b, &rhs));
  PetscCall(VecGetArrayWrite(x, &out));
  if (size > 1) {
    if (s->precision == kSingle)
      PetscCall(ApplySplit(comm, s->split, s->split.single, s->split.dense_single, rhs, out));
    else
      PetscCall(ApplySplit(comm, s->split, s->split.full, s->split.dense_full, rhs, out));
  } else if (s->precision == kSingle) {
    s->single.Solve(rhs, out);
  } else {
    s->full.Solve(rhs, out);
  }
  PetscCall(VecRestoreArrayWrite(x, &out));
  PetscCall(VecRestoreArrayRead(b, &rhs));
  // A solve streams every factor entry twice at two flops each, shared by the ranks.
  PetscCall(PetscLogFlops(4.0 * s->nonzeros / size));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Y = A^-1 X for the columns of a dense X: on one rank four columns per sweep
// of the factor (TiledFactor::SolveColumns; each column equal to PCApply's to
// round-off; only the target rows when PCSupernodalSetSolveTargets gave some),
// on several ranks PCApply column by column.
PetscErrorCode PCMatApply_Supernodal(PC pc, Mat X, Mat Y) {
  PetscFunctionBeginUser;
  Supernodal *s = static_cast<Supernodal *>(pc->data);
  PetscMPIInt size;
  PetscCallMPI(MPI_Comm_size(PetscObjectComm((PetscObject)pc), &size));
  PetscInt columns;
  PetscCall(MatGetSize(X, nullptr, &columns));
  if (size > 1 || s->failed) {
    for (PetscInt j = 0; j < columns; ++j) {
      Vec x, y;
      PetscCall(MatDenseGetColumnVecRead(X, j, &x));
      PetscCall(MatDenseGetColumnVecWrite(Y, j, &y));
      PetscCall(PCApply_Supernodal(pc, x, y));
      PetscCall(MatDenseRestoreColumnVecWrite(Y, j, &y));
      PetscCall(MatDenseRestoreColumnVecRead(X, j, &x));
    }
    PetscFunctionReturn(PETSC_SUCCESS);
  }
  const PetscScalar *x;
  PetscScalar *y;
  PetscInt ldx, ldy;
  PetscCall(MatDenseGetLDA(X, &ldx));
  PetscCall(MatDenseGetLDA(Y, &ldy));
  PetscCall(MatDenseGetArrayRead(X, &x));
  PetscCall(MatDenseGetArrayWrite(Y, &y));
  if (s->precision == kSingle) {
    s->single.SetSolveTargets(s->targets);
    s->single.SolveColumns(static_cast<int>(columns), x, ldx, y, ldy);
  } else {
    s->full.SetSolveTargets(s->targets);
    s->full.SolveColumns(static_cast<int>(columns), x, ldx, y, ldy);
  }
  PetscCall(MatDenseRestoreArrayWrite(Y, &y));
  PetscCall(MatDenseRestoreArrayRead(X, &x));
  PetscCall(PetscLogFlops(4.0 * s->nonzeros * columns));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode PCView_Supernodal(PC pc, PetscViewer viewer) {
  PetscFunctionBeginUser;
  Supernodal *s = static_cast<Supernodal *>(pc->data);
  PetscBool ascii;
  PetscCall(PetscObjectTypeCompare((PetscObject)viewer, PETSCVIEWERASCII, &ascii));
  if (ascii) {
    PetscMPIInt size;
    PetscCallMPI(MPI_Comm_size(PetscObjectComm((PetscObject)pc), &size));
    PetscCall(PetscViewerASCIIPrintf(
        viewer, "  CHOLMOD supernodal Cholesky, ordering %s, solves in %s precision\n",
        kOrderings[s->ordering], kPrecisions[s->precision]));
    if (size > 1)
      PetscCall(PetscViewerASCIIPrintf(
          viewer,
          "  split at a separator of %" PetscInt_FMT
          " DOFs: a factor of the interior per rank, the dense Schur complement "
          "on rank 0\n",
          s->split.separator));
    if (s->stored > 0)
      PetscCall(PetscViewerASCIIPrintf(viewer,
                                       "  factor: %.4g nonzeros, %.4g stored entries, %.4g flops\n",
                                       s->nonzeros, s->stored, s->flops));
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode PCCreate_Supernodal(PC pc) {
  PetscFunctionBeginUser;
  pc->data = new Supernodal();
  pc->ops->setup = PCSetUp_Supernodal;
  pc->ops->apply = PCApply_Supernodal;
  pc->ops->matapply = PCMatApply_Supernodal;
  pc->ops->reset = PCReset_Supernodal;
  pc->ops->destroy = PCDestroy_Supernodal;
  pc->ops->setfromoptions = PCSetFromOptions_Supernodal;
  pc->ops->view = PCView_Supernodal;
  PetscFunctionReturn(PETSC_SUCCESS);
}

// One rank: the symbolic factor of A (kept for the set-up); its entries.
PetscErrorCode PredictOneRank(Supernodal *s, Mat A, SupernodalPrediction *prediction) {
  PetscFunctionBeginUser;
  cholmod_free_factor(&s->factor, &s->common);
  PetscCall(AnalysePattern(s, A, nullptr, &s->factor));
  prediction->factor_entries = prediction->factor_entries_total =
      static_cast<double>(s->factor->xsize);
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Several ranks: the separator's size n_S first (a count, nothing allocated);
// when its dense blocks fit the budget, the split structure and the symbolic
// factors of the ranks' pieces (kept for the set-up) and their entries.
PetscErrorCode PredictSplit(Supernodal *s, Mat A, double budget_bytes,
                            SupernodalPrediction *prediction) {
  PetscFunctionBeginUser;
  MPI_Comm comm = PetscObjectComm((PetscObject)A);
  PetscMPIInt rank;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  const PetscInt *ranges;
  PetscCall(MatGetOwnershipRanges(A, &ranges));
  std::vector<PetscInt> mine;
  PetscCall(OwnedSeparatorDofs(A, ranges[rank], ranges[rank + 1], &mine));
  PetscInt64 separator = static_cast<PetscInt64>(mine.size());
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &separator, 1, MPIU_INT64, MPI_SUM, comm));
  prediction->separator = separator;
  prediction->separator_bytes =
      SupernodalSeparatorBytes(separator, s->precision == kSingle ? 4 : 8);
  if (prediction->separator_bytes > budget_bytes || separator > s->limits.max_separator)
    PetscFunctionReturn(PETSC_SUCCESS);
  PetscCall(SplitStructure(s, A));
  const double entries = s->split.factor ? static_cast<double>(s->split.factor->xsize) : 0.0;
  double largest = entries, total = entries;
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &largest, 1, MPI_DOUBLE, MPI_MAX, comm));
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &total, 1, MPI_DOUBLE, MPI_SUM, comm));
  prediction->factor_entries = largest;
  prediction->factor_entries_total = total;
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace

double SupernodalSeparatorBytes(PetscInt64 separator, int bytes_per_entry) {
  const double square = static_cast<double>(separator) * static_cast<double>(separator);
  // Every rank: the trailing block of its factor copied out, and its
  // contribution to the Schur complement (sum on rank 0); MPI's reduction
  // buffer; rank 0: the dense factor kept for the solves.
  return 2.0 * sizeof(double) * square +
         sizeof(double) * std::min(square, static_cast<double>(kReduceChunk)) +
         bytes_per_entry * square;
}

PetscErrorCode PCSupernodalPredict(PC pc, SupernodalPrediction *prediction) {
  PetscFunctionBeginUser;
  PetscBool is_supernodal;
  PetscCall(PetscObjectTypeCompare((PetscObject)pc, kPCSupernodal, &is_supernodal));
  PetscCheck(is_supernodal, PetscObjectComm((PetscObject)pc), PETSC_ERR_ARG_WRONG,
             "not a supernodal PC");
  PetscCheck(pc->pmat, PetscObjectComm((PetscObject)pc), PETSC_ERR_ORDER,
             "supernodal: the operator must be set before the prediction");
  Supernodal *s = static_cast<Supernodal *>(pc->data);
  *prediction = SupernodalPrediction();
  prediction->limits = s->limits;
  const double budget_bytes = s->limits.budget_mb * kBytesPerMB;
  PetscMPIInt size;
  PetscCallMPI(MPI_Comm_size(PetscObjectComm((PetscObject)pc), &size));
  if (size == 1)
    PetscCall(PredictOneRank(s, pc->pmat, prediction));
  else
    PetscCall(PredictSplit(s, pc->pmat, budget_bytes, prediction));
  prediction->analysed = size == 1 || (prediction->separator_bytes <= budget_bytes &&
                                       prediction->separator <= s->limits.max_separator);
  if (prediction->analysed) {
    PetscCall(MatGetNonzeroState(pc->pmat, &s->pattern_state));  // the set-up reuses the analysis
    // The numeric factor in double, replaced by its copy in the solves'
    // precision (double or single) as the copy is made, beside the separator's blocks.
    prediction->bytes = prediction->factor_entries * kCholmodBytesPerEntry * kCopyPeakOverFactor +
                        prediction->separator_bytes;
  } else {
    prediction->bytes = prediction->separator_bytes;
  }
  prediction->affordable = prediction->analysed && prediction->bytes <= budget_bytes;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode RegisterSupernodalPC() {
  PetscFunctionBeginUser;
  static bool registered = false;
  if (!registered) PetscCall(PCRegister(kPCSupernodal, PCCreate_Supernodal));
  registered = true;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode PCSupernodalSetSinglePrecision(PC pc, bool single) {
  PetscFunctionBeginUser;
  PetscBool is_supernodal;
  PetscCall(PetscObjectTypeCompare((PetscObject)pc, kPCSupernodal, &is_supernodal));
  PetscCheck(is_supernodal, PetscObjectComm((PetscObject)pc), PETSC_ERR_ARG_WRONG,
             "not a supernodal PC");
  static_cast<Supernodal *>(pc->data)->precision = single ? kSingle : kDouble;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode PCSupernodalSetSolveTargets(PC pc, PetscInt count, const PetscInt rows[]) {
  PetscFunctionBeginUser;
  PetscBool is_supernodal;
  PetscCall(PetscObjectTypeCompare((PetscObject)pc, kPCSupernodal, &is_supernodal));
  PetscCheck(is_supernodal, PetscObjectComm((PetscObject)pc), PETSC_ERR_ARG_WRONG,
             "not a supernodal PC");
  Supernodal *s = static_cast<Supernodal *>(pc->data);
  s->targets.assign(rows, rows + count);
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode PCSupernodalGetFactorSize(PC pc, double *stored_entries, double *nonzeros,
                                         double *factor_flops, int *bytes_per_entry) {
  PetscFunctionBeginUser;
  PetscBool is_supernodal;
  PetscCall(PetscObjectTypeCompare((PetscObject)pc, kPCSupernodal, &is_supernodal));
  PetscCheck(is_supernodal, PetscObjectComm((PetscObject)pc), PETSC_ERR_ARG_WRONG,
             "not a supernodal PC");
  const Supernodal *s = static_cast<const Supernodal *>(pc->data);
  *stored_entries = s->stored;
  *nonzeros = s->nonzeros;
  *factor_flops = s->flops;
  *bytes_per_entry = s->precision == kSingle ? 4 : 8;
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
