#!/usr/bin/env bash
# The Blender check of export/BLENDER.md, from a fresh clone: installs Blender 4.5.3 as a
# Python module into a virtual environment (about 950 MB, a few minutes, once), builds
# nelf, then for each asset: imports it with the add-on (export/blender/nelf_relight),
# renders the colour grid and the material relit under three worlds of data/envmaps (one
# turned 90 degrees) with Cycles and compares each with `nelf render` under the same map;
# and runs the add-on's operators and error paths inside Blender. Not part of CI.
#
#   scripts/blender_check.sh OUT ASSET.nelf [ASSET.nelf ...]
#
# Environment: VENV (default .venv-blender), CHECK_ARGS (options of blender_check.py;
# default: 256², pixel means of 4x4 rays against Cycles' box filter, 32 samples).
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${1:?usage: scripts/blender_check.sh OUT ASSET.nelf [ASSET.nelf ...]}
shift
[ $# -ge 1 ] || { echo "name at least one .nelf asset" >&2; exit 2; }
VENV=${VENV:-.venv-blender}
CHECK_ARGS=${CHECK_ARGS:-size=256 pixel_grid=4 samples=32}

if ! "$VENV/bin/python" -c "import bpy" 2>/dev/null; then
  python=$(command -v python3.11 || command -v python3)
  "$python" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))' || {
    echo "bpy 4.5.3 needs Python 3.11; $python is $("$python" --version)" >&2
    exit 1
  }
  "$python" -m venv "$VENV"
  "$VENV/bin/pip" install --quiet bpy==4.5.3
fi
cargo build --release --quiet

mkdir -p "$OUT"
for asset in "$@"; do
  name=$(basename "$asset" .nelf)
  echo "== $name"
  # shellcheck disable=SC2086
  "$VENV/bin/python" scripts/blender_check.py "$asset" "$OUT/$name" $CHECK_ARGS | grep '^{' | tee "$OUT/$name.jsonl"
  "$VENV/bin/python" export/blender/tests/addon_in_blender.py "$OUT/$name/asset.vdb" | grep -E '^(ok|FAIL)'
done
