#!/usr/bin/env bash
# Measures the web viewer in headless Chromium, on WebGPU and on WebGL2 (both on
# SwiftShader, i.e. the CPU):
# bundle bytes (raw and gzipped), time to the first frame, frames per second while
# redrawing continuously, and the PSNR of the page's frame against `nelf render` of the
# same camera and lighting (whole image and foreground).
#
#   scripts/measure_web.sh ASSET [ENVMAP] [OUT_DIR]     # default map data/envmaps/studio.exr, out out/web-measure
#
# Needs a release build of nelf (cargo build --release), chromium, Node with web/tests's
# packages (npm ci --prefix web/tests) and python3 (the static file server).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
asset="$1"
env="${2:-$root/data/envmaps/studio.exr}"
out="${3:-$root/out/web-measure}"
nelf="${NELF:-$root/target/release/nelf}"
rm -rf "$out" && mkdir -p "$out"
"$nelf" export web "$asset" --envmap "$env" -o "$out/site" > "$out/export.txt"
echo "bundle (bytes, gzip -9 bytes):"
for f in index.html nelf_web.js nelf_web_bg.wasm; do
  echo "  $f $(stat -c %s "$out/site/$f") $(gzip -9c "$out/site/$f" | wc -c)"
done
port=$((20000 + RANDOM % 20000))
python3 -m http.server -d "$out/site" -b 127.0.0.1 "$port" > "$out/server.log" 2>&1 &
server=$!
trap 'kill $server' EXIT
sleep 1
url="http://127.0.0.1:$port/index.html?tonemap=linear&background=0,0,0&jitter=0&continuous=1"
for backend in webgpu webgl2; do
  node "$root/web/tests/shoot.mjs" "$url" "$out/$backend" "$backend" --fps 10 > /dev/null
  node -e '
const r = JSON.parse(require("fs").readFileSync(process.argv[1]));
if (r.data.nelfError) { console.error("page error: " + r.data.nelfError); process.exit(1); }
require("fs").writeFileSync(process.argv[2], r.data.nelfCamera);
console.log(`${process.argv[3]} (${r.data.nelfGpu}): first frame ${r.data.nelfFirstFrameMs} ms after the module started ` +
  `(page load to 3 frames: ${r.wait_ms} ms); ${r.fps.toFixed(2)} fps over 10 s (smoothed frame interval ${r.frame_ms} ms); view ${r.data.nelfMarch} px`);
' "$out/$backend/report.json" "$out/camera_$backend.json" "$backend"
  "$nelf" render "$asset" --camera "$out/camera_$backend.json" --envmap "$env" -o "$out/reference_$backend.png" > "$out/render_$backend.txt"
  echo "  page vs nelf render: $(node "$root/web/tests/psnr.mjs" "$out/$backend/view.png" "$out/reference_$backend.png")"
done
