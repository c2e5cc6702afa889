#!/usr/bin/env bash
# End-to-end checks of the crease program: the subcommands work on the sample
# rig, and bad input gives a clear error and exit code 1, never a crash.
# Usage: cli_test.sh CREASE_BINARY DATA_DIR
set -u
crease="$1"; data="$2"
tmp="$(mktemp -d)"; trap 'rm -rf "$tmp"' EXIT
fails=0; passes=0

ok() {  # ok DESCRIPTION CMD...: the command succeeds
  local d="$1"; shift
  if "$@" >"$tmp/out" 2>&1; then passes=$((passes+1)); else echo "FAIL (exit $?): $d"; cat "$tmp/out"; fails=$((fails+1)); fi
}
bad() {  # bad DESCRIPTION EXPECTED_TEXT CMD...: exit 1 with the text in the message
  local d="$1" text="$2"; shift 2
  "$@" >"$tmp/out" 2>&1; local rc=$?
  if [ $rc -ne 1 ] && [ $rc -ne 105 ] && [ $rc -ne 106 ] && [ $rc -ne 109 ]; then
    echo "FAIL: $d: exit code $rc (expected a clean error)"; cat "$tmp/out"; fails=$((fails+1)); return
  fi
  if ! grep -qF -- "$text" "$tmp/out"; then
    echo "FAIL: $d: message lacks '$text':"; cat "$tmp/out"; fails=$((fails+1)); return
  fi
  passes=$((passes+1))
}

ok "help" "$crease" --help
ok "version" "$crease" version
ok "rig import" "$crease" rig import --objs "$data/sample_rig" --units cm --out "$tmp/r.crig"
ok "rig info" "$crease" rig info "$tmp/r.crig" --regions-png "$tmp/regions.png"
ok "rig info json" "$crease" rig info "$tmp/r.crig" --json
ok "rig evaluate ply" "$crease" rig evaluate "$tmp/r.crig" -e jawOpen=1 -i 0=1 -o "$tmp/e.ply"
ok "rig evaluate vtp" "$crease" rig evaluate "$tmp/r.crig" -e jawOpen=1 -o "$tmp/e.vtp"
ok "mesh info" "$crease" mesh info "$tmp/e.ply"
ok "mesh convert ply->obj" "$crease" mesh convert "$tmp/e.ply" "$tmp/e.obj"
ok "mesh convert obj->vtp" "$crease" mesh convert "$tmp/e.obj" "$tmp/e2.vtp" --normals
ok "mesh convert vtp->ply ascii" "$crease" mesh convert "$tmp/e.vtp" "$tmp/e3.ply" --ascii
ok "mesh render" "$crease" mesh render "$tmp/e.vtp" --field region --width 64 --height 64 -o "$tmp/e.png"
[ -s "$tmp/e.png" ] || { echo "FAIL: render wrote no image"; fails=$((fails+1)); }

