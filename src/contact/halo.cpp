#include "contact/halo.hpp"

#include <type_traits>

#include "common/exchange.hpp"

namespace softbody {

PetscErrorCode GatherRankBoxes(MPI_Comm comm, const std::vector<Box> &mine,
                               std::vector<RankBox> *others, PetscInt64 *bytes_sent) {
  PetscFunctionBeginUser;
  static_assert(std::is_trivially_copyable<RankBox>::value, "boxes travel as bytes");
  PetscMPIInt rank;
  PetscCallMPI(MPI_Comm_rank(comm, &rank));
  std::vector<RankBox> own, all;
  for (size_t b = 0; b < mine.size(); ++b)
    if (!mine[b].Empty()) {
      RankBox box{rank, static_cast<int32_t>(b), {}, {}};
      for (int c = 0; c < 3; ++c) {
        box.lower[c] = mine[b].lower[c];
        box.upper[c] = mine[b].upper[c];
      }
      own.push_back(box);
    }
  PetscCall(AllGatherRecords(comm, own, &all));
  *bytes_sent += static_cast<PetscInt64>(own.size() * sizeof(RankBox));
  others->clear();
  for (const RankBox &r : all)
    if (r.rank != rank) others->push_back(r);
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
