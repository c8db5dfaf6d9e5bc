#!/usr/bin/env python3
"""The committed .clang-format stays applied: clang-format --dry-run -Werror on
every tracked .cpp and .hpp file (git ls-files; every such file under src/ and
tests/ when the tree is not a git checkout) must report nothing.

Fix with `clang-format -i FILE` (the version of Debian's clang-format package;
another version may format differently). Skipped (77) when clang-format is not
installed.
"""
import os
import shutil
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

ROOT = os.path.abspath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
SUFFIXES = (".cpp", ".hpp")


def source_files():
    """The C++ files of the tree, relative to ROOT."""
    if shutil.which("git"):
        listed = subprocess.run(["git", "ls-files", "-z", "--", "*.cpp", "*.hpp"], cwd=ROOT, capture_output=True,
                                text=True)
        if listed.returncode == 0:
            return sorted(name for name in listed.stdout.split("\0") if name.endswith(SUFFIXES))
    found = []
    for top in ("src", "tests"):
        for folder, _, names in os.walk(os.path.join(ROOT, top)):
            found += [os.path.relpath(os.path.join(folder, n), ROOT) for n in names if n.endswith(SUFFIXES)]
    return sorted(found)


def main():
    harness.arguments()
    checks = harness.Checks()
    clang_format = shutil.which("clang-format")
    if clang_format is None:
        print("SKIP: clang-format is not installed (Debian package clang-format)")
        sys.exit(harness.SKIP)
    version = subprocess.run([clang_format, "--version"], capture_output=True, text=True).stdout.strip()
    files = source_files()
    checks.check(os.path.isfile(os.path.join(ROOT, ".clang-format")) and len(files) > 0,
                 f".clang-format and {len(files)} C++ files ({version})")
    result = subprocess.run([clang_format, "--dry-run", "-Werror", *files], cwd=ROOT, capture_output=True,
                            text=True)
    unformatted = sorted({line.split(":")[0] for line in result.stderr.splitlines() if ": error:" in line})
    checks.check(result.returncode == 0 and not unformatted,
                 f"clang-format --dry-run -Werror: exit {result.returncode}, "
                 + (f"{len(unformatted)} files to format: {' '.join(unformatted)} (clang-format -i FILE)"
                    if unformatted else "every file formatted" if result.returncode == 0 else result.stderr[-2000:]))
    checks.exit()


if __name__ == "__main__":
    main()