# The studio, end to end on small images.
ok "synth rig" "$crease" synth rig -o "$tmp/head.crig"
ok "synth actor" "$crease" synth actor --rig "$tmp/head.crig" --seed 3 -o "$tmp/actor.json"
ok "synth render" "$crease" synth render --rig "$tmp/head.crig" --actor "$tmp/actor.json" -e browInnerUp=1 --light raking-above --size 160x120 --samples 1 -o "$tmp/still.png"
ok "synth sequence" "$crease" synth sequence --rig "$tmp/head.crig" --actor "$tmp/actor.json" --preset wrinkle-workout --first-frame 30 --frames 2 --size 160x120 -o "$tmp/seq"
[ -s "$tmp/seq/frames/000031.png" ] && [ -s "$tmp/seq/truth/000031.json" ] || { echo "FAIL: sequence outputs missing"; fails=$((fails+1)); }
ok "synth sequence motion blur + passes" "$crease" synth sequence --rig "$tmp/head.crig" --actor "$tmp/actor.json" --preset fast-motion --frames 1 --size 160x120 --passes -o "$tmp/blur"
[ -s "$tmp/blur/passes/000000_depth.exr" ] && [ -s "$tmp/blur/passes/000000_mask.png" ] || { echo "FAIL: passes missing"; fails=$((fails+1)); }
ok "synth mesh" "$crease" synth mesh --dataset "$tmp/seq" --frame 31 -o "$tmp/frame31.ply"
bad "sequence exists" "already exists" "$crease" synth sequence --rig "$tmp/head.crig" --actor "$tmp/actor.json" --preset talking --frames 1 --size 160x120 -o "$tmp/seq"
printf 'keys:\n  - t: 0\n    pose: {yawn: 1}\n' > "$tmp/bad.yaml"
bad "bad sequence yaml" "unknown field 'yawn'" "$crease" synth sequence --rig "$tmp/head.crig" --actor "$tmp/actor.json" --script "$tmp/bad.yaml" -o "$tmp/seq2"
[ ! -e "$tmp/seq2" ] || { echo "FAIL: a dataset was written despite an error"; fails=$((fails+1)); }
bad "unknown light" "unknown" "$crease" synth render --rig "$tmp/head.crig" --seed 1 --light disco -o "$tmp/x.png"
printf '{"version": 1}' > "$tmp/bad_actor.json"
bad "bad actor" "bad_actor.json" "$crease" synth render --rig "$tmp/head.crig" --actor "$tmp/bad_actor.json" -o "$tmp/x.png"
python3 -c 'import json,sys; a=json.load(open(sys.argv[1])); a["identity"]=a["identity"][:3]; json.dump(a,open(sys.argv[2],"w"))' "$tmp/actor.json" "$tmp/few_identity.json"
bad "actor of another rig" "few_identity.json: the actor has 3 identity coefficients" "$crease" synth render --rig "$tmp/head.crig" --actor "$tmp/few_identity.json" -o "$tmp/x.png"
ok "render-scan" "$crease" synth render-scan --mesh "$tmp/e.obj" --albedo "$tmp/regions.png" --units mm --size 160x120 --samples 1 -o "$tmp/scan.png"
bad "render-scan without texture" "tex.png: file does not exist" "$crease" synth render-scan --mesh "$tmp/e.obj" --albedo "$tmp/tex.png" -o "$tmp/x.png"
bad "unknown actor option" "unknown option 'nope'" "$crease" synth actor --rig "$tmp/head.crig" --set nope=1 -o "$tmp/x.json"
bad "bad studio option" "StudioOptions.distance_mm" "$crease" synth sequence --rig "$tmp/head.crig" --actor "$tmp/actor.json" --preset talking --frames 1 --set distance_mm=5 -o "$tmp/seq3"
bad "frame not in dataset" "not in this dataset" "$crease" synth mesh --dataset "$tmp/seq" --frame 7 -o "$tmp/x.ply"

# The global tracker (issue 5): the ground-truth-prior control on the small sequence,
# dlib on frames without a face (a loss, not a crash), and bad input.
ok "track ground-truth-prior" "$crease" track -i "$tmp/seq" --ground-truth-prior --noise 0.5 -o "$tmp/track_gt" --preview "$tmp/track_gt.avi"
[ -s "$tmp/track_gt/frames/000031.json" ] && [ -s "$tmp/track_gt/meshes/000031.ply" ] && [ -s "$tmp/track_gt/tracking.pvd" ] && [ -s "$tmp/track_gt.avi" ] \
  || { echo "FAIL: track wrote no per-frame outputs"; fails=$((fails+1)); }
grep -q '"vertex_px"' "$tmp/track_gt/summary.json" || { echo "FAIL: track summary lacks the error against ground truth"; fails=$((fails+1)); }
mkdir -p "$tmp/noface"; cp "$tmp/regions.png" "$tmp/noface/a.png"; cp "$tmp/regions.png" "$tmp/noface/b.png"
ok "track without a face" "$crease" track -i "$tmp/noface" --rig "$tmp/head.crig" -o "$tmp/track_none"
grep -q "tracked 0 of 2 frames" "$tmp/out" || { echo "FAIL: frames without a face should be reported as lost"; cat "$tmp/out"; fails=$((fails+1)); }
bad "track missing input" "does not exist" "$crease" track -i "$tmp/nothing.mp4" --rig "$tmp/head.crig" -o "$tmp/t2"
mkdir -p "$tmp/emptydir"
bad "track empty folder" "no images" "$crease" track -i "$tmp/emptydir" --rig "$tmp/head.crig" -o "$tmp/t2"
echo "not a video" > "$tmp/fake.mp4"
bad "track unreadable video" "fake.mp4" "$crease" track -i "$tmp/fake.mp4" --rig "$tmp/head.crig" -o "$tmp/t2"
bad "track regressor without model" "tracker_model" "$crease" track -i "$tmp/seq" --landmarks regressor -o "$tmp/t2"
bad "ground-truth-prior needs a dataset" "needs a crease sequence dataset" "$crease" track -i "$tmp/noface" --rig "$tmp/head.crig" --ground-truth-prior -o "$tmp/t2"

