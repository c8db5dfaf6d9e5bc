// RowAssembler (row_assembly.hpp): the matrix, elastic force and energy it
// writes straight into A's CSR values equal the element-by-element COO assembly
// (assembly.hpp, coo_reference.hpp) in linear and corotational mode, for both shear scales, and
// so do the corotated stiffness damping's increment force and energy; and
// its speed (printed, not asserted: the machine may be shared).
#include <gtest/gtest.h>
#include <petscmat.h>

#include <chrono>
#include <random>

#include "box_mesh.hpp"
#include "coo_reference.hpp"
#include "fem/assembly.hpp"
#include "fem/partition.hpp"
#include "fem/row_assembly.hpp"
#include "io/scene.hpp"
#include "petsc_environment.hpp"

using namespace softbody;
using namespace softbody::coo_reference;

namespace {

Scene BoxScene(int nx, int ny, int nz) {
  Scene scene;
  Body body;
  body.material = {1000.0, 1e6, 0.4};
  body.fixed = false;
  body.mesh = BoxMesh(nx, ny, nz, 0.1);
  body.first_vertex = 0;
  scene.bodies.push_back(body);
  return scene;
}

// Positions: rest positions rotated by a large angle, stretched by `stretch`
// along x and compressed by half of it along z, and perturbed by `noise` (m;
// the box's cells are 0.1 m).
PetscErrorCode DeformedPositions(Vec rest, Vec x, double stretch = 0.1, double noise_size = 0.01) {
  PetscFunctionBeginUser;
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0.0, noise_size);
  const Eigen::Matrix3d R =
      Eigen::AngleAxisd(1.1, Eigen::Vector3d(1, 2, 3).normalized()).toRotationMatrix();
  const PetscScalar *X;
  PetscScalar *y;
  PetscInt n;
  PetscCall(VecGetLocalSize(rest, &n));
  PetscCall(VecGetArrayRead(rest, &X));
  PetscCall(VecGetArray(x, &y));
  for (PetscInt v = 0; v < n / 3; ++v) {
    const Eigen::Vector3d p(X[3 * v] * (1 + stretch), X[3 * v + 1],
                            X[3 * v + 2] * (1 - 0.5 * stretch));
    const Eigen::Vector3d q = R * p;
    for (int c = 0; c < 3; ++c) y[3 * v + c] = q[c] + noise(rng);
  }
  PetscCall(VecRestoreArrayRead(rest, &X));
  PetscCall(VecRestoreArray(x, &y));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// |reference - v| (2-norm) and |reference| in *scale; reference holds v's local
// entries in order (one rank), work is a vector like v.
PetscReal DifferenceFrom(const std::vector<PetscScalar> &reference, Vec v, Vec work,
                         PetscReal *scale) {
  PetscScalar *w;
  VecGetArray(work, &w);
  std::copy(reference.begin(), reference.end(), w);
  VecRestoreArray(work, &w);
  PetscReal difference;
  VecNorm(work, NORM_2, scale);
  VecAXPY(work, -1.0, v);
  VecNorm(work, NORM_2, &difference);
  return difference;
}

double RelativeMatrixDifference(Mat A, Mat B) {
  Mat D;
  MatConvert(A, MATSAME, MAT_INITIAL_MATRIX, &D);
  MatAXPY(D, -1.0, B, DIFFERENT_NONZERO_PATTERN);
  PetscReal difference, scale;
  MatNorm(D, NORM_FROBENIUS, &difference);
  MatNorm(B, NORM_FROBENIUS, &scale);
  MatDestroy(&D);
  return difference / scale;
}

struct Fixture {
  Scene scene;
  MeshShare share;
  DofLayout layout;
  LocalTets tets;
  LocalElements elements;
  State state;
  RowAssembler assembler;
  Mat A = nullptr;

  explicit Fixture(int nx, int ny, int nz, double shear_scale) : scene(BoxScene(nx, ny, nz)) {
    PetscMPIInt rank, size;
    MPI_Comm_rank(PETSC_COMM_WORLD, &rank);
    MPI_Comm_size(PETSC_COMM_WORLD, &size);
    share = ShareScene(scene, rank, size);
    BuildDofLayout(PETSC_COMM_WORLD, PartitionOptions(), &share, &layout);
    MigrateTets(PETSC_COMM_WORLD, share, layout, &tets);
    elements = CollectLocalElements(scene, layout, tets);
    CreateState(PETSC_COMM_WORLD, share, layout, elements, &state);
    assembler.Setup(PETSC_COMM_WORLD, scene, layout, std::move(tets), shear_scale,
                    state.rest_positions);
    assembler.CreateMatrix(&A);
  }
  ~Fixture() { MatDestroy(&A); }
};

}  // namespace

