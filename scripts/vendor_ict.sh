#!/usr/bin/env bash
# Makes the studio's vendored realistic head, data/ict/ict_face_light.crig, from
# the ICT-FaceKit "Light" face model (USC ICT Vision and Graphics Lab, MIT
# licence): the neutral head, its 53 expression shapes and 100 identity modes,
# imported with crease's own importer as a multi-part head (data/ict/ict_parts.json:
# the README's vertex ranges, without the lacrimal-fluid, eye-blend and
# eye-occlusion helper meshes, which are shading tricks for a game engine) with
# ICT's 68 Multi-PIE landmarks, written compactly (deltas quantised to 5 µm in 16
# bits, zlib). The licence and credits are copied beside it.
#
#   scripts/vendor_ict.sh [ICT_SOURCE]   ICT_SOURCE: ict-facekit.tar.xz or its
#                                        unpacked ict-facekit/ folder
#                                        (default ../shared/data/ict-facekit.tar.xz)
# Needs a built crease (scripts/setup.sh). Deterministic: the same input gives
# the same bytes.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
src="${1:-$root/../shared/data/ict-facekit.tar.xz}"
crease="${CREASE_BIN:-$root/build/apps/crease/crease}"
[ -x "$crease" ] || { echo "vendor_ict: $crease not found: build first (scripts/setup.sh)" >&2; exit 1; }
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
if [ -d "$src" ]; then
  kit="$(cd "$src" && pwd)"
elif [ -f "$src" ]; then
  tar -xJf "$src" -C "$tmp"
  kit="$tmp/ict-facekit"
else
  echo "vendor_ict: $src: no such file or folder (expected ict-facekit.tar.xz or its ict-facekit/ folder)" >&2
  exit 1
fi
[ -f "$kit/FaceXModel/generic_neutral_mesh.obj" ] || { echo "vendor_ict: $kit has no FaceXModel/generic_neutral_mesh.obj" >&2; exit 1; }
out="$root/data/ict"
mkdir -p "$out"
# From the kit's parent folder with a relative path, so that the rig's "source"
# (and so its bytes) does not depend on where the kit was unpacked.
(cd "$(dirname "$kit")" && "$crease" rig import --objs "$(basename "$kit")/FaceXModel" --units cm \
  --parts "$out/ict_parts.json" --landmarks "$(basename "$kit")/FaceXModel/vertex_indices.json" \
  --compact -o "$out/ict_face_light.crig")
cp "$kit/LICENSE" "$out/LICENSE"
cp "$kit/CREDITS.md" "$out/CREDITS.md"
ls -l "$out"
