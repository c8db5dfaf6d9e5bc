// PETSc (and MPI) for a GoogleTest program: initialised before the first test,
// finalised after the last. Include it in exactly one source of the program.
// Also small helpers of the tests that run on several ranks.
#pragma once

#include <gtest/gtest.h>
#include <petscsys.h>

#include <vector>

#include "common/exchange.hpp"

namespace softbody {

class PetscEnvironment : public ::testing::Environment {
 public:
  void SetUp() override { PetscInitializeNoArguments(); }
  void TearDown() override { PetscFinalize(); }
};

inline const auto *const kPetscEnvironment =
    ::testing::AddGlobalTestEnvironment(new PetscEnvironment);

// This rank and the number of ranks of PETSC_COMM_WORLD.
inline PetscMPIInt Rank() {
  PetscMPIInt rank;
  MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
  return rank;
}
inline PetscMPIInt Size() {
  PetscMPIInt size;
  MPI_Comm_size(PETSC_COMM_WORLD, &size);
  return size;
}

// Every rank's values, in rank order, on every rank.
template <class T>
std::vector<T> AllGather(const std::vector<T> &mine) {
  std::vector<T> all;
  AllGatherRecords(PETSC_COMM_WORLD, mine, &all);
  return all;
}

}  // namespace softbody
