#!/usr/bin/env python3
"""The seed OFF scene: ../shared/seed-data/infomgp-p3/bunny-scene.txt (one bunny.off).

Seed data only (skipped without ../shared): OFF surfaces meshed by TetGen on
load are checked on the project's own surfaces by test_off_scenes.py, whose
checks this file applies to the seed bunny: 2 ranks, 2 steps, as many vertices
as the `tetgen` program makes of bunny.off with the same switches, and the OFF
vertices first, rigidly placed.
"""
import os
import sys
import tempfile

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import harness  # noqa: E402
from test_off_scenes import check_off_scene  # noqa: E402


def main():
    args = harness.arguments()
    checks = harness.Checks()
    scene = harness.seed(args, "infomgp-p3", "bunny-scene.txt")
    bunny = os.path.join(os.path.dirname(scene), "bunny.off")
    check_off_scene(checks, args, "infomgp-p3 bunny", scene, bunny, tempfile.mkdtemp(dir=args.work))
    checks.exit()


if __name__ == "__main__":
    main()
