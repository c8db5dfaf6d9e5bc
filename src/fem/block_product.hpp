// Products with K stored as 3 x 3 blocks (MATBAIJ, block size 3) at the memory's
// pace, with PETSc's own rounding.
//
// PETSc 3.18's MatMult_SeqBAIJ_3 keeps three scalar sums per block row, each
// adding three products per block one after another: a chain of dependent
// additions that leaves the loads waiting (1.5 ms per product of the 103 k-tet
// TetGen mesh's K, 22 MB, about 15 GB/s, on an AMD EPYC core that streams
// 27-31 GB/s). The kernels here hold a block row's three sums in one vector of
// four lanes (the fourth unused) and add a block's three columns times the
// vector's entries in the same order and with the same roundings (no fused
// multiply-add), so the result is PETSc's, bit for bit.
#pragma once

#include <petscmat.h>

namespace softbody {

// Not collective. Makes MatMult with `blocks` (MATSEQBAIJ or MATMPIBAIJ, block
// size 3, assembled) use these kernels: on a sequential matrix its product; on
// a parallel one the product with its diagonal part and the product-and-add
// with its off-diagonal part, which PETSc's MatMult_MPIBAIJ calls around the
// halo exchange. The matrix's values must not change afterwards (the kernels
// read them through MatSeqBAIJGetArray at each product, so a change of values
// would be seen, but a change of pattern is not supported).
PetscErrorCode UseBlockProducts(Mat blocks);

}  // namespace softbody
