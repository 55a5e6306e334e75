#!/usr/bin/env bash
# A real-scan-like bake, end to end (issue 14's figures): the head-and-shoulders
# test mesh (the scanned head of data/meshes/head.off on a striped shirt whose
# collar is a one-sided open sheet with loose flaps; OBJ + MTL + JPEG texture,
# written by `nelf-scene`'s defect_meshes example) is photographed from 5 views at
# SIZE² under a real HDRI, baked with the defaults, and scored at 8 novel views each
# under another real HDRI (every map in data/envmaps, the source one included).
#
#   cargo build --release -p nelf --bins -p nelf-bake --examples -p nelf-scene
#   bash scripts/eval_scan.sh [OUT_DIR]     # env: SIZE (256), SOURCE_ENV (courtyard), BAKE_ARGS
#
# Prints the bake's stage timings and the evaluation (whole image, foreground,
# 8-bit PNG figures); writes previews to OUT_DIR/previews.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-out/scan}
SIZE=${SIZE:-256}
SOURCE_ENV=${SOURCE_ENV:-courtyard}
NELF=target/release/nelf
EVAL=target/release/examples/bake_eval
mkdir -p "$OUT"

cargo run --release -q -p nelf-scene --example defect_meshes -- "$OUT/meshes"
mesh="$OUT/meshes/head_and_shoulders.obj"
height=$(awk '$1 == "v" { if (min == "" || $3 < min) min = $3; if (max == "" || $3 > max) max = $3 } END { print max - min }' "$mesh")

targets=()
for env in data/envmaps/*.exr; do targets+=(--target-envmap "$env"); done
cap="$OUT/capture"
if [ ! -f "$cap/cameras.json" ]; then
  $NELF capture synth -o "$cap" --mesh "$mesh" --mesh-height-m "$height" --width "$SIZE" --height "$SIZE" \
    --envmap "data/envmaps/$SOURCE_ENV.exr" --targets "$(( ${#targets[@]} / 2 ))" "${targets[@]}" --json > "$cap.report.json"
fi
start=$EPOCHREALTIME
# shellcheck disable=SC2086
$NELF bake capture "$cap" -o "$OUT/scan.nelf" --quiet ${BAKE_ARGS:-} > /dev/null
end=$EPOCHREALTIME
python3 -c "import sys; print(f'bake wall time {float(sys.argv[2]) - float(sys.argv[1]):.1f} s')" "$start" "$end"
python3 -c "import json, sys; r = json.load(open(sys.argv[1]))['report']; print(json.dumps({k: r[k] for k in ('voxel_size_m', 'voxels', 'lt_voxels', 'rank', 'file_size', 'timings')}, indent=1))" "$OUT/scan.bake.json"
$EVAL "$OUT/scan.nelf" "$cap" --out "$OUT/previews"
