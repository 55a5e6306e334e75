#!/usr/bin/env bash
# Portability: type-checks the whole workspace (every crate, tests and examples)
# for targets other than the host, so a dependency placed under a platform-only
# table, or code that only builds on glibc, fails here instead of on a user's machine.
#
#   ./scripts/check_targets.sh [TARGET...]    # default: the targets CI checks
#
# `cargo check` runs the -sys crates' build scripts, which compile C and C++ (zstd,
# ꟻLIP) with the target's cross compiler: Debian's mingw-w64 for Windows and
# gcc-aarch64-linux-gnu for 64-bit Arm. `./scripts/test` installs them (it is the
# one list of system packages) and calls this script after the tests.
set -euo pipefail
cd "$(dirname "$0")/.."

targets=("$@")
if [ "${#targets[@]}" -eq 0 ]; then
  targets=(x86_64-pc-windows-gnu aarch64-unknown-linux-gnu)
fi

for target in "${targets[@]}"; do
  if command -v rustup >/dev/null 2>&1 && ! rustup target list --installed | grep -qx "$target"; then
    echo "check_targets: installing the $target standard library"
    rustup target add "$target"
  fi
  case "$target" in
    x86_64-pc-windows-gnu) cross_cc=x86_64-w64-mingw32-gcc ;;
    aarch64-unknown-linux-gnu) cross_cc=aarch64-linux-gnu-gcc ;;
    *) cross_cc="" ;;
  esac
  if [ -n "$cross_cc" ] && ! command -v "$cross_cc" >/dev/null 2>&1; then
    echo "check_targets: $target needs the C cross compiler $cross_cc (Debian: ./scripts/test installs it)" >&2
    exit 1
  fi
  echo "check_targets: cargo check --workspace --all-targets --target $target"
  start=$SECONDS
  cargo check --workspace --all-targets --target "$target"
  echo "check_targets: $target checked in $((SECONDS - start)) s"
done
