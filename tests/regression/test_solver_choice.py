#!/usr/bin/python3
"""The default solver's choice between the supernodal factor and multigrid (solver.hpp).

The bench's struck beam at about 1e4 tets (tools/bench.py), linear mode, 5 steps
of 0.02 s, 2 ranks unless said. Checked:
(a) default options: the factor stays ("choice  split supernodal factor:
    separator n_S = N, predicted ... <= budget ..."), the solver line says
    supernodal, and the predicted n_S equals the separator the set-up built
    (-ksp_view: "split at a separator of N DOFs");
(b) -pc_supernodal_budget_mb 1e9 (far above the need): the factor stays and the
    positions are bit for bit those of (a);
(c) -pc_supernodal_budget_mb 1 (below the separator's dense blocks alone):
    "choice  CG + GAMG: the split factor's separator n_S = N would need X MB per
    rank > budget 1 MB" with the same N and X > 1, the solver line says cg +
    gamg, and the positions equal (a)'s to 1e-6 of the largest displacement (CG's
    rtol is 1e-10); the decision is made before anything of the factor is
    allocated: under -info the choice's line is printed and no numeric
    factorisation of the supernodal PC ever runs (its "factorising" lines absent);
(d) -pc_supernodal_max_separator 10: CG + GAMG, the reason names the option;
(e) one rank, -pc_supernodal_budget_mb 0.5: CG + GAMG, "the factor would need";
(f) corotational mode, -warp_pc_supernodal_budget_mb 1: "choice  warp around
    GAMG: ...", positions equal those of the default (warp around the factor) to
    1e-6 of the largest displacement;
(g) -pc_supernodal_budget_mb -1: one error line naming the option, non-zero exit.
"""
import os
import re
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402
import bench  # noqa: E402  (tools/, on the path through harness)

args = harness.arguments()
checks = harness.Checks()
scene = bench.write_beam(args.work, 10000)
COMMON = ["-scene", scene, "-steps", 5, "-dt", 0.02, "-output_every", 5]
CHOICE = re.compile(r"^  choice +(.*)$", re.M)
SOLVER = re.compile(r"^  solver +(\w+) \+ (\w+)", re.M)
SEPARATOR = re.compile(r"n_S = ([\d ]+\d)")


def simulate(label, ranks, options):
    output = harness.fresh_result(args.work, label)
    r = harness.run(args, ranks, COMMON + options + ["-output", output], check=False)
    checks.check(r.returncode == 0, f"{label}: exit {r.returncode} {r.stderr.strip()[-300:]}")
    choice = CHOICE.search(r.stdout)
    solver = SOLVER.search(r.stdout)
    frames = harness.read_frames(output) if r.returncode == 0 else None
    return {"out": r.stdout, "choice": choice.group(1) if choice else "", "solver": solver.groups() if solver else (),
            "frames": frames}


def separator(text):
    m = SEPARATOR.search(text)
    return int(m.group(1).replace(" ", "")) if m else None


def agree(label, run, reference, limit):
    if run["frames"] is None or reference["frames"] is None:
        return
    x, y = run["frames"]["positions"], reference["frames"]["positions"]
    scale = np.abs(y - reference["frames"]["mesh/rest_positions"]).max()
    difference = np.abs(x - y).max()
    checks.check(difference <= limit * scale,
                 f"{label}: positions within {difference:.2g} m of the factor's (limit {limit:g} x {scale:.3g} m)")


# (a) the default keeps the factor; its predicted separator is the one built.
direct = simulate("direct", 2, ["-ksp_view"])
n_s = separator(direct["choice"])
built = re.search(r"split at a separator of (\d+) DOFs", direct["out"])
checks.check(direct["choice"].startswith("split supernodal factor: separator n_S = ") and "<= budget" in direct["choice"],
             f"(a) default: choice '{direct['choice']}'")
checks.check(direct["solver"] == ("preonly", "supernodal"), f"(a) default: solver {direct['solver']}")
checks.check(built is not None and n_s == int(built.group(1)),
             f"(a) predicted n_S {n_s} equals the separator built, {built.group(1) if built else None}")

