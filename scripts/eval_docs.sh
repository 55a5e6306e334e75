#!/usr/bin/env bash
# Regenerates docs/eval: the Pareto and stability reports and their charts for the
# procedural demo head (head:0) and the shared scanned head (data/meshes/head.off,
# turned 90° to face +z), issue 16's figures. Full runs, long on 2 cores (see
# docs/eval/README.md for the times measured); each run resumes from its results
# file, so a stopped run continues and a finished one only rewrites its report.
#
#   cargo build --release -p nelf && bash scripts/eval_docs.sh [WORK_DIR]   # default out/eval
set -euo pipefail
cd "$(dirname "$0")/.."
WORK=${1:-out/eval}
NELF=target/release/nelf
SCAN=(data/meshes/head.off --mesh-rotate-y-deg 90)
mkdir -p "$WORK" docs/eval

$NELF eval pareto --quiet -o "$WORK/demo-pareto" head:0
$NELF eval pareto --quiet -o "$WORK/scan-pareto" "${SCAN[@]}"
$NELF eval stability --quiet -o "$WORK/demo-stability" head:0
# The scan runs the axes that depend on its shape (the defect meshes, millimetre
# pose noise and soft masks are measured on the demo head).
$NELF eval stability --quiet -o "$WORK/scan-stability" "${SCAN[@]}" \
  --axes views,spread_deg,target_angle_deg,sun_radius_deg,hdri,rank,pose_noise_deg,mask_px

for run in demo-pareto scan-pareto demo-stability scan-stability; do
  dest="docs/eval/$run"
  rm -rf "$dest"
  mkdir -p "$dest"
  cp "$WORK/$run/report.html" "$WORK/$run"/*.csv "$dest/"
  cp -r "$WORK/$run/charts" "$dest/charts"
done
echo "docs/eval updated"
