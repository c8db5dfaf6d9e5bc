// Measurements of a run against the machine (-bench): how long a step takes,
// how much of it the memory traffic explains, and what the run occupies.
//
// With -bench, after the time loop:
//   step_s          median wall time of a time step (s)
//   assemble_s      median of -bench_assembly_repeats fills of A at the final
//                   positions (linear: the rest stiffness, corotational: the
//                   rotations, rotated element blocks and forces), s;
//                   assemble_rate = tets / assemble_s / ranks (tets/s per rank)
//   factor_s        the largest factorisation / preconditioner set-up of the run (s)
//   iterations      mean solver iterations per step
//   matrix_nonzeros nonzeros of A (= those of K)
//   factor_nonzeros nonzeros of the Cholesky factor L (linear direct solver; the
//                   warp preconditioner's factor of A0), 0 without a factor
//   peak_rss_mb     largest resident set of any rank (MB), before the triad
//   bandwidth_gbs   STREAM triad a = b + s c on every rank at once, arrays of
//                   -bench_triad_mb MB per rank, 3 x 8 bytes per element, best
//                   of 5 passes, summed over ranks (GB/s)
//   bound_s         lower bound of a step's memory traffic over bandwidth_gbs:
//                   per product, 12 bytes per nonzero of A (value and column
//                   index; one product per CG iteration) or 8 + 4/9 per
//                   nonzero of K (3 x 3 blocks, one index per block; the one
//                   product of a linear direct step); 2 x 8 bytes per nonzero
//                   of L per solve with it (a forward and a backward sweep;
//                   2 x 4 for a single-precision factor); 8 bytes per nonzero
//                   of A per refill (corotational); and per product or solve
//                   its input and output vector (2 x 8 bytes per DOF); the
//                   rest of the step's vector work not counted
//   bound_fraction  bound_s / step_s
// Rank 0 prints them as one line, "softbody bench: name=value ...", and they go
// into the result file as root attributes.
#pragma once

#include <petscksp.h>

#include <string>
#include <utility>
#include <vector>

#include "io/scene.hpp"
#include "solvers/integrator.hpp"

namespace softbody {

struct BenchmarkOptions {
  PetscBool enabled = PETSC_FALSE;  // -bench
  // -bench_assembly_repeats: the median of 5 fills ignores one or two disturbed by
  // the system.
  PetscInt assembly_repeats = 5;
  // -bench_triad_mb: MB per array per rank; 128 MB is far beyond any cache, so
  // the triad measures memory bandwidth.
  PetscReal triad_mb = 128;
};

// Collective. Reads -bench, -bench_assembly_repeats, -bench_triad_mb.
PetscErrorCode ProcessBenchmarkOptions(MPI_Comm comm, BenchmarkOptions *options);

// Not collective. Largest resident set size of this process so far (MB).
double PeakResidentMegabytes();

// Collective. STREAM triad on every rank at once: summed bandwidth (GB/s).
PetscErrorCode TriadBandwidth(MPI_Comm comm, PetscReal megabytes_per_array,
                              double *gigabytes_per_second);

class Benchmark {
 public:
  explicit Benchmark(const BenchmarkOptions &options) : options_(options) {}

  bool enabled() const { return options_.enabled; }
  // Not collective. After every time step: its wall time (s) and the
  // integrator's statistics after it.
  void RecordStep(double seconds, const SolverStatistics &statistics);
  // Collective. The measurements after the time loop (x: final positions);
  // prints the line on rank 0.
  PetscErrorCode Finish(MPI_Comm comm, const Scene &scene, ImplicitEuler *integrator, Vec x);
  // name, value pairs for the result file (empty unless enabled and finished).
  const std::vector<std::pair<std::string, double>> &attributes() const { return attributes_; }

 private:
  // Significant digits of the values on the "softbody bench:" line.
  static constexpr int kPrintedDigits = 6;
  // Rank 0 prints the attributes as one line "softbody bench: name=value ...".
  PetscErrorCode PrintAttributes(MPI_Comm comm) const;

  BenchmarkOptions options_;
  std::vector<double> step_seconds_, setup_seconds_;
  PetscInt last_total_iterations_ = 0;
  std::vector<std::pair<std::string, double>> attributes_;
};

}  // namespace softbody