# Training (Sec. 4) on a tiny scan set: one old actor at 256² maps, one camera.
ok "synth scans" "$crease" synth scans --rig "$tmp/head.crig" --actors 1 --seed 11 --cameras 2 --size 200x150 --samples 1 -e browInnerUp=1,browOuterUp=1 --set resolution=256 --set surface_min_vertices=1000 --set age_min=1 -o "$tmp/scans"
ok "train" "$crease" train --scans "$tmp/scans" --out "$tmp/model.cdm" --set detail.map_resolution=256 --set detail.operator_resolution=96 --set patch.size=8 --set pca.dimensions=6 --set ferns.num_ferns=20 --set ferns.num_sampled_pixels=20 --set fit.max_fit_vertices=300
grep -q "wrinkle band" "$tmp/model_report/report.md" || { echo "FAIL: training report lacks the detail-extraction accuracy"; fails=$((fails+1)); }
[ -s "$tmp/model_report/eigen_patches.png" ] || { echo "FAIL: training wrote no eigen-patch picture"; fails=$((fails+1)); }
ok "model info" "$crease" model info "$tmp/model.cdm"
grep -q "K = 20" "$tmp/out" || { echo "FAIL: model info does not show K"; fails=$((fails+1)); }
bad "model info on a rig" "not a crease detail model" "$crease" model info "$tmp/head.crig"
bad "train without scans" "no scans.json" "$crease" train --scans "$tmp" --rig "$tmp/head.crig" --out "$tmp/m2.cdm"
bad "unknown training option" "unknown option 'ferns'" "$crease" train --scans "$tmp/scans" --out "$tmp/m2.cdm" --set ferns=3
bad "bad training option" "num_ferns" "$crease" train --scans "$tmp/scans" --out "$tmp/m2.cdm" --set ferns.num_ferns=0
# Issue 18: a key from before option sections names its new key; a key set twice is refused.
bad "old training key" "unknown option 'pca_dimensions': it is now 'pca.dimensions'" "$crease" train --scans "$tmp/scans" --out "$tmp/m2.cdm" --set pca_dimensions=6
printf 'pca:\n  dimensions: 4\npca.dimensions: 6\n' > "$tmp/twice.yaml"
bad "training key twice" "option 'pca.dimensions' is set twice" "$crease" train --scans "$tmp/scans" --out "$tmp/m2.cdm" --config "$tmp/twice.yaml"
bad "unknown training light" "light 'disco'" "$crease" train --scans "$tmp/scans" --out "$tmp/m2.cdm" --set training_lights=disco
[ ! -e "$tmp/m2.cdm" ] || { echo "FAIL: model written despite an error"; fails=$((fails+1)); }
# Online capture (issue 6) on the 2-frame sequence with the tiny model, then its metrics.
ok "capture" "$crease" capture -i "$tmp/seq" --model "$tmp/model.cdm" --ground-truth-prior --set detail.wrinkle_frames=2 --set hifi.resolution=64 --preview "$tmp/cap.avi" -o "$tmp/cap"
for f in capture.json rig.crig timings.csv frames/000031.json frames/000031.cfr displacement/000031.exr maps/mesoscopic.exr maps/wrinkle_map.png meshes/hifi/000030.ply hifi.pvd refined.pvd previews/000030.png; do
  [ -s "$tmp/cap/$f" ] || { echo "FAIL: capture did not write $f"; fails=$((fails+1)); }
done
ok "eval" "$crease" eval --capture "$tmp/cap" --dataset "$tmp/seq" --set surface_every=1 --set surface_mesh_resolution=64
grep -q "refined L~^t" "$tmp/cap/eval.md" && grep -q '"coarse_px"' "$tmp/cap/eval.json" && [ -s "$tmp/cap/eval_frames.csv" ] \
  && grep -q "Refinement steps at the flow points" "$tmp/cap/eval.md" && grep -q "LK from the true positions" "$tmp/cap/eval.md" \
  || { echo "FAIL: eval wrote no metrics"; fails=$((fails+1)); }
