#!/usr/bin/env bash
# Runs every cargo-fuzz target, one after another (one libFuzzer job: the machine may be
# shared), for RUNS executions each (default 1,000,000). Needs cargo-fuzz and a nightly
# toolchain (README, "Input limits and fuzzing"). Usage, from anywhere:
#
#   fuzz/run_all.sh [RUNS [TARGET...]]
#
# Each target starts from the seeds the stable fuzzer writes (`reader_fuzz --write-seeds`,
# the same inputs the regression test replays) and from fuzz/corpus/<target> (saved crash
# inputs); what libFuzzer learns goes to fuzz/work/<target> (ignored by git), kept between
# runs. Crashes, OOMs and timeouts land in fuzz/artifacts/<target>/; copy them into
# fuzz/corpus/<target>/ once fixed, where `cargo test --test library io_limits` replays them.
# Per target the log is fuzz/logs/<target>.log; a summary line per target is printed.
set -euo pipefail

runs=${1:-1000000}
shift || true
fuzz=$(cd "$(dirname "$0")" && pwd)
cd "$fuzz/.."
# SEEDS_PROFILE=test reuses the test build of the crate, when that one is warm.
cargo run --profile "${SEEDS_PROFILE:-release}" --example reader_fuzz -- --write-seeds "$fuzz/seeds"
cd "$fuzz"
toolchain=${FUZZ_TOOLCHAIN:-+nightly}
cargo "$toolchain" fuzz build
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
    mapfile -t targets < <(cargo "$toolchain" fuzz list)
fi
mkdir -p logs
status=0
for t in "${targets[@]}"; do
    mkdir -p "work/$t" "corpus/$t"
    SECONDS=0
    # -max_len covers the largest seed (a 30 kB triangle strip); -timeout makes a slow
    # input a finding; -rss_limit_mb is libFuzzer's default, stated.
    if ! cargo "$toolchain" fuzz run "$t" "work/$t" "seeds/$t" "corpus/$t" -- \
        -runs="$runs" -max_len=65536 -timeout=10 -rss_limit_mb=2048 \
        -print_final_stats=1 >"logs/$t.log" 2>&1; then
        status=1
        echo "$t: FAILED (see fuzz/logs/$t.log and fuzz/artifacts/$t/)"
    fi
    wall=$SECONDS
    done_line=$(grep -E '^#[0-9]+[[:space:]]+DONE' "logs/$t.log" | tail -1 || true)
    execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "logs/$t.log" | tail -1)
    rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "logs/$t.log" | tail -1)
    rss=$(sed -n 's/^stat::peak_rss_mb: *//p' "logs/$t.log" | tail -1)
    printf '%s: execs=%s wall_s=%s exec_per_s=%s peak_rss_mb=%s | %s\n' \
        "$t" "${execs:-?}" "$wall" "${rate:-?}" "${rss:-?}" "${done_line:-no DONE line}"
done
exit $status
