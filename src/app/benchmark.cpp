#include "app/benchmark.hpp"

#include <sys/resource.h>

#include <algorithm>
#include <cstdio>
#include <limits>
#include <memory>
#include <sstream>

#include "common/large_array.hpp"
#include "common/number_format.hpp"
#include "common/options.hpp"
#include "solvers/supernodal/supernodal.hpp"
#include "solvers/warp/warp_preconditioner.hpp"

namespace softbody {

namespace {

// Timed passes of the triad; the best one counts (the others warm caches and
// pages, or are disturbed by the system).
constexpr int kTriadPasses = 5;
// Bytes a product with A reads per nonzero: an 8-byte value and a 4-byte
// column index (MATAIJ).
constexpr double kProductBytesPerNonzero = 12.0;
// The same for the linear step's product with K, stored as 3 x 3 blocks
// (MATBAIJ): the value and a ninth of a block's column index.
constexpr double kBlockProductBytesPerNonzero = 8.0 + 4.0 / 9.0;
// Sweeps over the factor L per solve with it: a forward and a backward one.
constexpr double kFactorSweepsPerSolve = 2.0;
// Bytes a refill of A writes per nonzero (corotational mode): its 8-byte value.
constexpr double kRefillBytesPerNonzero = 8.0;
// Vectors of n doubles a product or a solve moves at least: its input, read,
// and its output, written.
constexpr double kVectorsPerOperation = 2.0;

}  // namespace

PetscErrorCode ProcessBenchmarkOptions(MPI_Comm comm, BenchmarkOptions *o) {
  PetscFunctionBeginUser;
  PetscCall(CheckOptionSyntax(comm, {{OptionSyntax::kBool, "-bench"},
                                     {OptionSyntax::kInteger, "-bench_assembly_repeats"},
                                     {OptionSyntax::kReal, "-bench_triad_mb"}}));
  PetscOptionsBegin(comm, nullptr, "Benchmark (measurements against the machine)", nullptr);
  PetscCall(PetscOptionsBool(
      "-bench",
      "Measure the run: median step, assembly, factorisation, peak memory, triad "
      "bandwidth and the step's memory-traffic bound (printed and in the result file)",
      nullptr, o->enabled, &o->enabled, nullptr));
  PetscCall(PetscOptionsInt("-bench_assembly_repeats", "Timed fills of A after the time loop",
                            nullptr, o->assembly_repeats, &o->assembly_repeats, nullptr));
  PetscCall(PetscOptionsReal("-bench_triad_mb", "Size of each triad array per rank (MB)", nullptr,
                             o->triad_mb, &o->triad_mb, nullptr));
  PetscOptionsEnd();
  PetscCheck(o->assembly_repeats >= 1, comm, PETSC_ERR_USER_INPUT,
             "option -bench_assembly_repeats: must be >= 1 (got %" PetscInt_FMT ")",
             o->assembly_repeats);
  PetscCheck(o->triad_mb > 0, comm, PETSC_ERR_USER_INPUT,
             "option -bench_triad_mb: must be > 0 (got %s)", FormatNumber(o->triad_mb).c_str());
  PetscFunctionReturn(PETSC_SUCCESS);
}

double PeakResidentMegabytes() {
  struct rusage usage;
  getrusage(RUSAGE_SELF, &usage);
  return usage.ru_maxrss / 1024.0;  // Linux: kilobytes
}

PetscErrorCode TriadBandwidth(MPI_Comm comm, PetscReal megabytes_per_array,
                              double *gigabytes_per_second) {
  PetscFunctionBeginUser;
  const size_t n = static_cast<size_t>(megabytes_per_array * 1e6 / sizeof(double));
  LargeArray<double> a(n), b(n), c(n);  // as the factor of the single-precision solves
  for (size_t i = 0; i < n; ++i) {      // first touch: the pages exist before timing
    a[i] = 0.0;
    b[i] = 1.0;
    c[i] = 2.0;
  }
  PetscMPIInt size;
  PetscCallMPI(MPI_Comm_size(comm, &size));
  double best = std::numeric_limits<double>::infinity();
  for (int pass = 0; pass < kTriadPasses; ++pass) {
    PetscCallMPI(MPI_Barrier(comm));
    const double start = MPI_Wtime();
    double *PETSC_RESTRICT pa = a.data();
    const double *PETSC_RESTRICT pb = b.data(), *PETSC_RESTRICT pc = c.data();
    for (size_t i = 0; i < n; ++i) pa[i] = pb[i] + 3.0 * pc[i];
    PetscCallMPI(MPI_Barrier(comm));
    best = std::min(best, MPI_Wtime() - start);
  }
  double checksum = a[n / 2];  // keeps the loop
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &checksum, 1, MPI_DOUBLE, MPI_SUM, comm));
  PetscCheck(checksum == 7.0 * size, comm, PETSC_ERR_PLIB, "triad: wrong result");
  *gigabytes_per_second = size * 3.0 * sizeof(double) * n / best / 1e9;
  PetscFunctionReturn(PETSC_SUCCESS);
}

