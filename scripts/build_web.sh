#!/usr/bin/env bash
# Builds the web viewer (crate nelf-web, wasm32) into a folder, web/dist by default:
# nelf_web_bg.wasm + nelf_web.js (wasm-bindgen --target web) + index.html.
# `nelf export web` embeds web/dist; tests/web.rs rebuilds it with this script and fails
# if the committed files differ, so commit web/dist after changing the viewer.
#
# Needs: rustup target wasm32-unknown-unknown, wasm-bindgen-cli at the version
# Cargo.lock pins, clang (the C zstd builds for wasm32 with it). .ci/run installs them.
# Paths are remapped so the bytes do not depend on where the clone or cargo home lives.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
out="${1:-$root/web/dist}"
cd "$root"
cargo_home="${CARGO_HOME:-$HOME/.cargo}"
lock_version="$(grep -A1 '^name = "wasm-bindgen"$' Cargo.lock | sed -n 's/^version = "\(.*\)"/\1/p')"
have_version="$(wasm-bindgen --version 2>/dev/null | awk '{print $2}')" || true
if [ "$have_version" != "$lock_version" ]; then
  echo "build_web: wasm-bindgen $lock_version is needed (found: ${have_version:-none});" \
    "run: cargo install wasm-bindgen-cli --version =$lock_version" >&2
  exit 1
fi
remap="--remap-path-prefix=$root=/nelf --remap-path-prefix=$cargo_home=/cargo"
if [ -n "${CARGO_TARGET_DIR:-}" ]; then
  remap="$remap --remap-path-prefix=$(cd "$CARGO_TARGET_DIR" 2>/dev/null && pwd || echo "$CARGO_TARGET_DIR")=/nelf/target"
fi
export CARGO_TARGET_WASM32_UNKNOWN_UNKNOWN_RUSTFLAGS="$remap"
export CC_wasm32_unknown_unknown="${CC_wasm32_unknown_unknown:-clang}"
cargo build --release --locked --target wasm32-unknown-unknown -p nelf-web
mkdir -p "$out"
wasm-bindgen --target web --no-typescript --remove-name-section --out-dir "$out" \
  "${CARGO_TARGET_DIR:-$root/target}/wasm32-unknown-unknown/release/nelf_web.wasm"
cp web/index.html "$out/index.html"
ls -l "$out"
