// ProjectedSolver with two-sided constraints, by both of its paths (the
// Delassus path and the projected Delassus path), against the conditions the
// solution must meet, checked here from A, b and the returned reactions:
// - every one-sided constraint holds exactly: n . v_i = c (a vertex held by
//   three orthonormal ones has its prescribed velocity);
// - every two-sided row is complementary: r = n . (v_a - sum_k w_k v_k) - c >= 0,
//   lambda >= 0, lambda r = 0, and the row pushed hard is active;
// - the forces balance: R = A v - b - J_2^T lambda is zero at free vertices and
//   along n at a one-sided vertex, whose reported reaction is n . R.
// And the two paths give the same velocities. A is a chain of vertices joined
// by springs of random anisotropic stiffness plus a lumped mass; the
// unconstrained solver is CG with Jacobi (rtol 1e-14), so the test runs on
// any rank count.
// Runs on ranks: 1 3
#include <gtest/gtest.h>
#include <petscksp.h>

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "petsc_environment.hpp"
#include "solvers/projected_solve.hpp"

using namespace softbody;

namespace {

constexpr PetscInt kVertices = 60;
// The KKT conditions hold to the inner CG's rtol 1e-10 times the condition
// number of the chain (about 1e2): velocities and forces of order 1.
constexpr double kTolerance = 1e-7;

struct Problem {
  Mat A = nullptr;
  Vec b = nullptr;
  KSP ksp = nullptr;
  PetscInt begin = 0, end = 0;             // owned vertices
  std::vector<VelocityConstraint> global;  // vertex: the natural (= PETSc) number
  ~Problem() {
    KSPDestroy(&ksp);
    MatDestroy(&A);
    VecDestroy(&b);
  }
};

Eigen::Vector3d RandomUnit(std::mt19937 &random) {
  std::normal_distribution<double> normal(0.0, 1.0);
  return Eigen::Vector3d(normal(random), normal(random), normal(random)).normalized();
}

// A (3 kVertices DOFs): mass 1 per vertex, spring e between vertices e and
// e + 1 with stiffness Q diag(d) Q^T (Q random rotation, d in [1, 20]).
void Assemble(Problem *p) {
  PetscCallAbort(PETSC_COMM_WORLD,
                 MatCreateAIJ(PETSC_COMM_WORLD, PETSC_DECIDE, PETSC_DECIDE, 3 * kVertices,
                              3 * kVertices, 9, nullptr, 6, nullptr, &p->A));
  PetscCallAbort(PETSC_COMM_WORLD, MatSetBlockSize(p->A, 3));
  PetscInt rows_begin, rows_end;
  PetscCallAbort(PETSC_COMM_WORLD, MatGetOwnershipRange(p->A, &rows_begin, &rows_end));
  p->begin = rows_begin / 3, p->end = rows_end / 3;
  std::mt19937 random(7);
  std::uniform_real_distribution<double> stiffness(1.0, 20.0);
  for (PetscInt e = 0; e + 1 < kVertices; ++e) {
    const Eigen::Matrix3d Q =
        Eigen::HouseholderQR<Eigen::Matrix3d>(Eigen::Matrix3d::Random()).householderQ();
    const Eigen::Matrix3d k =
        Q * Eigen::Vector3d(stiffness(random), stiffness(random), stiffness(random)).asDiagonal() *
        Q.transpose();
    const PetscInt ends[2] = {e, e + 1};
    for (int a = 0; a < 2; ++a) {
      if (ends[a] < p->begin || ends[a] >= p->end) continue;
      for (int c = 0; c < 2; ++c)
        for (int i = 0; i < 3; ++i)
          for (int j = 0; j < 3; ++j)
            PetscCallAbort(PETSC_COMM_WORLD,
                           MatSetValue(p->A, 3 * ends[a] + i, 3 * ends[c] + j,
                                       (a == c ? 1.0 : -1.0) * k(i, j), ADD_VALUES));
    }
  }
  for (PetscInt r = rows_begin; r < rows_end; ++r)
    PetscCallAbort(PETSC_COMM_WORLD, MatSetValue(p->A, r, r, 1.0, ADD_VALUES));
  PetscCallAbort(PETSC_COMM_WORLD, MatAssemblyBegin(p->A, MAT_FINAL_ASSEMBLY));
  PetscCallAbort(PETSC_COMM_WORLD, MatAssemblyEnd(p->A, MAT_FINAL_ASSEMBLY));
  PetscCallAbort(PETSC_COMM_WORLD, MatCreateVecs(p->A, nullptr, &p->b));
  std::uniform_real_distribution<double> force(-1.0, 1.0);
  for (PetscInt r = 0; r < 3 * kVertices; ++r) {
    const double value = force(random);  // every rank draws every value
    if (r >= rows_begin && r < rows_end)
      PetscCallAbort(PETSC_COMM_WORLD, VecSetValue(p->b, r, value, INSERT_VALUES));
  }
  PetscCallAbort(PETSC_COMM_WORLD, VecAssemblyBegin(p->b));
  PetscCallAbort(PETSC_COMM_WORLD, VecAssemblyEnd(p->b));
  PetscCallAbort(PETSC_COMM_WORLD, KSPCreate(PETSC_COMM_WORLD, &p->ksp));
  PetscCallAbort(PETSC_COMM_WORLD, KSPSetOperators(p->ksp, p->A, p->A));
  PetscCallAbort(PETSC_COMM_WORLD, KSPSetType(p->ksp, KSPCG));
  PC pc;
  PetscCallAbort(PETSC_COMM_WORLD, KSPGetPC(p->ksp, &pc));
  PetscCallAbort(PETSC_COMM_WORLD, PCSetType(pc, PCJACOBI));
  PetscCallAbort(PETSC_COMM_WORLD,
                 KSPSetTolerances(p->ksp, 1e-14, PETSC_DEFAULT, PETSC_DEFAULT, 10000));
  PetscCallAbort(PETSC_COMM_WORLD, KSPSetUp(p->ksp));
}

// `one_sided` vertices (every other from vertex 1) with one random normal
// each, three of them held whole (three orthonormal constraints); two
// two-sided rows on free vertices: the first pushes hard (c = 5 m/s: active),
// the second is far from binding (c = -100 m/s: inactive).
void Constrain(Problem *p, int one_sided) {
  std::mt19937 random(11);
  std::uniform_real_distribution<double> speed(-1.0, 1.0);
  for (int k = 0; k < one_sided; ++k) {
    const PetscInt vertex = 1 + 2 * k;
    if (k % 10 == 3) {  // held whole, like the collision guard's zones
      const Eigen::Matrix3d Q =
          Eigen::HouseholderQR<Eigen::Matrix3d>(Eigen::Matrix3d::Random()).householderQ();
      for (int j = 0; j < 3; ++j) {
        VelocityConstraint c{vertex, Q.col(j), speed(random)};
        c.prescribes_all = true;
        c.order_key = vertex;
        p->global.push_back(c);
      }
      continue;
    }
    VelocityConstraint c{vertex, RandomUnit(random), speed(random)};
    c.order_key = vertex;
    p->global.push_back(c);
  }
  const PetscInt free_vertices[2][4] = {{2 * one_sided + 2, 10, 12, 14},
                                        {2 * one_sided + 4, 30, 32, 34}};
  const double velocities[2] = {5.0, -100.0};
  for (int r = 0; r < 2; ++r) {
    VelocityConstraint c{free_vertices[r][0], RandomUnit(random), velocities[r]};
    c.two_sided = true;
    c.face = {free_vertices[r][1], free_vertices[r][2], free_vertices[r][3]};
    c.weights = Eigen::Vector3d(0.2, 0.3, 0.5);
    c.order_key = free_vertices[r][0];
    p->global.push_back(c);
  }
}

// The constraints of this rank's vertices, in local numbering.
std::vector<VelocityConstraint> Owned(const Problem &p) {
  std::vector<VelocityConstraint> owned;
  for (VelocityConstraint c : p.global)
    if (c.vertex >= p.begin && c.vertex < p.end) {
      c.vertex -= p.begin;
      owned.push_back(c);
    }
  return owned;
}

// Every rank's copy of a distributed vector.
std::vector<double> Whole(Vec x) {
  VecScatter scatter;
  Vec all;
  PetscCallAbort(PETSC_COMM_WORLD, VecScatterCreateToAll(x, &scatter, &all));
  PetscCallAbort(PETSC_COMM_WORLD,
                 VecScatterBegin(scatter, x, all, INSERT_VALUES, SCATTER_FORWARD));
  PetscCallAbort(PETSC_COMM_WORLD, VecScatterEnd(scatter, x, all, INSERT_VALUES, SCATTER_FORWARD));
  const PetscScalar *values;
  PetscCallAbort(PETSC_COMM_WORLD, VecGetArrayRead(all, &values));
  std::vector<double> whole(values, values + 3 * kVertices);
  PetscCallAbort(PETSC_COMM_WORLD, VecRestoreArrayRead(all, &values));
  VecScatterDestroy(&scatter);
  VecDestroy(&all);
  return whole;
}

Eigen::Vector3d At(const std::vector<double> &x, PetscInt vertex) {
  return Eigen::Vector3d(x[3 * vertex], x[3 * vertex + 1], x[3 * vertex + 2]);
}

struct Solution {
  std::vector<double> v;
  std::vector<double> reactions;  // of p.global, every rank's (summed)
};

// Solves with `solver` (a new one when null) from a zero guess; *iterations:
// the inner CG's.
Solution SolveBy(Problem *p, TwoSidedPath path, ProjectedSolver *solver = nullptr,
                 PetscInt *iterations_out = nullptr) {
  ProjectedSolver own_solver;
  if (!solver) solver = &own_solver;
  solver->set_two_sided_path(path);
  const std::vector<VelocityConstraint> owned = Owned(*p);
  Vec v;
  PetscCallAbort(PETSC_COMM_WORLD, VecDuplicate(p->b, &v));
  PetscCallAbort(PETSC_COMM_WORLD, VecZeroEntries(v));
  std::vector<PetscReal> reactions;
  PetscInt iterations = 0;
  PetscCallAbort(PETSC_COMM_WORLD, solver->Solve(p->ksp, p->b, owned, v, &reactions, &iterations));
  if (iterations_out) *iterations_out = iterations;
  Solution s{Whole(v), std::vector<double>(p->global.size(), 0.0)};
  size_t k = 0;
  for (size_t g = 0; g < p->global.size(); ++g)
    if (p->global[g].vertex >= p->begin && p->global[g].vertex < p->end)
      s.reactions[g] = reactions[k++];
  MPI_Allreduce(MPI_IN_PLACE, s.reactions.data(), static_cast<int>(s.reactions.size()), MPI_DOUBLE,
                MPI_SUM, PETSC_COMM_WORLD);
  VecDestroy(&v);
  return s;
}

// The conditions of the file comment; `expected_active`: the two-sided rows
// that must be active.
void ExpectSolves(Problem *p, const Solution &s, const char *path, int expected_active = 1) {
  SCOPED_TRACE(path);
  // R = A v - b - J_2^T lambda, every rank's copy.
  Vec v, R;
  PetscCallAbort(PETSC_COMM_WORLD, VecDuplicate(p->b, &v));
  PetscCallAbort(PETSC_COMM_WORLD, VecDuplicate(p->b, &R));
  for (PetscInt r = 3 * p->begin; r < 3 * p->end; ++r)
    PetscCallAbort(PETSC_COMM_WORLD, VecSetValue(v, r, s.v[r], INSERT_VALUES));
  PetscCallAbort(PETSC_COMM_WORLD, VecAssemblyBegin(v));
  PetscCallAbort(PETSC_COMM_WORLD, VecAssemblyEnd(v));
  PetscCallAbort(PETSC_COMM_WORLD, MatMult(p->A, v, R));
  PetscCallAbort(PETSC_COMM_WORLD, VecAXPY(R, -1.0, p->b));
  std::vector<double> residual = Whole(R);
  VecDestroy(&v);
  VecDestroy(&R);
  std::vector<char> constrained(kVertices, 0);
  int active = 0;
  for (size_t g = 0; g < p->global.size(); ++g) {
    const VelocityConstraint &c = p->global[g];
    if (!c.two_sided) continue;
    const double lambda = s.reactions[g];
    const Eigen::Vector3d relative = At(s.v, c.vertex) - c.weights[0] * At(s.v, c.face[0]) -
                                     c.weights[1] * At(s.v, c.face[1]) -
                                     c.weights[2] * At(s.v, c.face[2]);
    const double r = c.normal.dot(relative) - c.velocity;
    EXPECT_GE(r, -kTolerance) << "two-sided row " << g;
    EXPECT_GE(lambda, 0.0) << "two-sided row " << g;
    EXPECT_LE(std::abs(lambda * r), kTolerance) << "two-sided row " << g;
    active += lambda > kTolerance;
    // Its impulse: +lambda n on the vertex, -lambda w_k n on the face.
    for (int a = 0; a < 4; ++a) {
      const PetscInt vertex = a == 0 ? c.vertex : c.face[a - 1];
      const double weight = a == 0 ? 1.0 : -c.weights[a - 1];
      for (int i = 0; i < 3; ++i) residual[3 * vertex + i] -= lambda * weight * c.normal[i];
    }
  }
  EXPECT_EQ(active, expected_active) << "the row pushed hard is active, the other not";
  for (size_t g = 0; g < p->global.size(); ++g) {
    const VelocityConstraint &c = p->global[g];
    if (c.two_sided) continue;
    constrained[c.vertex] = 1;
    EXPECT_NEAR(c.normal.dot(At(s.v, c.vertex)), c.velocity, kTolerance) << "one-sided " << g;
    EXPECT_NEAR(c.normal.dot(At(residual, c.vertex)), s.reactions[g], kTolerance)
        << "one-sided " << g << ": its reaction";
    if (!c.prescribes_all)  // a single constraint: the force lies along n
      EXPECT_LE((At(residual, c.vertex) - c.normal * c.normal.dot(At(residual, c.vertex))).norm(),
                kTolerance)
          << "one-sided " << g << ": the force lies along n";
  }
  for (PetscInt vertex = 0; vertex < kVertices; ++vertex)
    if (!constrained[vertex])
      EXPECT_LE(At(residual, vertex).norm(), kTolerance) << "free vertex " << vertex;
}

double LargestDifference(const Solution &a, const Solution &b, double *scale) {
  double difference = 0;
  *scale = 0;
  for (size_t i = 0; i < a.v.size(); ++i) {
    difference = std::max(difference, std::abs(a.v[i] - b.v[i]));
    *scale = std::max(*scale, std::abs(a.v[i]));
  }
  return difference;
}

// The unconstrained solver becomes an exact factorisation of A (LU of the
// whole matrix on every rank): M^-1 = A^-1.
void UseFactorisation(Problem *p) {
  PetscCallAbort(PETSC_COMM_WORLD, KSPSetType(p->ksp, KSPPREONLY));
  PC pc;
  PetscCallAbort(PETSC_COMM_WORLD, KSPGetPC(p->ksp, &pc));
  PetscCallAbort(PETSC_COMM_WORLD, PCSetType(pc, PCREDUNDANT));
  PetscCallAbort(PETSC_COMM_WORLD, KSPSetUp(p->ksp));
}

// Every path for two-sided rows meets the conditions, and its velocities are
// the Delassus path's to kTolerance of their scale.
void ExpectEveryPathAgrees(Problem *p) {
  const Solution delassus = SolveBy(p, TwoSidedPath::kDelassus);
  ExpectSolves(p, delassus, "Delassus path");
  const std::pair<TwoSidedPath, const char *> others[] = {
      {TwoSidedPath::kProjected, "projected Delassus path"},
      {TwoSidedPath::kAugmented, "augmented Lagrangian path"}};
  for (const auto &[path, name] : others) {
    const Solution other = SolveBy(p, path);
    ExpectSolves(p, other, name);
    double scale;
    const double difference = LargestDifference(delassus, other, &scale);
    EXPECT_LE(difference, kTolerance * scale)
        << name << ": the velocities against the Delassus path's";
  }
}

TEST(ProjectedSolver, EveryTwoSidedPathMeetsTheConditionsAndTheyAgree) {
  Problem p;
  Assemble(&p);
  Constrain(&p, 20);
  ExpectEveryPathAgrees(&p);
}

// The same with a factorisation as the unconstrained solver, which the
// augmented path also takes from kAugmentedFactorCost rows on: its projected
// solves then precondition with A^-1.
TEST(ProjectedSolver, EveryTwoSidedPathAgreesWithAFactorisation) {
  Problem p;
  Assemble(&p);
  UseFactorisation(&p);
  Constrain(&p, 20);
  ExpectEveryPathAgrees(&p);
}

// Contacts found from both sides (a vertex of one body on the other's face,
// and that face's vertex on the first body's face) make nearly the same row
// twice, with right-hand sides a hair apart: the tighter one binds. The
// augmented path's multipliers would drain from the looser row by rho times
// that hair per outer iteration; it stops once the violation no longer falls
// and lies within its stall tolerance (1e-4 of the speeds), so it takes a few
// outer iterations, not its limit of 60 (each at least one CG iteration),
// and its velocities agree with the Delassus path's (least-norm on the
// redundant rows) to that tolerance.
TEST(ProjectedSolver, AugmentedPathStopsOnRowsFoundFromBothSides) {
  Problem p;
  Assemble(&p);
  Constrain(&p, 20);
  VelocityConstraint twin = p.global[p.global.size() - 2];  // the row that binds
  twin.velocity -= 1e-6;                                    // looser by a hair
  twin.weights = Eigen::Vector3d(0.2 + 1e-4, 0.3, 0.5 - 1e-4);
  p.global.push_back(twin);
  const Solution delassus = SolveBy(&p, TwoSidedPath::kDelassus);
  ProjectedSolver solver;
  const Solution augmented = SolveBy(&p, TwoSidedPath::kAugmented, &solver);
  double scale;
  const double difference = LargestDifference(delassus, augmented, &scale);
  EXPECT_LE(difference, 1e-4 * scale);
  EXPECT_LT(solver.augmented_outer_iterations(), 10) << "the outer iterations stopped at the stall";
}

// Two rows in conflict: the row that binds and its mirror (the opposite
// normal), asking for a relative velocity kConflict above what the first
// allows. Both push, their multipliers grow at every outer iteration and the
// compromise between them does not move: the augmented path stops once the
// violation stays put (within 1e-3 of the speeds), in a few outer
// iterations rather than its limit of 60, with each row violated by about
// half the conflict and the one-sided constraints held.
TEST(ProjectedSolver, AugmentedPathStopsOnRowsInConflict) {
  Problem p;
  Assemble(&p);
  Constrain(&p, 20);
  const VelocityConstraint binding = p.global[p.global.size() - 2];
  constexpr double kConflict = 4e-3;  // m/s: between 1e-4 and 1e-3 of the speeds (about 5)
  VelocityConstraint mirror = binding;
  mirror.normal = -binding.normal;
  mirror.velocity = -binding.velocity + kConflict;
  p.global.push_back(mirror);
  ProjectedSolver solver;
  const Solution s = SolveBy(&p, TwoSidedPath::kAugmented, &solver);
  EXPECT_LT(solver.augmented_outer_iterations(), 10) << "stopped on the conflict";
  for (const VelocityConstraint &c : {binding, mirror}) {
    const Eigen::Vector3d relative = At(s.v, c.vertex) - c.weights[0] * At(s.v, c.face[0]) -
                                     c.weights[1] * At(s.v, c.face[1]) -
                                     c.weights[2] * At(s.v, c.face[2]);
    EXPECT_GE(c.normal.dot(relative) - c.velocity, -kConflict) << "violated by about half";
  }
  for (const VelocityConstraint &c : p.global)
    if (!c.two_sided)
      EXPECT_NEAR(c.normal.dot(At(s.v, c.vertex)), c.velocity, kTolerance) << "one-sided held";
}

// The constraint correction (constraint_correction.hpp) with M^-1 = A^-1 is
// the exact inverse of the projected operator: the inner CG ends in one
// iteration, where the plain preconditioner needs about one per constraint
// (this problem: 20 constrained vertices, two of them held whole). Also after
// a change of the right-hand side (the same rows: S reused) and of the
// constraints (the columns reused, a new S), and both meet the conditions and
// give the same velocities.
TEST(ProjectedSolver, ConstraintCorrectionEndsInOneIterationWithAFactorisation) {
  Problem p;
  Assemble(&p);
  Constrain(&p, 20);
  p.global.erase(std::remove_if(p.global.begin(), p.global.end(),
                                [](const VelocityConstraint &c) { return c.two_sided; }),
                 p.global.end());
  UseFactorisation(&p);
  PetscInt plain_iterations = 0, iterations = 0;
  const Solution plain = SolveBy(&p, TwoSidedPath::kAuto, nullptr, &plain_iterations);
  ExpectSolves(&p, plain, "plain preconditioner", 0);
  EXPECT_GE(plain_iterations, 10) << "without the correction";

  ProjectedSolver solver;
  solver.set_constraint_correction(true);
  const Solution corrected = SolveBy(&p, TwoSidedPath::kAuto, &solver, &iterations);
  ExpectSolves(&p, corrected, "corrected preconditioner", 0);
  EXPECT_LE(iterations, 1) << "the first solve";
  double scale;
  const double difference = LargestDifference(plain, corrected, &scale);
  EXPECT_LE(difference, kTolerance * scale);
  const PetscInt columns = solver.correction_column_solves();
  EXPECT_EQ(columns, 3 * 20) << "three columns per constrained vertex";

  PetscCallAbort(PETSC_COMM_WORLD, VecScale(p.b, -2.0));  // the same rows: S reused
  const Solution scaled = SolveBy(&p, TwoSidedPath::kAuto, &solver, &iterations);
  ExpectSolves(&p, scaled, "another right-hand side", 0);
  EXPECT_LE(iterations, 1) << "another right-hand side";

  p.global.resize(p.global.size() / 2);  // fewer rows: the columns reused, a new S
  const Solution fewer = SolveBy(&p, TwoSidedPath::kAuto, &solver, &iterations);
  ExpectSolves(&p, fewer, "fewer constraints", 0);
  EXPECT_LE(iterations, 1) << "fewer constraints";
  EXPECT_EQ(solver.correction_column_solves(), columns) << "no new column";
}

// With an inexact M (Jacobi) the correction is still a preconditioner of the
// same problem: the conditions hold, also with two-sided rows (the projected
// Delassus path). (Here it saves no iteration: Jacobi's diagonal is nearly
// isotropic per vertex, where P M^-1 P is already (P M P)^+.)
TEST(ProjectedSolver, ConstraintCorrectionWithAnInexactPreconditionerSolvesTheSameProblem) {
  Problem p;
  Assemble(&p);
  Constrain(&p, 20);
  ProjectedSolver solver;
  solver.set_constraint_correction(true);
  PetscInt plain_iterations = 0, iterations = 0;
  const Solution plain = SolveBy(&p, TwoSidedPath::kProjected, nullptr, &plain_iterations);
  const Solution corrected = SolveBy(&p, TwoSidedPath::kProjected, &solver, &iterations);
  ExpectSolves(&p, corrected, "corrected, projected Delassus path");
  double scale;
  const double difference = LargestDifference(plain, corrected, &scale);
  EXPECT_LE(difference, kTolerance * scale);
  EXPECT_GT(solver.correction_column_solves(), 0) << "the correction took part";
}

}  // namespace
