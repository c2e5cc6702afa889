#!/usr/bin/env bash
# The experiment runner on Slurm (issue 20), end to end on a single-node cluster that
# scripts/slurm_local.sh brings up in a private folder:
#   1. a tiny training-only experiment (2 sweep points × 2 seeds: 4 runs, 9 stages)
#      runs locally;
#   2. the same through Slurm into another cache, alike stages as job arrays (9 stages
#      in 4 sbatch calls: rig, the scans of both seeds, their pairs, the 4 models); one
#      scans task is cancelled (scancel JOBID_TASK) mid-stage: the runner fails, the
#      stage has no stage.json, `crease experiment status` names it failed with its
#      command and its state, which the claim keeps;
#   3. a rerun resubmits only what is missing (not the other scans task; 7 stages in
#      5 sbatch calls, since the other seed's stages are now a wave ahead), and a second
#      runner started on the same cache meanwhile submits nothing (it waits on the
#      first one's claims);
#   4. results.csv equals the local one except timing columns, experiment.json is
#      byte-identical, runs/*.json equal apart from timings and cache paths;
#   5. bad input: an unknown executor, a missing sbatch, sbatch refusing a job.
# Skips (exit 77) only when not root or when the Slurm packages are missing;
# CI runs as root and scripts/setup.sh installs them (scripts/deps.txt).
# Usage: slurm_cluster_test.sh CREASE_BINARY SOURCE_DIR
set -u
crease="$1"; src="$2"
if [ "$(id -u)" -ne 0 ]; then echo "SKIP: the local Slurm cluster needs root"; exit 77; fi
for t in munged slurmctld slurmd sbatch squeue scancel; do
  command -v "$t" > /dev/null 2>&1 ||
    { echo "SKIP: $t is not installed (Debian: slurmctld slurmd slurm-client munge; scripts/setup.sh installs them)"; exit 77; }
done

tmp="$(mktemp -d /tmp/crease-slurm-test.XXXXXX)"
chmod 711 "$tmp"  # munged's socket folder and its parents must be o+x
state="$tmp/slurm-state"
# Two free consecutive ports (slurmctld, slurmd): a developer's cluster may hold the defaults.
port="$(python3 -c '
import socket
for p in range(7301, 7700, 2):
    try:
        for q in (p, p + 1):
            s = socket.socket(); s.bind(("127.0.0.1", q)); s.close()
        print(p); break
    except OSError:
        pass')"
export CREASE_SLURM_PORT="$port"
cleanup() {
  jobs -p | xargs -r kill 2>/dev/null
  bash "$src/scripts/slurm_local.sh" down "$state" > /dev/null 2>&1
  rm -rf "$tmp"
}
trap cleanup EXIT
fails=0
fail() { echo "FAIL: $*"; fails=$((fails+1)); }
die() { echo "FAIL: $*"; exit 1; }

t0=$(date +%s)
bash "$src/scripts/slurm_local.sh" up "$state" > /dev/null || die "the local cluster did not come up (logs: $state/log)"
export SLURM_CONF="$state/slurm.conf"
echo "cluster up in $(( $(date +%s) - t0 )) s (ports $port, $((port + 1)))"

cat > "$tmp/tiny.yaml" <<'EOF'
name: slurm-tiny
seeds: 2
dataset:
  training_actors: 1
  scan_cameras: 1
  scan_samples: 1
  scan_expressions: ["browInnerUp=1,browOuterUp=1"]
  scan_size: 320x240
  capture: false
actor: {resolution: 256, surface_min_vertices: 20000}
training: {detail.map_resolution: 256}
sweep:
  values:
    training.ferns.num_ferns: [20, 40]
slurm:
  default: {cpus: 1, mem: 1G, time: "10:00"}
EOF

# 1. Locally.
t0=$(date +%s)
"$crease" experiment run "$tmp/tiny.yaml" -o "$tmp/local" > "$tmp/local.log" 2>&1 || { cat "$tmp/local.log"; die "the local run failed"; }
echo "local run: $(( $(date +%s) - t0 )) s"

