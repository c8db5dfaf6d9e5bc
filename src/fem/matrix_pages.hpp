// A matrix's arrays on 2 MB pages: the values and column indices that every
// product streams from memory (K in the linear step, A in the corotational
// step's CG iterations), moved onto transparent huge pages once assembled.
//
// PETSc allocates them with malloc, on 4 KB pages. A stream over 4 KB pages
// takes a TLB miss per page, and the core's hardware prefetcher stops at each
// page boundary and starts again behind it. madvise(MADV_HUGEPAGE) allows the
// kernel huge pages in the range, and MADV_COLLAPSE (Linux 6.1 and later)
// moves its present 4 KB pages into 2 MB pages at once, contents kept (the
// factor's own arrays get huge pages at allocation: common/large_array.hpp).
// Only the whole 2 MB pages inside each array move; the values do not change.
// Both calls are hints: where the kernel refuses (older kernels, transparent
// huge pages off), the arrays stay as they are.
#pragma once

#include <petscmat.h>

namespace softbody {

// Not collective. Moves the local parts' values and column indices of
// `matrix` (MATSEQAIJ, MATMPIAIJ, MATSEQBAIJ or MATMPIBAIJ, assembled; other
// types are left alone) onto huge pages where the kernel allows it.
PetscErrorCode MoveMatrixToHugePages(Mat matrix);

}  // namespace softbody
