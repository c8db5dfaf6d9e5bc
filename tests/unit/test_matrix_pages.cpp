// MoveMatrixToHugePages (matrix_pages.hpp): K's values and products are the
// same after the move (bit for bit, AIJ and BAIJ, on 1 and 3 ranks), and where
// the kernel has transparent huge pages and MADV_COLLAPSE (Linux 6.1 and
// later), the pages under K's values are 2 MB pages afterwards, read from
// /proc/self/smaps.
// Runs on ranks: 1 3
#include <gtest/gtest.h>
#include <petscmat.h>
#include <sys/utsname.h>

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <sstream>
#include <string>

#include "box_stiffness.hpp"
#include "fem/block_matrix.hpp"
#include "fem/matrix_pages.hpp"
#include "petsc_environment.hpp"
#include "vec_equal.hpp"

using namespace softbody;

namespace {

// y = K x with x = (1, 2, 3, ...) / n.
Vec Product(Mat K) {
  Vec x, y;
  MatCreateVecs(K, &x, &y);
  PetscInt begin, end, n;
  VecGetOwnershipRange(x, &begin, &end);
  VecGetSize(x, &n);
  for (PetscInt i = begin; i < end; ++i) VecSetValue(x, i, (i + 1.0) / n, INSERT_VALUES);
  VecAssemblyBegin(x);
  VecAssemblyEnd(x);
  MatMult(K, x, y);
  VecDestroy(&x);
  return y;
}

// Moves `moved` and checks it against its copy and its product made before.
void ExpectUnchangedByMove(Mat moved) {
  Mat copy;
  ASSERT_EQ(MatDuplicate(moved, MAT_COPY_VALUES, &copy), 0);
  Vec before = Product(moved);
  ASSERT_EQ(MoveMatrixToHugePages(moved), 0);
  PetscBool equal;
  ASSERT_EQ(MatEqual(moved, copy, &equal), 0);
  EXPECT_TRUE(equal);
  Vec after = Product(moved);
  EXPECT_TRUE(BitwiseEqual(before, after));
  VecDestroy(&before);
  VecDestroy(&after);
  MatDestroy(&copy);
}

// Kilobytes of 2 MB pages in the mapping of this process that holds `address`
// (its AnonHugePages line in /proc/self/smaps); -1 when not found. The advice
// splits a mapping at the range's ends, so `address` must lie inside the range.
long HugePageKilobytes(const void *address) {
  const uintptr_t a = reinterpret_cast<uintptr_t>(address);
  std::ifstream smaps("/proc/self/smaps");
  std::string line;
  bool inside = false;
  while (std::getline(smaps, line)) {
    unsigned long long start, end;
    if (std::sscanf(line.c_str(), "%llx-%llx ", &start, &end) == 2 && line.find(':') > 12) {
      inside = a >= start && a < end;
      continue;
    }
    long kilobytes;
    if (inside && std::sscanf(line.c_str(), "AnonHugePages: %ld kB", &kilobytes) == 1)
      return kilobytes;
  }
  return -1;
}

// Transparent huge pages not switched off, and a kernel with MADV_COLLAPSE.
bool KernelCanCollapse() {
  std::ifstream mode("/sys/kernel/mm/transparent_hugepage/enabled");
  std::stringstream text;
  text << mode.rdbuf();
  if (!mode || text.str().find("[never]") != std::string::npos) return false;
  utsname name;
  int major = 0, minor = 0;
  if (uname(&name) != 0 || std::sscanf(name.release, "%d.%d", &major, &minor) != 2) return false;
  return major > 6 || (major == 6 && minor >= 1);
}

}  // namespace

TEST(MatrixPages, ValuesAndProductsUnchanged) {
  BoxStiffness box(8, 6, 5);
  ExpectUnchangedByMove(box.K);  // AIJ
  Mat blocks;
  ASSERT_EQ(CopyToBlockMatrix(box.K, &blocks), 0);
  ExpectUnchangedByMove(blocks);  // BAIJ
  MatDestroy(&blocks);
}

TEST(MatrixPages, ValuesOnHugePages) {
  if (!KernelCanCollapse()) GTEST_SKIP() << "no transparent huge pages or no MADV_COLLAPSE";
  // About 1e5 tets: K's values in blocks take about 20 MB on one rank.
  BoxStiffness box(40, 20, 21);
  Mat blocks;
  ASSERT_EQ(CopyToBlockMatrix(box.K, &blocks), 0);
  Mat local = blocks;
  PetscMPIInt size;
  MPI_Comm_size(PETSC_COMM_WORLD, &size);
  if (size > 1) MatMPIBAIJGetSeqBAIJ(blocks, &local, nullptr, nullptr);
  PetscScalar *values;
  MatSeqBAIJGetArray(local, &values);
  MatInfo info;
  MatGetInfo(local, MAT_LOCAL, &info);
  const PetscScalar *middle = values + static_cast<size_t>(info.nz_used) / 2;
  const long before = HugePageKilobytes(middle);
  ASSERT_EQ(MoveMatrixToHugePages(blocks), 0);
  const long after = HugePageKilobytes(middle);
  MatSeqBAIJRestoreArray(local, &values);
  PetscPrintf(PETSC_COMM_SELF, "huge pages under K's values: %ld kB before, %ld kB after\n", before,
              after);
  EXPECT_GE(after, 2048);  // a whole 2 MB page at least, in the ~20 / size MB
  MatDestroy(&blocks);
}
