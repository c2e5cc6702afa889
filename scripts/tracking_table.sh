#!/usr/bin/env bash
# Measures README's per-source tracking table (issue 5): the global tracker's landmark
# error, the fitted rig's landmark error and the 2D error of the visible coarse vertices
# against the studio's ground truth, per landmark source (dlib, crease's regressor, the
# ground-truth prior), on the `talking` and `fast-motion` presets of novel actors.
#
#   scripts/tracking_table.sh [ACTOR_SEED ...]      (default: 201 202 203)
#
# Trains the regressor with `crease train-tracker` defaults (36 actors x 40 renders since 0.4.7,
# seeds 1000..1035; the novel actors' seeds do not overlap), renders each sequence at
# 640x480 under the studio light (talking 90 frames, fast-motion 60 frames with motion
# blur), tracks it with each source and prints a Markdown table: the mean over actors of
# each actor's mean over tracked frames, +- the standard deviation over actors, and the
# tracked frames. Outputs go to ${CREASE_OUT:-out/tracking_table}; about 10 minutes on
# 2 cores after the build.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${CREASE_BUILD_DIR:-$root/build}"
crease="$build/apps/crease/crease"
out="${CREASE_OUT:-$root/out/tracking_table}"
seeds=("$@")
[ ${#seeds[@]} -gt 0 ] || seeds=(201 202 203)
mkdir -p "$out"

[ -f "$out/head.crig" ] || "$crease" synth rig -o "$out/head.crig"
[ -f "$out/tracker.ctrk" ] || "$crease" train-tracker --rig "$out/head.crig" -o "$out/tracker.ctrk"

for seed in "${seeds[@]}"; do
  for preset in talking fast-motion; do
    frames=90
    [ "$preset" = fast-motion ] && frames=60
    ds="$out/actor$seed/$preset"
    [ -f "$ds/dataset.json" ] || "$crease" synth sequence --rig "$out/head.crig" --actor-seed "$seed" \
      --preset "$preset" --frames "$frames" --no-maps --overwrite -o "$ds"
    "$crease" track -i "$ds" --landmarks dlib --no-meshes -o "$out/actor$seed/$preset.dlib" >/dev/null
    "$crease" track -i "$ds" --tracker "$out/tracker.ctrk" --no-meshes -o "$out/actor$seed/$preset.regressor" >/dev/null
    "$crease" track -i "$ds" --ground-truth-prior --no-meshes -o "$out/actor$seed/$preset.gt" >/dev/null
  done
done

python3 - "$out" "${seeds[@]}" <<'EOF'
import json, statistics, sys
out, seeds = sys.argv[1], sys.argv[2:]
def cell(values, fmt):
    if len(values) == 1:
        return fmt.format(values[0])
    return (fmt + " ± " + fmt).format(statistics.mean(values), statistics.stdev(values))
print(f"actors {', '.join(seeds)}: mean over actors ± sd over actors of each actor's mean over tracked frames\n")
print("| sequence | landmark source | tracked frames | landmark error | (IOD) | fitted rig's landmarks | visible vertices (2D) |")
print("|---|---|---|---|---|---|---|")
for preset in ("talking", "fast-motion"):
    for key, name in (("dlib", "dlib"), ("regressor", "crease regressor"), ("gt", "ground-truth prior")):
        rows = [json.load(open(f"{out}/actor{s}/{preset}.{key}/summary.json")) for s in seeds]
        tracked = sum(r["tracked_frames"] for r in rows)
        total = sum(r["frames"] for r in rows)
        err = [r["error"] for r in rows if "error" in r]
        if not err:
            print(f"| {preset} | {name} | {tracked}/{total} | — | — | — | — |")
            continue
        lm = "—" if key == "gt" else cell([e["landmark_px"] for e in err], "{:.1f}") + " px"
        iod = "—" if key == "gt" else cell([e["landmark_iod"] for e in err], "{:.3f}")
        fit = cell([e["fit_landmark_px"] for e in err], "{:.2f}") + " px"
        vert = cell([e["vertex_px"] for e in err], "{:.1f}") + " px"
        print(f"| {preset} | {name} | {tracked}/{total} | {lm} | {iod} | {fit} | {vert} |")
EOF
