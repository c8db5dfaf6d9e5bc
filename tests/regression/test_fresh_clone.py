#!/usr/bin/env python3
"""A fresh clone without ../shared runs the whole suite; only the seed-data tests skip.

1. `git clone` of this source tree's HEAD (committed files only: a tree with
   uncommitted changes is cloned at HEAD all the same, and the script says so)
   into the work folder, where no ../shared lies beside it.
2. The clone's tests/ configured on its own against the programs of the build
   that runs this test (cmake -S clone/tests -DSOFTBODY_PREBUILT_DIR=BUILD, see
   tests/CMakeLists.txt): nothing is compiled, but every script, scene, mesh,
   corpus and data file is the clone's.
3. Its ctest -j2, less fuzz_smoke (it compiles the fuzzers).
Checked: the clone registers the same tests as this build (less fuzz_smoke and
this test; when the tree is clean), every one of them passes except the
seed-data tests SEED_TESTS, which must report skipped, and test_leaks, which
skips unless the build has AddressSanitizer.
Skipped (77) when git is not installed, when the source tree is not a git
checkout, and in the sanitizer build (the check is about the tree, not the
build: the default build runs it).
"""
import os
import re
import shutil
import subprocess
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

ROOT = os.path.abspath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
# The tests that compare with the seed coursework data in ../shared (test_seed_*.py).
SEED_TESTS = {"test_seed_constraints", "test_seed_grader", "test_seed_off_scenes", "test_seed_practical3_scenes"}
# Every test_seed_*.py is one (tests/regression/CMakeLists.txt gives them alone --shared).
SEED_PREFIX = "test_seed_"
# Skipped for the kind of build, not for the data: the leak check needs AddressSanitizer.
BUILD_SKIPS = {"test_leaks"}
NOT_IN_CLONE = {"fuzz_smoke", "test_fresh_clone"}
RESULT = re.compile(r"Test\s+#\d+: (\S+) \.+\s*(\*\*\*)?(\w[\w ]*?)\s+[\d.]+ sec")


def git(*arguments, cwd=ROOT):
    return subprocess.run(["git", *arguments], cwd=cwd, capture_output=True, text=True)


def registered_tests(build):
    """Test names ctest lists in a build folder."""
    listing = subprocess.run(["ctest", "-N"], cwd=build, capture_output=True, text=True).stdout
    return set(re.findall(r"Test\s+#\d+: (\S+)", listing))


def main():
    args = harness.arguments()
    checks = harness.Checks()
    libraries = subprocess.run(["ldd", args.softbody], capture_output=True, text=True).stdout
    if "libasan" in libraries or "libclang_rt.asan" in libraries:
        print("SKIP: a sanitizer build (the default build runs the fresh-clone check)")
        sys.exit(harness.SKIP)
    if shutil.which("git") is None:
        print("SKIP: git is not installed")
        sys.exit(harness.SKIP)
    head = git("rev-parse", "HEAD")
    if head.returncode != 0:
        print(f"SKIP: {ROOT} is not a git checkout (nothing to clone)")
        sys.exit(harness.SKIP)
    commit = head.stdout.strip()
    changes = git("status", "--porcelain", "--untracked-files=no").stdout.strip()
    if changes:
        print(f"note: the source tree has uncommitted changes; the clone tests HEAD {commit[:12]} without them")

    # 1. The clone, with no ../shared beside it.
    clone, build = os.path.join(args.work, "clone"), os.path.join(args.work, "build")
    for folder in (clone, build):
        shutil.rmtree(folder, ignore_errors=True)
    start = time.monotonic()
    for step in (["clone", "--quiet", "--no-checkout", ROOT, clone], ["fetch", "--quiet", ROOT, commit],
                 ["checkout", "--quiet", commit]):
        result = git(*step, cwd=args.work if step[0] == "clone" else clone)
        if not checks.check(result.returncode == 0, f"git {' '.join(step[:3])}: exit {result.returncode} "
                                                    f"{result.stderr.strip()[:300]}"):
            checks.exit()
    shared = os.path.join(clone, "..", "shared")
    checks.check(not os.path.exists(shared), f"no {os.path.normpath(shared)} beside the clone")

    # 2. Its tests, configured against this build's programs.
    prebuilt = os.path.dirname(os.path.abspath(args.softbody))
    configure = subprocess.run(["cmake", "-S", os.path.join(clone, "tests"), "-B", build,
                                f"-DSOFTBODY_PREBUILT_DIR={prebuilt}"], capture_output=True, text=True)
    if not checks.check(configure.returncode == 0, f"cmake -S clone/tests -DSOFTBODY_PREBUILT_DIR={prebuilt}"):
        print(configure.stdout[-3000:], configure.stderr[-3000:])
        checks.exit()
    in_clone = registered_tests(build)
    in_build = registered_tests(prebuilt) - NOT_IN_CLONE
    same = in_clone == in_build
    checks.check(same or bool(changes),
                 f"the clone registers the {len(in_clone)} tests of this build less {sorted(NOT_IN_CLONE)}"
                 + ("" if same else f" (only in the clone: {sorted(in_clone - in_build)}, only in this build: "
                                    f"{sorted(in_build - in_clone)}; the uncommitted changes explain it)"))
    checks.check(SEED_TESTS <= in_clone, f"the seed-data tests {sorted(SEED_TESTS)} are among them")

    # 3. Its suite.
    suite = subprocess.run(["ctest", "-j2", "-E", "^(" + "|".join(sorted(NOT_IN_CLONE)) + ")$",
                            "--output-on-failure"], cwd=build, capture_output=True, text=True,
                           env=harness.mpi_environment(), timeout=840)
    seconds = time.monotonic() - start
    print("\n".join(line for line in suite.stdout.splitlines() if RESULT.search(line) or "tests passed" in line))
    outcomes = {m.group(1): m.group(3) for m in map(RESULT.search, suite.stdout.splitlines()) if m}
    checks.check(set(outcomes) == in_clone, f"ctest ran all {len(in_clone)} tests ({len(outcomes)} results)")
    for name in sorted(in_clone):
        outcome = outcomes.get(name, "not run")
        if name in SEED_TESTS or name.startswith(SEED_PREFIX):
            checks.check(outcome == "Skipped", f"{name}: {outcome} (seed data: must skip)")
        elif name in BUILD_SKIPS:
            checks.check(outcome in ("Passed", "Skipped"), f"{name}: {outcome} (skips unless built with ASan)")
        elif not checks.check(outcome == "Passed", f"{name}: {outcome}"):
            print(suite.stdout[-6000:])
    print(f"fresh clone: clone, configure and suite in {seconds:.0f} s")
    checks.exit()


if __name__ == "__main__":
    main()
