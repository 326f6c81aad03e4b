#!/usr/bin/env bash
# The unseen-data sweep: `trispline fit` with its defaults on every mesh of CGAL's demo
# data (143 files: organic models, CAD parts, coarse spheres, broken meshes), one line of
# figures per mesh. Two sweeps (old and new binary) compared by `scripts/sweep_compare.py`
# say what a change does on data nobody tuned on.
#
#     scripts/cgal_sweep.sh BINARY OUT_DIR [extra `fit` arguments...]
#
# The meshes are fetched once into $CGAL_DATA (default /tmp/cgal) from Debian's
# libcgal-demo package (`apt-get download`, no root needed); they are third-party data and
# never belong in the repository. Each fit gets 300 s; a fit that fails or times out is a
# line with its exit code. Per mesh: OUT_DIR/<name>/ holds the outputs and log.txt, and
# OUT_DIR/sweep.txt the lines.
set -euo pipefail

if [ $# -lt 2 ]; then
    echo "usage: $0 BINARY OUT_DIR [fit arguments...]" >&2
    exit 2
fi
binary=$(realpath "$1")
out=$(realpath -m "$2")
shift 2
data=${CGAL_DATA:-/tmp/cgal}
meshes="$data/data/meshes"

if [ ! -d "$meshes" ]; then
    mkdir -p "$data"
    (
        cd "$data"
        apt-get download libcgal-demo >/dev/null
        dpkg-deb -x libcgal-demo_*.deb package
        tar xzf package/usr/share/doc/libcgal-dev/data.tar.gz
    )
fi

mkdir -p "$out"
: >"$out/sweep.txt"
for file in "$meshes"/*.off "$meshes"/*.obj "$meshes"/*.ply "$meshes"/*.stl; do
    [ -f "$file" ] || continue
    name=$(basename "$file")
    dir="$out/${name%.*}"
    rm -rf "$dir"
    mkdir -p "$dir"
    start=$(date +%s.%N)
    code=0
    timeout 300 "$binary" fit --out "$dir" "$@" "$file" >"$dir/log.txt" 2>&1 || code=$?
    end=$(date +%s.%N)
    python3 - "$dir" "$name" "$code" "$start" "$end" >>"$out/sweep.txt" <<'PY'
import json, sys

folder, name, code, start, end = sys.argv[1:]
wall = float(end) - float(start)
try:
    report = json.load(open(folder + "/report.json"))
except (OSError, ValueError):
    print(f"{name:34s} exit={code} no-report wall={wall:.2f}")
    sys.exit(0)
stray = report.get("stray") or {}
print(
    f"{name:34s} path={report.get('path')} pts={report.get('data_points')} "
    f"ctrl={report.get('control_points')} "
    f"rms={report['final']['geometric_rms_error']:.4e} "
    f"stray={100 * stray.get('share_of_diagonal', 0):.3f} wall={wall:.2f} "
    f"status={report.get('status')}"
)
PY
    tail -n 1 "$out/sweep.txt"
done
