#!/usr/bin/env bash
# Accuracy / size / time of bakes (issue 4's table): two heads (the procedural head,
# seed 0, and the scanned data/meshes/head.off) × bake resolutions × rank
# policies (chosen per scene vs a fixed K), scored by the reference renderer against
# path-traced ground truth at held-aside novel views, one per shared HDRI (8 novel
# lights), plus the source views under the capture's lighting.
#
#   cargo build --release -p nelf --bins -p nelf-bake --examples
#   bash scripts/eval_bakes.sh [OUT_DIR]        # env: SIZE (px, 128), RESOLUTIONS ("64 96 128 160"), FIXED_RANK (16), REFERENCE_RES (128)
#
# Writes OUT_DIR/table.md. Reads the HDRIs and the scan from data/ (DATA=... for another folder).
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-out/eval}
DATA=${DATA:-data}
SIZE=${SIZE:-128}
RESOLUTIONS=${RESOLUTIONS:-"64 96 128 160"}
FIXED_RANK=${FIXED_RANK:-16}
REFERENCE_RES=${REFERENCE_RES:-128}
NELF=target/release/nelf
EVAL=target/release/examples/bake_eval
mkdir -p "$OUT"

targets=()
for env in "$DATA"/envmaps/*.exr; do targets+=(--target-envmap "$env"); done
n_targets=$(( ${#targets[@]} / 2 ))

declare -A capture_args=(
  [procedural]=""
  [scan]="--mesh $DATA/meshes/head.off --mesh-rotate-y-deg 90"
)
for head in procedural scan; do
  cap="$OUT/capture_$head"
  if [ ! -f "$cap/cameras.json" ]; then
    # shellcheck disable=SC2086
    $NELF capture synth -o "$cap" --width "$SIZE" --height "$SIZE" --targets "$n_targets" "${targets[@]}" ${capture_args[$head]} --json > "$cap.report.json"
  fi
done

{
  echo "| head | resolution | voxel (mm) | rank policy | K | voxels | file (bytes) | bake (s) | LT (s) | rank choice (s) | compression loss (dB) | PSNR targets (dB) | SSIM targets | interior PSNR targets (dB) | edge share | PSNR sources (dB) | render (s) |"
  echo "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"
} > "$OUT/table.md"
for head in procedural scan; do
  for res in $RESOLUTIONS; do
    policies=(auto "K=$FIXED_RANK")
    # Near-lossless reference (K = 128, f16) at one resolution: the loss due to PCA +
    # quantization alone is its PSNR minus the others'.
    [ "$res" = "$REFERENCE_RES" ] && policies+=("K=128-f16")
    for policy in "${policies[@]}"; do
      name="${head}_${res}_${policy/=/}"
      rank_args=()
      case "$policy" in
        auto) ;;
        K=128-f16) rank_args=(--rank 128 --encoding f16) ;;
        *) rank_args=(--rank "$FIXED_RANK") ;;
      esac
      start=$EPOCHREALTIME
      $NELF bake capture "$OUT/capture_$head" -o "$OUT/$name.nelf" --resolution "$res" --quiet "${rank_args[@]}" > /dev/null
      end=$EPOCHREALTIME
      $EVAL "$OUT/$name.nelf" "$OUT/capture_$head" --json > "$OUT/$name.eval.json"
      python3 - "$OUT/$name" "$head" "$res" "$policy" "$start" "$end" >> "$OUT/table.md" <<'PY'
import json, sys
stem, head, res, policy, start, end = sys.argv[1:]
secs = float(end) - float(start)
bake = json.load(open(stem + ".bake.json"))["report"]
ev = json.load(open(stem + ".eval.json"))
t, s = ev["mean_targets"], ev["mean_sources"]
tm = bake["timings"]
print(f"| {head} | {res} | {1000 * bake['voxel_size_m']:.2f} | {policy} | {bake['rank']} | {bake['voxels']} | {bake['file_size']} | {secs:.1f} | "
      f"{tm['lt_secs']:.1f} | {tm['rank_secs']:.1f} | {bake['loss_db']:.3f} | {t['psnr_db']:.2f} | {t['ssim']:.4f} | "
      f"{t['interior_psnr_db']:.2f} | {t['edge_share']:.2f} | {s['psnr_db']:.2f} | {t['render_secs']:.3f} |")
PY
    done
  done
done
cat "$OUT/table.md"
