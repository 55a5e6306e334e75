#!/usr/bin/env bash
# Measures `nelf batch` (docs/measurements/2026-12-06-batch.md):
#   1. 16 bakes of 128² captures (14 procedural heads, the repository's head scan
#      from two sides) as a plain loop, `nelf batch local -j 2`, and a job array on a
#      one-node Slurm cluster (scripts/slurm_cluster.sh): wall time and overhead per
#      item (the engine's: wall minus the longest chain of commands; ours: each
#      record's item_secs minus its command's secs);
#   2. `nelf train data` for 32 heads in one process and through 4 shards: same files;
#   3. plan and collect of a synthetic 100,000-item manifest, and its array split.
#
#   scripts/bench_batch.sh OUT [BAKE OPTIONS...]   (default: --resolution 48 --view-dependence off)
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=$(realpath -m "${1:?usage: scripts/bench_batch.sh OUT [BAKE OPTIONS...]}")
shift
BAKE=("$@")
[ ${#BAKE[@]} -gt 0 ] || BAKE=(--resolution 48 --view-dependence off)
export RUST_BACKTRACE=0
cargo build --release -q
NELF=$PWD/target/release/nelf
mkdir -p "$OUT"
now() { date +%s.%N; }
secs() { echo "$2 - $1" | bc; }

echo "== captures (16 at 128²)"
mkdir -p "$OUT/captures"
for seed in $(seq 0 13); do
  [ -f "$OUT/captures/head$seed/cameras.json" ] || "$NELF" capture synth -o "$OUT/captures/head$seed" \
      --head-seed "$seed" --width 128 --height 128 --targets 2 >/dev/null
done
for turn in 90 60; do
  [ -f "$OUT/captures/scan$turn/cameras.json" ] || "$NELF" capture synth -o "$OUT/captures/scan$turn" \
      --mesh data/meshes/head.off --mesh-rotate-y-deg "$turn" --width 128 --height 128 --targets 2 >/dev/null
done

plan() { # folder
  rm -rf "$1"
  "$NELF" batch plan bake "$OUT"/captures/* --out "$1" -- "${BAKE[@]}" >/dev/null
}

echo "== plain loop"
plan "$OUT/loop"
start=$(now)
"$NELF" batch commands --direct "$OUT/loop/plan.jsonl" | while read -r line; do
  dir=$(echo "$line" | sed -E "s/.*--out '?([^' ]*)\/asset.nelf.*/\1/")
  mkdir -p "$dir"
  t=$(now); sh -c "$line" >/dev/null 2>&1; echo "$(secs "$t" "$(now)")" >>"$OUT/loop/secs.txt"
done
loop_wall=$(secs "$start" "$(now)")
loop_cmd=$(paste -sd+ "$OUT/loop/secs.txt" | bc)
echo "loop: $loop_wall s wall, $loop_cmd s of commands"

summary() { # plan wall label jobs
  python3 - "$1" "$2" "$3" "$4" <<'PY'
import json, sys, glob, os
plan, wall, label, jobs = sys.argv[1], float(sys.argv[2]), sys.argv[3], int(sys.argv[4])
recs = [json.load(open(p)) for p in glob.glob(os.path.splitext(plan)[0] + ".results/*.json")]
cmd = sum(r["secs"] for r in recs); item = sum(r["item_secs"] for r in recs)
ours = (item - cmd) / len(recs)
engine = (wall * jobs - item) / len(recs)
print(f"{label}: {len(recs)} items, {wall:.1f} s wall, {cmd:.1f} s of commands, "
      f"ours {ours*1000:.0f} ms/item, the engine's {engine:.2f} s/item (wall × {jobs} slots − item time, per item), "
      f"mean command {cmd/len(recs):.2f} s")
PY
}

echo "== nelf batch local -j 2"
plan "$OUT/local"
start=$(now)
"$NELF" batch local "$OUT/local/plan.jsonl" -j 2 --quiet
summary "$OUT/local/plan.jsonl" "$(secs "$start" "$(now)")" "local -j 2" 2

echo "== one-node Slurm cluster (2 CPUs, 1 per task)"
CLUSTER=$(mktemp -d)
trap 'scripts/slurm_cluster.sh stop "$CLUSTER" >/dev/null 2>&1 || true' EXIT
scripts/slurm_cluster.sh start "$CLUSTER" >/dev/null
export SLURM_CONF=$CLUSTER/etc/slurm.conf
plan "$OUT/slurm"
start=$(now)
"$NELF" batch slurm "$OUT/slurm/plan.jsonl" --cpus 1 --mem 2G --submit --wait >/dev/null
summary "$OUT/slurm/plan.jsonl" "$(secs "$start" "$(now)")" "slurm array" 2
"$NELF" batch status "$OUT/slurm/plan.jsonl" | tail -1
for id in $(cd "$OUT/local" && ls -d */ | tr -d /); do
  [ "$id" = plan.results ] && continue
  cmp -s "$OUT/local/$id/asset.nelf" "$OUT/loop/$id/asset.nelf" || echo "local $id differs from the loop"
  cmp -s "$OUT/slurm/$id/asset.nelf" "$OUT/loop/$id/asset.nelf" || echo "slurm $id differs from the loop"
done
echo "assets compared (local, slurm vs loop): differences listed above, if any"

echo "== nelf train data, 32 heads at 64²"
rm -rf "$OUT/data" "$OUT/data_single" "$OUT"/data_plan.*
t=$(now); "$NELF" train data --out "$OUT/data" --heads 28 --val-heads 4 --size 64 --quiet
echo "single process: $(secs "$t" "$(now)") s"
mv "$OUT/data" "$OUT/data_single"
"$NELF" batch plan train-data --out "$OUT/data" --heads 28 --val-heads 4 --shard 8 --plan "$OUT/data_plan.jsonl" -- --size 64 >/dev/null
t=$(now); "$NELF" batch slurm "$OUT/data_plan.jsonl" --cpus 1 --mem 2G --submit --wait | tail -1
echo "4 shards on the cluster: $(secs "$t" "$(now)") s"
(cd "$OUT/data_single" && find . -type f | sort) | while read -r f; do
  cmp -s "$OUT/data_single/$f" "$OUT/data/$f" || echo "differs: $f"
done | sort | uniq -c | sed 's/^/  /' >"$OUT/data_diff.txt"
echo "files that differ (head.json holds the render seconds): $(wc -l <"$OUT/data_diff.txt")"; grep -v "head.json" "$OUT/data_diff.txt" || true
echo "  of $(cd "$OUT/data_single" && find . -type f | wc -l) files"

echo "== 100,000 items"
B=$OUT/big; rm -rf "$B"; mkdir -p "$B"
seq -f "/shared/captures/person%06g" 0 99999 >"$B/list.csv"
t=$(now); "$NELF" batch plan bake --list "$B/list.csv" --out "$B/out" --chunk 100 --plan "$B/plan.jsonl"
echo "plan: $(secs "$t" "$(now)") s, $(stat -c %s "$B/plan.jsonl") bytes"
python3 - "$B" <<'PY'
import json, sys, os
b = sys.argv[1]; d = os.path.join(b, "plan.results"); os.makedirs(d, exist_ok=True)
lines = open(os.path.join(b, "plan.jsonl")).read().splitlines()[1:]
for i, line in enumerate(lines):
    item = json.loads(line)
    os.makedirs(item["output"], exist_ok=True)
    rec = {"id": item["id"], "kind": "bake", "hash": item["hash"], "status": "done" if i % 1000 else "failed",
           "secs": 40.0, "item_secs": 40.1, "host": "node%02d" % (i % 16), "pid": 1000 + i, "finished_unix": 0,
           "exit_code": 0 if i % 1000 else 1, "error": "" if i % 1000 else "Error: capture: cameras.json: missing",
           "output": item["output"], "outputs": [], "figures": {"file_size": 1000000 + i, "rank": 16}}
    open(os.path.join(d, item["id"] + ".json"), "w").write(json.dumps(rec))
PY
t=$(now); "$NELF" batch status "$B/plan.jsonl" | sed -n 1p; echo "status: $(secs "$t" "$(now)") s"
t=$(now); "$NELF" batch collect "$B/plan.jsonl"; echo "collect: $(secs "$t" "$(now)") s"
"$NELF" batch slurm "$B/plan.jsonl" --cpus 2 --mem 8G --minutes-per-item 2 --max-parallel 64 >/dev/null
grep -E "^#SBATCH --(array|time)" "$B/plan.sbatch"