void Benchmark::RecordStep(double seconds, const SolverStatistics &statistics) {
  if (!options_.enabled) return;
  step_seconds_.push_back(seconds);
  setup_seconds_.push_back(statistics.last_setup_seconds);
  last_total_iterations_ = statistics.total_iterations;
}

namespace {

double Median(std::vector<double> values) {
  if (values.empty()) return 0;
  std::sort(values.begin(), values.end());
  const size_t n = values.size();
  return n % 2 ? values[n / 2] : 0.5 * (values[n / 2 - 1] + values[n / 2]);
}

// Nonzeros of the Cholesky factor behind pc (0 when there is none) and the
// bytes per entry its solves read.
PetscErrorCode FactorNonzeros(PC pc, double *nonzeros, int *bytes_per_entry) {
  PetscFunctionBeginUser;
  *nonzeros = 0;
  *bytes_per_entry = 8;
  PetscBool warp, supernodal, cholesky;
  PetscCall(PetscObjectTypeCompare((PetscObject)pc, kPCWarp, &warp));
  if (warp) PetscCall(PCWarpGetInnerPC(pc, &pc));
  if (!pc) PetscFunctionReturn(PETSC_SUCCESS);
  PetscCall(PetscObjectTypeCompare((PetscObject)pc, kPCSupernodal, &supernodal));
  PetscCall(PetscObjectTypeCompareAny((PetscObject)pc, &cholesky, PCCHOLESKY, PCLU, ""));
  if (supernodal) {
    double stored, flops;
    PetscCall(PCSupernodalGetFactorSize(pc, &stored, nonzeros, &flops, bytes_per_entry));
  } else if (cholesky) {
    MatSolverType package;
    PetscCall(PCFactorGetMatSolverType(pc, &package));
    PetscBool mumps;
    PetscCall(PetscStrcmp(package, MATSOLVERMUMPS, &mumps));
    if (mumps) {
      Mat factor;
      PetscInt entries;
      PetscCall(PCFactorGetMatrix(pc, &factor));
      constexpr PetscInt kInfogFactorEntries = 29;  // MUMPS INFOG(29): entries in the factors
      PetscCall(MatMumpsGetInfog(factor, kInfogFactorEntries, &entries));  // < 0: millions
      *nonzeros = entries < 0 ? -1e6 * entries : entries;
    } else {
      Mat factor;
      MatInfo info;
      PetscCall(PCFactorGetMatrix(pc, &factor));
      PetscCall(MatGetInfo(factor, MAT_GLOBAL_SUM, &info));
      *nonzeros = info.nz_used;
    }
  }
  PetscFunctionReturn(PETSC_SUCCESS);
}

// What the step's memory traffic depends on: the sizes of A and of the factor
// behind the preconditioner, and whether the solve is direct (preonly).
struct SystemSizes {
  double matrix_nonzeros = 0, factor_nonzeros = 0;
  double rows = 0;       // n, the system's global size
  int factor_bytes = 8;  // bytes per factor entry read by a solve
  PetscBool preonly = PETSC_FALSE;
};

PetscErrorCode MeasureSystem(ImplicitEuler *integrator, SystemSizes *sizes) {
  PetscFunctionBeginUser;
  MatInfo info;
  PetscCall(MatGetInfo(integrator->system_matrix(), MAT_GLOBAL_SUM, &info));
  sizes->matrix_nonzeros = info.nz_used;
  PetscInt rows;
  PetscCall(MatGetSize(integrator->system_matrix(), &rows, nullptr));
  sizes->rows = static_cast<double>(rows);
  PC pc;
  PetscCall(KSPGetPC(integrator->solver(), &pc));
  PetscCall(FactorNonzeros(pc, &sizes->factor_nonzeros, &sizes->factor_bytes));
  PetscCall(PetscObjectTypeCompare((PetscObject)integrator->solver(), KSPPREONLY, &sizes->preonly));
  PetscFunctionReturn(PETSC_SUCCESS);
}

// Bytes a step must move at least (see benchmark.hpp), with `iterations` mean
// solver iterations per solve and `solves_per_step` solves per step.
double StepTrafficBytes(const SystemSizes &sizes, bool corotational, double iterations,
                        double solves_per_step) {
  // A direct solve: the linear step's one product is with K; else CG's with A.
  const double products = sizes.preonly ? (corotational ? 0.0 : 1.0) : iterations * solves_per_step;
  const double product_bytes =
      sizes.preonly ? kBlockProductBytesPerNonzero : kProductBytesPerNonzero;
  const double factor_solves =
      sizes.preonly ? solves_per_step
                    : (sizes.factor_nonzeros > 0 ? iterations * solves_per_step : 0.0);
  return product_bytes * sizes.matrix_nonzeros * products +
         kFactorSweepsPerSolve * sizes.factor_bytes * sizes.factor_nonzeros * factor_solves +
         kVectorsPerOperation * sizeof(double) * sizes.rows * (products + factor_solves) +
         (corotational ? kRefillBytesPerNonzero * sizes.matrix_nonzeros : 0.0);
}

}  // namespace

