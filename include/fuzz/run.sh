#!/usr/bin/env bash
# Builds the libFuzzer target of the C reader (include/fuzz/fuzz_nelf.c) with clang,
# AddressSanitizer and UBSan, and runs it.
#
#   include/fuzz/run.sh [SECONDS] [LIBFUZZER ARGS...]     # default 60 seconds
#
# Work folder: target/c-fuzz/ (corpus/ grows from run to run, crashes go to
# artifacts/). The seed corpus (seeds/) is written once by the C reader's Rust test
# (`cargo test -p nelf-format --release --test c_reader`), which makes small valid
# files of every encoding and codec path. Needs clang with libFuzzer (Debian: clang)
# and the Debian packages libzstd-dev libxxhash-dev.
#
# Single allocations above 32 MiB count as crashes (-malloc_limit_mb): the reader
# never allocates more than 4 MiB at once (one decoded chunk) plus what the input's
# own length bounds.
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
seconds="${1:-60}"
[ "$#" -gt 0 ] && shift
work="$root/target/c-fuzz"
mkdir -p "$work/corpus" "$work/artifacts"
cc="${FUZZ_CC:-clang}"

"$cc" -std=c99 -g -O1 -Wall -Wextra -Werror \
  -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=all \
  -I "$root/include" "$root/include/fuzz/fuzz_nelf.c" -o "$work/fuzz_nelf" -lzstd -lxxhash -lm

seeds="$work/seeds"
if [ ! -d "$seeds" ] || [ -z "$(ls -A "$seeds")" ]; then
  echo "run.sh: writing the seed corpus to $seeds"
  (cd "$root" && NELF_C_FUZZ_SEEDS="$seeds" cargo test -p nelf-format --release --test c_reader \
    -- fuzz_seeds_are_read_by_the_c_reader)
fi

exec "$work/fuzz_nelf" "$work/corpus" "$seeds" \
  -max_total_time="$seconds" -artifact_prefix="$work/artifacts/" \
  -malloc_limit_mb=32 -rss_limit_mb=2048 -print_final_stats=1 "$@"