TEST(RowAssembler, EqualsCooAssembly) {
  for (const double shear_scale : {1.0, 0.25}) {
    Fixture f(4, 3, 5, shear_scale);
    const double stiffness_scale = 2e-3, mass_scale = 1.01;
    // Linear: K and A = mass_scale M + stiffness_scale K.
    {
      Mat reference;
      CooValues values(144 * f.elements.size());
      LinearStiffnessValues(f.elements, shear_scale, stiffness_scale, &values);
      ASSERT_EQ(ReferenceMatrix(PETSC_COMM_WORLD, f.layout, f.elements, values, f.state.lumped_mass,
                                mass_scale, &reference),
                0);
      ASSERT_EQ(f.assembler.Fill(f.A, RowAssembler::FillTerms()
                                          .Stiffness(stiffness_scale)
                                          .Mass(f.state.lumped_mass, mass_scale)),
                0);
      EXPECT_LT(RelativeMatrixDifference(f.A, reference), 1e-14) << "shear scale " << shear_scale;
      MatDestroy(&reference);
    }
    // Corotational: A, f_el and the energy at deformed, rotated positions.
    {
      Vec x, force, reference_force;
      VecDuplicate(f.state.rest_positions, &x);
      VecDuplicate(x, &force);
      VecDuplicate(x, &reference_force);
      ASSERT_EQ(DeformedPositions(f.state.rest_positions, x), 0);
      PetscReal energy;
      f.assembler.ComputeVertexRotations(true);
      ASSERT_EQ(f.assembler.Fill(f.A, RowAssembler::FillTerms()
                                          .Stiffness(stiffness_scale)
                                          .Mass(f.state.lumped_mass, mass_scale)
                                          .CorotatedAt(x)
                                          .ElasticForce(force)
                                          .StrainEnergy(&energy)),
                0);

      Mat reference;
      PetscInt local_dofs;
      VecGetLocalSize(f.state.lumped_mass, &local_dofs);
      CooValues values;
      const PetscScalar *xa, *Xa;
      VecGetArrayRead(x, &xa);
      VecGetArrayRead(f.state.rest_positions, &Xa);
      // One rank: the touched vertices are all vertices, in order.
      std::vector<PetscScalar> force_touched(3 * f.elements.touched_vertices.size());
      ASSERT_EQ(f.elements.touched_vertices.size() * 3, static_cast<size_t>(local_dofs));
      const double reference_energy = CorotatedStiffnessValues(
          f.elements, shear_scale, xa, Xa, stiffness_scale, &values, force_touched.data());
      VecRestoreArrayRead(x, &xa);
      VecRestoreArrayRead(f.state.rest_positions, &Xa);
      ASSERT_EQ(ReferenceMatrix(PETSC_COMM_WORLD, f.layout, f.elements, values, f.state.lumped_mass,
                                mass_scale, &reference),
                0);
      EXPECT_LT(RelativeMatrixDifference(f.A, reference), 1e-13) << "shear scale " << shear_scale;
      PetscReal scale;
      const PetscReal difference = DifferenceFrom(force_touched, force, reference_force, &scale);
      EXPECT_LT(difference, 1e-12 * scale);
      EXPECT_NEAR(energy, reference_energy, 1e-12 * reference_energy);
      // Vertex rotations are proper rotations.
      const std::vector<double> &rotations = f.assembler.vertex_rotations();
      ASSERT_EQ(rotations.size(), 3 * static_cast<size_t>(local_dofs));
      for (size_t v = 0; v < rotations.size() / 9; ++v) {
        const Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> R(rotations.data() +
                                                                               9 * v);
        EXPECT_LT((R.transpose() * R - Eigen::Matrix3d::Identity()).norm(), 1e-12);
        EXPECT_NEAR(R.determinant(), 1.0, 1e-12);
      }
      MatDestroy(&reference);
      VecDestroy(&x);
      VecDestroy(&force);
      VecDestroy(&reference_force);
    }
  }
}

