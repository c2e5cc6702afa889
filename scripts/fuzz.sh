#!/usr/bin/env bash
# Builds the libFuzzer targets of fuzz/ (clang, ASan+UBSan; scripts/asan_build.sh, in
# build-asan/) and runs each for a bounded time (issue 19).
#
#   scripts/fuzz.sh                  every target for 5 s (what .ci/run does)
#   scripts/fuzz.sh 600              every target for 10 minutes
#   scripts/fuzz.sh 3600 ply vtp     the named targets (ply → ply_fuzzer) for an hour each
#   CREASE_FUZZ_RUNS=1000000 CREASE_FUZZ_PARALLEL=2 scripts/fuzz.sh 3600 ply obj
#                                    each until 10^6 executions or an hour (issue 19's
#                                    bound), two targets at a time (one per core)
#
# Each run: -max_total_time=SECONDS -rss_limit_mb=2048 (every allocation above 2 GB
# counts too) -timeout=25 (one input taking longer is a hang), the target's dictionary
# (fuzz/dict/), its seeds (fuzz/corpus/<target>/ and the files crease itself writes:
# fuzz/write_seeds.cc) and a working corpus in build-asan/fuzz/corpus/<target>/ that
# grows across runs. A finding stops that target; its input is saved under
# build-asan/fuzz/crashes/<target>/ and the script exits 1 after running the others.
# Replay one input: build-asan/fuzz/<target> FILE. A fixed finding goes to
# fuzz/regressions/<target>/ (ctest replays it: fuzz_regression.<target>).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${CREASE_ASAN_BUILD_DIR:-$root/build-asan}"
seconds="${1:-5}"
[ $# -gt 0 ] && shift

declare -A dict=(
  [ply_fuzzer]=ply [obj_fuzzer]=obj [vtp_fuzzer]=vtp [gltf_fuzzer]=gltf
  [crig_fuzzer]=array_file [cdm_fuzzer]=array_file [ctrk_fuzzer]=array_file [cpr_fuzzer]=array_file
  [camera_json_fuzzer]=json [actor_json_fuzzer]=json [scans_json_fuzzer]=json [dataset_json_fuzzer]=json
  [experiment_yaml_fuzzer]=yaml [options_yaml_fuzzer]=yaml [sequence_yaml_fuzzer]=yaml
  [png_fuzzer]= [exr_fuzzer]=
  [cfr_fuzzer]=array_file [capture_json_fuzzer]=json [truth_json_fuzzer]=json [dlib_xml_fuzzer]=xml
)
all=(ply_fuzzer obj_fuzzer vtp_fuzzer gltf_fuzzer png_fuzzer exr_fuzzer crig_fuzzer cdm_fuzzer ctrk_fuzzer
     cpr_fuzzer scans_json_fuzzer dataset_json_fuzzer camera_json_fuzzer actor_json_fuzzer
     options_yaml_fuzzer experiment_yaml_fuzzer sequence_yaml_fuzzer cfr_fuzzer capture_json_fuzzer
     truth_json_fuzzer dlib_xml_fuzzer)
targets=()
for t in "$@"; do
  t="${t%_fuzzer}_fuzzer"
  [ -n "${dict[$t]+x}" ] || { echo "fuzz.sh: no target $t (targets: ${all[*]})" >&2; exit 2; }
  targets+=("$t")
done
[ ${#targets[@]} -gt 0 ] || targets=("${all[@]}")

fz="$build/fuzz"
# CREASE_FUZZ_WRITTEN_SEEDS=0 skips the seeds crease writes (write_seeds links every
# library; CI's core subset does without them, from the text corpora and an empty start)
# and leaves build-asan/fuzz/seeds/ as it is (another fuzz.sh may be reading it).
if [ "${CREASE_FUZZ_WRITTEN_SEEDS:-1}" = 1 ]; then
  rm -rf "$fz/seeds"
  "$root/scripts/asan_build.sh" write_seeds "${targets[@]}"
  "$fz/write_seeds" "$fz/seeds"
else
  "$root/scripts/asan_build.sh" "${targets[@]}"
fi

export ASAN_OPTIONS="${ASAN_OPTIONS:-detect_leaks=1}" UBSAN_OPTIONS="${UBSAN_OPTIONS:-print_stacktrace=1}" \
  LSAN_OPTIONS="${LSAN_OPTIONS:-suppressions=$root/fuzz/lsan.supp}"
# One target's run; its result line goes to $fz/$t.result (read below: "ok" or a FINDING).
run_target() {
  local t="$1"
  mkdir -p "$fz/corpus/$t" "$fz/crashes/$t" "$fz/seeds/$t"
  local args=(-max_total_time="$seconds" -rss_limit_mb=2048 -timeout=25 -print_final_stats=1
        -artifact_prefix="$fz/crashes/$t/")
  [ -n "${CREASE_FUZZ_RUNS:-}" ] && args+=(-runs="$CREASE_FUZZ_RUNS")
  [ -n "${dict[$t]}" ] && args+=(-dict="$root/fuzz/dict/${dict[$t]}.dict")
  local seeds=("$fz/seeds/$t") log="$fz/$t.log" start result runs rate
  [ -d "$root/fuzz/corpus/$t" ] && seeds+=("$root/fuzz/corpus/$t")
  start=$(date +%s)
  if (cd "$fz" && "./$t" "${args[@]}" "$fz/corpus/$t" "${seeds[@]}") >"$log" 2>&1; then
    result=ok
  else
    result="FINDING (log: $log; input: $(ls -t "$fz/crashes/$t" | head -1))"
  fi
  runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -1)
  printf '%-24s %12s %10s %8s  %s\n' "$t" "${runs:-?}" "${rate:-?}" "$(( $(date +%s) - start ))" "$result" \
    >"$fz/$t.result"
}

# CREASE_FUZZ_PARALLEL targets at a time (default 1); results in the order given.
parallel="${CREASE_FUZZ_PARALLEL:-1}"
for t in "${targets[@]}"; do
  rm -f "$fz/$t.result"
  while [ "$(jobs -rp | wc -l)" -ge "$parallel" ]; do wait -n || true; done
  run_target "$t" &
done
wait || true
failed=()
printf '%-24s %12s %10s %8s  %s\n' target executions exec/s seconds result
for t in "${targets[@]}"; do
  if [ -f "$fz/$t.result" ]; then cat "$fz/$t.result"; else echo "$t: no result (the run did not finish)"; fi
  grep -q '  ok$' "$fz/$t.result" 2>/dev/null || failed+=("$t")
done
if [ ${#failed[@]} -gt 0 ]; then
  echo "fuzz.sh: findings in ${failed[*]}" >&2
  exit 1
fi
