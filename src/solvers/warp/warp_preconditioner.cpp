#include "solvers/warp/warp_preconditioner.hpp"

// A new PC type is added as PETSc documents it (PCRegister with a creation
// routine that fills the PC's operations), which needs the PC's private header.
#include <petsc/private/pcimpl.h>

#include <vector>

#include "solvers/solver.hpp"
#include "solvers/supernodal/supernodal.hpp"

namespace softbody {

namespace {

struct Warp {
  Mat linear = nullptr;           // A0 (referenced)
  PC inner = nullptr;             // A0^-1
  std::vector<double> rotations;  // 9 per owned vertex, row-major
  SolverChoice choice;            // of the inner PC
  Vec rotated = nullptr, inner_solution = nullptr;
};

PetscErrorCode PCReset_Warp(PC pc) {
  PetscFunctionBeginUser;
  Warp *w = static_cast<Warp *>(pc->data);
  PetscCall(VecDestroy(&w->rotated));
  PetscCall(VecDestroy(&w->inner_solution));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode PCDestroy_Warp(PC pc) {
  PetscFunctionBeginUser;
  Warp *w = static_cast<Warp *>(pc->data);
  PetscCall(PCReset_Warp(pc));
  PetscCall(PCDestroy(&w->inner));
  PetscCall(MatDestroy(&w->linear));
  delete w;
  pc->data = nullptr;
  PetscFunctionReturn(PETSC_SUCCESS);
}

// The inner PC on A0: supernodal Cholesky in single precision by default while
// affordable (else GAMG, solver.hpp), its options under the prefix warp_ (after
// the warp PC's own prefix).
PetscErrorCode CreateInnerPC(PC pc, Warp *w) {
  PetscFunctionBeginUser;
  PetscCall(RegisterSupernodalPC());
  PetscCall(PCCreate(PetscObjectComm((PetscObject)pc), &w->inner));
  PetscCall(PCSetOptionsPrefix(w->inner, "warp_"));
  const char *prefix;
  PetscCall(PCGetOptionsPrefix(pc, &prefix));
  if (prefix) PetscCall(PCAppendOptionsPrefix(w->inner, prefix));
  PetscCall(PCSetType(w->inner, kPCSupernodal));
  // A preconditioner needs no more than single precision, and its triangular
  // solves then stream half the bytes (-warp_pc_supernodal_precision double
  // to compare).
  PetscCall(PCSupernodalSetSinglePrecision(w->inner, true));
  PetscCall(PCSetOperators(w->inner, w->linear, w->linear));
  PetscCall(PCSetFromOptions(w->inner));
  // The factor only within its limits, else a multigrid cycle on A0.
  PetscCall(ChooseFactorOrMultigrid(nullptr, w->inner, &w->choice));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode PCSetUp_Warp(PC pc) {
  PetscFunctionBeginUser;
  Warp *w = static_cast<Warp *>(pc->data);
  PetscCheck(w->linear, PetscObjectComm((PetscObject)pc), PETSC_ERR_ORDER,
             "warp: PCWarpSetLinearOperator was not called");
  if (!w->inner) PetscCall(CreateInnerPC(pc, w));
  PetscCall(PCSetUp(w->inner));  // factorises only when A0 changed
  PCFailedReason inner_reason;   // A0 not positive definite: the KSP stops (supernodal.hpp)
  PetscCall(PCGetFailedReason(w->inner, &inner_reason));
  PetscCall(PCSetFailedReason(pc, inner_reason));
  if (!w->rotated) PetscCall(MatCreateVecs(w->linear, &w->rotated, &w->inner_solution));
  PetscInt n;
  PetscCall(VecGetLocalSize(w->rotated, &n));
  PetscCheck(static_cast<size_t>(3 * n) == w->rotations.size(), PETSC_COMM_SELF, PETSC_ERR_ORDER,
             "warp: PCWarpSetRotations gave %zu values for %" PetscInt_FMT " local rows",
             w->rotations.size(), n);
  PetscFunctionReturn(PETSC_SUCCESS);
}

// out_v = R_v in_v (transposed: R_v^T in_v) for every owned vertex v.
template <bool kTransposed>
PetscErrorCode RotatePerVertex(const std::vector<double> &rotations, Vec in, Vec out) {
  PetscFunctionBeginUser;
  const PetscScalar *a;
  PetscScalar *b;
  PetscInt n;
  PetscCall(VecGetLocalSize(in, &n));
  PetscCall(VecGetArrayRead(in, &a));
  PetscCall(VecGetArrayWrite(out, &b));
  for (PetscInt v = 0; v < n / 3; ++v) {
    const double *R = rotations.data() + 9 * v, *x = a + 3 * v;
    double *y = b + 3 * v;
    for (int i = 0; i < 3; ++i)
      y[i] = kTransposed ? R[i] * x[0] + R[3 + i] * x[1] + R[6 + i] * x[2]
                         : R[3 * i] * x[0] + R[3 * i + 1] * x[1] + R[3 * i + 2] * x[2];
  }
  PetscCall(VecRestoreArrayRead(in, &a));
  PetscCall(VecRestoreArrayWrite(out, &b));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode PCApply_Warp(PC pc, Vec b, Vec x) {
  PetscFunctionBeginUser;
  Warp *w = static_cast<Warp *>(pc->data);
  PetscCall(RotatePerVertex<true>(w->rotations, b, w->rotated));
  PetscCall(PCApply(w->inner, w->rotated, w->inner_solution));
  PetscCall(RotatePerVertex<false>(w->rotations, w->inner_solution, x));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode PCView_Warp(PC pc, PetscViewer viewer) {
  PetscFunctionBeginUser;
  Warp *w = static_cast<Warp *>(pc->data);
  PetscBool ascii;
  PetscCall(PetscObjectTypeCompare((PetscObject)viewer, PETSCVIEWERASCII, &ascii));
  if (ascii) {
    PetscCall(PetscViewerASCIIPrintf(
        viewer, "  per-vertex rotations around the linear system's factor:\n"));
    if (w->inner) {
      PetscCall(PetscViewerASCIIPushTab(viewer));
      PetscCall(PCView(w->inner, viewer));
      PetscCall(PetscViewerASCIIPopTab(viewer));
    }
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode PCCreate_Warp(PC pc) {
  PetscFunctionBeginUser;
  pc->data = new Warp();
  pc->ops->setup = PCSetUp_Warp;
  pc->ops->apply = PCApply_Warp;
  pc->ops->reset = PCReset_Warp;
  pc->ops->destroy = PCDestroy_Warp;
  pc->ops->view = PCView_Warp;
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace

PetscErrorCode RegisterWarpPC() {
  PetscFunctionBeginUser;
  static bool registered = false;
  if (!registered) PetscCall(PCRegister(kPCWarp, PCCreate_Warp));
  registered = true;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode PCWarpSetLinearOperator(PC pc, Mat linear) {
  PetscFunctionBeginUser;
  Warp *w = static_cast<Warp *>(pc->data);
  PetscCall(PetscObjectReference((PetscObject)linear));
  PetscCall(MatDestroy(&w->linear));
  w->linear = linear;
  if (w->inner) PetscCall(PCSetOperators(w->inner, linear, linear));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode PCWarpSetRotations(PC pc, PetscInt vertices, const double *rotations) {
  PetscFunctionBeginUser;
  Warp *w = static_cast<Warp *>(pc->data);
  w->rotations.assign(rotations, rotations + 9 * vertices);
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode PCWarpGetInnerChoice(PC pc, SolverChoice *choice) {
  PetscFunctionBeginUser;
  *choice = static_cast<Warp *>(pc->data)->choice;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode PCWarpGetInnerPC(PC pc, PC *inner) {
  PetscFunctionBeginUser;
  *inner = static_cast<Warp *>(pc->data)->inner;
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