# (b) a budget far above the need: the same factor, the same numbers.
high = simulate("high", 2, ["-pc_supernodal_budget_mb", "1e9"])
checks.check(high["solver"] == ("preonly", "supernodal"), f"(b) budget 1e9 MB: solver {high['solver']}")
if high["frames"] is not None and direct["frames"] is not None:
    checks.check(np.array_equal(high["frames"]["positions"], direct["frames"]["positions"]),
                 "(b) budget 1e9 MB: positions bit for bit those of the default")

# (c) a budget below the separator's blocks: multigrid, decided before allocation.
low = simulate("low", 2, ["-pc_supernodal_budget_mb", "1", "-info"])
need = re.search(r"would need ([\d .]+) MB per rank > budget 1 MB", low["choice"])
checks.check(low["choice"].startswith("CG + GAMG: the split factor's separator n_S = ") and need is not None
             and separator(low["choice"]) == n_s and float(need.group(1).replace(" ", "")) > 1,
             f"(c) budget 1 MB: choice '{low['choice']}' (n_S of (a): {n_s})")
checks.check(low["solver"] == ("cg", "gamg"), f"(c) budget 1 MB: solver {low['solver']}")
info = [line for line in low["out"].splitlines() if "solver choice:" in line]
factorising = [line for line in low["out"].splitlines() if "supernodal: factorising" in line]
checks.check(len(info) >= 1 and not factorising,
             f"(c) -info: {len(info)} 'solver choice' lines, {len(factorising)} supernodal factorisations")
agree("(c) budget 1 MB", low, direct, 1e-6)
# The factorisations are there under -info when the factor is chosen (so their absence above means something).
# The prediction's symbolic analysis is the set-up's: one per rank, not two.
shown = simulate("shown", 2, ["-info"])
checks.check(any("supernodal: factorising" in line for line in shown["out"].splitlines()),
             "(c) -info with the factor: its 'supernodal: factorising' lines are printed")
analyses = sum("supernodal: analysing" in line for line in shown["out"].splitlines())
checks.check(analyses == 2, f"(a) -info: {analyses} symbolic analyses on 2 ranks (one each: the prediction's, kept)")

# (d) the separator's own limit.
small = simulate("max-separator", 2, ["-pc_supernodal_max_separator", "10"])
checks.check(small["choice"].startswith("CG + GAMG: ") and "-pc_supernodal_max_separator 10" in small["choice"],
             f"(d) -pc_supernodal_max_separator 10: choice '{small['choice']}'")

# (e) one rank: the whole factor's predicted size.
one = simulate("one-rank", 1, ["-pc_supernodal_budget_mb", "0.5"])
checks.check(one["choice"].startswith("CG + GAMG: the factor would need ") and "> budget 0.5 MB" in one["choice"]
             and one["solver"] == ("cg", "gamg"),
             f"(e) one rank, budget 0.5 MB: choice '{one['choice']}', solver {one['solver']}")
agree("(e) one rank, budget 0.5 MB", one, direct, 1e-6)

# (f) corotational: the warp preconditioner's inner solve.
warp = simulate("warp", 2, ["-mode", "corotational"])
warp_gamg = simulate("warp-gamg", 2, ["-mode", "corotational", "-warp_pc_supernodal_budget_mb", "1"])
checks.check(warp["choice"].startswith("warp around split supernodal factor: "),
             f"(f) corotational default: choice '{warp['choice']}'")
checks.check(warp_gamg["choice"].startswith("warp around GAMG: the split factor's separator"),
             f"(f) corotational, inner budget 1 MB: choice '{warp_gamg['choice']}'")
agree("(f) corotational, inner GAMG", warp_gamg, warp, 1e-6)

# (g) bad input.
r = harness.run(args, 2, COMMON + ["-pc_supernodal_budget_mb", "-1"], timeout=120, check=False)
lines = [line for line in r.stderr.splitlines() if line.startswith("softbody: error")]
checks.check(r.returncode != 0 and len(lines) == 1 and "-pc_supernodal_budget_mb" in lines[0],
             f"(g) -pc_supernodal_budget_mb -1: exit {r.returncode}, {lines}")
checks.exit()