# 2. Through Slurm, arrays where stages are alike; one scans task cancelled while it runs.
t0=$(date +%s)
"$crease" experiment run "$tmp/tiny.yaml" -o "$tmp/slurm" --executor slurm --slurm-poll 0.5 > "$tmp/slurm1.log" 2>&1 &
runner=$!
job=""
for _ in $(seq 1 3000); do  # up to 5 min: CI runs other tests beside this one
  job="$(squeue -h -r -o '%i %j %T' | awk '$2 ~ /^crease-scans-/ && $3 == "RUNNING" {print $1; exit}')"
  [ -n "$job" ] && break
  kill -0 "$runner" 2>/dev/null || break
  sleep 0.1
done
[ -n "$job" ] || { cat "$tmp/slurm1.log"; die "the scans job never ran"; }
case "$job" in *_*) ;; *) fail "the scans of the two seeds were not an array (job $job)";; esac
sleep 2
scancel "$job"
wait "$runner"; rc=$?
[ "$rc" -ne 0 ] || fail "the runner succeeded although its scans job was cancelled"
grep -q "an input stage failed\|runs failed" "$tmp/slurm1.log" || fail "the runner's log does not say what failed"
grep -q "slurm: 9 stages submitted in 4 sbatch calls (3 arrays), 0 already queued" "$tmp/slurm1.log" ||
  { cat "$tmp/slurm1.log"; fail "the 9 stages were not submitted as 1 job and 3 arrays"; }
[ "$(ls "$tmp"/slurm/cache/scans/*/stage.json 2>/dev/null | wc -l)" -eq 1 ] ||
  fail "not exactly the other scans task is complete"
