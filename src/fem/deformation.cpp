#include "fem/deformation.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace softbody {

namespace {

// "body:time:sx,sy,sz" -> Deformation; false when malformed.
bool ParseDeformation(const std::string &text, Deformation *d) {
  std::string fields = text;
  std::replace(fields.begin(), fields.end(), ':', ' ');
  std::replace(fields.begin(), fields.end(), ',', ' ');
  std::istringstream in(fields);
  std::string rest;
  return static_cast<bool>(in >> d->body >> d->time >> d->scale[0] >> d->scale[1] >> d->scale[2]) &&
         !(in >> rest) && d->scale.allFinite() && std::isfinite(d->time);
}

}  // namespace

PetscErrorCode ProcessDeformationOptions(MPI_Comm comm, std::string *text) {
  PetscFunctionBeginUser;
  char buffer[PETSC_MAX_PATH_LEN] = "";
  PetscOptionsBegin(comm, nullptr, "Prescribed deformation", nullptr);
  PetscCall(PetscOptionsString("-deform",
                               "Scale body b about its centroid by (sx,sy,sz) at time t (s): "
                               "b:t:sx,sy,sz, several separated by ';'",
                               nullptr, buffer, buffer, sizeof(buffer), nullptr));
  PetscOptionsEnd();
  *text = buffer;
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ParseDeformations(MPI_Comm comm, const std::string &text, const Scene &scene,
                                 std::vector<Deformation> *deformations) {
  PetscFunctionBeginUser;
  deformations->clear();
  std::istringstream list(text);
  std::string item;
  while (std::getline(list, item, ';')) {
    Deformation d;
    PetscCheck(ParseDeformation(item, &d), comm, PETSC_ERR_USER_INPUT,
               "option -deform: '%s' is not body:time:sx,sy,sz", item.c_str());
    PetscCheck(d.body >= 0 && d.body < (PetscInt)scene.bodies.size(), comm, PETSC_ERR_USER_INPUT,
               "option -deform: body %" PetscInt_FMT " out of range 0..%zu", d.body,
               scene.bodies.size() - 1);
    PetscCheck(!scene.bodies[d.body].fixed, comm, PETSC_ERR_USER_INPUT,
               "option -deform: body %" PetscInt_FMT " is fixed and cannot be deformed", d.body);
    PetscCheck(d.time >= 0, comm, PETSC_ERR_USER_INPUT,
               "option -deform: time must be >= 0 (got %g)", (double)d.time);
    PetscCheck((d.scale.array() != 0).all(), comm, PETSC_ERR_USER_INPUT,
               "option -deform: scale factors must be non-zero");
    deformations->push_back(d);
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode ApplyDueDeformations(const Scene &scene, const DofLayout &layout, PetscReal time,
                                    PetscReal tolerance, Vec lumped_mass, Vec positions,
                                    std::vector<Deformation> *deformations, bool *changed) {
  PetscFunctionBeginUser;
  *changed = false;
  std::vector<int32_t> body_of;
  for (Deformation &d : *deformations) {
    if (d.applied || d.time > time + tolerance) continue;
    if (body_of.empty()) body_of = OwnedVertexBodies(scene, layout);
    PetscScalar *x;
    const PetscScalar *m;
    PetscCall(VecGetArray(positions, &x));
    PetscCall(VecGetArrayRead(lumped_mass, &m));
    // Mass-weighted centroid of the body: sums of m x and m over its vertices.
    double sums[4] = {0, 0, 0, 0}, global[4];
    for (PetscInt p = 0; p < layout.local_count(); ++p)
      if (body_of[p] == d.body) {
        for (int c = 0; c < 3; ++c) sums[c] += m[3 * p] * x[3 * p + c];
        sums[3] += m[3 * p];
      }
    PetscCallMPI(MPI_Allreduce(sums, global, 4, MPI_DOUBLE, MPI_SUM,
                               PetscObjectComm((PetscObject)positions)));
    for (PetscInt p = 0; p < layout.local_count(); ++p)
      if (body_of[p] == d.body)
        for (int c = 0; c < 3; ++c) {
          const double centre = global[c] / global[3];
          x[3 * p + c] = centre + d.scale[c] * (x[3 * p + c] - centre);
        }
    PetscCall(VecRestoreArray(positions, &x));
    PetscCall(VecRestoreArrayRead(lumped_mass, &m));
    d.applied = true;
    *changed = true;
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
