#!/usr/bin/env bash
# crease's main job. Installs what is missing, builds Release, then runs the most
# complete thing crease does today, end to end on the bundled sample rig:
#   1. import a blendshape OBJ folder (quads, cm, per-corner UVs with a seam,
#      68 landmarks) into a crease rig, deriving the region masks;
#   2. describe the rig and draw its UV layout with regions and landmarks;
#   3. evaluate an expression and write it as PLY and as VTP with per-vertex fields;
#   4. ray-trace shaded previews (Embree) of the expression, plain and coloured by
#      displacement from the neutral.
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

step "done. Outputs:"
for f in sample.crig rig_regions.png expression.vtp expression.ply expression.png expression_displacement.png; do
  printf '  %s\n' "$out/$f"
done
printf 'Open the .vtp in ParaView (colour by displacement_magnitude_mm or region) and the .png files in any viewer.\n'