bad "capture exists" "already exists" "$crease" capture -i "$tmp/seq" --model "$tmp/model.cdm" --ground-truth-prior -o "$tmp/cap"
# The ground-truth-fit control (issue 17's exact geometry): L^t is the truth up to the
# actor's personal deviations, far closer than the landmark fit of the prior control.
ok "capture ground-truth fit" "$crease" capture -i "$tmp/seq" --model "$tmp/model.cdm" --ground-truth-fit --set detail.wrinkle_frames=2 --no-meshes -o "$tmp/cap_fit"
ok "eval ground-truth fit" "$crease" eval --capture "$tmp/cap_fit" --dataset "$tmp/seq" --set surface_every=0
python3 - "$tmp/cap/eval.json" "$tmp/cap_fit/eval.json" <<'PY' || { echo "FAIL: the ground-truth fit is not closer than the prior"; fails=$((fails+1)); }
import json, sys
prior, fit = (json.load(open(p))["tracking"]["coarse_px"] for p in sys.argv[1:3])
print(f"coarse 2D error: ground-truth prior {prior:.2f} px, ground-truth fit {fit:.2f} px")
sys.exit(0 if fit < 0.5 * prior and fit < 1.5 else 1)
PY
# A perfect regressor (issue 17): the capture's D^t replaced by the truth D* that eval
# writes scores 0 on the band normal error, and the surface measure's true-detail row is
# the full row; L~^t alone keeps its error. Its D^HF replaced by the D^HF of the true
# albedo (also written by eval) is found to be that map.
ok "eval truth maps" "$crease" eval --capture "$tmp/cap_fit" --dataset "$tmp/seq" --set surface_every=0 --set truth_maps_dir="$tmp/truth_maps"
mkdir -p "$tmp/cap_oracle/displacement" && cp -r "$tmp/cap_fit/capture.json" "$tmp/cap_fit/rig.crig" "$tmp/cap_fit/frames" "$tmp/cap_fit/maps" "$tmp/cap_oracle/" \
  && cp "$tmp/truth_maps/"[0-9]*.exr "$tmp/cap_oracle/displacement/" \
  && cp "$tmp/truth_maps/mesoscopic_albedo.exr" "$tmp/cap_oracle/maps/mesoscopic.exr"
[ -s "$tmp/truth_maps/wrinkle_mask.png" ] || { echo "FAIL: eval wrote no wrinkle_mask.png beside the truth maps"; fails=$((fails+1)); }
ok "eval perfect regressor" "$crease" eval --capture "$tmp/cap_oracle" --dataset "$tmp/seq" --set surface_every=1 --set surface_mesh_resolution=64 --set active_reference_rms_mm=0
python3 - "$tmp/cap_oracle/eval.json" <<'PY' || { echo "FAIL: the perfect regressor's normal errors"; fails=$((fails+1)); }
import json, sys
s = json.load(open(sys.argv[1]))["surface"]
b, full, true, albedo = s["band"], s["full"], s["true_detail"], s["mesoscopic_albedo"]
print(f"band normal error: L~^t {b['coarse_deg']:.3f}, L~^t + D* {b['detail_deg']:.4f} deg; "
      f"surface: H^t {full['normal_deg']:.3f}, true detail {true['normal_deg']:.3f} deg; "
      f"D^HF made of the true albedo: correlation {albedo['correlation']:.4f} with the albedo's D^HF")
# Each wrinkle region's own figures (displacement.by_region, its band): the truth itself
# correlates 1 with the truth wherever the truth varies.
d = json.load(open(sys.argv[1]))["displacement"]
regions = [(k, r) for key in ("by_region", "by_region_band") for k, r in d[key].items()]
varying = [(k, r) for k, r in regions if r["texels"] > 0 and r["reference_rms_mm"] > 1e-6]
print("by region: " + ", ".join(f"{k} {r['correlation']:.4f}" for k, r in varying))
sys.exit(0 if b["coarse_deg"] > 0.01 and b["detail_deg"] < 1e-4 and abs(full["normal_deg"] - true["normal_deg"]) < 1e-4
         and albedo["correlation"] > 0.999 and len(varying) >= 2 and all(r["correlation"] > 0.999 for _, r in varying)
         and set(d["by_region"]) <= {"forehead", "glabella", "left_eye", "right_eye", "left_cheek", "right_cheek", "nose", "mouth"}
         else 1)
