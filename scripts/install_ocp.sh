#!/usr/bin/env bash
# Makes OpenCASCADE's Python bindings (PyPI: cadquery-ocp) available to the STEP
# cross-check (scripts/occ_patchwork.py, run by tests/process/cli_export.rs) and prints the
# Python that imports them. Idempotent and quick when one is there: $TRISPLINE_OCP_PYTHON,
# then the project's own virtual environment under ~/.cache/trispline/ocp; only when
# neither imports OCP is that environment made and the wheel installed (some 70 MB, with
# VTK beside it). A virtual environment keeps the machine's own Python packages untouched.
set -euo pipefail

usable() {
    [[ -n $1 && -x $1 ]] && "$1" -c 'from OCP.STEPControl import STEPControl_Reader' 2>/dev/null
}

venv="${XDG_CACHE_HOME:-$HOME/.cache}/trispline/ocp"
for candidate in "${TRISPLINE_OCP_PYTHON:-}" "$venv/bin/python"; do
    if usable "$candidate"; then
        echo "$candidate"
        exit 0
    fi
done

python3 -m venv "$venv" >&2
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check 'cadquery-ocp>=7.7' >&2
if ! usable "$venv/bin/python"; then
    echo "install_ocp.sh: cadquery-ocp installed in $venv, but OCP does not import" >&2
    exit 1
fi
echo "$venv/bin/python"
