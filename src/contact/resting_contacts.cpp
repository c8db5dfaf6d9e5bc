#include "contact/resting_contacts.hpp"

namespace softbody {

namespace {

// A checkpoint's obstacle field: the body (-1 the ground), or -2 - f for feature point f.
int32_t EncodeObstacle(const Contact &contact) {
  return contact.feature >= 0 ? -2 - contact.feature : contact.body;
}
int32_t FeatureOf(int32_t entry) {
  return entry <= -2 ? -2 - entry : -1;
}

}  // namespace

bool RestingContacts::any_feature() const {
  for (const auto &[local, contact] : entries_)
    if (contact.feature >= 0) return true;
  return false;
}

PetscErrorCode RestingContacts::Gather(MPI_Comm comm, std::vector<std::array<int32_t, 2>> *all,
                                       std::vector<double> *reactions) const {
  PetscFunctionBeginUser;
  std::vector<int32_t> local;
  std::vector<double> local_reactions;
  for (const auto &[vertex, contact] : entries_) {
    local.insert(local.end(), {contact.natural, EncodeObstacle(contact)});
    local_reactions.push_back(contact.reaction);
  }
  PetscMPIInt rank, size, count = static_cast<PetscMPIInt>(local.size());
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  PetscCallMPI(MPI_Comm_size(comm, &size));
  std::vector<PetscMPIInt> counts(size), offsets(size + 1, 0);
  PetscCallMPI(MPI_Gather(&count, 1, MPI_INT, counts.data(), 1, MPI_INT, 0, comm));
  for (int r = 0; r < size; ++r) offsets[r + 1] = offsets[r] + (rank == 0 ? counts[r] : 0);
  std::vector<int32_t> gathered(offsets[size]);
  PetscCallMPI(MPI_Gatherv(local.data(), count, MPI_INT32_T, gathered.data(), counts.data(),
                           offsets.data(), MPI_INT32_T, 0, comm));
  all->resize(gathered.size() / 2);
  for (size_t i = 0; i < all->size(); ++i) (*all)[i] = {gathered[2 * i], gathered[2 * i + 1]};
  for (int r = 0; r < size; ++r) {  // one reaction per entry
    counts[r] /= 2;
    offsets[r] /= 2;
  }
  reactions->resize(all->size());
  PetscCallMPI(MPI_Gatherv(local_reactions.data(), count / 2, MPI_DOUBLE, reactions->data(),
                           counts.data(), offsets.data(), MPI_DOUBLE, 0, comm));
  PetscFunctionReturn(PETSC_SUCCESS);
}

void RestingContacts::Restore(const std::vector<std::array<int32_t, 2>> &all,
                              const std::vector<double> &reactions, const DofLayout &layout,
                              const SharpFeatures &features, const Known &known) {
  entries_.clear();
  for (size_t i = 0; i < all.size(); ++i) {
    const auto &[natural, entry] = all[i];
    const int32_t feature = FeatureOf(entry);
    if (feature >= 0  ? static_cast<size_t>(feature) >= features.size()
        : entry == -1 ? !known.ground
                      : !known.bodies || static_cast<size_t>(entry) >= known.num_bodies)
      continue;
    if (natural < 0 || static_cast<size_t>(natural) >= layout.petsc_of_natural.size()) continue;
    const PetscInt local = layout.LocalOfNatural(natural);
    if (local < 0) continue;
    Contact contact{natural, feature >= 0 ? features.body_of(feature) : entry, 0.0, false, feature};
    contact.reaction = reactions.empty() ? 0.0 : reactions[i];
    entries_.push_back({local, contact});
  }
}

}  // namespace softbody