PY
# The truth registered through the image (eval/registered_truth.h): the texture of the
# ground-truth fit slides less on the face than the prior control's, and keeps the truth.
python3 - "$tmp/cap/eval.json" "$tmp/cap_fit/eval.json" <<'PY' || { echo "FAIL: registered truth"; fails=$((fails+1)); }
import json, sys
prior, fit = (json.load(open(p)).get("registered") for p in sys.argv[1:3])
print(f"texture slide: ground-truth prior {prior['slide_mm']:.2f} mm, ground-truth fit {fit['slide_mm']:.2f} mm; "
      f"truth band kept {prior['truth_band_correlation']:.2f} / {fit['truth_band_correlation']:.2f}")
# D*'s band slid on the face decorrelates with the slide (eval's truth_shift), and the
# exact fit's texture does not drift on the skin between frames.
shift = json.load(open(sys.argv[2]))["truth_shift"]
print(f"D* slid 0.5 / 4 mm: {shift['0_5mm']:.2f} / {shift['4mm']:.2f}; drift of the exact fit {fit['drift_mm']:.3f} mm")
sys.exit(0 if fit["slide_mm"] < prior["slide_mm"] and fit["slide_mm"] < 1.0 and fit["truth_band_correlation"] > 0.5
         and shift["0_5mm"] > shift["4mm"] and shift["0_5mm"] < 1.0 and fit["drift_mm"] < 0.3 else 1)
PY
# The landmark source's error by face part: the ground-truth prior's points are the truth's.
python3 - "$tmp/cap/eval.json" <<'PY' || { echo "FAIL: landmark errors of the ground-truth prior"; fails=$((fails+1)); }
import json, sys
lm = json.load(open(sys.argv[1]))["landmarks"]
print(f"ground-truth prior landmarks: {lm['px']:.3f} px over {lm['frames']} frames")
parts = lm["parts"]
print("  by part: " + ", ".join(f"{k} {v['px']:.3f}" for k, v in parts.items()))
ok_parts = set(parts) == {"jaw", "brows", "nose", "eyes", "mouth"} and all(0 <= v["px"] < 0.5 and abs(v["dx"]) < 0.5 and abs(v["dy"]) < 0.5 for v in parts.values())
sys.exit(0 if lm["frames"] >= 1 and lm["px"] < 0.5 and ok_parts else 1)
PY
# The still face (issue 17): D^t's frame-to-frame correlation over a held expression,
# split by whether the held truth has wrinkles (eval's active frames). A perfect
# regressor (D^t = D*) over a held brow raise correlates 1 and counts as a pair with
# wrinkles; with the activity threshold out of reach it counts as one without.
ok "synth sequence held brow raise" "$crease" synth sequence --rig "$tmp/head.crig" --actor "$tmp/actor.json" --preset scan-holds --first-frame 40 --frames 2 --size 160x120 -o "$tmp/hold"
ok "capture held brow raise" "$crease" capture -i "$tmp/hold" --model "$tmp/model.cdm" --ground-truth-fit --set detail.wrinkle_frames=2 --no-meshes -o "$tmp/cap_hold"
ok "eval held brow raise" "$crease" eval --capture "$tmp/cap_hold" --dataset "$tmp/hold" --set surface_every=0 --set truth_maps_dir="$tmp/hold_truth"
mkdir -p "$tmp/still/displacement" && cp -r "$tmp/cap_hold/capture.json" "$tmp/cap_hold/rig.crig" "$tmp/cap_hold/frames" "$tmp/cap_hold/maps" "$tmp/still/" \
  && cp "$tmp/hold_truth/000040.exr" "$tmp/hold_truth/000041.exr" "$tmp/still/displacement/"
ok "eval still face" "$crease" eval --capture "$tmp/still" --dataset "$tmp/hold" --set surface_every=0 -o "$tmp/still_active"
ok "eval still face, no active frame" "$crease" eval --capture "$tmp/still" --dataset "$tmp/hold" --set surface_every=0 --set active_reference_rms_mm=1e9 -o "$tmp/still_inactive"
python3 - "$tmp/still_active/eval.json" "$tmp/still_inactive/eval.json" <<'PY' || { echo "FAIL: the still face split by the held truth"; fails=$((fails+1)); }
import json, sys
act, inact = (json.load(open(p))["displacement"] for p in sys.argv[1:3])
for name, d in (("truth with wrinkles", act), ("threshold out of reach", inact)):
    print(f"still face, {name}: {d['still_pairs']} pair(s), {d['still_active_pairs']} with wrinkles in the truth, "
          f"{d['still_inactive_pairs']} without; correlation {d.get('still_correlation')}, pooled {d.get('still_pooled_correlation')}")
