// PETSc (and MPI) for a GoogleTest program: initialised before the first test,
// finalised after the last. Include it in exactly one source of the program.
#pragma once

#include <gtest/gtest.h>
#include <petscsys.h>

namespace softbody {

class PetscEnvironment : public ::testing::Environment {
 public:
  void SetUp() override { PetscInitializeNoArguments(); }
  void TearDown() override { PetscFinalize(); }
};

inline const auto *const kPetscEnvironment =
    ::testing::AddGlobalTestEnvironment(new PetscEnvironment);

}  // namespace softbody
