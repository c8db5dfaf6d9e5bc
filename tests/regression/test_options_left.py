"""Options nothing read are reported, not silently ignored.

Runs the beam scene for two steps on two ranks:
(a) with typos -integratr bdf2 -ksp_rtoll 1e-3: exit 0, the summary on stdout,
    and on stderr exactly one warning line per typo (rank 0 only, so not two),
    -ksp_rtoll's naming -ksp_rtol as the likely option;
(b) a typo of one of softbody's own options (-stepz) suggests it (-steps);
(c) an option of a solver the run does not use (-warp_pc_type: the inner
    solver of the corotational default, in linear mode) is reported;
(d) -options_left 0 silences the report;
(e) -quiet keeps the warnings (they are not the summary);
(f) a run whose options are all read prints nothing on stderr.
"""
import os
import re
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402

args = harness.arguments()
checks = harness.Checks()
scene = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scenes", "beam-scene.txt")
WARNING = re.compile(r"^softbody: warning: option (-\w+) was not used(?: \(did you mean (-\w+)\?\))?$")


def warnings(options, ranks=2):
    """Runs softbody; returns (exit code, stdout, {option: suggestion or None}, warning lines)."""
    result = harness.run(args, ranks, ["-scene", scene, "-steps", 2] + options, check=False)
    lines = [line for line in result.stderr.splitlines() if line.startswith("softbody: warning:")]
    found = {}
    for line in lines:
        match = WARNING.match(line)
        if match:
            found[match.group(1)] = match.group(2)
    return result.returncode, result.stdout, found, lines


code, out, found, lines = warnings(["-integratr", "bdf2", "-ksp_rtoll", "1e-3"])
checks.check(code == 0 and "softbody run summary" in out,
             f"(a) typos: exit {code}, summary {'on stdout' if 'softbody run summary' in out else 'missing'}")
checks.check(len(lines) == 2 and set(found) == {"-integratr", "-ksp_rtoll"},
             f"(a) one warning per typo, from rank 0 only: {lines}")
checks.check(found.get("-ksp_rtoll") == "-ksp_rtol", f"(a) -ksp_rtoll suggests {found.get('-ksp_rtoll')}")

code, _, found, lines = warnings(["-stepz", "3"])
checks.check(code == 0 and found == {"-stepz": "-steps"}, f"(b) softbody's own option: {lines}")

code, _, found, lines = warnings(["-warp_pc_type", "gamg"])
checks.check(code == 0 and list(found) == ["-warp_pc_type"],
             f"(c) the warp preconditioner's option in linear mode is reported: {lines}")

code, _, found, lines = warnings(["-integratr", "bdf2", "-ksp_rtoll", "1e-3", "-options_left", "0"])
checks.check(code == 0 and not lines, f"(d) -options_left 0: exit {code}, {len(lines)} warnings")

code, out, found, lines = warnings(["-ksp_rtoll", "1e-3", "-quiet"])
checks.check(code == 0 and not out.strip() and list(found) == ["-ksp_rtoll"],
             f"(e) -quiet: stdout {'empty' if not out.strip() else 'not empty'}, warnings {lines}")

result = harness.run(args, 2, ["-scene", scene, "-steps", 2, "-quiet", "-dt", 0.01, "-mode", "linear"],
                     check=False)
checks.check(result.returncode == 0 and not result.stderr.strip(),
             f"(f) every option read: exit {result.returncode}, stderr {result.stderr.strip()[:200]!r}")
checks.exit()