// The corotated stiffness damping (integrator.hpp): from a start configuration
// x0 to x1, force sum_e R1 K_e (y1_e - y0_e) and energy sum_e |y1_e - y0_e|_K_e^2 / 2
// (y = R^T x - X) equal the element-by-element reference, which stores y_e
// itself (the row assembler stores its displacement gradient), for both shear
// scales; and a rigid motion between x0 and x1 has neither.
TEST(RowAssembler, IncrementDampingEqualsReference) {
  for (const double shear_scale : {1.0, 0.25}) {
    Fixture f(4, 3, 5, shear_scale);
    Vec x0, x1, force, reference_force;
    VecDuplicate(f.state.rest_positions, &x0);
    VecDuplicate(x0, &x1);
    VecDuplicate(x0, &force);
    VecDuplicate(x0, &reference_force);
    ASSERT_EQ(DeformedPositions(f.state.rest_positions, x0, 0.05, 1e-3), 0);
    ASSERT_EQ(DeformedPositions(f.state.rest_positions, x1, 0.1, 0.01), 0);
    std::vector<double> start, current;
    RowAssembler::IncrementDamping damping{&start, nullptr, force};
    ASSERT_EQ(f.assembler.Fill(f.A, RowAssembler::FillTerms().CorotatedAt(x0).Damping(&damping)),
              0);
    damping = {&current, &start, force};
    ASSERT_EQ(f.assembler.Fill(f.A, RowAssembler::FillTerms().CorotatedAt(x1).Damping(&damping)),
              0);

    // Reference: the COO pass with CorotatedDamping, at x0 (y0) then at x1.
    PetscInt local_dofs;
    VecGetLocalSize(x0, &local_dofs);
    ASSERT_EQ(f.elements.touched_vertices.size() * 3, static_cast<size_t>(local_dofs));  // one rank
    CooValues values;
    std::vector<PetscScalar> force_touched(local_dofs), increment_touched(local_dofs);
    std::vector<double> y0, y1;
    const PetscScalar *x0a, *x1a, *Xa;
    VecGetArrayRead(x0, &x0a);
    VecGetArrayRead(x1, &x1a);
    VecGetArrayRead(f.state.rest_positions, &Xa);
    CorotatedDamping first{&y0, nullptr, nullptr};
    CorotatedStiffnessValues(f.elements, shear_scale, x0a, Xa, 1.0, &values, force_touched.data(),
                             &first);
    CorotatedDamping second{&y1, y0.data(), increment_touched.data()};
    CorotatedStiffnessValues(f.elements, shear_scale, x1a, Xa, 1.0, &values, force_touched.data(),
                             &second);
    VecRestoreArrayRead(x0, &x0a);
    VecRestoreArrayRead(x1, &x1a);
    VecRestoreArrayRead(f.state.rest_positions, &Xa);
    EXPECT_GT(second.energy, 0.0);
    EXPECT_NEAR(damping.energy, second.energy, 1e-12 * second.energy)
        << "shear scale " << shear_scale;
    PetscReal scale;
    const PetscReal difference = DifferenceFrom(increment_touched, force, reference_force, &scale);
    EXPECT_LT(difference, 1e-12 * scale) << "shear scale " << shear_scale;

    // x1 = x0 turned by 40 degrees and shifted: no increment, no force, no energy.
    const Eigen::Matrix3d Q =
        Eigen::AngleAxisd(0.7, Eigen::Vector3d(0, 1, 1).normalized()).toRotationMatrix();
    PetscScalar *x1w;
    VecGetArrayRead(x0, &x0a);
    VecGetArray(x1, &x1w);
    for (PetscInt v = 0; v < local_dofs / 3; ++v)
      Eigen::Map<Eigen::Vector3d>(x1w + 3 * v) =
          Q * Eigen::Vector3d(x0a + 3 * v) + Eigen::Vector3d(1, -2, 3);
    VecRestoreArray(x1, &x1w);
    VecRestoreArrayRead(x0, &x0a);
    damping = {&current, &start, force};
    ASSERT_EQ(f.assembler.Fill(f.A, RowAssembler::FillTerms().CorotatedAt(x1).Damping(&damping)),
              0);
    PetscReal rigid_force;
    VecNorm(force, NORM_2, &rigid_force);
    EXPECT_LT(rigid_force, 1e-9 * scale);
    EXPECT_LT(damping.energy, 1e-16 * second.energy + 1e-300);
    for (Vec *w : {&x0, &x1, &force, &reference_force}) VecDestroy(w);
  }
}

// The corotational refill rate (rotations, rotated element blocks, force,
// energy, written into A), best of a few fills of a ~100k-tet box turned by 63
// degrees with strains of about 1 %. Printed only.
TEST(RowAssembler, CorotationalRefillRate) {
  Fixture f(40, 20, 21, 1.0);
  Vec x, force;
  VecDuplicate(f.state.rest_positions, &x);
  VecDuplicate(x, &force);
  ASSERT_EQ(DeformedPositions(f.state.rest_positions, x, 0.01, 1e-3), 0);
  double best = 1e30;
  for (int repeat = 0; repeat < 7; ++repeat) {
    PetscReal energy;
    const auto start = std::chrono::steady_clock::now();
    ASSERT_EQ(f.assembler.Fill(f.A, RowAssembler::FillTerms()
                                        .Stiffness(1e-3)
                                        .Mass(f.state.lumped_mass, 1.0)
                                        .CorotatedAt(x)
                                        .ElasticForce(force)
                                        .StrainEnergy(&energy)),
              0);
    best = std::min(
        best, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
  }
  const double tets = static_cast<double>(f.scene.num_tets());
  std::printf("corotational refill of %.0f tets: %.2f ms, %.2f M tets/s (best of 7)\n", tets,
              1e3 * best, tets / best / 1e6);
  VecDestroy(&x);
  VecDestroy(&force);
}
