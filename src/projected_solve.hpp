// The implicit step's linear solve with contact: A v = b subject to velocity
// constraints n_i . v_i = c_i on some vertices (frictionless: the tangential
// velocity stays free), in the spirit of Baraff & Witkin 1998 ("Large steps in
// cloth simulation", the filtered CG). With P the projection that removes the
// constrained normal components and z the vector of the prescribed ones,
// v = P w + z where
//
//     (P A P + I - P) w = P (b - A z),
//
// an SPD system solved by CG preconditioned with P M^-1 P + I - P, M^-1 being the
// unconstrained solver's preconditioner (for the direct preset: A's Cholesky
// factor, so CG needs at most one iteration per constraint, usually far fewer).
// The constraint's reaction is lambda_i = n_i . (A v - b)_i (kg m/s, the normal
// impulse the obstacle gives vertex i this step): positive pushes outward.
// Options of the inner solve take the prefix -contact_ (e.g. -contact_ksp_rtol).
#pragma once

#include <petscksp.h>

#include <Eigen/Core>
#include <vector>

namespace softbody {

struct VelocityConstraint {
  PetscInt vertex;          // local vertex index (owned)
  Eigen::Vector3d normal;   // unit
  PetscReal velocity;       // prescribed n . v (m/s)
};

class ProjectedSolver {
 public:
  ProjectedSolver() = default;
  ProjectedSolver(const ProjectedSolver &) = delete;
  ProjectedSolver &operator=(const ProjectedSolver &) = delete;
  ~ProjectedSolver();

  // Collective. v: initial guess on entry, solution on exit. reactions: one per
  // constraint. `solver` is the set-up unconstrained KSP of A.
  PetscErrorCode Solve(KSP solver, Vec b, const std::vector<VelocityConstraint> &constraints, Vec v,
                       std::vector<PetscReal> *reactions, PetscInt *iterations);

 private:
  static PetscErrorCode ApplyOperator(Mat shell, Vec w, Vec y);
  static PetscErrorCode ApplyPreconditioner(PC shell, Vec w, Vec y);
  // y = P w (project == true) or y = (I - P) w.
  void Project(const PetscScalar *w, PetscScalar *y, bool project) const;
  PetscErrorCode ProjectVec(Vec w, Vec y, bool project) const;

  KSP inner_ = nullptr;
  Mat shell_ = nullptr;
  Mat A_ = nullptr;                 // not owned
  PC unconstrained_pc_ = nullptr;   // not owned
  const std::vector<VelocityConstraint> *constraints_ = nullptr;
  Vec work_ = nullptr, work2_ = nullptr, z_ = nullptr, rhs_ = nullptr, w_ = nullptr;
};

}  // namespace softbody
