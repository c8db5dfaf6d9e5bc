#!/usr/bin/env python3
"""Every tool in tools/ prints its help for -help (PETSc's spelling), --help and -h.

For each tools/*.py that is a command (has a main guard): exit status 0, a "usage:"
line naming the script, and the -help text equal to the --help text. (argparse on
its own reads "-help" as -h with the argument "elp" and fails.)
"""
import glob
import os
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def main():
    harness.arguments()
    checks = harness.Checks()
    tools = [path for path in sorted(glob.glob(os.path.join(ROOT, "tools", "*.py")))
             if "__main__" in open(path).read()]
    checks.check(len(tools) >= 7, f"{len(tools)} tools found")
    for path in tools:
        name = os.path.basename(path)
        texts = {}
        for spelling in ("-help", "--help", "-h"):
            run = subprocess.run([sys.executable, path, spelling], capture_output=True, text=True,
                                 timeout=60)
            texts[spelling] = run.stdout
            checks.check(run.returncode == 0 and f"usage: {name}" in run.stdout,
                         f"{name} {spelling}: exit {run.returncode}, usage line "
                         f"({(run.stdout or run.stderr).strip().splitlines()[:1]})")
        checks.check(texts["-help"] == texts["--help"], f"{name}: -help prints what --help prints")
    checks.exit()


if __name__ == "__main__":
    main()
