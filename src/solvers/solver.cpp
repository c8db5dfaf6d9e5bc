#include "solvers/solver.hpp"

#include <cstdio>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "solvers/supernodal/supernodal.hpp"
#include "solvers/warp/warp_preconditioner.hpp"

namespace softbody {

PetscErrorCode RegisterPreconditioners() {
  PetscFunctionBeginUser;
  PetscCall(RegisterSupernodalPC());
  PetscCall(RegisterWarpPC());
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ApplyPresetDefaults(const char *preset) {
  PetscFunctionBeginUser;
  PetscCall(RegisterPreconditioners());
  // PetscOptionsInsertString knows no comments: drop them line by line.
  std::istringstream lines(preset);
  std::string line, options;
  while (std::getline(lines, line)) options += line.substr(0, line.find('#')) + ' ';
  PetscCall(PetscOptionsInsertString(nullptr, options.c_str()));
  // Re-insert the command line (and its -options_file) so that it wins.
  int argc = 0;
  char **argv = nullptr;
  PetscCall(PetscGetArgs(&argc, &argv));
  PetscCall(PetscOptionsInsert(nullptr, &argc, &argv, nullptr));
  PetscFunctionReturn(PETSC_SUCCESS);
}

namespace {

constexpr double kBytesPerMB = 1024.0 * 1024.0;

// "52 000"-style integers and "1 536 MB" for the summary.
std::string Grouped(double value) {
  std::string digits = std::to_string(static_cast<long long>(value + 0.5)), grouped;
  for (size_t i = 0; i < digits.size(); ++i) {
    if (i > 0 && (digits.size() - i) % 3 == 0) grouped += ' ';
    grouped += digits[i];
  }
  return grouped;
}

// Megabytes: digits grouped from 100 MB on, three significant digits below.
std::string Megabytes(double bytes) {
  const double mb = bytes / kBytesPerMB;
  if (mb >= 100) return Grouped(mb) + " MB";
  char text[32];
  std::snprintf(text, sizeof(text), "%.3g MB", mb);
  return text;
}

// Why the factor stays or gives way, one phrase.
std::string Reason(const SupernodalPrediction &p, PetscMPIInt ranks) {
  const std::string need = Megabytes(p.bytes) + " per rank",
                    budget = "budget " + Megabytes(p.limits.budget_mb * kBytesPerMB);
  const std::string separator = "separator n_S = " + Grouped(static_cast<double>(p.separator));
  if (p.affordable)
    return (ranks == 1 ? "" : separator + ", ") + "predicted " + need + " <= " + budget;
  if (ranks == 1) return "the factor would need " + need + " > " + budget;
  if (p.separator > p.limits.max_separator)
    return "the split factor's " + separator + " > -pc_supernodal_max_separator " +
           Grouped(static_cast<double>(p.limits.max_separator)) +
           " (its dense blocks alone: " + Megabytes(p.separator_bytes) + " per rank, " + budget +
           ")";
  return "the split factor's " + separator + " would need " + need + " > " + budget;
}

// Every "-name value" of a preset (comments dropped) into the database where
// the name (after prefix) has no value yet.
PetscErrorCode InsertWhereUnset(const char *prefix, const char *preset) {
  PetscFunctionBeginUser;
  std::istringstream lines(preset);
  std::string line, token, name;
  std::vector<std::pair<std::string, std::string>> options;
  while (std::getline(lines, line)) {
    std::istringstream tokens(line.substr(0, line.find('#')));
    while (tokens >> token) {
      if (token[0] == '-')
        options.emplace_back("-" + std::string(prefix ? prefix : "") + token.substr(1), "");
      else if (!options.empty())
        options.back().second = token;
    }
  }
  for (const auto &[option, value] : options) {
    PetscBool set;
    PetscCall(PetscOptionsHasName(nullptr, nullptr, option.c_str(), &set));
    if (!set) PetscCall(PetscOptionsSetValue(nullptr, option.c_str(), value.c_str()));
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

// "-" + the object's options prefix + name.
std::string PrefixedOption(PetscObject object, const char *name) {
  const char *prefix = nullptr;
  PetscObjectGetOptionsPrefix(object, &prefix);
  return std::string("-") + (prefix ? prefix : "") + name;
}

// GAMG's Galerkin products P^T A P on parallel matrices (MPIAIJ; the serial
// product has no such choice), when the default turned to it because the factor
// would not fit: PETSc's memory-lean algorithm. The default algorithm holds about
// a third more per rank (weak series, docs/scaling.md) for a set-up 3-5 times
// faster; a user's -matptap_via wins.
constexpr const char *kLeanGalerkinProduct[] = {"-matptap_via", "allatonce"};

}  // namespace

PetscErrorCode ChooseFactorOrMultigrid(KSP ksp, PC pc, SolverChoice *choice) {
  PetscFunctionBeginUser;
  *choice = SolverChoice();
  PetscBool supernodal;
  PetscCall(PetscObjectTypeCompare((PetscObject)pc, kPCSupernodal, &supernodal));
  if (!supernodal) PetscFunctionReturn(PETSC_SUCCESS);
  SupernodalPrediction prediction;
  PetscCall(PCSupernodalPredict(pc, &prediction));
  PetscMPIInt ranks;
  PetscCallMPI(MPI_Comm_size(PetscObjectComm((PetscObject)pc), &ranks));
  choice->checked = true;
  choice->scalable = !prediction.affordable;
  const std::string why = Reason(prediction, ranks);
  PetscCall(PetscInfo(pc, "solver choice: %s\n", why.c_str()));
  if (!choice->scalable) {
    choice->reason =
        std::string(ranks == 1 ? "supernodal factor" : "split supernodal factor") + ": " + why;
    PetscFunctionReturn(PETSC_SUCCESS);
  }
  // Through the database, so that PCSetFromOptions does not turn it back.
  PetscCall(
      PetscOptionsSetValue(nullptr, PrefixedOption((PetscObject)pc, "pc_type").c_str(), PCGAMG));
  PetscBool product_given;
  PetscCall(PetscOptionsHasName(nullptr, nullptr, kLeanGalerkinProduct[0], &product_given));
  if (!product_given && ranks > 1)
    PetscCall(PetscOptionsSetValue(nullptr, kLeanGalerkinProduct[0], kLeanGalerkinProduct[1]));
  PetscBool preonly = PETSC_FALSE;
  if (ksp) PetscCall(PetscObjectTypeCompare((PetscObject)ksp, KSPPREONLY, &preonly));
  if (preonly) {
    PetscCall(
        PetscOptionsSetValue(nullptr, PrefixedOption((PetscObject)ksp, "ksp_type").c_str(), KSPCG));
    const char *prefix;
    PetscCall(KSPGetOptionsPrefix(ksp, &prefix));
    PetscCall(InsertWhereUnset(prefix, kScalablePreset));
  }
  if (ksp)
    PetscCall(KSPSetFromOptions(ksp));
  else
    PetscCall(PCSetFromOptions(pc));
  choice->reason = std::string(preonly ? "CG + GAMG" : "GAMG") + ": " + why;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode CreateSolver(Mat A, Vec coordinates, KSP *ksp, SolverChoice *choice) {
  PetscFunctionBeginUser;
  PetscCall(RegisterPreconditioners());
  PetscCall(MatSetOption(A, MAT_SPD, PETSC_TRUE));
  PetscCall(MatSetOption(A, MAT_SPD_ETERNAL, PETSC_TRUE));
  MatNullSpace rigid_body_modes;
  PetscCall(MatNullSpaceCreateRigidBody(coordinates, &rigid_body_modes));
  PetscCall(MatSetNearNullSpace(A, rigid_body_modes));
  PetscCall(MatNullSpaceDestroy(&rigid_body_modes));
  PetscCall(KSPCreate(PetscObjectComm((PetscObject)A), ksp));
  PetscCall(KSPSetOperators(*ksp, A, A));
  PetscCall(KSPSetFromOptions(*ksp));
  PC chosen;
  PetscCall(KSPGetPC(*ksp, &chosen));
  PetscCall(ChooseFactorOrMultigrid(*ksp, chosen, choice));
  // Iterative solvers start from the previous velocity (the solution vector's
  // content); a direct solve ignores any guess.
  PetscBool preonly;
  PetscCall(PetscObjectTypeCompare((PetscObject)*ksp, KSPPREONLY, &preonly));
  // The warp preconditioner starts from zero (warp_preconditioner.hpp);
  // -ksp_initial_guess_nonzero decides where given.
  PetscBool guess_set, warp;
  PC pc;
  PetscCall(KSPGetPC(*ksp, &pc));
  PetscCall(PetscObjectTypeCompare((PetscObject)pc, kPCWarp, &warp));
  PetscCall(PetscOptionsHasName(nullptr, nullptr, "-ksp_initial_guess_nonzero", &guess_set));
  if (!preonly && !guess_set)
    PetscCall(KSPSetInitialGuessNonzero(*ksp, warp ? PETSC_FALSE : PETSC_TRUE));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
