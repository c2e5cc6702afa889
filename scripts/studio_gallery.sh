#!/usr/bin/env bash
# README's picture of the studio's people: actors on the realistic ICT-FaceKit
# head (the default) under the studio's lights, beside the procedural head.
#   scripts/studio_gallery.sh [OUT.png]     (default docs/studio_actors.png)
# Needs a built crease (scripts/setup.sh); about a minute on 2 cores.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
crease="${CREASE_BIN:-$root/build/apps/crease/crease}"
out="${1:-$root/docs/studio_actors.png}"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
"$crease" synth rig --head ict -o "$tmp/ict.crig" >/dev/null
"$crease" synth rig --head procedural -o "$tmp/procedural.crig" >/dev/null
# Rows: lights; columns: four ICT actors with expressions and yaws, then the procedural head.
shots=("1 0 neutral" "2 20 mouthSmile=0.8,cheekSquint=0.5" "3 -15 browInnerUp=1,browOuterUp=1" "4 10 jawOpen=0.35")
for light in studio front raking-side; do
  for s in "${shots[@]}"; do
    read -r seed yaw expr <<<"$s"
    e=(); [ "$expr" = neutral ] || e=(-e "$expr")
    "$crease" synth render --rig "$tmp/ict.crig" --seed "$seed" --light "$light" --yaw "$yaw" --fov 30 \
      --size 360x400 "${e[@]}" -o "$tmp/${light}_ict_${seed}.png" >/dev/null
  done
  "$crease" synth render --rig "$tmp/procedural.crig" --seed 1 --light "$light" --fov 30 --size 360x400 \
    -o "$tmp/${light}_procedural.png" >/dev/null
done
/usr/bin/python3 - "$tmp" "$out" <<'PY'
import sys, matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt, matplotlib.image as mpimg
tmp, out = sys.argv[1], sys.argv[2]
lights = ["studio", "front", "raking-side"]
cols = [f"ict_{s}" for s in (1, 2, 3, 4)] + ["procedural"]
titles = ["ICT actor 1", "ICT actor 2, smile", "ICT actor 3, brows up", "ICT actor 4, jaw open", "procedural head (0.2)"]
fig, axes = plt.subplots(len(lights), len(cols), figsize=(len(cols) * 2.4, len(lights) * 2.75), dpi=110)
for r, light in enumerate(lights):
    for c, col in enumerate(cols):
        ax = axes[r][c]
        ax.imshow(mpimg.imread(f"{tmp}/{light}_{col}.png"))
        ax.set_xticks([]); ax.set_yticks([])
        if r == 0: ax.set_title(titles[c], fontsize=8)
        if c == 0: ax.set_ylabel(light, fontsize=9)
fig.tight_layout(pad=0.3)
fig.savefig(out)
print("wrote", out)
PY
