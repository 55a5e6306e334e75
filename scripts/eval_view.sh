#!/usr/bin/env bash
# View-dependent light transport (issue 17): the procedural head with the default
# sheen, the same head matte, and the scanned head (data/meshes/head.off) with the
# default sheen, each captured with 5 source views and one held-aside novel view per
# shared HDRI (8 novel lights), baked with --view-dependence off, sh1, sh2, 3 learned
# lobes and auto, and scored by the reference renderer against path-traced ground truth
# at the held-aside views (bake_eval: PSNR, SSIM, ꟻLIP, interior PSNR), with the file bytes.
# `auto` judges its candidates at those same held-aside views (the explicit rows do not).
#
#   cargo build --release -p nelf --bins -p nelf-bake --examples
#   bash scripts/eval_view.sh [OUT_DIR]      # env: SIZE (px, 128), RESOLUTION (128), CHOICES
#
# Writes OUT_DIR/table.md.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:-out/eval-view}
DATA=${DATA:-data}
SIZE=${SIZE:-128}
RESOLUTION=${RESOLUTION:-128}
CHOICES=${CHOICES:-"off sh1 sh2 3 auto"}
NELF=target/release/nelf
EVAL=target/release/examples/bake_eval
mkdir -p "$OUT"

targets=()
for env in "$DATA"/envmaps/*.exr; do targets+=(--target-envmap "$env"); done
n_targets=$(( ${#targets[@]} / 2 ))

declare -A capture_args=(
  [sheen]=""
  [matte]="--specular-weight 0"
  [scan]="--mesh $DATA/meshes/head.off --mesh-rotate-y-deg 90"
)
heads=${HEADS:-"sheen matte scan"}
for head in $heads; do
  cap="$OUT/capture_$head"
  if [ ! -f "$cap/cameras.json" ]; then
    # shellcheck disable=SC2086
    $NELF capture synth -o "$cap" --width "$SIZE" --height "$SIZE" --targets "$n_targets" "${targets[@]}" ${capture_args[$head]} --json > "$cap.report.json"
  fi
done

{
  echo "| head | view dependence | kept | J | K_v | K | file (bytes) | bytes ratio | bake (s) | view stage (s) | PSNR targets (dB) | SSIM targets | ꟻLIP targets | interior PSNR targets (dB) | PSNR sources (dB) |"
  echo "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"
} > "$OUT/table.md"
for head in $heads; do
  base_bytes=""
  for choice in $CHOICES; do
    name="${head}_${choice}"
    start=$EPOCHREALTIME
    $NELF bake capture "$OUT/capture_$head" -o "$OUT/$name.nelf" --resolution "$RESOLUTION" --view-dependence "$choice" --quiet > /dev/null
    end=$EPOCHREALTIME
    $EVAL "$OUT/$name.nelf" "$OUT/capture_$head" --json > "$OUT/$name.eval.json"
    python3 - "$OUT/$name" "$head" "$choice" "$start" "$end" "$OUT/${head}_off.bake.json" >> "$OUT/table.md" <<'PY'
import json, os, sys
stem, head, choice, start, end, off = sys.argv[1:]
secs = float(end) - float(start)
bake = json.load(open(stem + ".bake.json"))["report"]
base = json.load(open(off))["report"]["file_size"] if os.path.exists(off) else bake["file_size"]
ev = json.load(open(stem + ".eval.json"))
t, s = ev["mean_targets"], ev["mean_sources"]
view = bake.get("view") or {}
idx = view.get("chosen_index")
cand = view["candidates"][idx] if idx is not None else None
kept = view.get("chosen", "off")
print(f"| {head} | {choice} | {kept} | {cand['lobes'] if cand else 0} | {cand['rank'] if cand else 0} | {bake['rank']} | {bake['file_size']} | "
      f"{bake['file_size'] / base:.2f} | {secs:.1f} | {bake['timings'].get('view_secs', 0):.1f} | {t['psnr_db']:.2f} | {t['ssim']:.4f} | {t['flip']:.4f} | "
      f"{t['interior_psnr_db']:.2f} | {s['psnr_db']:.2f} |")
PY
  done
done
cat "$OUT/table.md"
