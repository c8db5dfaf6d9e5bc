// Linked into the softbody program of the sanitizer build only (-DSOFTBODY_SANITIZE=ON).
//
// LeakSanitizer checks at exit. In a process that ran MPI, Open MPI leaves behind
// allocations made in MPI_Init and MPI_Finalize, by plug-ins it has unloaded by
// then; the default (frame-pointer) unwinder stops at the first frame of those
// uninstrumented libraries, so the reports cannot be told from ours or suppressed
// by name, and the full unwinder (fast_unwind_on_malloc=0) that makes them
// suppressible slows every allocation, and the suite, about fourfold. So softbody
// skips the leak check at exit unless SOFTBODY_LSAN=1: tests/regression/test_leaks.py sets it,
// with the full unwinder and tests/sanitize/lsan.supp, for a few representative
// runs. Everything else of ASan and UBSan stays on in every run.
#include <cstdlib>
#include <cstring>

extern "C" int __lsan_is_turned_off() {
  const char *requested = std::getenv("SOFTBODY_LSAN");
  return !(requested && std::strcmp(requested, "1") == 0);
}
