#!/usr/bin/env bash
# kill -9 test (issue 19): `crease synth sequence`, `capture`, `train` and
# `experiment run` on tiny inputs, each killed N times at a random moment.
#
# Usage: scripts/kill_test.sh [N] [COMMAND...]     (N default 20; COMMAND: sequence capture train experiment)
# Environment: CREASE (the binary, default build/apps/crease/crease), KILL_TEST_SEED
# (default 19: the same seed kills at the same moments), KILL_TEST_DIR (work folder,
# default a new one under /tmp, removed on success).
#
# For each command: one uninterrupted run gives the reference output and the runtime T.
# Then N times (N kills mid-run; a run that ends before its kill is checked as well and
# another drawn, up to 2N runs): start the command in its own session, sleep a random 5–95 % of T,
# kill -9 the command's own process (its children are not signalled: they must die
# with it), and check
#   (a) no process of its session is left 3 s later (then the group is killed anyway),
#   (b) nothing a rerun would trust is wrong: every file outside a temporary
#       (".NAME.tmp-HOST-PID") and outside an experiment stage folder without its
#       stage.json equals the reference (scripts/compare_outputs.py --subset), so there
#       is no final output without its completion marker and no partial file under a
#       final name;
# then rerun the same command to completion and compare the whole output with the
# reference (scripts/compare_outputs.py: bytes, except timing and host fields; stray
# temporaries count as differences, so the rerun must remove them).
# Prints one line per kill and a count per command; exits 1 on any failure.
set -u
N="${1:-20}"; shift || true
here="$(cd "$(dirname "$0")/.." && pwd)"
crease="${CREASE:-$here/build/apps/crease/crease}"
[ $# -gt 0 ] && commands=("$@") || commands=(sequence capture train experiment)
RANDOM="${KILL_TEST_SEED:-19}"
work="${KILL_TEST_DIR:-$(mktemp -d /tmp/crease-kill.XXXXXX)}"
mkdir -p "$work/in"
compare="$here/scripts/compare_outputs.py"
failures=0

# The command under test into the array `cmd`, writing into $work/run (absolute
# paths, the same as in the reference run).
command_of() {
  local i="$work/in" o="$work/run"
  case "$1" in
    sequence) cmd=(synth sequence --rig "$i/head.crig" --actor "$i/actor.json" --preset wrinkle-workout \
                --first-frame 30 --frames 2 --size 160x120 -o "$o/seq") ;;
    capture) cmd=(capture -i "$i/seq" --model "$i/model.cdm" --ground-truth-prior --set detail.wrinkle_frames=2 \
                --set hifi.resolution=64 -o "$o/cap") ;;
    train) cmd=(train --scans "$i/scans" --out "$o/model.cdm" --set detail.map_resolution=256 --set detail.operator_resolution=96 \
                --set patch.size=8 --set pca.dimensions=6 --set ferns.num_ferns=20 --set ferns.num_sampled_pixels=20 \
                --set fit.max_fit_vertices=300) ;;
    experiment) cmd=(experiment run "$here/tests/data/experiment_kill.yaml" -o "$o/exp") ;;
  esac
}

# The inputs: a rig, a small actor, a 2-frame sequence, a scan set and a model.
make_inputs() {
  local i="$work/in"
  [ -s "$i/model.cdm" ] && return 0
  echo "making the inputs in $i"
  "$crease" synth rig -o "$i/head.crig" &&
    "$crease" synth actor --rig "$i/head.crig" --seed 3 --set resolution=256 --set surface_min_vertices=1000 \
      -o "$i/actor.json" &&
    "$crease" synth sequence --rig "$i/head.crig" --actor "$i/actor.json" --preset wrinkle-workout --first-frame 30 \
      --frames 2 --size 160x120 -o "$i/seq" &&
    "$crease" synth scans --rig "$i/head.crig" --actors 1 --seed 11 --cameras 2 --size 200x150 --samples 1 \
      -e browInnerUp=1,browOuterUp=1 --set resolution=256 --set surface_min_vertices=1000 --set age_min=1 \
      -o "$i/scans" &&
    "$crease" train --scans "$i/scans" --out "$i/model.cdm" --set detail.map_resolution=256 --set ferns.num_ferns=20 \
      --set detail.operator_resolution=96 --set patch.size=8 --set pca.dimensions=6 --set ferns.num_sampled_pixels=20 \
      --set fit.max_fit_vertices=300
} >"$work/inputs.log" 2>&1

fail() { echo "  FAIL: $*"; failures=$((failures + 1)); trial_failed=1; }

