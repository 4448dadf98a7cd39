#!/usr/bin/env bash
# Issue 9, items 1 and 2: a 2-take, 8-shard batch through a single-node Slurm cluster started
# here on loopback (tests/batch/slurm_cluster.sh) gives collected outputs identical, byte for
# byte, to the local backend's; then two array tasks are cancelled mid-run and one written frame
# is damaged, and `batch resume` redoes only the missing and the damaged frames (mtimes of every
# other frame file unchanged) and the collected outputs are again identical.
#   batch_slurm_test.sh PREVIZ_BIN TMPDIR        exit 77 (skipped) only when Slurm is absent
set -uo pipefail
bin="$1"; tmp="$2"
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
source "$here/../cli/checks.sh"
source "$here/slurm_cluster.sh"
if ! slurm_cluster_available; then
  echo "SKIPPED: '$slurm_cluster_missing' is not installed (Debian: apt-get install slurm-wlm munge); scripts/setup.sh installs them"
  exit 77
fi
rm -rf "$tmp"; mkdir -p "$tmp"

# Two takes of one rig, 4 frames each (1 frame per shard), 4 witnesses at 320x180 (the studio's rig follows the seed,
# so take b keeps seed 1 and differs by its sensor noise).
"$bin" synth --preset studio --out "$tmp/take_a" --frames 4 --cams 4 --size 320x180 --seed 1 \
  --no-meshes --quiet >/dev/null 2>&1 || { fail "synth take_a"; finish; exit 1; }
"$bin" synth --preset studio --out "$tmp/take_b" --frames 4 --cams 4 --size 320x180 --seed 1 --noise 2 \
  --no-meshes --quiet >/dev/null 2>&1 || { fail "synth take_b"; finish; exit 1; }
cmp -s "$tmp/take_a/truth/rig.json" "$tmp/take_b/truth/rig.json" && ok "both takes share one rig" || fail "rigs differ"
# With --props every shard also runs the track stage (at 320x180 no tag decodes: the crate is
# "lost" in every frame file, which still exercises the stage's commands, ledger and resume).
plan=(--takes "$tmp/take_a" "$tmp/take_b" --rig "$tmp/take_a/truth/rig.json" --props "$tmp/take_a/props.json"
      --quality preview --shards-per-take 4)

# The local backend's result.
"$bin" batch plan "${plan[@]}" --out "$tmp/local" >/dev/null 2>&1 || fail "plan local"
"$bin" batch submit "$tmp/local" --local --jobs 1 --quiet >/dev/null 2>&1 && ok "local backend ran 8 shards (1 job, OpenMP on every core; Slurm tasks get 1 core each)" || fail "local submit"
"$bin" batch collect "$tmp/local" --y-up --out "$tmp/local_out" >/dev/null 2>&1 && ok "local collect" || fail "local collect"

slurm_cluster_start "$tmp/cluster" || { fail "start the Slurm cluster"; finish; exit 1; }
ok "Slurm cluster up (SlurmctldHost=localhost(127.0.0.1), node localhost, $slurm_cluster_cpus CPUs)"

# Item 1: the same batch through --slurm.
"$bin" batch plan "${plan[@]}" --out "$tmp/slurm" >/dev/null 2>&1 || fail "plan slurm"
json=$("$bin" batch submit "$tmp/slurm" --slurm --wait --poll 1 --json 2>"$tmp/slurm_submit.log")
rc=$?
grep -q '"shards":\[0,1,2,3,4,5,6,7\]' <<<"$json" && ok "one sbatch --array job of 8 tasks" || fail "slurm submit: $json $(tail -5 "$tmp/slurm_submit.log")"
[ $rc = 0 ] && ok "every Slurm task finished its shard" || fail "slurm shards unfinished (rc $rc): $(tail -5 "$tmp/slurm_submit.log")"
job=$(sed -n 's/.*"job_id":"\([0-9]*\)".*/\1/p' <<<"$json")
[ "$(ls "$tmp/slurm/slurm/logs/${job}"_*.out 2>/dev/null | wc -l)" = 8 ] && ok "8 array task logs" || fail "array task logs"
grep -q '"slurm_job_id"' "$tmp/slurm/state/5.json" && ok "task state names its Slurm job" || fail "state without slurm job id"
status=$("$bin" batch status "$tmp/slurm" --json 2>/dev/null)
grep -q '"done":8' <<<"$status" && ok "status: 8 shards done" || fail "status: $status"
grep -q '"scheduler":"COMPLETED"' <<<"$status" && ok "status reads Slurm's states (COMPLETED)" || fail "status without Slurm states: $status"
"$bin" batch collect "$tmp/slurm" --y-up --out "$tmp/slurm_out" >/dev/null 2>&1 && ok "slurm collect" || fail "slurm collect"
if diff -r "$tmp/local_out" "$tmp/slurm_out" >"$tmp/diff1.txt"; then
  ok "collected outputs identical byte for byte, local vs slurm ($(find "$tmp/slurm_out" -type f | wc -l) files)"
else fail "local and slurm differ: $(head -c 600 "$tmp/diff1.txt")"; fi