grep -lq "\"job_id\": \"${job%_*}\"" "$tmp"/slurm/cache/scans/*.slurm/claim.json ||
  fail "the scans claims do not name the array job ${job%_*}"
grep -q '"final_state": "CANCELLED"' "$tmp"/slurm/cache/scans/*.slurm/claim.json ||
  fail "the claim of the cancelled scans task does not keep its final state"
"$crease" experiment status "$tmp/slurm/slurm-tiny" > "$tmp/status.txt" 2>&1 || fail "experiment status failed"
grep -q "^  failed *scans .*job $job CANCELLED" "$tmp/status.txt" || fail "status does not list the scans task $job as failed"
grep -q "crease synth scans" "$tmp/status.txt" || fail "status does not name the failed command"
grep -q "^  done *rig" "$tmp/status.txt" || fail "status does not list the rig as done"
grep -q "2 done, 0 queued, 0 running, 7 failed" "$tmp/status.txt" || fail "status counts are wrong"
echo "--- status after scancel of job $job:"; head -n 7 "$tmp/status.txt"

# 3. The rerun resubmits what is missing; a second runner on the same cache submits nothing.
"$crease" experiment run "$tmp/tiny.yaml" -o "$tmp/slurm" --executor slurm --slurm-poll 0.5 > "$tmp/slurm2.log" 2>&1 &
runner=$!
for _ in $(seq 1 1200); do grep -q "stages submitted" "$tmp/slurm2.log" && break; sleep 0.1; done
# The other seed's scans are complete, so its pairs and models are a wave ahead of the
# cancelled seed's: scans, pairs 2, pairs 1, models 2 (an array), models 1 (an array).
grep -q "slurm: 7 stages submitted in 5 sbatch calls (2 arrays), 0 already queued" "$tmp/slurm2.log" ||
  { cat "$tmp/slurm2.log"; fail "the rerun did not submit exactly the 7 missing stages (the cancelled scans alone)"; }
"$crease" experiment run "$tmp/tiny.yaml" -o "$tmp/second" --cache "$tmp/slurm/cache" --executor slurm --slurm-poll 0.5 \
  > "$tmp/second.log" 2>&1 || { cat "$tmp/second.log"; fail "the second runner failed"; }
grep -q "slurm: 0 stages submitted" "$tmp/second.log" || { cat "$tmp/second.log"; fail "the second runner submitted stages the first had claimed"; }
wait "$runner" || { cat "$tmp/slurm2.log"; fail "the rerun failed"; }
echo "slurm run with a cancelled job and its rerun: $(( $(date +%s) - t0 )) s"
grep -q "4/4 runs ok, 9 stages (2 cached, 7 run, 0 failed)" "$tmp/slurm2.log" || { cat "$tmp/slurm2.log"; fail "the rerun's summary"; }
"$crease" experiment status "$tmp/slurm/slurm-tiny" | grep -q "9 done, 0 queued, 0 running, 0 failed" || fail "status after the rerun"

# 4. The collected results equal the local run's.
python3 - "$tmp/local/slurm-tiny" "$tmp/slurm/slurm-tiny" "$tmp/second/slurm-tiny" <<'EOF' || fail "results differ"
import csv, json, os, re, sys
timing = re.compile(r"(^|\.)(seconds|timing|speed)(\.|$)")
def rows(d):
    with open(os.path.join(d, "results.csv")) as f:
        r = list(csv.reader(f))
    keep = [i for i, k in enumerate(r[0]) if not timing.search(k)]
    return [[row[i] for i in keep] for row in r], len(r[0]) - len(keep)
def run_json(path):
    j = json.load(open(path))
    for k in ("stage_seconds", "commands", "images"):
        j.pop(k, None)
    j["metrics"] = {k: v for k, v in j.get("metrics", {}).items() if not timing.search(k)}
    return j
local, skipped = rows(sys.argv[1])
ok = True
for other in sys.argv[2:]:
    r, _ = rows(other)
    if r != local:
        print("results.csv differs:", other); ok = False
    if open(os.path.join(other, "experiment.json")).read() != open(os.path.join(sys.argv[1], "experiment.json")).read():
        print("experiment.json differs:", other); ok = False
    for name in sorted(os.listdir(os.path.join(sys.argv[1], "runs"))):
        if run_json(os.path.join(sys.argv[1], "runs", name)) != run_json(os.path.join(other, "runs", name)):
            print("runs/%s differs:" % name, other); ok = False
print("results.csv: %d rows, %d columns compared (%d timing columns left out)" % (len(local) - 1, len(local[0]), skipped))
assert len(local) == 5 and all(row[2] == "ok" for row in local[1:]), local
sys.exit(0 if ok else 1)
EOF

# 5. Bad input.
"$crease" experiment run "$tmp/tiny.yaml" -o "$tmp/bad" --executor cloud > "$tmp/bad.log" 2>&1
[ $? -eq 1 ] && grep -q "executor 'cloud'" "$tmp/bad.log" || fail "an unknown executor is not a clean error"
PATH="/nonexistent" "$crease" experiment run "$tmp/tiny.yaml" -o "$tmp/bad" --cache "$tmp/badcache" --executor slurm \
  > "$tmp/bad.log" 2>&1
[ $? -eq 1 ] && grep -q "cannot run squeue\|cannot run sbatch" "$tmp/bad.log" || { cat "$tmp/bad.log"; fail "a missing sbatch is not a clean error"; }
"$crease" experiment run "$tmp/tiny.yaml" -o "$tmp/bad" --cache "$tmp/badcache2" --executor slurm \
  --slurm-args "--partition=nosuch" > "$tmp/bad.log" 2>&1
[ $? -eq 1 ] && grep -q "sbatch failed for the rig stage" "$tmp/bad.log" && grep -qi "partition" "$tmp/bad.log" ||
  { cat "$tmp/bad.log"; fail "a failing sbatch is not a clean error naming its message"; }

echo "$fails failed"
[ "$fails" -eq 0 ]
