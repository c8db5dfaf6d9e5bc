#!/usr/bin/env python3
"""Bad input ends the run with one clear line, never a hang, crash or traceback.

Every case runs softbody (2 ranks, some also 1 rank) on a hand-written input
from tests/data/bad_input/ or with a bad option, and checks:
- every rank exits non-zero (each rank is wrapped so that its own exit code is
  reported and mpirun does not cut a waiting rank short: a rank that waits on
  another is a hang, caught by the time limit);
- stderr holds exactly one line starting with "softbody: error:", and it names
  the file and line (or the option) at fault and a keyword of the problem;
- no "PETSC ERROR" traceback, no signal, no MPI_ABORT;
- no output file is left behind when a run fails.
A positive control (the valid tiny scene) must run and exit 0 on every rank.
Each case prints one PASS/FAIL line with the message seen.
"""
import argparse
import os
import re
import shutil
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

INPUTS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "data", "bad_input")
RANK_LIMIT = 25  # seconds a rank may run before `timeout` ends it (a hang)
RUN_LIMIT = 40  # seconds for the whole mpirun
MARK = "softbody-test-rank-exit"

# Each rank runs under this wrapper: it reports "MARK rank code" on stderr and
# exits 0, so mpirun never aborts the other rank (a rank left waiting on a
# collective shows up as code 124 from timeout instead of being killed).
WRAPPER = ('timeout -k 5 %d "$0" "$@"; code=$?; '
           'echo "%s ${OMPI_COMM_WORLD_RANK:-${PMIX_RANK:-?}} $code" >&2; exit 0' % (RANK_LIMIT, MARK))


def scene(name):
    return os.path.join(INPUTS, name)


class Case:
    """where: groups of alternatives; the message must hold one alternative of
    every group. keys: the message must hold one of them (case-insensitive)."""

    def __init__(self, name, options, where, keys, ranks=(2,), must_not_exist=()):
        self.name, self.options, self.where, self.keys = name, options, where, keys
        self.ranks, self.must_not_exist = ranks, must_not_exist


def run(args, ranks, options):
    """Returns (per-rank exit codes, stdout, stderr without the wrapper's lines) or
    None on a time-out of the whole run."""
    wrapped = argparse.Namespace(**vars(args))
    wrapped.softbody = "/bin/sh"
    try:
        result = harness.run(wrapped, ranks, ["-c", WRAPPER, args.softbody] + list(options),
                             timeout=RUN_LIMIT, check=False)
    except subprocess.TimeoutExpired:
        return None
    codes, lines = {}, []
    for line in result.stderr.splitlines():
        match = re.fullmatch(MARK + r" (\S+) (\d+)", line.strip())
        if match:
            codes[match.group(1)] = int(match.group(2))
        else:
            lines.append(line)
    if result.returncode != 0:
        codes["mpirun"] = result.returncode
    return codes, result.stdout, "\n".join(lines)


def judge(case, ranks, outcome):
    """Returns (ok, one-line description)."""
    if outcome is None:
        return False, f"mpirun did not finish within {RUN_LIMIT} s (hang)"
    codes, stdout, stderr = outcome
    problems = []
    rank_codes = {r: c for r, c in codes.items() if r != "mpirun"}
    if len(rank_codes) != ranks:
        problems.append(f"exit codes of {len(rank_codes)} of {ranks} ranks reported ({codes})")
    for r, c in sorted(rank_codes.items()):
        if c == 124 or c == 137:
            problems.append(f"rank {r} hung (killed after {RANK_LIMIT} s)")
        elif c == 0:
            problems.append(f"rank {r} exited 0")
        elif c >= 128:
            problems.append(f"rank {r} died of signal {c - 128}")
    text = stdout + "\n" + stderr
    for bad in ("PETSC ERROR", "MPI_ABORT", "Segmentation", "signal", "Traceback"):
        if bad in text:
            problems.append(f"'{bad}' in the output")
    errors = [l for l in stderr.splitlines() if l.startswith("softbody: error:")]
    message = errors[0] if errors else "(no 'softbody: error:' line)"
    if len(errors) != 1:
        problems.append(f"{len(errors)} 'softbody: error:' lines")
    if errors:
        for group in case.where:
            if not any(alt in message for alt in group):
                problems.append("message does not name " + " or ".join(repr(a) for a in group))
        if not any(k.lower() in message.lower() for k in case.keys):
            problems.append("message has none of " + ", ".join(repr(k) for k in case.keys))
    for path in case.must_not_exist:
        if os.path.exists(path):
            problems.append(f"{path} was left behind")
    if not errors:
        tail = [l for l in stderr.splitlines() if l.strip()][:2]
        message += " stderr starts: " + " | ".join(tail)
    return not problems, message + ("" if not problems else "  <-- " + "; ".join(problems))


