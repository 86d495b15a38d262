#!/usr/bin/env bash
# Bounded libFuzzer runs of every fuzz target of tests/c/ (fuzz_deserialize_<FMU>,
# fuzz_run_<FMU>), each seeded with real serialized states and programs written by
# fuzz_seeds_<FMU> and with the corpus kept from earlier runs.
#
# Inputs that once crashed a target are kept in tests/c/fuzz_crashes/<target>/ and
# replayed at the start of every run.
#
# usage: tests/c/fuzz.sh BUILD_DIR SECONDS_PER_TARGET [WORK_DIR]
#   BUILD_DIR  configured with CC=clang -DPIEZO_FUZZ=ON, built with --target fuzz_targets
#   WORK_DIR   corpora (kept between runs), logs and crash-* files; default BUILD_DIR/fuzz
# PIEZO_FUZZ_SEED=N fixes libFuzzer's random seed (-seed=N): the run then tries the same inputs
# in the same order each time, as far as its time allows (CI: a gate that a commit passes or
# fails reproducibly); unset, each run draws its own seed and explores further (a campaign).
# Prints one line per target with its executions; exit code 1 if a target crashed
# (the input is WORK_DIR/crash-*: rerun it with the target to see the report, and
# with PIEZO_FUZZ_LOG=1 to see the FMU's messages).
set -euo pipefail
build=${1:?usage: fuzz.sh BUILD_DIR SECONDS_PER_TARGET [WORK_DIR]}
seconds=${2:?usage: fuzz.sh BUILD_DIR SECONDS_PER_TARGET [WORK_DIR]}
work=${3:-$build/fuzz}
bin="$build/tests"
mkdir -p "$work"
failed=0
total=0
seed_opt=()
[ -z "${PIEZO_FUZZ_SEED:-}" ] || seed_opt=(-seed="$PIEZO_FUZZ_SEED")
# every FMU the build made targets for (CMakeLists.txt FMU_IDS: tests/c/CMakeLists.txt)
ids=$(cd "$bin" && ls fuzz_seeds_* | sed 's/^fuzz_seeds_//')
[ -n "$ids" ] || { echo "no fuzz targets in $bin (build with --target fuzz_targets)" >&2; exit 2; }
for id in $ids; do
    seeds="$work/seeds/$id"
    rm -rf "$seeds"
    mkdir -p "$seeds/deserialize" "$seeds/run"
    "$bin/fuzz_seeds_$id" "$seeds" >/dev/null
    for kind in deserialize run; do
        target="fuzz_${kind}_$id"
        corpus="$work/corpus/$target"
        log="$work/$target.log"
        mkdir -p "$corpus"
        # inputs that once crashed a target (tests/c/fuzz_crashes/<target>/) are run first, as seeds
        crashes="$(dirname "$0")/fuzz_crashes/$target"
        [ -d "$crashes" ] || crashes=""
        status=0
        "$bin/$target" ${seed_opt[@]+"${seed_opt[@]}"} -max_total_time="$seconds" -timeout=20 -rss_limit_mb=2048 -print_final_stats=1 \
            -artifact_prefix="$work/" "$corpus" "$seeds/$kind" $crashes >"$log" 2>&1 || status=$?
        execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
        printf '%-44s %10s executions in %ss, corpus %5d inputs, %s\n' "$target" "${execs:-?}" "$seconds" \
            "$(find "$corpus" -type f | wc -l)" "$([ "$status" = 0 ] && echo ok || echo "CRASH (see $log)")"
        total=$((total + ${execs:-0}))
        if [ "$status" != 0 ]; then
            failed=1
            grep -E "ERROR|SUMMARY|Test unit written" "$log" | head -5 || true
        fi
    done
done
echo "fuzzing: $total executions in total, seed ${PIEZO_FUZZ_SEED:-random}," \
    "$([ "$failed" = 0 ] && echo 'no crash' || echo 'CRASHES FOUND')"
exit "$failed"