# The same frames by the expression held (displacement.by_expression): one expression,
# named without its side, both frames, the truth correlating 1 with itself.
by = act["by_expression"]
print("by expression: " + ", ".join(f"{k}: {e['frames']} frames, band {e['band']['correlation']:.4f}" for k, e in by.items()))
one = list(by.values())[0] if len(by) == 1 else None
sys.exit(0 if one and not list(by)[0].endswith(("_L", "_R")) and one["frames"] == 2 and one["band"]["correlation"] > 0.9999
         and inact["by_expression"] == {}
         and act["still_active_pairs"] == 1 and act["still_inactive_pairs"] == 0 and act["still_active_correlation"] > 0.9999
         and act["still_pooled_correlation"] > 0.9999 and "still_inactive_correlation" not in act
         and inact["still_inactive_pairs"] == 1 and inact["still_active_pairs"] == 0 and inact["still_inactive_correlation"] > 0.9999
         and "still_active_correlation" not in inact else 1)
PY
bad "prior and fit controls together" "exclude each other" "$crease" capture -i "$tmp/seq" --model "$tmp/model.cdm" --ground-truth-prior --ground-truth-fit -o "$tmp/cap3"
bad "capture missing model" "m3.cdm" "$crease" capture -i "$tmp/seq" --model "$tmp/m3.cdm" -o "$tmp/cap2"
bad "capture model of another kind" "detail model" "$crease" capture -i "$tmp/seq" --model "$tmp/actor.json" -o "$tmp/cap2"
bad "capture missing input" "does not exist" "$crease" capture -i "$tmp/nothing.mp4" --model "$tmp/model.cdm" --rig "$tmp/head.crig" -o "$tmp/cap2"
bad "capture unknown option" "unknown option 'ferns'" "$crease" capture -i "$tmp/seq" --model "$tmp/model.cdm" --set ferns=2 -o "$tmp/cap2"
[ ! -e "$tmp/cap2" ] || { echo "FAIL: capture folder written despite an error"; fails=$((fails+1)); }
bad "eval not a capture" "capture.json" "$crease" eval --capture "$tmp/seq" --dataset "$tmp/seq"
bad "eval not a dataset" "dataset.json" "$crease" eval --capture "$tmp/cap" --dataset "$tmp/scans"

# Issue 19: files crease writes, edited to lie about their sizes, devices and an alias
# bomb give a clear error naming the file, not a crash, a hang or gigabytes.
python3 - "$tmp" <<'PY'
import json, re, struct, sys, zlib
d = sys.argv[1]
def put(name, data): open(f"{d}/{name}", "wb").write(data)
vtp = open(f"{d}/e.vtp", "rb").read()  # binary: zlib blocks, UInt32 block headers
at = vtp.index(b"_", vtp.index(b"<AppendedData")) + 1  # the first array's block header
def word(k, v): return vtp[:at + 4 * k] + struct.pack("<I", v) + vtp[at + 4 * k + 4:]
put("neg.vtp", re.sub(rb'NumberOfPoints="\d+"', b'NumberOfPoints="-1"', vtp))
put("polys.vtp", re.sub(rb'NumberOfPolys="\d+"', b'NumberOfPolys="2000000000"', vtp))
put("blocks0.vtp", word(0, 0))
put("blocksize0.vtp", word(1, 0))
put("blocksff.vtp", word(0, 0xFFFFFFFF))
png = bytearray(open(f"{d}/regions.png", "rb").read())
png[16:24] = struct.pack(">II", 100000, 100000)
png[29:33] = struct.pack(">I", zlib.crc32(bytes(png[12:29])))
put("huge.png", bytes(png))
yaml = "a: &a [x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"{c}: &{c} [{', '.join(['*' + chr(ord(c) - 1)] * 9)}]\n" for c in "bcdefghi")
put("bomb.yaml", yaml.encode())
ds = json.load(open(f"{d}/seq/dataset.json"))
ds["files"]["frame"] = "frames/{frame:999999999d}.png"
import os; os.makedirs(f"{d}/seqpat", exist_ok=True)
put("seqpat/dataset.json", json.dumps(ds).encode())
for name, key, value in (("seqv99", "version", 99), ("seqneg", "width", -640)):
    bad = json.load(open(f"{d}/seq/dataset.json")); bad[key] = value
    os.makedirs(f"{d}/{name}", exist_ok=True); put(f"{name}/dataset.json", json.dumps(bad).encode())