def main():
    args = harness.arguments()
    checks = harness.Checks()
    work = os.path.abspath(args.work)
    valid = scene("valid.txt")

    no_folder = os.path.join(work, "no_such_folder")
    shutil.rmtree(no_folder, ignore_errors=True)
    bad_output = os.path.join(no_folder, "out.h5")
    regular_file = os.path.join(work, "regular_file")
    with open(regular_file, "w") as f:
        f.write("not a folder\n")
    matrices = os.path.join(regular_file, "matrices")
    left_over = os.path.join(work, "bad_scene.h5")
    for path in (left_over, left_over[:-3] + ".xdmf"):
        if os.path.exists(path):
            os.remove(path)

    def body(name, line, keys, ranks=(2,)):
        return Case(name, ["-scene", scene(name + ".txt"), "-steps", 1],
                    [[f"{name}.txt:{line}:"]], keys, ranks)

    def option(name, value, keys, ranks=(2,)):
        return Case(f"option {name} {value}", ["-scene", valid, "-steps", 1, name, value],
                    [[f"option {name}"]], keys, ranks)

    def mesh(name, mesh_file, line, keys, ranks=(2,)):
        return Case(name, ["-scene", scene(name + ".txt"), "-steps", 1],
                    [[f"{mesh_file}:{line}:" for line in (line if isinstance(line, tuple) else (line,))]],
                    keys, ranks)

    cases = [
        Case("missing scene file", ["-scene", scene("no_such_scene.txt")],
             [["no_such_scene.txt"]], ["cannot open", "no such", "not found", "does not exist"],
             ranks=(2, 1)),
        # The scene line that names the mesh, and the mesh file itself.
        Case("missing mesh file", ["-scene", scene("missing_mesh.txt")],
             [["missing_mesh.txt:2:"], ["no_such_mesh.mesh"]],
             ["cannot open", "no such", "not found", "does not exist"]),
        body("field_count", 2, ["fields"], ranks=(2, 1)),
        body("non_numeric", 2, ["not a number", "abc"], ranks=(2, 1)),
        # End of file: the last line (3, 5) or the one after it (4, 6).
        Case("few_meshes", ["-scene", scene("few_meshes.txt")],
             [["few_meshes.txt:3:", "few_meshes.txt:4:"]], ["mesh lines", "expected 3"]),
        Case("few_velocities", ["-scene", scene("few_velocities.txt")],
             [["few_velocities.txt:5:", "few_velocities.txt:6:"]], ["velocity lines", "expected 3"]),
        body("extra_velocities", 5, ["unexpected", "extra", "after"]),
        body("velocity_vertex_range", 5, ["vertex index", "out of range"]),
        body("velocity_mesh_range", 4, ["mesh index", "out of range"]),
        body("nu_half", 2, ["poisson"]),
        body("nu_minus_one", 2, ["poisson"]),
        body("young_zero", 2, ["young"]),
        body("young_negative", 2, ["young"]),
        body("density_zero", 2, ["density"]),
        body("density_negative", 2, ["density"]),
        body("nan_field", 2, ["not finite", "nan"]),
        body("inf_field", 2, ["not finite", "inf"]),
        body("fixed_two", 2, ["is_fixed"]),
        body("zero_quaternion", 2, ["quaternion"]),
        mesh("mesh_bad_vertex_index", "bad_vertex_index.mesh", 11, ["vertex index", "out of range"]),
        mesh("mesh_degenerate", "degenerate.mesh", 11, ["degenerate", "zero volume"], ranks=(2, 1)),
        # 4 vertices announced, 3 given: the last line (7) or the one after it (8).
        mesh("mesh_truncated", "truncated.mesh", (7, 8), ["end of file", "truncated"]),
        mesh("mesh_unknown_keyword", "unknown_keyword.mesh", 9, ["unknown", "Pyramids"]),
        option("-dt", 0, ["> 0", "positive"], ranks=(2, 1)),
        option("-dt", -1, ["> 0", "positive"]),
        option("-steps", -1, [">= 0", "negative"]),
        option("-alpha", -1, [">= 0", "negative"]),
        option("-output_every", 0, [">= 1", "positive"]),
        option("-shear_scale", 0, ["> 0", "positive"]),
        Case("missing -scene", ["-steps", 1], [["-scene"]], ["required", "missing"], ranks=(2, 1)),
        Case("-output into a missing folder", ["-scene", valid, "-steps", 1, "-output", bad_output],
             [["option -output"]], ["cannot create", "no such", "does not exist"], ranks=(2, 1),
             must_not_exist=[bad_output, bad_output[:-3] + ".xdmf"]),
        Case("-export_matrices under a regular file",
             ["-scene", valid, "-steps", 1, "-export_matrices", matrices],
             [["option -export_matrices"]], ["cannot create", "not a directory"], ranks=(2, 1)),
        Case("bad scene with -output leaves no file",
             ["-scene", scene("nu_half.txt"), "-steps", 1, "-output", left_over],
             [["nu_half.txt:2:"]], ["poisson"],
             must_not_exist=[left_over, left_over[:-3] + ".xdmf"]),
        # Beyond the first list: option values that are not numbers, not finite, not a choice.
        option("-dt", "abc", ["not a number", "abc", "numeric"]),
        option("-steps", "1.5", ["integer", "1.5"]),
        option("-dt", "inf", ["finite", "inf"]),
        option("-mode", "foo", ["not one of", "foo"]),
        option("-vertex_order", "foo", ["not one of", "foo"]),
        option("-partitioner", "foo", ["not one of", "foo"]),
        option("-contact_solve", "foo", ["not one of", "foo"]),
        # (PETSc's own parse of these ended in a traceback and exit 139)
        option("-sharp_edges", "maybe", ["true or false", "maybe"]),
        option("-impulse_spreading", "2", ["true or false"]),
        option("-quiet", "maybe", ["true or false"]),
        option("-progress", "maybe", ["true or false"]),
        option("-bench", "maybe", ["true or false"]),
    ]

    for case in cases:
        for ranks in case.ranks:
            ok, line = judge(case, ranks, run(args, ranks, case.options))
            checks.check(ok, f"[{ranks} rank{'s' if ranks > 1 else ''}] {case.name}: {line}")

    # Positive control: the same machinery sees a clean run of the valid scene.
    for ranks in (2, 1):
        out = os.path.join(work, f"valid-{ranks}.h5")
        if os.path.exists(out):
            os.remove(out)
        outcome = run(args, ranks, ["-scene", valid, "-steps", 3, "-output", out])
        if outcome is None:
            checks.check(False, f"[{ranks} rank{'s' if ranks > 1 else ''}] valid scene: hang")
            continue
        codes, stdout, stderr = outcome
        ok = (sorted(codes) == sorted(str(r) for r in range(ranks)) and not any(codes.values())
              and "softbody: error" not in stderr and "PETSC ERROR" not in stderr
              and os.path.exists(out))
        checks.check(ok, f"[{ranks} rank{'s' if ranks > 1 else ''}] valid scene runs: exit codes {codes}, output "
                         f"{'written' if os.path.exists(out) else 'missing'}"
                     + ("" if ok else "  <-- stderr: " + " | ".join(stderr.splitlines()[:3])))
    checks.exit()


if __name__ == "__main__":
    main()
