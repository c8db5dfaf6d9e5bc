// Records sent to a few ranks, whose receivers do not know in advance who sends
// to them: the pattern of a halo that follows moving bodies.
//
// PETSc's PetscCommBuildTwoSided (a non-blocking consensus: synchronous sends
// and MPI_Ibarrier) tells every rank who sends to it and how many records;
// then the records travel point to point between those ranks only. Unlike
// ExchangeRecords (exchange.hpp: an MPI_Alltoall of counts, O(P) integers per
// rank and call) no rank sends or receives anything from ranks it has no
// business with, so the bytes per step follow the halo, not the rank count.
// Written here rather than with PetscSF because the receivers do not know
// their roots (the halo changes every step).
#pragma once

#include <petscsys.h>

#include <algorithm>
#include <climits>
#include <numeric>
#include <type_traits>
#include <vector>

namespace softbody {

class NeighbourExchange {
 public:
  NeighbourExchange() = default;
  NeighbourExchange(const NeighbourExchange &) = delete;
  NeighbourExchange &operator=(const NeighbourExchange &) = delete;
  ~NeighbourExchange() {
    if (comm_ != MPI_COMM_NULL) PetscCallVoid(PetscCommDestroy(&comm_));
  }

  // Collective. A private communicator and tag (reused by every exchange:
  // each exchange completes before the next starts, and MPI keeps the order
  // of messages between two ranks).
  PetscErrorCode Setup(MPI_Comm comm) {
    PetscFunctionBeginUser;
    PetscCall(PetscCommDuplicate(comm, &comm_, &tag_));
    PetscFunctionReturn(PETSC_SUCCESS);
  }

  // Collective. to_ranks: distinct ranks other than this one, each with its
  // records in `records` (to_counts[i] for to_ranks[i], in that order).
  // *received: every record sent to this rank, senders in rank order, each
  // sender's in its order. Returns in *bytes_sent the payload this rank sent.
  template <class Record>
  PetscErrorCode Exchange(const std::vector<PetscMPIInt> &to_ranks,
                          const std::vector<PetscMPIInt> &to_counts,
                          const std::vector<Record> &records, std::vector<Record> *received,
                          PetscInt64 *bytes_sent) const {
    static_assert(std::is_trivially_copyable<Record>::value, "records travel as bytes");
    PetscFunctionBeginUser;
    PetscMPIInt num_from, *from_ranks, *from_counts;
    PetscCall(PetscCommBuildTwoSided(comm_, 1, MPI_INT, static_cast<PetscMPIInt>(to_ranks.size()),
                                     to_ranks.data(), to_counts.data(), &num_from, &from_ranks,
                                     &from_counts));
    std::vector<PetscMPIInt> order(num_from);  // senders in rank order
    std::iota(order.begin(), order.end(), 0);
    std::sort(order.begin(), order.end(),
              [&](PetscMPIInt a, PetscMPIInt b) { return from_ranks[a] < from_ranks[b]; });
    std::vector<size_t> offset(num_from + 1, 0);
    for (PetscMPIInt i = 0; i < num_from; ++i)
      offset[i + 1] = offset[i] + static_cast<size_t>(from_counts[order[i]]);
    received->resize(offset[num_from]);
    std::vector<MPI_Request> requests;
    for (PetscMPIInt i = 0; i < num_from; ++i)
      PetscCall(Post(MPI_Irecv, received->data() + offset[i], from_counts[order[i]],
                     from_ranks[order[i]], &requests));
    *bytes_sent = 0;
    for (size_t i = 0, start = 0; i < to_ranks.size(); start += to_counts[i], ++i) {
      PetscCall(Post(MPI_Isend, const_cast<Record *>(records.data() + start), to_counts[i],
                     to_ranks[i], &requests));
      *bytes_sent += static_cast<PetscInt64>(to_counts[i]) * sizeof(Record);
    }
    PetscCallMPI(
        MPI_Waitall(static_cast<int>(requests.size()), requests.data(), MPI_STATUSES_IGNORE));
    PetscCall(PetscFree(from_ranks));
    PetscCall(PetscFree(from_counts));
    PetscFunctionReturn(PETSC_SUCCESS);
  }

 private:
  // One non-blocking send or receive of `count` records as bytes (none for 0).
  template <class Record, class Call>
  PetscErrorCode Post(Call call, Record *data, PetscMPIInt count, PetscMPIInt rank,
                      std::vector<MPI_Request> *requests) const {
    PetscFunctionBeginUser;
    PetscCheck(static_cast<size_t>(count) <= INT_MAX / sizeof(Record), comm_, PETSC_ERR_SUP,
               "a halo message larger than MPI can send at once: run on more ranks");
    if (count == 0) PetscFunctionReturn(PETSC_SUCCESS);
    requests->emplace_back();
    PetscCallMPI(call(data, static_cast<int>(count * sizeof(Record)), MPI_BYTE, rank, tag_, comm_,
                      &requests->back()));
    PetscFunctionReturn(PETSC_SUCCESS);
  }

  MPI_Comm comm_ = MPI_COMM_NULL;
  PetscMPIInt tag_ = 0;
};

}  // namespace softbody
