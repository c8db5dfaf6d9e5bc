#include "supernodal.hpp"

// A new PC type is added as PETSc documents it (PCRegister with a creation
// routine that fills the PC's operations), which needs the PC's private header.
#include <petsc/private/pcimpl.h>

#include <cholmod.h>

#include <algorithm>
#include <cstring>
#include <vector>

#include "large_array.hpp"

namespace softbody {

namespace {

static_assert(sizeof(PetscInt) == sizeof(int), "CHOLMOD is called with 32-bit indices");

const char *const kOrderings[] = {"best", "amd", "metis", "SupernodalOrdering", "", nullptr};
enum SupernodalOrdering { kOrderingBest, kOrderingAmd, kOrderingMetis };
const char *const kPrecisions[] = {"double", "single", "SupernodalPrecision", "", nullptr};
enum SupernodalPrecision { kDouble, kSingle };

// CHOLMOD's supernodal factor copied into softbody's own storage (huge pages,
// large_array.hpp) in the precision Real, and the two triangular solves with it.
// Real = float: half the bytes of a solve, about 1e-7 relative accuracy (for a
// preconditioner). In double precision CHOLMOD's own solve was faster.
template <typename Real>
struct PackedFactor {
  int n = 0, supernodes = 0;
  std::vector<int> permutation, first_column, row_start, value_start, rows;  // CHOLMOD's Perm, super, pi, px, s
  LargeArray<Real> values;
  std::vector<Real> y, work;

  void From(const cholmod_factor *L) {
    n = static_cast<int>(L->n);
    supernodes = static_cast<int>(L->nsuper);
    const int *perm = static_cast<const int *>(L->Perm), *super = static_cast<const int *>(L->super),
              *pi = static_cast<const int *>(L->pi), *px = static_cast<const int *>(L->px),
              *s = static_cast<const int *>(L->s);
    permutation.assign(perm, perm + n);
    first_column.assign(super, super + supernodes + 1);
    row_start.assign(pi, pi + supernodes + 1);
    value_start.assign(px, px + supernodes + 1);
    rows.assign(s, s + pi[supernodes]);
    const double *x = static_cast<const double *>(L->x);
    values.resize(L->xsize);
    for (size_t i = 0; i < L->xsize; ++i) values[i] = static_cast<Real>(x[i]);
    y.resize(n);
    size_t largest = 0;
    for (int k = 0; k < supernodes; ++k) largest = std::max<size_t>(largest, pi[k + 1] - pi[k]);
    work.resize(largest);
  }

