// Records sent to the ranks that need them: one personalised all-to-all.
//
// Written here rather than with PetscSF because the receivers do not know in
// advance what they will get (a star forest needs its roots known): each rank
// knows only what it sends where. One MPI_Alltoall of the counts tells every rank
// what to expect; O(P) integers per rank, which is fine up to thousands of ranks.
#pragma once

#include <petscsys.h>

#include <climits>
#include <cstdint>
#include <type_traits>
#include <vector>

namespace softbody {

// Collective. `send` holds the records for rank 0, then those for rank 1, ...
// (send_counts[q] for rank q); *received gets every rank's records for this rank,
// senders in rank order, each sender's in its order. Records are sent as bytes.
template <class Record>
PetscErrorCode ExchangeRecords(MPI_Comm comm, const std::vector<Record> &send,
                               const std::vector<int> &send_counts, std::vector<Record> *received) {
  static_assert(std::is_trivially_copyable<Record>::value, "records travel as bytes");
  PetscFunctionBeginUser;
  const size_t size = send_counts.size();
  std::vector<int> receive_counts(size), send_offsets(size, 0), receive_offsets(size, 0);
  PetscCallMPI(
      MPI_Alltoall(send_counts.data(), 1, MPI_INT, receive_counts.data(), 1, MPI_INT, comm));
  int64_t sent = 0, total = 0;
  for (size_t q = 0; q < size; ++q) {
    send_offsets[q] = static_cast<int>(sent);
    receive_offsets[q] = static_cast<int>(total);
    sent += send_counts[q];
    total += receive_counts[q];
  }
  int too_many = sent > INT_MAX || total > INT_MAX;  // MPI counts are int: all ranks stop
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &too_many, 1, MPI_INT, MPI_MAX, comm));
  PetscCheck(!too_many, comm, PETSC_ERR_SUP,
             "more records for one rank than MPI can exchange at once: run on more ranks");
  received->resize(total);
  MPI_Datatype record;
  PetscCallMPI(MPI_Type_contiguous(sizeof(Record), MPI_BYTE, &record));
  PetscCallMPI(MPI_Type_commit(&record));
  PetscCallMPI(MPI_Alltoallv(send.data(), send_counts.data(), send_offsets.data(), record,
                             received->data(), receive_counts.data(), receive_offsets.data(),
                             record, comm));
  PetscCallMPI(MPI_Type_free(&record));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