# Processes of session $1 still alive (the command was started as its session leader).
survivors() { ps -e -o pid=,sid=,args= | awk -v s="$1" '$2 == s'; }

# One kill: start, sleep, kill -9 the leader, check orphans and what is left, rerun, compare.
kill_once() {
  local name="$1" ms="$2" delay_ms pid left k
  trial_failed=0
  rm -rf "$work/run"; mkdir -p "$work/run"
  delay_ms=$(( ms * (5 + RANDOM % 91) / 100 ))
  command_of "$name"
  setsid "$crease" "${cmd[@]}" >"$work/killed.log" 2>&1 &
  pid=$!
  sleep "$(printf '%d.%03d' $((delay_ms / 1000)) $((delay_ms % 1000)))"
  if kill -0 "$pid" 2>/dev/null && kill -9 "$pid" 2>/dev/null; then k=killed; else k=finished; fi
  wait "$pid" 2>/dev/null
  for _ in 1 2 3 4 5 6; do left="$(survivors "$pid")"; [ -z "$left" ] && break; sleep 0.5; done
  if [ -n "$left" ]; then
    fail "orphans after kill -9 of $pid:"; echo "$left" | sed 's/^/    /'
    kill -9 -- "-$pid" 2>/dev/null
    echo "$left" | awk '{print $1}' | xargs -r kill -9 2>/dev/null
  fi
  python3 "$compare" --subset "$work/ref/$name" "$work/run" >"$work/subset.txt" || {
    fail "after the kill, output a rerun would trust is wrong:"; sed 's/^/    /' "$work/subset.txt"; }
  "$crease" "${cmd[@]}" >"$work/rerun.log" 2>&1 ||
    grep -q "already exists" "$work/rerun.log" ||
    { fail "the rerun failed:"; tail -5 "$work/rerun.log" | sed 's/^/    /'; }
  python3 "$compare" "$work/ref/$name" "$work/run" >"$work/full.txt" || {
    fail "the rerun's output differs from the reference:"; sed 's/^/    /' "$work/full.txt"; }
  echo "  $name: $k at ${delay_ms} ms of ${ms} ms: $([ $trial_failed = 0 ] && echo ok || echo FAILED)"
  if [ $trial_failed != 0 ]; then  # kept for a look: the output and both logs
    mkdir -p "$work/failed"; mv "$work/run" "$work/failed/$name-$delay_ms"
    cp "$work/killed.log" "$work/rerun.log" "$work/failed/$name-$delay_ms/"
  fi
  [ $k = killed ] && kills=$((kills + 1))
  [ $trial_failed = 0 ]
}

# The reference run, then N kills; prints the tally.
test_command() {
  local name="$1" t0 ms ok=0
  kills=0
  rm -rf "$work/run" "$work/ref/$name"; mkdir -p "$work/run" "$work/ref"
  t0=$(date +%s%N)
  command_of "$name"
  "$crease" "${cmd[@]}" >"$work/ref-$name.log" 2>&1 || {
    fail "$name: the reference run failed (see $work/ref-$name.log)"; return; }
  ms=$(( ($(date +%s%N) - t0) / 1000000 ))
  mv "$work/run" "$work/ref/$name"
  echo "$name: reference run ${ms} ms; $N kills"
  # Runs that finish before their kill (the machine got faster) are checked too but
  # do not count: up to 2N runs until N were killed mid-run.
  local runs=0
  while [ $kills -lt "$N" ] && [ $runs -lt $((2 * N)) ]; do
    runs=$((runs + 1))
    kill_once "$name" "$ms" && ok=$((ok + 1))
  done
  echo "$name: $kills killed mid-run in $runs runs, $ok of $runs passed"
  summary+=("$name: $kills killed mid-run in $runs runs, $ok of $runs passed")
}

command -v setsid >/dev/null || { echo "kill_test.sh: needs setsid (util-linux)"; exit 2; }
[ -x "$crease" ] || { echo "kill_test.sh: no crease binary at $crease (set CREASE)"; exit 2; }
make_inputs || { echo "kill_test.sh: making the inputs failed; see $work/inputs.log"; exit 1; }
summary=()
start=$(date +%s)
for c in "${commands[@]}"; do test_command "$c"; done
echo "---"; printf '%s\n' "${summary[@]}"
echo "kill_test.sh: $failures failures in $(( $(date +%s) - start )) s (seed ${KILL_TEST_SEED:-19}, work $work)"
[ $failures -eq 0 ] && [ -z "${KILL_TEST_DIR:-}" ] && rm -rf "$work"
[ $failures -eq 0 ]