PY
bad "vtp NumberOfPoints=-1" 'neg.vtp: not a readable VTK XML PolyData file: Piece NumberOfPoints="-1"' "$crease" mesh info "$tmp/neg.vtp"
bad "vtp NumberOfPolys 2e9" "polys.vtp: not a readable VTK XML PolyData file: array 'offsets' holds" "$crease" mesh convert "$tmp/polys.vtp" "$tmp/x.ply"
bad "vtp 0 blocks" "blocks0.vtp: not a readable VTK XML PolyData file" "$crease" mesh info "$tmp/blocks0.vtp"
bad "vtp block size 0" "bad compressed block sizes" "$crease" mesh info "$tmp/blocksize0.vtp"
bad "vtp 2^32-1 blocks" "past the end of the file" "$crease" mesh convert "$tmp/blocksff.vtp" "$tmp/x.ply"
bad "experiment alias bomb" "bomb.yaml: the YAML expands to more than" "$crease" experiment run "$tmp/bomb.yaml" --dry-run
bad "render-scan albedo device" "/dev/zero: is not a regular file" "$crease" synth render-scan --mesh "$tmp/e.obj" --albedo /dev/zero --units mm --size 160x120 --samples 1 -o "$tmp/x.png"
bad "render-scan displacement device" "/dev/zero: is not a regular file" "$crease" synth render-scan --mesh "$tmp/e.obj" --albedo "$tmp/regions.png" --displacement /dev/zero --units mm --size 160x120 --samples 1 -o "$tmp/x.png"
bad "rig info device" "/dev/zero: is not a regular file" "$crease" rig info /dev/zero
bad "model info device" "/dev/zero: is not a regular file" "$crease" model info /dev/zero
bad "PNG claiming 100000x100000" "huge.png: the header claims 100000x100000 pixels" "$crease" synth render-scan --mesh "$tmp/e.obj" --albedo "$tmp/huge.png" --units mm --size 160x120 --samples 1 -o "$tmp/x.png"
bad "eval frame pattern width" "seqpat/dataset.json: files.frame" "$crease" eval --capture "$tmp/cap" --dataset "$tmp/seqpat"
bad "dataset version 99" "seqv99/dataset.json: version 99 is not supported" "$crease" eval --capture "$tmp/cap" --dataset "$tmp/seqv99"
bad "dataset negative width" "seqneg/dataset.json: width = -640 is outside" "$crease" track -i "$tmp/seqneg" -o "$tmp/t_neg"
[ ! -e "$tmp/x.png" ] && [ ! -e "$tmp/x.ply" ] || { echo "FAIL: output written despite an error"; fails=$((fails+1)); }

bad "missing mesh" "nope.ply: file does not exist" "$crease" mesh info "$tmp/nope.ply"
printf 'ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n' > "$tmp/badidx.ply"
bad "index out of range" "badidx.ply" "$crease" mesh info "$tmp/badidx.ply"
printf 'ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\nnan 0 0\n0 1 0\n3 0 1 2\n' > "$tmp/nan.ply"
bad "NaN vertex" "nan.ply" "$crease" mesh info "$tmp/nan.ply"
printf 'not a mesh' > "$tmp/garbage.ply"
bad "garbage PLY" "garbage.ply" "$crease" mesh info "$tmp/garbage.ply"
bad "unknown extension" "supported" "$crease" mesh convert "$tmp/e.ply" "$tmp/e.xyz"
[ ! -e "$tmp/e.xyz" ] || { echo "FAIL: half-written output"; fails=$((fails+1)); }
bad "missing rig folder" "not a folder" "$crease" rig import --objs "$tmp/none" --units cm --out "$tmp/x.crig"
bad "bad units" "units" "$crease" rig import --objs "$data/sample_rig" --units furlong --out "$tmp/x.crig"
bad "bad face range" "[A, B)" "$crease" rig import --objs "$data/sample_rig" --units cm --face-vertices 12 --out "$tmp/x.crig"
bad "ambiguous face range" "B included" "$crease" rig import --objs "$data/sample_rig" --units cm --face-vertices 0:12 --out "$tmp/x.crig"
[ ! -e "$tmp/x.crig" ] || { echo "FAIL: rig written despite an error"; fails=$((fails+1)); }
bad "not a rig" "not a crease rig" "$crease" rig info "$tmp/e.ply"
bad "unknown expression" "no expression named 'smile'" "$crease" rig evaluate "$tmp/r.crig" -e smile=1 -o "$tmp/y.ply"
bad "bad weight" "not a number" "$crease" rig evaluate "$tmp/r.crig" -e jawOpen=lots -o "$tmp/y.ply"
bad "unknown field" "no per-vertex field 'foo'" "$crease" mesh render "$tmp/e.vtp" --field foo -o "$tmp/y.png"
bad "unknown subcommand" "" "$crease" frobnicate
bad "train-tracker without data" "give --rig" "$crease" train-tracker --out "$tmp/t.ctrk"
bad "train-tracker bad option" "num_ferns" "$crease" train-tracker --data "$tmp" --out "$tmp/t.ctrk" --set regressor.num_ferns=0
bad "train-tracker missing folder" "not a folder of labelled faces" "$crease" train-tracker --data "$tmp/none" --out "$tmp/t.ctrk"
[ ! -e "$tmp/t.ctrk" ] || { echo "FAIL: tracker written despite an error"; fails=$((fails+1)); }

