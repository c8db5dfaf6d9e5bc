// The implicit step's linear solve with contact: A v = b subject to velocity
// constraints n_k . v_i = c_k on some vertices (one to three per vertex, e.g. a
// normal, or a normal and two tangents for a sticking contact; the rest of the
// velocity stays free), in the spirit of Baraff & Witkin 1998 ("Large steps in
// cloth simulation", the filtered CG). With P the projection that removes, per
// vertex, the span of its constraint directions and z the prescribed part,
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
//
// Two-sided constraints (free-free contacts, VelocityConstraint::two_sided)
// couple vertices of different bodies, possibly on other ranks, and are
// inequalities. When any rank has one, every constraint becomes a row j of J
// (a vertex constraint: its combined directions, CombineConstraints; a
// two-sided one: its vertex and face), and the step solves the mixed
// complementarity problem on the Delassus operator D = J A^-1 J^T (mixed_lcp.hpp):
// D is built from one solve with the unconstrained solver per row (back-solves
// with the direct preset; in linear mode with a factorisation, from the kept
// columns A^-1 e of the rows' vertices instead: two_sided_solve.cpp), reduced
// over the ranks and solved identically on each; then A v = b + J^T lambda.
// The rows are few (a stack of blocks: a few hundred); scenes without
// two-sided constraints never take this path.
// When the one-sided rows far outnumber the two-sided ones (m1 >= 16 (m2 + 2),
// kProjectedSolveCost in projected_solve.cpp; e.g. two bodies pressed into
// each other and the ground, held by the collision guard's zones), the
// projected Delassus path keeps the one-sided constraints in the projection:
// with S(f) the projected solve of A v = f, affine, S(f) = z + G (f - A z),
// G = P (P A P + I - P)^-1 P, it solves the problem of the m2 two-sided rows
// J_2 on D_2 = J_2 G J_2^T (m2 homogeneous projected solves) and
// g = J_2 S(b) - c, then v = S(b + J_2^T lambda): m2 + 2 projected solves
// instead of m1 + m2 + 1 back-solves and a dense problem of size m1 + m2. The
// same solution, to the inner CG's tolerance.
// With an iterative unconstrained solver (CG + GAMG, the corotational warp) a
// column of D costs a whole Krylov solve, so many rows (one- and two-sided:
// more than kAugmentedSolveCost, projected_solve.cpp) take the augmented Lagrangian
// path instead (augmented_solve.cpp): the two-sided rows enter the projected
// operator as a penalty, P (A + J_S^T R J_S) P, on the rows S that push, and
// their multipliers are updated between projected solves until every row
// holds to a tolerance: a few projected solves whatever the number of rows.
// With a factorisation it is taken from kAugmentedFactorCost rows on, where
// the Delassus path's back-solves per row and m x m problem cost more. The
// multipliers start from VelocityConstraint::guess (a resting contact's last
// reaction).
#pragma once

#include <petscksp.h>

#include <Eigen/Core>
#include <array>
#include <map>
#include <memory>
#include <vector>

