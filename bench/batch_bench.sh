#!/usr/bin/env bash
# Batch benchmark (issue 9, item 6): frames/s of the same batch (2 studio takes x 12 frames,
# 4 witnesses at 320x180, voxel 0.02 m, 8 shards) on the local backend with 1, 2 and 4 jobs and
# on Slurm (a single-node loopback cluster, tests/batch/slurm_cluster.sh; skipped with a line
# saying so when Slurm is absent). One JSON line per case on stdout:
#   {"stage":"batch", "size", "backend", "jobs", "frames", "shards", "ms", "fps", "carve_ms_sum",
#    "slots", "overhead_ms_per_shard", "wrapper_ms_per_shard", "first_start_ms"}
# overhead_ms_per_shard = (ms x slots - carve_ms_sum) / shards: slot time per shard not spent in
# carve (scheduling, process start, checksums, idle tail); wrapper_ms_per_shard = the task's own
# time outside carve (input checksums + ledger); first_start_ms = submit to the first task start.
#   batch_bench.sh PREVIZ_BIN [TMPDIR]
set -uo pipefail
bin="$1"; tmp="${2:-/tmp/previz_batch_bench.$$}"
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
source "$here/../tests/batch/slurm_cluster.sh"
rm -rf "$tmp"; mkdir -p "$tmp"
frames=12
# Two takes of one rig (the studio's rig follows the seed): b adds sensor noise.
"$bin" synth --preset studio --out "$tmp/take_a" --frames $frames --cams 4 --size 320x180 --seed 1 \
  --no-meshes --quiet >/dev/null 2>&1 || { echo "synth failed" >&2; exit 1; }
"$bin" synth --preset studio --out "$tmp/take_b" --frames $frames --cams 4 --size 320x180 --seed 1 \
  --noise 2 --no-meshes --quiet >/dev/null 2>&1 || { echo "synth failed" >&2; exit 1; }
plan=(--takes "$tmp/take_a" "$tmp/take_b" --rig "$tmp/take_a/truth/rig.json" --quality preview --shards-per-take 4)
size="2 takes x $frames frames, 4 witnesses 320x180, voxel 0.02 m, 8 shards"
now_ms() { date +%s%3N; }

# Sums over the shards' state files: stage_ms, total_ms - stage_ms, earliest started_unix_ms.
field() { sed -n "s/.*\"$1\": *\([0-9.e+-]*\).*/\1/p" "$2" | head -n 1; }
report() {  # backend jobs slots job_dir wall_ms submit_unix_ms
  local backend="$1" jobs="$2" slots="$3" job="$4" ms="$5" t0="$6" rows="" f
  for f in "$job"/state/*.json; do
    rows+="$(field stage_ms "$f") $(field total_ms "$f") $(field started_unix_ms "$f")"$'\n'
  done
  awk -v backend="$backend" -v jobs="$jobs" -v slots="$slots" -v ms="$ms" -v t0="$t0" \
      -v frames=$((2 * frames)) -v size="$size" '
    NF == 3 { carve += $1; wrapper += $2 - $1; n++; if (first == 0 || $3 < first) first = $3 }
    END { printf "{\"stage\":\"batch\",\"size\":\"%s\",\"backend\":\"%s\",\"jobs\":%d,\"frames\":%d,\"shards\":%d,\"ms\":%.1f,\"fps\":%.3f,\"carve_ms_sum\":%.1f,\"slots\":%d,\"overhead_ms_per_shard\":%.1f,\"wrapper_ms_per_shard\":%.1f,\"first_start_ms\":%.0f}\n",
            size, backend, jobs, frames, n, ms, frames / (ms / 1000), carve, slots, (ms * slots - carve) / n, wrapper / n, first - t0 }' <<<"$rows"
}

for jobs in 1 2 4; do
  job="$tmp/local_$jobs"
  "$bin" batch plan "${plan[@]}" --out "$job" >/dev/null 2>&1
  t0=$(now_ms)
  "$bin" batch submit "$job" --local --jobs $jobs --quiet >/dev/null 2>&1 || { echo "local $jobs failed" >&2; continue; }
  t1=$(now_ms)
  slots=$(( jobs < 8 ? jobs : 8 ))
  report local $jobs $slots "$job" $((t1 - t0)) $t0
done

if slurm_cluster_available && [ "$(id -u)" = 0 ]; then
  if slurm_cluster_start "$tmp/cluster"; then
    job="$tmp/slurm"
    "$bin" batch plan "${plan[@]}" --out "$job" >/dev/null 2>&1
    t0=$(now_ms)
    "$bin" batch submit "$job" --slurm --wait --poll 0.2 --quiet >/dev/null 2>&1 || echo "slurm run failed" >&2
    t1=$(now_ms)
    report slurm "$slurm_cluster_cpus" "$slurm_cluster_cpus" "$job" $((t1 - t0)) $t0
    slurm_cluster_stop
  else
    echo "batch_bench: the loopback Slurm cluster did not start" >&2
  fi
else
  echo "batch_bench: Slurm case skipped (${slurm_cluster_missing:-not root}: apt-get install slurm-wlm munge)" >&2
fi
rm -rf "$tmp"