# Experiments (issue 7): the configs parse, a bad config names its option, and the
# tiny config runs every stage as the real command, resumes from its cache and reports.
ok "experiment list" "$crease" experiment list
ok "experiment dry run" "$crease" experiment run all --profile quick --dry-run -o "$tmp/exp"
printf 'name: bad\ntraining: {num_fern: 3}\n' > "$tmp/bad.yaml"
bad "experiment unknown option" "num_fern" "$crease" experiment run "$tmp/bad.yaml" --dry-run
printf 'name: bad\nsweep: {values: {capture.detail.wrinkle_frames: [0]}}\n' > "$tmp/badsweep.yaml"
bad "experiment bad sweep" "wrinkle_frames" "$crease" experiment run "$tmp/badsweep.yaml" --dry-run
bad "experiment unknown name" "no such config" "$crease" experiment run nope
bad "experiment bad shard" "--shard" "$crease" experiment run tracking-refinement --shard 3 --dry-run
ok "experiment run (tiny, real stages)" "$crease" experiment run "$data/../tests/data/experiment_tiny.yaml" -o "$tmp/exp"
[ -s "$tmp/exp/tiny/results.csv" ] && [ -s "$tmp/exp/tiny/runs/capture.refine=true_seed1.json" ] ||
  { echo "FAIL: experiment wrote no results"; fails=$((fails+1)); }
ok "experiment rerun (all cached)" "$crease" experiment run "$data/../tests/data/experiment_tiny.yaml" -o "$tmp/exp"
grep -q "10 stages (10 cached, 0 run, 0 failed)" "$tmp/out" || { echo "FAIL: rerun did not reuse the cache"; cat "$tmp/out"; fails=$((fails+1)); }
ok "experiment dry run (all cached)" "$crease" experiment run "$data/../tests/data/experiment_tiny.yaml" -o "$tmp/exp" --dry-run
grep -q "tiny: 10 stages, 10 cached; to run: none" "$tmp/out" && grep -q "^    \[eval [0-9a-f]* cached\] crease eval" "$tmp/out" ||
  { echo "FAIL: the dry run does not say what is cached"; cat "$tmp/out"; fails=$((fails+1)); }
ok "report" "$crease" report "$tmp/exp/tiny"
# The detail ladder's own stages (issue 17): leave one actor out (R0) and the truth
# maps that place R1's patches.
ok "experiment run (tiny ladder)" "$crease" experiment run "$data/../tests/data/experiment_tiny_ladder.yaml" -o "$tmp/exp"
grep -q '"r0.held_out.ridge.correlation"' "$tmp/exp/tiny-ladder/runs/rung=R1_seed1.json" &&
  ls "$tmp"/exp/cache/truth-maps/*/maps/000002.exr > /dev/null 2>&1 ||
  { echo "FAIL: the ladder's loao or truth-maps stage left nothing"; fails=$((fails+1)); }
grep -q "refine" "$tmp/exp/tiny/report.md" && [ -s "$tmp/exp/tiny/figures/tiny_err.png" ] ||
  { echo "FAIL: report lacks the claim or the figure"; fails=$((fails+1)); }

echo "$passes passed, $fails failed"
[ "$fails" -eq 0 ]
