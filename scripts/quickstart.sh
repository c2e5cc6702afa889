#!/usr/bin/env bash
# crease's main job. Installs what is missing, builds Release, then runs the most
# complete thing crease does today, end to end:
#   1. imports the bundled blendshape OBJ folder (quads, cm, per-corner UVs with a
#      seam, 68 landmarks) into a crease rig, with derived region masks, and
#      ray-traces a preview of an expression;
#   2. builds the studio's procedural head rig and a seeded actor;
#   3. renders a brow raise under raking light and under front light (the forehead
#      wrinkles show under the first and fade under the second);
#   4. renders the first seconds of the `wrinkle-workout` performance with per-frame
#      ground truth (landmarks, rig parameters, displacement maps);
#   5. rebuilds the high-resolution ground-truth surface of one frame, and tracks the
#      performance (dlib landmarks, the rig fitted per frame) against its ground truth;
#   6. writes the training scans of 4 actors (neutral + 4 expressions each, ~0.7 M
#      vertex meshes, 3 calibrated cameras) and trains the detail model on them
#      (paper Sec. 4), printing the report: detail-extraction accuracy against the
#      studio's ground truth, the PCA energy, the cascade's training error, timings.
# Outputs go to ${CREASE_OUT:-out/quickstart}.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$root/scripts/setup.sh"

build="${CREASE_BUILD_DIR:-$root/build}"
crease="$build/apps/crease/crease"
out="${CREASE_OUT:-$root/out/quickstart}"
mkdir -p "$out"
step() { printf '\n[crease quickstart] %s\n' "$*"; }

step "crease version"
"$crease" version
step "importing the sample blendshape OBJ folder data/sample_rig (cm)"
"$crease" rig import --objs "$root/data/sample_rig" --units cm --out "$out/sample.crig"
step "describing the rig"
"$crease" rig info "$out/sample.crig" --regions-png "$out/rig_regions.png"
step "evaluating an expression (jaw open, left smile, inner brows raised)"
"$crease" rig evaluate "$out/sample.crig" -e jawOpen=0.7 -e mouthSmile_L=1 -e browInnerUp=1 -o "$out/expression.vtp"
"$crease" rig evaluate "$out/sample.crig" -e jawOpen=0.7 -e mouthSmile_L=1 -e browInnerUp=1 -o "$out/expression.ply"
"$crease" mesh info "$out/expression.vtp"
step "ray-tracing previews"
"$crease" mesh render "$out/expression.ply" -o "$out/expression.png"
"$crease" mesh render "$out/expression.vtp" --field displacement_magnitude_mm -o "$out/expression_displacement.png"

step "building the studio's procedural head rig and actor 1 (an older actor: many, deep lines)"
"$crease" synth rig -o "$out/head.crig" --preview "$out/head_rig.png"
"$crease" synth actor --rig "$out/head.crig" --seed 1 -o "$out/actor1.json"
step "a brow raise under raking light and under front light"
"$crease" synth render --rig "$out/head.crig" --actor "$out/actor1.json" -e browInnerUp=1,browOuterUp=1 \
  --light raking-above --pitch 28 --fov 30 -o "$out/brow_raise_raking.png"
"$crease" synth render --rig "$out/head.crig" --actor "$out/actor1.json" -e browInnerUp=1,browOuterUp=1 \
  --light front --pitch 28 --fov 30 -o "$out/brow_raise_front.png"
step "rendering 2 s of the wrinkle-workout performance with ground truth"
"$crease" synth sequence --rig "$out/head.crig" --actor "$out/actor1.json" --preset wrinkle-workout \
  --frames 60 --overwrite -o "$out/wrinkle_workout"
"$crease" synth mesh --dataset "$out/wrinkle_workout" --frame 33 -o "$out/frame33_hires.ply"
step "tracking the performance: dlib landmarks and the rig fitted per frame, measured against the ground truth"
"$crease" track -i "$out/wrinkle_workout" -o "$out/tracking" --preview "$out/tracking.avi"

step "training scans: 4 actors, a neutral and 4 wrinkle expressions each, 3 cameras (about 2 min)"
"$crease" synth scans --rig "$out/head.crig" --overwrite -o "$out/scans"
step "training the detail model (paper Sec. 4; about 2 min)"
"$crease" train --scans "$out/scans" --out "$out/model.cdm"
"$crease" model info "$out/model.cdm"
step "done. Outputs:"
for f in sample.crig rig_regions.png expression.vtp expression.png expression_displacement.png \
         head.crig head_rig.png actor1.json brow_raise_raking.png brow_raise_front.png \
         wrinkle_workout/dataset.json wrinkle_workout/frames/000033.png frame33_hires.ply \
         tracking/summary.json tracking/tracking.pvd tracking.avi \
         scans/scans.json model.cdm model_report/report.md model_report/eigen_patches.png \
         model_report/wrinkle_map_actor_002.png model_report/displacement_actor_002_01_browInnerUp.png; do
  printf '  %s\n' "$out/$f"
done
printf 'Open .vtp and .ply files in ParaView or MeshLab and the .png files in any viewer.\n'
printf 'The dataset folder is described by its dataset.json and by synth/dataset.h.\n'
printf 'The training report (model_report/report.md) compares each extracted displacement map with the\n'
printf "studio's ground truth; displacement_*.png show them side by side (extracted left, truth right).\n"