# Item 2: cancel two array tasks mid-run, damage one written frame, resume.
"$bin" batch plan "${plan[@]}" --out "$tmp/fault" >/dev/null 2>&1 || fail "plan fault"
json=$("$bin" batch submit "$tmp/fault" --slurm --max-running 2 --json 2>/dev/null)
fjob=$(sed -n 's/.*"job_id":"\([0-9]*\)".*/\1/p' <<<"$json")
# Wait until tasks 2 and 3 run (the first two shards have finished by then), then cancel them.
cancelled=""
for _ in $(seq 1 600); do
  running=$(squeue -h -r -j "$fjob" -t RUNNING -o '%i' | sed 's/.*_//' | sort -n | tr '\n' ' ')
  n=$(wc -w <<<"$running")
  if [ "$n" = 2 ] && [ "$(awk '{print $1}' <<<"$running")" -ge 2 ]; then cancelled="$running"; break; fi
  sleep 0.1
done
if [ -n "$cancelled" ]; then
  for t in $cancelled; do scancel "${fjob}_$t"; done
  ok "cancelled running array tasks $cancelled"
else fail "never saw two tasks running"; fi
for _ in $(seq 1 600); do [ -z "$(squeue -h -j "$fjob" -t PENDING,RUNNING,COMPLETING -o '%i')" ] && break; sleep 0.5; done
status=$("$bin" batch status "$tmp/fault" --json 2>/dev/null)
grep -q '"scheduler":"CANCELLED"' <<<"$status" && ok "status shows the cancelled tasks" || fail "status: $status"
grep -q '"done":6' <<<"$status" && ok "status: 6 shards done, 2 not" || fail "status counts: $status"

# Damage one frame of a finished shard: one byte of take_a frame 0's OBJ (same size).
obj="$tmp/fault/work/take_a/carve/mesh/000000.obj"
size=$(stat -c %s "$obj")
orig=$(dd if="$obj" bs=1 skip=$((size / 2)) count=1 status=none)
[ "$orig" = 7 ] && new=8 || new=7
printf '%s' "$new" | dd of="$obj" bs=1 seek=$((size / 2)) conv=notrunc status=none
"$bin" batch status "$tmp/fault" --json 2>/dev/null | grep -q '"state":"corrupt"' && ok "status finds the damaged frame" || fail "damage not seen"

# Which frames were missing before the resume (not in any ledger).
find "$tmp/fault/work" \( -path '*/carve/*/*' -o -path '*/track/*/*' \) -type f -printf '%P %T@\n' | sort >"$tmp/before.txt"
missing_before=$("$bin" batch status "$tmp/fault" --json 2>/dev/null | grep -o '"missing":\[[0-9,]*\]' | grep -v '\[\]' | wc -l)
json=$("$bin" batch resume "$tmp/fault" --wait --poll 1 --json 2>"$tmp/resume.log")
rc=$?
[ $rc = 0 ] && ok "resume finished the batch" || fail "resume rc $rc: $(tail -5 "$tmp/resume.log")"
expect="[0,$(tr ' ' ',' <<<"$cancelled" | sed 's/,$//')]"
grep -qF "\"shards\":$expect" <<<"$json" && ok "resume submitted only shards $expect (damaged + cancelled)" || fail "resume shards: $json (expected $expect)"
grep -q '"backend":"slurm"' <<<"$json" && ok "resume used Slurm again" || fail "resume backend: $json"
grep -q 'frame 0 redone' "$tmp/fault/slurm/logs/"*_0.out && ok "task log names the redone frame" || fail "no redo line in shard 0's log"
find "$tmp/fault/work" \( -path '*/carve/*/*' -o -path '*/track/*/*' \) -type f -printf '%P %T@\n' | sort >"$tmp/after.txt"
# Every file that existed before is unchanged unless it is take_a frame 0's or belongs to a
# cancelled shard's frame that was unfinished (those appear or are rewritten).
# Shard t of the plan (4 per take of 4 frames, round robin): take_a for t < 4, frame t % 4.
cancel_frames=""
for t in $cancelled; do
  take=$([ "$t" -lt 4 ] && echo take_a || echo take_b)
  cancel_frames+=" $take/$(printf %06d $((t % 4)))"
done
bad=0; redone=0
while read -r path t; do
  newt=$(awk -v p="$path" '$1 == p {print $2}' "$tmp/after.txt")
  # (a cancelled task may leave an atomic write's hidden temp file, .000002.exr.tmp.*: its frame's)
  frame=$(sed -E 's/.*\/\.?([0-9]{6})\..*/\1/' <<<"$path"); take=${path%%/*}
  if [ "$take/$frame" = "take_a/000000" ]; then
    [ "$newt" != "$t" ] && redone=$((redone + 1))
  elif [[ " $cancel_frames " == *" $take/$frame "* ]]; then :
  elif [ "$newt" != "$t" ]; then bad=$((bad + 1)); echo "rewritten: $path"; fi
done <"$tmp/before.txt"
[ $bad = 0 ] && ok "no finished frame's file was rewritten" || fail "$bad finished files rewritten"
[ $redone = 16 ] && ok "the damaged frame's 16 files (15 carve: depth of main + 4 witnesses, mesh, points, report; 1 track) were redone" || fail "damaged frame: $redone of 16 files redone"
"$bin" batch collect "$tmp/fault" --y-up --out "$tmp/fault_out" >/dev/null 2>&1 && ok "fault collect" || fail "fault collect"
if diff -r "$tmp/slurm_out" "$tmp/fault_out" >"$tmp/diff2.txt"; then
  ok "after cancel + damage + resume, collected outputs identical to item 1's"
else fail "fault run differs: $(head -c 600 "$tmp/diff2.txt")"; fi

slurm_cluster_stop
ok "daemons stopped"
finish
