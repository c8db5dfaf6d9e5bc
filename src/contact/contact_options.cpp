#include "contact/contact_options.hpp"

#include "common/options.hpp"

namespace softbody {

namespace {

// The ranges of the options; bounds: the nbounds values of -edge_bounds.
PetscErrorCode CheckContactOptions(MPI_Comm comm, const PetscReal bounds[2], PetscInt nbounds,
                                   ContactOptions *o) {
  PetscFunctionBeginUser;
  PetscCheck(o->friction >= 0, comm, PETSC_ERR_USER_INPUT,
             "option -friction: must be >= 0 (got %g)", (double)o->friction);
  PetscCheck(o->restitution >= 0 && o->restitution <= 1, comm, PETSC_ERR_USER_INPUT,
             "option -restitution: must lie in [0, 1] (got %g)", (double)o->restitution);
  PetscCheck(o->gap > 0 && o->gap < 0.1, comm, PETSC_ERR_USER_INPUT,
             "option -contact_gap: must lie in (0, 0.1) edge lengths (got %g)", (double)o->gap);
  PetscCheck(o->halo_reach >= 1, comm, PETSC_ERR_USER_INPUT,
             "option -contact_halo_reach: must be >= 1 tet edge (got %g)", (double)o->halo_reach);
  PetscCheck(o->fixed_replicate_mb >= 0, comm, PETSC_ERR_USER_INPUT,
             "option -contact_fixed_replicate_mb: must be >= 0 MB (got %g)",
             (double)o->fixed_replicate_mb);
  if (o->edge_bounds) {
    PetscCheck(nbounds == 2, comm, PETSC_ERR_USER_INPUT, "option -edge_bounds: expected lo,hi");
    o->edge_lower = bounds[0];
    o->edge_upper = bounds[1];
    PetscCheck(o->edge_lower > 0 && o->edge_lower <= 1 && o->edge_upper >= 1, comm,
               PETSC_ERR_USER_INPUT, "option -edge_bounds: need 0 < lo <= 1 <= hi (got %g,%g)",
               (double)o->edge_lower, (double)o->edge_upper);
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace

PetscErrorCode ProcessContactOptions(MPI_Comm comm, ContactOptions *o) {
  PetscFunctionBeginUser;
  PetscCall(CheckOptionSyntax(comm, {{OptionSyntax::kReal, "-ground"},
                                     {OptionSyntax::kReal, "-restitution"},
                                     {OptionSyntax::kReal, "-friction"},
                                     {OptionSyntax::kBool, "-sharp_edges"},
                                     {OptionSyntax::kBool, "-impulse_spreading"},
                                     {OptionSyntax::kBool, "-contact_guard"},
                                     {OptionSyntax::kBool, "-contact_guard_reuse"},
                                     {OptionSyntax::kReal, "-contact_gap"},
                                     {OptionSyntax::kBool, "-self_contact"},
                                     {OptionSyntax::kReal, "-contact_halo_reach"},
                                     {OptionSyntax::kReal, "-contact_fixed_replicate_mb"},
                                     {OptionSyntax::kRealList, "-edge_bounds"}}));
  char path[PETSC_MAX_PATH_LEN] = "";
  PetscReal bounds[2] = {o->edge_lower, o->edge_upper};
  PetscInt nbounds = 2;
  PetscOptionsBegin(comm, nullptr, "Collisions and constraints", nullptr);
  PetscCall(PetscOptionsReal("-ground",
                             "Ground plane height y0 (m): vertices stay at y >= y0 (off if unset)",
                             nullptr, o->ground_y, &o->ground_y, &o->ground));
  PetscCall(PetscOptionsReal(
      "-restitution", "Coefficient of restitution e of collisions, 0 (no bounce) to 1 (elastic)",
      nullptr, o->restitution, &o->restitution, nullptr));
  PetscCall(
      PetscOptionsReal("-friction",
                       "Coulomb friction coefficient mu of collisions (0: frictionless, as the "
                       "coursework)",
                       nullptr, o->friction, &o->friction, nullptr));
  PetscCall(PetscOptionsBool(
      "-sharp_edges",
      "Fixed bodies' sharp edges and corners push free bodies' faces (not only free "
      "vertices against fixed faces)",
      nullptr, o->sharp_edges, &o->sharp_edges, nullptr));
  PetscCall(
      PetscOptionsBool("-impulse_spreading",
                       "Share each collision impulse among all vertices of the body, by inverse "
                       "squared distance",
                       nullptr, o->impulse_spreading, &o->impulse_spreading, nullptr));
  PetscCall(PetscOptionsString("-constraints",
                               "Distance constraints file: n, then 'm1 v1 m2 v2 [lo hi]' per line",
                               nullptr, path, path, sizeof(path), nullptr));
  PetscCall(
      PetscOptionsRealArray("-edge_bounds",
                            "Keep every boundary edge of the free bodies within lo,hi x its rest "
                            "length (off if unset)",
                            nullptr, bounds, &nbounds, &o->edge_bounds));
  PetscCall(PetscOptionsBool("-contact_guard",
                             "Continuous collision guard: no surface face, edge or vertex crosses "
                             "another's (or its own body's) during a step",
                             nullptr, o->guard, &o->guard, nullptr));
  PetscCall(PetscOptionsBool("-contact_guard_reuse",
                             "The guard keeps its answer for positions it has just found clean "
                             "(0: detects again; the same result)",
                             nullptr, o->guard_reuse, &o->guard_reuse, nullptr));
  PetscCall(PetscOptionsReal("-contact_gap",
                             "Contacts end this fraction of the body's mean boundary edge apart; "
                             "the guard keeps every surface pair at least a quarter of it apart",
                             nullptr, o->gap, &o->gap, nullptr));
  PetscCall(PetscOptionsBool("-self_contact",
                             "Guard each body's surface against itself (default: with any other "
                             "contact; 1 also for a lone body)",
                             nullptr, o->self_contact, &o->self_contact, &o->self_contact_set));
  PetscCall(PetscOptionsReal("-contact_halo_reach",
                             "Halo of contact: other ranks' vertices within this many of their "
                             "body's longest tet edge of a rank's own (>= 1; huge: all near)",
                             nullptr, o->halo_reach, &o->halo_reach, nullptr));
  PetscCall(PetscOptionsReal("-contact_fixed_replicate_mb",
                             "Every rank holds the fixed bodies' tets whole when they take at most "
                             "this many MB, else those near its own vertices (0: never whole)",
                             nullptr, o->fixed_replicate_mb, &o->fixed_replicate_mb, nullptr));
  PetscOptionsEnd();
  o->constraints_path = path;
  PetscCall(CheckContactOptions(comm, bounds, nbounds, o));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