namespace softbody {

class ConstraintCorrection;
struct RowPenalty;

struct VelocityConstraint {
  PetscInt vertex;         // local vertex index (owned)
  Eigen::Vector3d normal;  // unit direction n
  PetscReal velocity;      // prescribed n . v (m/s)
  bool immobile = false;   // from an obstacle that cannot yield (ground, fixed body)
  // One of three orthonormal constraints that prescribe the whole velocity (the
  // collision guard's): they override every other constraint of the vertex.
  bool prescribes_all = false;
  // Two-sided (a contact between two free bodies): the inequality
  //   n . (v_vertex - sum_k weights_k v_{face_k}) >= velocity,
  // face_k PETSc (global) vertex numbers of any rank (-1: none); its reaction
  // lambda >= 0 acts as +lambda n on the vertex and -lambda w_k n on face_k, so
  // the two bodies get equal and opposite impulses.
  bool two_sided = false;
  std::array<PetscInt, 3> face{{-1, -1, -1}};
  Eigen::Vector3d weights = Eigen::Vector3d::Zero();
  // A rank-independent number of the vertex (its natural number) that orders
  // the rows of the two-sided solve, so that they come in the same order on
  // any rank count; -1: the vertex's PETSc number (rank-dependent).
  PetscInt order_key = -1;
  // Two-sided: an estimate of its reaction lambda (N s), the last step's for a
  // resting contact; the augmented Lagrangian path starts its multiplier there
  // (the other paths do not read it).
  PetscReal guess = 0;
};
// The constraints of one vertex: an orthonormal basis of their directions and
// the velocity component in its span that satisfies them all.
struct ConstrainedVertex {
  PetscInt vertex;
  Eigen::Matrix3d basis;  // first `rank` columns
  int rank;
  Eigen::Vector3d prescribed;
};

// The constraints n_k . v = c_k of one vertex combined (directions unit). Two
// directions less than ~6 degrees apart (smallest singular value of [n_1 n_2]
// below kMinSeparation) cannot both hold exactly without a huge velocity
// ((c_1 - c_2) / sin of their angle): of such a group only one is imposed. The
// imposed set S is the largest one whose directions are well apart and whose
// exact solution p (least norm) satisfies the others as n_k . p >= c_k (it takes
// the vertex out of every obstacle at least as fast as asked); among equals the
// one with more constraints from immobile obstacles (a left-out direction holds
// only up to the free velocity's component along it), then the smallest |p|.
// Pure; the first six constraints are considered (a contact with its two
// friction tangents and the normals of up to three obstacles). Constraints that
// prescribe_all override the rest: the vertex's velocity is sum_k c_k n_k of them.
constexpr double kMinSeparation = 0.1;
ConstrainedVertex CombineConstraints(PetscInt vertex,
                                     const std::vector<VelocityConstraint> &constraints);

// How Solve treats two-sided constraints: by kAugmentedSolveCost,
// kAugmentedFactorCost and kProjectedSolveCost (auto), or always by one path
// (-contact_solve; the tests compare them).
enum class TwoSidedPath { kAuto, kDelassus, kProjected, kAugmented };
// Names for -contact_solve, in TwoSidedPath's order (PetscOptionsEnum's list).
extern const char *const kTwoSidedPaths[];

class ProjectedSolver {
 public:
  ProjectedSolver();
  ProjectedSolver(const ProjectedSolver &) = delete;
  ProjectedSolver &operator=(const ProjectedSolver &) = delete;
  ~ProjectedSolver();

  // Collective. v: initial guess on entry, solution on exit. reactions: one per
  // constraint. `solver` is the set-up unconstrained KSP of A.
  PetscErrorCode Solve(KSP solver, Vec b, const std::vector<VelocityConstraint> &constraints, Vec v,
                       std::vector<PetscReal> *reactions, PetscInt *iterations);
  void set_two_sided_path(TwoSidedPath path) { path_ = path; }
  // The projected CG's preconditioner with the constraint correction
  // (constraint_correction.hpp): worth it where the unconstrained
  // preconditioner is A's factorisation and A keeps its values over many
  // solves (linear mode), which its cached columns need.
  void set_constraint_correction(bool on) { correct_ = on; }
  // Not collective. Applications of M^-1 the correction spent on its columns.
  PetscInt correction_column_solves() const;
  // Outer iterations of the last solve by the augmented Lagrangian path.
  int augmented_outer_iterations() const { return augmented_outer_iterations_; }

