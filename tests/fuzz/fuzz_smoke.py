#!/usr/bin/env python3
"""Fuzz smoke run: builds the libFuzzer targets of the parsers with clang
(-DSOFTBODY_FUZZ=ON) in a folder of their own and runs each on its corpus
(tests/fuzz/corpus/<target>, read only) and then fuzzes it for a few seconds.
Fails on any crash, sanitizer report, time-out or memory blow-up; skipped (77)
when clang or its libFuzzer runtime is missing. New inputs and crash artifacts go
to <build>/runs/<target>/, never into the committed corpus.
"""
import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time

SKIP = 77


def find_clang():
    for cxx, cc in (("clang++", "clang"), ("clang++-14", "clang-14")):
        if shutil.which(cxx) and shutil.which(cc):
            return shutil.which(cxx), shutil.which(cc)
    return None, None


def has_libfuzzer(cxx):
    """True when `cxx -fsanitize=fuzzer` links a program."""
    with tempfile.TemporaryDirectory() as folder:
        source = os.path.join(folder, "probe.cpp")
        with open(source, "w") as f:
            f.write('extern "C" int LLVMFuzzerTestOneInput(const unsigned char *, unsigned long) '
                    '{ return 0; }\n')
        result = subprocess.run([cxx, "-fsanitize=fuzzer", source, "-o", os.path.join(folder, "probe")],
                                capture_output=True, text=True)
        return result.returncode == 0


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--source", required=True)
    parser.add_argument("--build", required=True)
    parser.add_argument("--targets", nargs="+", required=True)
    parser.add_argument("--seconds", type=int, default=5, help="fuzzing time per target")
    args = parser.parse_args()

    cxx, cc = find_clang()
    if not cxx:
        print("SKIP: clang++ not found (Debian packages clang, libclang-rt-14-dev)")
        return SKIP
    if not has_libfuzzer(cxx):
        print(f"SKIP: {cxx} cannot link -fsanitize=fuzzer (Debian package libclang-rt-14-dev)")
        return SKIP

    start = time.time()
    configure = ["cmake", "-S", args.source, "-B", args.build, "-DSOFTBODY_FUZZ=ON",
                 f"-DCMAKE_CXX_COMPILER={cxx}", f"-DCMAKE_C_COMPILER={cc}",
                 "-DCMAKE_BUILD_TYPE=RelWithDebInfo"]
    build = ["cmake", "--build", args.build, "-j2", "--target"] + [f"fuzz_{t}" for t in args.targets]
    for command in (configure, build):
        result = subprocess.run(command, capture_output=True, text=True)
        if result.returncode != 0:
            print("FAIL:", " ".join(command))
            print(result.stdout[-5000:], result.stderr[-5000:])
            return 1
    print(f"built the fuzzers in {time.time() - start:.0f} s ({args.build})")

    # Leaks inside MPI/PETSc initialisation are not ours (the fuzzers do not
    # initialise either, but keep the same suppressions as the sanitizer suite).
    env = dict(os.environ)
    suppressions = os.path.join(args.source, "tests", "sanitize", "lsan.supp")
    if os.path.exists(suppressions) and "suppressions=" not in env.get("LSAN_OPTIONS", ""):
        env["LSAN_OPTIONS"] = f"suppressions={suppressions}:" + env.get("LSAN_OPTIONS", "")

    failed = []
    for target in args.targets:
        corpus = os.path.join(args.source, "tests", "fuzz", "corpus", target)
        work = os.path.join(args.build, "runs", target)
        shutil.rmtree(work, ignore_errors=True)
        os.makedirs(os.path.join(work, "new"))
        command = [os.path.join(args.build, "tests", "fuzz", f"fuzz_{target}"),
                   os.path.join(work, "new"), corpus,
                   f"-max_total_time={args.seconds}", "-rss_limit_mb=2048", "-timeout=5",
                   "-print_final_stats=1", f"-artifact_prefix={work}/"]
        t0 = time.time()
        result = subprocess.run(command, capture_output=True, text=True, env=env,
                                timeout=args.seconds + 120)
        runs = re.search(r"stat::number_of_executed_units:\s*(\d+)", result.stderr)
        seeds = len(os.listdir(corpus))
        line = (f"fuzz_{target}: {seeds} corpus files, {runs.group(1) if runs else '?'} runs "
                f"in {time.time() - t0:.1f} s, exit {result.returncode}")
        if result.returncode != 0:
            failed.append(target)
            print("FAIL", line)
            print(" ".join(command))
            print(result.stderr[-8000:])
        else:
            print("PASS", line)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