  // x = A^-1 b with A = P^T L L^T P. Supernode k holds columns [first, first +
  // columns) of L as a column-major block of `height` rows: the triangle on top,
  // the rows listed in `rows` below it. Plain loops (vectorised; the reductions
  // by omp simd): at this size they stream the factor at the memory's speed,
  // where single-precision BLAS-2 calls reached about two thirds of it.
  void Solve(const double *b, double *x) {
    for (int i = 0; i < n; ++i) y[i] = static_cast<Real>(b[permutation[i]]);
    for (int k = 0; k < supernodes; ++k) {  // L y = P b
      const int first = first_column[k], columns = first_column[k + 1] - first;
      const int height = row_start[k + 1] - row_start[k], below = height - columns;
      const Real *block = values.data() + value_start[k];
      Real *yk = y.data() + first, *w = work.data();
      for (int j = 0; j < columns; ++j) {
        const Real *column = block + static_cast<size_t>(j) * height;
        const Real v = yk[j] / column[j];
        yk[j] = v;
        for (int i = j + 1; i < columns; ++i) yk[i] -= column[i] * v;
      }
      if (below > 0) {
        for (int i = 0; i < below; ++i) w[i] = 0;
        for (int j = 0; j < columns; ++j) {
          const Real *column = block + static_cast<size_t>(j) * height + columns;
          const Real v = yk[j];
#pragma omp simd
          for (int i = 0; i < below; ++i) w[i] += column[i] * v;
        }
        const int *r = rows.data() + row_start[k] + columns;
        for (int i = 0; i < below; ++i) y[r[i]] -= w[i];
      }
    }
    for (int k = supernodes - 1; k >= 0; --k) {  // L^T z = y
      const int first = first_column[k], columns = first_column[k + 1] - first;
      const int height = row_start[k + 1] - row_start[k], below = height - columns;
      const Real *block = values.data() + value_start[k];
      Real *yk = y.data() + first, *w = work.data();
      if (below > 0) {
        const int *r = rows.data() + row_start[k] + columns;
        for (int i = 0; i < below; ++i) w[i] = y[r[i]];
        for (int j = 0; j < columns; ++j) {
          const Real *column = block + static_cast<size_t>(j) * height + columns;
          Real sum = 0;
#pragma omp simd reduction(+ : sum)
          for (int i = 0; i < below; ++i) sum += column[i] * w[i];
          yk[j] -= sum;
        }
      }
      for (int j = columns - 1; j >= 0; --j) {
        const Real *column = block + static_cast<size_t>(j) * height;
        Real sum = 0;
#pragma omp simd reduction(+ : sum)
        for (int i = j + 1; i < columns; ++i) sum += column[i] * yk[i];
        yk[j] = (yk[j] - sum) / column[j];
      }
    }
    for (int i = 0; i < n; ++i) x[permutation[i]] = y[i];
  }
};

struct Supernodal {
  cholmod_common common;
  bool started = false;
  cholmod_factor *factor = nullptr;
  PetscObjectState pattern_state = -1;   // nonzero state of the factorised pattern
  SupernodalOrdering ordering = kOrderingBest;
  SupernodalPrecision precision = kDouble;
  PackedFactor<float> single;
  cholmod_dense *solution = nullptr, *work_y = nullptr, *work_e = nullptr;  // cholmod_solve2's
  // More than one rank: A and the right-hand side gathered on rank 0.
  Mat *gathered = nullptr;
  VecScatter to_zero = nullptr;
  Vec rhs_zero = nullptr, solution_zero = nullptr;
  double stored = 0, nonzeros = 0, flops = 0;
  int ordering_used = -1;
};

PetscErrorCode ReleaseFactor(Supernodal *s) {
  PetscFunctionBeginUser;
  if (s->started) {
    cholmod_free_factor(&s->factor, &s->common);
    cholmod_free_dense(&s->solution, &s->common);
    cholmod_free_dense(&s->work_y, &s->common);
    cholmod_free_dense(&s->work_e, &s->common);
    cholmod_finish(&s->common);
    s->started = false;
  }
  if (s->gathered) PetscCall(MatDestroySubMatrices(1, &s->gathered));
  PetscCall(VecScatterDestroy(&s->to_zero));
  PetscCall(VecDestroy(&s->rhs_zero));
  PetscCall(VecDestroy(&s->solution_zero));
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

PetscErrorCode PCSetFromOptions_Supernodal(PC pc, PetscOptionItems *PetscOptionsObject) {
  PetscFunctionBeginUser;
  Supernodal *s = static_cast<Supernodal *>(pc->data);
  PetscOptionsHeadBegin(PetscOptionsObject, "Supernodal Cholesky (CHOLMOD) options");
  PetscCall(PetscOptionsEnum("-pc_supernodal_ordering",
                             "Fill-reducing ordering: best (CHOLMOD tries AMD, then METIS if AMD fills "
                             "much, and keeps the better), amd or metis",
                             nullptr, kOrderings, (PetscEnum)s->ordering, (PetscEnum *)&s->ordering, nullptr));
  PetscCall(PetscOptionsEnum("-pc_supernodal_precision",
                             "Precision of the factor in the solves: double, or single (half the memory traffic, "
                             "about 1e-7 relative accuracy: for use as a preconditioner)",
                             nullptr, kPrecisions, (PetscEnum)s->precision, (PetscEnum *)&s->precision, nullptr));
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

PetscErrorCode FactorOnThisRank(Supernodal *s, Mat A, bool new_pattern) {
  PetscFunctionBeginUser;
  if (!s->started) {
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
  PetscInt n;
  const PetscInt *row_start, *columns;
  PetscBool done;
  PetscCall(MatGetRowIJ(A, 0, PETSC_FALSE, PETSC_FALSE, &n, &row_start, &columns, &done));
  PetscCheck(done, PETSC_COMM_SELF, PETSC_ERR_SUP, "supernodal: no CSR access to the matrix");
  const PetscScalar *values;
  PetscCall(MatSeqAIJGetArrayRead(A, &values));
  cholmod_sparse view = LowerView(n, row_start, columns, values);
  if (new_pattern || !s->factor) {
    cholmod_free_factor(&s->factor, &s->common);
    s->factor = cholmod_analyze(&view, &s->common);
    PetscCheck(s->factor, PETSC_COMM_SELF, PETSC_ERR_LIB, "supernodal: CHOLMOD analysis failed (status %d)",
               s->common.status);
    s->ordering_used = s->common.selected >= 0 ? s->common.method[s->common.selected].ordering : -1;
  }
  const int ok = cholmod_factorize(&view, s->factor, &s->common);
  PetscCall(MatSeqAIJRestoreArrayRead(A, &values));
  PetscCall(MatRestoreRowIJ(A, 0, PETSC_FALSE, PETSC_FALSE, &n, &row_start, &columns, &done));
  PetscCheck(ok && s->common.status == CHOLMOD_OK, PETSC_COMM_SELF, PETSC_ERR_MAT_CH_ZRPVT,
             "supernodal: the matrix is not positive definite (CHOLMOD status %d, column %d)",
             s->common.status, (int)s->factor->minor);
  s->stored = static_cast<double>(s->factor->xsize);
  s->nonzeros = s->common.lnz;
  s->flops = s->common.fl;
  PetscCheck(s->factor->is_super && s->factor->xtype == CHOLMOD_REAL, PETSC_COMM_SELF, PETSC_ERR_LIB,
             "supernodal: CHOLMOD did not return a real supernodal factor");
  if (s->precision == kSingle) {
    s->single.From(s->factor);
    // Keep the symbolic factor (for refactorisations), free CHOLMOD's values.
    PetscCheck(cholmod_change_factor(CHOLMOD_PATTERN, 0, 1, 1, 1, s->factor, &s->common), PETSC_COMM_SELF,
               PETSC_ERR_LIB, "supernodal: CHOLMOD could not drop the factor's values");
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
  PetscMPIInt size, rank;
  MPI_Comm comm = PetscObjectComm((PetscObject)pc);
  PetscCallMPI(MPI_Comm_size(comm, &size));
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  if (size == 1) {
    PetscCall(FactorOnThisRank(s, A, new_pattern));
  } else {
    PetscInt rows;
    PetscCall(MatGetSize(A, &rows, nullptr));
    IS all;
    PetscCall(ISCreateStride(PETSC_COMM_SELF, rank == 0 ? rows : 0, 0, 1, &all));
    if (new_pattern && s->gathered) PetscCall(MatDestroySubMatrices(1, &s->gathered));
    PetscCall(MatCreateSubMatrices(A, 1, &all, &all, s->gathered ? MAT_REUSE_MATRIX : MAT_INITIAL_MATRIX,
                                   &s->gathered));
    PetscCall(ISDestroy(&all));
    if (rank == 0) PetscCall(FactorOnThisRank(s, s->gathered[0], new_pattern));
    if (!s->to_zero) {
      Vec like;
      PetscCall(MatCreateVecs(A, &like, nullptr));
      PetscCall(VecScatterCreateToZero(like, &s->to_zero, &s->rhs_zero));
      PetscCall(VecDuplicate(s->rhs_zero, &s->solution_zero));
      PetscCall(VecDestroy(&like));
    }
    double sizes[3] = {s->stored, s->nonzeros, s->flops};
    PetscCallMPI(MPI_Bcast(sizes, 3, MPI_DOUBLE, 0, comm));
    s->stored = sizes[0];
    s->nonzeros = sizes[1];
    s->flops = sizes[2];
  }
  s->pattern_state = pattern;
  PetscFunctionReturn(PETSC_SUCCESS);
}

// x = A^-1 b on this rank (rank 0, or the only rank).
PetscErrorCode SolveOnThisRank(Supernodal *s, Vec b, Vec x) {
  PetscFunctionBeginUser;
  const PetscScalar *rhs;
  PetscScalar *out;
  PetscCall(VecGetArrayRead(b, &rhs));
  PetscCall(VecGetArrayWrite(x, &out));
  if (s->precision == kSingle) {
    s->single.Solve(rhs, out);
  } else {  // CHOLMOD's own solve (BLAS-2 per supernode) streams the double factor fastest
    PetscInt n;
    PetscCall(VecGetLocalSize(b, &n));
    cholmod_dense dense;
    std::memset(&dense, 0, sizeof(dense));
    dense.nrow = dense.d = dense.nzmax = n;
    dense.ncol = 1;
    dense.x = const_cast<PetscScalar *>(rhs);
    dense.xtype = CHOLMOD_REAL;
    dense.dtype = CHOLMOD_DOUBLE;
    const int ok = cholmod_solve2(CHOLMOD_A, s->factor, &dense, nullptr, &s->solution, nullptr, &s->work_y,
                                  &s->work_e, &s->common);
    PetscCheck(ok, PETSC_COMM_SELF, PETSC_ERR_LIB, "supernodal: CHOLMOD solve failed (status %d)", s->common.status);
    std::memcpy(out, s->solution->x, sizeof(PetscScalar) * n);
  }
  PetscCall(VecRestoreArrayWrite(x, &out));
  PetscCall(VecRestoreArrayRead(b, &rhs));
  PetscCall(PetscLogFlops(4.0 * s->nonzeros));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode PCApply_Supernodal(PC pc, Vec b, Vec x) {
  PetscFunctionBeginUser;
  Supernodal *s = static_cast<Supernodal *>(pc->data);
  if (!s->to_zero) {
    PetscCall(SolveOnThisRank(s, b, x));
    PetscFunctionReturn(PETSC_SUCCESS);
  }
  PetscCall(VecScatterBegin(s->to_zero, b, s->rhs_zero, INSERT_VALUES, SCATTER_FORWARD));
  PetscCall(VecScatterEnd(s->to_zero, b, s->rhs_zero, INSERT_VALUES, SCATTER_FORWARD));
  PetscMPIInt rank;
  PetscCallMPI(MPI_Comm_rank(PetscObjectComm((PetscObject)pc), &rank));
  if (rank == 0) PetscCall(SolveOnThisRank(s, s->rhs_zero, s->solution_zero));
  PetscCall(VecScatterBegin(s->to_zero, s->solution_zero, x, INSERT_VALUES, SCATTER_REVERSE));
  PetscCall(VecScatterEnd(s->to_zero, s->solution_zero, x, INSERT_VALUES, SCATTER_REVERSE));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode PCView_Supernodal(PC pc, PetscViewer viewer) {
  PetscFunctionBeginUser;
  Supernodal *s = static_cast<Supernodal *>(pc->data);
  PetscBool ascii;
  PetscCall(PetscObjectTypeCompare((PetscObject)viewer, PETSCVIEWERASCII, &ascii));
  if (ascii) {
    PetscCall(PetscViewerASCIIPrintf(viewer, "  CHOLMOD supernodal Cholesky on rank 0, ordering %s, solves in %s precision\n",
                                     kOrderings[s->ordering], kPrecisions[s->precision]));
    if (s->stored > 0)
      PetscCall(PetscViewerASCIIPrintf(viewer, "  factor: %.4g nonzeros, %.4g stored entries, %.4g flops\n",
                                       s->nonzeros, s->stored, s->flops));
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode PCCreate_Supernodal(PC pc) {
  PetscFunctionBeginUser;
  pc->data = new Supernodal();
  pc->ops->setup = PCSetUp_Supernodal;
  pc->ops->apply = PCApply_Supernodal;
  pc->ops->applysymmetricleft = nullptr;
  pc->ops->reset = PCReset_Supernodal;
  pc->ops->destroy = PCDestroy_Supernodal;
  pc->ops->setfromoptions = PCSetFromOptions_Supernodal;
  pc->ops->view = PCView_Supernodal;
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace

PetscErrorCode RegisterSupernodalPC() {
  PetscFunctionBeginUser;
  static bool registered = false;
  if (!registered) PetscCall(PCRegister(kPCSupernodal, PCCreate_Supernodal));
  registered = true;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode PCSupernodalGetFactorSize(PC pc, double *stored_entries, double *nonzeros,
                                         double *factor_flops) {
  PetscFunctionBeginUser;
  PetscBool is_supernodal;
  PetscCall(PetscObjectTypeCompare((PetscObject)pc, kPCSupernodal, &is_supernodal));
  PetscCheck(is_supernodal, PetscObjectComm((PetscObject)pc), PETSC_ERR_ARG_WRONG, "not a supernodal PC");
  const Supernodal *s = static_cast<const Supernodal *>(pc->data);
  *stored_entries = s->stored;
  *nonzeros = s->nonzeros;
  *factor_flops = s->flops;
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