 private:
  static PetscErrorCode ApplyOperator(Mat shell, Vec w, Vec y);
  static PetscErrorCode ApplyPreconditioner(PC shell, Vec w, Vec y);
  // y = P w (project == true) or y = (I - P) w.
  void Project(const PetscScalar *w, PetscScalar *y, bool project) const;
  // Groups the constraints by vertex (any order) and combines each vertex's.
  void GroupByVertex(const std::vector<VelocityConstraint> &constraints);
  PetscErrorCode ProjectVec(Vec w, Vec y, bool project) const;
  // Solve's steps: the work vectors, the shell operator and the inner CG (first
  // call); z_ = the prescribed velocities; reactions n_k . (A v - b)_i.
  PetscErrorCode CreateInnerSolver(Vec b);
  PetscErrorCode SetPrescribedVelocities();
  PetscErrorCode Reactions(Vec b, Vec v, const std::vector<VelocityConstraint> &constraints,
                           std::vector<PetscReal> *reactions);
  // A v = f under the one-sided constraints (vertices_): prescribed velocities
  // when `prescribed`, zero otherwise; v: initial guess in, solution out; adds
  // the inner CG's iterations.
  PetscErrorCode SolveConstrained(Vec f, bool prescribed, Vec v, PetscInt *iterations);
  // The projected solve (no two-sided constraint on any rank).
  PetscErrorCode SolveProjected(Vec b, const std::vector<VelocityConstraint> &constraints, Vec v,
                                std::vector<PetscReal> *reactions, PetscInt *iterations);
  // The Delassus path and the projected Delassus path (file comment); collective.
  PetscErrorCode SolveTwoSided(KSP solver, Vec b,
                               const std::vector<VelocityConstraint> &constraints, Vec v,
                               std::vector<PetscReal> *reactions, PetscInt *iterations);
  PetscErrorCode SolveTwoSidedProjected(KSP solver, Vec b,
                                        const std::vector<VelocityConstraint> &constraints, Vec v,
                                        std::vector<PetscReal> *reactions, PetscInt *iterations);
  // The augmented Lagrangian path (augmented_solve.cpp); collective.
  PetscErrorCode SolveTwoSidedAugmented(Vec b, const std::vector<VelocityConstraint> &constraints,
                                        Vec v, std::vector<PetscReal> *reactions,
                                        PetscInt *iterations);
  // y = A x, plus the penalty's term while the augmented path solves.
  PetscErrorCode ApplyA(Vec x, Vec y) const;

  KSP inner_ = nullptr;
  Mat shell_ = nullptr;
  Mat A_ = nullptr;                // not owned
  PC unconstrained_pc_ = nullptr;  // not owned
  std::vector<ConstrainedVertex> vertices_;
  Vec work_ = nullptr, work2_ = nullptr, z_ = nullptr, rhs_ = nullptr, w_ = nullptr;
  Vec column_ = nullptr, column_rhs_ = nullptr;  // the projected Delassus path's
  const RowPenalty *penalty_ = nullptr;          // the augmented path's, while it solves
  int augmented_outer_iterations_ = 0;
  TwoSidedPath path_ = TwoSidedPath::kAuto;
  // The constraint correction: requested, and ready for this solve's vertices_.
  bool correct_ = false, corrected_ = false;
  std::unique_ptr<ConstraintCorrection> correction_;
  // When correct_: sets corrected_ for vertices_ (collective).
  PetscErrorCode SetupCorrection();
  // The Delassus path's columns A^-1 e of its rows' vertices' DOFs, when
  // correct_ (two_sided_solve.cpp): collective; vertices: this solve's rows'
  // (ascending, the same on every rank); *ready: all of them are kept.
  PetscErrorCode KeepDelassusColumns(KSP solver, const std::vector<PetscInt> &vertices, bool *ready,
                                     PetscInt *iterations);
  // Destroys the kept columns of the vertices not in `keep` (ascending).
  void DropDelassusColumns(const std::vector<PetscInt> &keep);
  std::map<PetscInt, std::array<Vec, 3>> delassus_columns_;
  Mat delassus_A_ = nullptr;       // not owned
  KSP delassus_solver_ = nullptr;  // not owned
  PetscObjectState delassus_state_ = -1;
};

}  // namespace softbody