PetscErrorCode Benchmark::Finish(MPI_Comm comm, const Scene &scene, ImplicitEuler *integrator,
                                 Vec x) {
  PetscFunctionBeginUser;
  if (!options_.enabled) PetscFunctionReturn(PETSC_SUCCESS);
  double peak_rss = PeakResidentMegabytes();
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &peak_rss, 1, MPI_DOUBLE, MPI_MAX, comm));
  PetscMPIInt ranks;
  PetscCallMPI(MPI_Comm_size(comm, &ranks));

  std::vector<double> assembly;
  PetscCall(integrator->TimeAssembly(x, options_.assembly_repeats, &assembly));
  double assemble_s = Median(assembly);
  PetscCallMPI(MPI_Allreduce(MPI_IN_PLACE, &assemble_s, 1, MPI_DOUBLE, MPI_MAX, comm));

  const SolverStatistics &stats = integrator->statistics();
  SystemSizes sizes;
  PetscCall(MeasureSystem(integrator, &sizes));
  const double steps = static_cast<double>(step_seconds_.size());
  const double iterations = stats.solves ? double(stats.total_iterations) / stats.solves : 0;
  const double step_s = Median(step_seconds_);
  double factor_s = stats.factor_seconds;
  for (double s : setup_seconds_) factor_s = std::max(factor_s, s);

  double bandwidth;
  PetscCall(TriadBandwidth(comm, options_.triad_mb, &bandwidth));
  const double solves_per_step = steps > 0 ? stats.solves / steps : 1;
  const double bytes =
      StepTrafficBytes(sizes, integrator->mode() == MODE_COROTATIONAL, iterations, solves_per_step);
  const double bound_s = bytes / (bandwidth * 1e9);
  const double tets = static_cast<double>(scene.num_tets());

  attributes_ = {{"bench_tets", tets},
                 {"bench_vertices", double(scene.num_vertices())},
                 {"bench_ranks", double(ranks)},
                 {"bench_steps", steps},
                 {"step_s", step_s},
                 {"assemble_s", assemble_s},
                 {"assemble_rate", tets / assemble_s / ranks},
                 {"factor_s", factor_s},
                 {"iterations", iterations},
                 {"matrix_nonzeros", sizes.matrix_nonzeros},
                 {"factor_nonzeros", sizes.factor_nonzeros},
                 {"peak_rss_mb", peak_rss},
                 {"bandwidth_gbs", bandwidth},
                 {"bound_s", bound_s},
                 {"bound_fraction", step_s > 0 ? bound_s / step_s : 0.0}};
  PetscCall(PrintAttributes(comm));
  PetscFunctionReturn(PETSC_SUCCESS);
}

PetscErrorCode Benchmark::PrintAttributes(MPI_Comm comm) const {
  PetscFunctionBeginUser;
  std::ostringstream line;
  line << "softbody bench:";
  line.precision(kPrintedDigits);
  for (const auto &[name, value] : attributes_) line << ' ' << name << '=' << value;
  PetscCall(PetscPrintf(comm, "%s\n", line.str().c_str()));
  PetscFunctionReturn(PETSC_SUCCESS);
}

}  // namespace softbody
