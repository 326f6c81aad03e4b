#!/usr/bin/env python3
"""Two sweeps of `scripts/cgal_sweep.sh` side by side: what a change did on unseen data.

    scripts/sweep_compare.py BEFORE/sweep.txt AFTER/sweep.txt [--all] [--path object]

Per mesh of the chosen path (in the BEFORE sweep; all paths when --path is 'any'): the
control count, the RMS and its ratio, the stray (share of the diagonal, in percent) and the
wall time, flagged '*' when the RMS moved by more than 3 % or the stray crossed the 0.5 %
bound (--all prints every mesh). Then the geometric means of the RMS and wall ratios, how
many got better or worse by more than 1 %, and how many lie past the stray bound before and
after; the RMS ratio again over the meshes whose control count did not change (the stray
escalation moves counts, and a fit with more controls is not a better method). Meshes
without a report (refused or failed) in only one sweep are listed.
"""

import argparse
import math
import re

LINE = re.compile(
    r"(\S+)\s+path=(\S+) pts=(\d+) ctrl=(\d+) rms=(\S+) stray=(\S+) wall=(\S+)"
)
STRAY_BOUND_PCT = 0.5


def load(path):
    fits, failed = {}, set()
    for line in open(path):
        m = LINE.match(line)
        if m:
            fits[m[1]] = dict(
                path=m[2],
                ctrl=int(m[4]),
                rms=float(m[5]),
                stray=float(m[6]),
                wall=float(m[7]),
            )
        elif line.strip():
            failed.add(line.split()[0])
    return fits, failed


def geometric_mean(values):
    return math.exp(sum(math.log(v) for v in values) / len(values)) if values else float("nan")


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("before")
    parser.add_argument("after")
    parser.add_argument("--all", action="store_true")
    parser.add_argument("--path", default="object")
    args = parser.parse_args()
    (before, failed_before), (after, failed_after) = load(args.before), load(args.after)
    rms_logs, wall_logs = [], []
    over = [0, 0]
    for name in sorted(before):
        if name not in after:
            continue
        x, y = before[name], after[name]
        if args.path != "any" and x["path"] != args.path:
            continue
        if x["rms"] > 0 and y["rms"] > 0:
            rms_logs.append(math.log(y["rms"] / x["rms"]))
        if x["wall"] > 0 and y["wall"] > 0:
            wall_logs.append(math.log(y["wall"] / x["wall"]))
        past = (x["stray"] > STRAY_BOUND_PCT, y["stray"] > STRAY_BOUND_PCT)
        over[0] += past[0]
        over[1] += past[1]
        ratio = (y["rms"] + 1e-300) / (x["rms"] + 1e-300)
        moved = abs(math.log(ratio)) > math.log(1.03) or past[0] != past[1]
        if moved or args.all:
            print(
                f"{name:32s} ctrl {x['ctrl']:5d}->{y['ctrl']:5d} "
                f"rms {x['rms']:.3e}->{y['rms']:.3e} ({ratio:.3f}) "
                f"stray {x['stray']:.3f}->{y['stray']:.3f} "
                f"wall {x['wall']:.2f}->{y['wall']:.2f}{' *' if moved else ''}"
            )
    print(
        f"{len(wall_logs)} meshes: RMS ratio geometric mean "
        f"{geometric_mean([math.exp(v) for v in rms_logs]):.3f} "
        f"(better {sum(v < -0.01 for v in rms_logs)}, worse {sum(v > 0.01 for v in rms_logs)}); "
        f"wall ratio {geometric_mean([math.exp(v) for v in wall_logs]):.3f}; "
        f"past the stray bound {over[0]} -> {over[1]}"
    )
    same = [
        math.log(after[n]["rms"] / before[n]["rms"])
        for n in before
        if n in after
        and (args.path == "any" or before[n]["path"] == args.path)
        and before[n]["ctrl"] == after[n]["ctrl"]
        and before[n]["rms"] > 0
        and after[n]["rms"] > 0
    ]
    print(
        f"{len(same)} of them at the same control count: RMS ratio geometric mean "
        f"{geometric_mean([math.exp(v) for v in same]):.3f} "
        f"(better {sum(v < -0.01 for v in same)}, worse {sum(v > 0.01 for v in same)})"
    )
    both = failed_before & failed_after
    print(f"no report in either sweep (refused or failed): {len(both)}")
    for label, names in (
        ("no report before only", failed_before - both),
        ("no report after only", failed_after - both),
    ):
        if names:
            print(f"{label}: {' '.join(sorted(names))}")


if __name__ == "__main__":
    main()
