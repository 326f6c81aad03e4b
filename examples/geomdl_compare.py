#!/usr/bin/env python3
"""The peer side of examples/geomdl_compare.rs: NURBS-Python (geomdl) approximate_surface
on a grid file, timed, its control net written as JSON for the Rust side to measure with
the same error routine as ours.

usage: geomdl_compare.py GRID.txt OUT.json [ctrl_u ctrl_v degree_u degree_v repeats]
GRID.txt: first line "rows cols", then rows*cols lines "x y z", row-major.
Installs geomdl with pip when it is missing.
"""
import json
import subprocess
import sys
import time

try:
    from geomdl import fitting
except ImportError:
    subprocess.check_call([sys.executable, "-m", "pip", "install", "--quiet", "geomdl"])
    from geomdl import fitting

import geomdl


def main():
    grid_path, out_path = sys.argv[1], sys.argv[2]
    cu, cv, p, q, repeats = (list(map(int, sys.argv[3:8])) + [12, 12, 3, 3, 20][len(sys.argv[3:8]):])
    with open(grid_path) as f:
        rows, cols = map(int, f.readline().split())
        pts = [tuple(map(float, line.split())) for line in f if line.strip()]
    assert len(pts) == rows * cols, (len(pts), rows, cols)
    times = []
    surf = None
    for _ in range(repeats):
        t = time.perf_counter()
        surf = fitting.approximate_surface(pts, rows, cols, p, q, ctrlpts_size_u=cu, ctrlpts_size_v=cv)
        times.append((time.perf_counter() - t) * 1e3)
    times.sort()
    out = {
        "geomdl_version": geomdl.__version__,
        "python": sys.version.split()[0],
        "ms_min": times[0],
        "ms_median": times[len(times) // 2],
        "repeats": repeats,
        "degree_u": surf.degree_u,
        "degree_v": surf.degree_v,
        "knots_u": list(surf.knotvector_u),
        "knots_v": list(surf.knotvector_v),
        "control_grid": [surf.ctrlpts_size_u, surf.ctrlpts_size_v],
        # geomdl stores the net with v running fastest, like our row-major order.
        "control_points": [list(c) for c in surf.ctrlpts],
    }
    with open(out_path, "w") as f:
        json.dump(out, f)


if __name__ == "__main__":
    main()
