#!/usr/bin/env bash
# kill -9 at random moments (issue 35): `previz carve`, `previz batch submit` (local pool) and
# `previz run --out` are each started on a tiny synthetic take and killed with SIGKILL (the
# whole process group: a batch's tasks die with it, as in a power cut) after a random delay
# within the uninterrupted run's duration, N times per command. After each kill:
#   1. every output file present is whole: previz_output_check reads each one fully (PNG/EXR
#      decoded, JSON parsed, PLY/PCD/OBJ read); temporaries of interrupted atomic writes are
#      counted apart (no reader takes them for an output);
#   2. the same command is run again (carve and batch resume from what is finished; run redoes
#      every frame) and its outputs are compared with the uninterrupted run's, byte for byte.
#      Files that carry timings are compared with those fields taken out: every key "ms",
#      "*_ms", "elapsed_s", "wall_s" (report/*.json, carve.jsonl, run.jsonl, props.jsonl).
#      For batch the data (JOB/work/) is compared; its bookkeeping (ledger, logs, state,
#      submissions, manifest: job paths, times, checksums of the reports) is not, and
#      `batch status` must say every shard done.
# Prints one line per kill and a JSON summary; exit 1 when an output was incomplete or a resume
# differed.
#
#   bash scripts/killtest.sh [--points 20] [--commands "carve batch run"] [--seed 1]
#        [--previz build/app/previz] [--check build/tests/cli/previz_output_check] [--work out/killtest]
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
previz="$here/build/app/previz"
check="$here/build/tests/cli/previz_output_check"
work="$here/out/killtest"
points=20
commands="carve batch run"
seed=1
while (($#)); do
  case "$1" in
    --previz) previz="$(realpath "$2")"; shift 2 ;;
    --check) check="$(realpath "$2")"; shift 2 ;;
    --work) work="$2"; shift 2 ;;
    --points) points="$2"; shift 2 ;;
    --commands) commands="$2"; shift 2 ;;
    --seed) seed="$2"; shift 2 ;;
    *) echo "killtest: unknown option $1" >&2; exit 2 ;;
  esac
done
[ -x "$previz" ] || { echo "killtest: no previz at $previz" >&2; exit 2; }
[ -x "$check" ] || { echo "killtest: no previz_output_check at $check" >&2; exit 2; }
rm -rf "$work"
mkdir -p "$work"
work="$(realpath "$work")"
take="$work/take"
RANDOM=$seed

"$previz" synth --preset studio --out "$take" --frames 6 --cams 4 --size 160x96 --main-size 240x136 \
  --no-meshes --noise 2 --quiet > /dev/null 2>&1

# The command for one output folder (batch: the job folder, planned first; the plan is not
# what is killed).
prepare() {
  local cmd=$1 out=$2
  if [ "$cmd" = batch ]; then
    "$previz" batch plan --takes "$take" --rig "$take/truth/rig.json" --frames-per-shard 2 --depth-cameras main \
      --out "$out" > /dev/null 2>&1
  fi
}
command_line() {
  local cmd=$1 out=$2
  case "$cmd" in
    carve) echo "$previz carve --take $take --rig $take/truth/rig.json --main-poses $take/truth/main_poses.jsonl --out $out --quiet" ;;
    batch) echo "$previz batch submit $out --jobs 2 --quiet" ;;
    run) echo "$previz run --take $take --out $out --quiet" ;;
  esac
}
data_dir() {  # what is compared
  local cmd=$1 out=$2
  if [ "$cmd" = batch ]; then echo "$out/work"; else echo "$out"; fi
}
checked() {  # what must be whole after a kill: every output, and batch's bookkeeping (not the
  # logs/ it captures the stage commands' stdout and stderr into as they come)
  local cmd=$1 out=$2
  if [ "$cmd" = batch ]; then
    echo "$out/work $out/ledger $out/state $out/manifest.json $out/submissions.jsonl"
  else
    echo "$out"
  fi
}

# Compares two output trees: same files (temporaries aside), same bytes, or for JSON with
# timings the same values once the timings are out. Prints "identical" or the differences.
compare() {
  python3 - "$1" "$2" <<'PY'
import json, os, sys
a, b = sys.argv[1], sys.argv[2]
def temp(name): return name.startswith('.') and ('.tmp.' in name or '.pcl.' in name)
def files(root):
    out = set()
    for d, _, fs in os.walk(root):
        for f in fs:
            if not temp(f): out.add(os.path.relpath(os.path.join(d, f), root))
    return out
TIMING = ('ms', 'elapsed_s', 'wall_s')
def strip(v):
    if isinstance(v, dict):
        return {k: strip(x) for k, x in v.items() if not (k in TIMING or k.endswith('_ms'))}
    if isinstance(v, list): return [strip(x) for x in v]
    return v
def same_json(pa, pb, lines):
    ta, tb = open(pa).read(), open(pb).read()
    if lines:
        la = [strip(json.loads(l)) for l in ta.splitlines() if l.strip()]
        lb = [strip(json.loads(l)) for l in tb.splitlines() if l.strip()]
        return la == lb
    return strip(json.loads(ta)) == strip(json.loads(tb))
fa, fb = files(a), files(b)
diff = ['only in the uninterrupted run: ' + f for f in sorted(fa - fb)] + ['only in the resumed run: ' + f for f in sorted(fb - fa)]
normalised = 0
for f in sorted(fa & fb):
    pa, pb = os.path.join(a, f), os.path.join(b, f)
    if open(pa, 'rb').read() == open(pb, 'rb').read(): continue
    if f.endswith('.json') or f.endswith('.jsonl'):
        try:
            if same_json(pa, pb, f.endswith('.jsonl')):
                normalised += 1
                continue
        except Exception as e:
            diff.append(f + ': ' + str(e)); continue
    diff.append('differs: ' + f)
print('identical' if not diff else '; '.join(diff[:8]) + (' ...' if len(diff) > 8 else ''), normalised)
PY
}

total_incomplete=0
total_differ=0
summary="{"
first=1
for cmd in $commands; do
  ref="$work/ref_$cmd"
  prepare "$cmd" "$ref"
  $(command_line "$cmd" "$ref") > /dev/null 2>&1 || { echo "killtest: the uninterrupted $cmd failed" >&2; exit 1; }
  # The checker must see damage: every file of a copy of the reference cut by 7 bytes.
  damaged="$work/damaged_$cmd"
  rm -rf "$damaged"
  cp -r "$(data_dir "$cmd" "$ref")" "$damaged"
  find "$damaged" -type f | while read -r f; do truncate -s $(($(stat -c %s "$f") - 7)) "$f"; done
  d=$({ "$check" "$damaged" 2> /dev/null || true; } | python3 -c 'import json,sys; j=json.load(sys.stdin); print(j["files"] - len(j["incomplete"]))')
  [ "$d" -eq 0 ] || { echo "killtest: previz_output_check took $d damaged $cmd outputs for whole" >&2; exit 1; }
  rm -rf "$damaged"
  # The kills fall within a warm run's duration (the first run also pays for the page cache):
  # the shorter of two.
  ref_ms=0
  for w in 1 2; do
    warm="$work/warm_$cmd"
    prepare "$cmd" "$warm"
    t0=$(date +%s%N)
    $(command_line "$cmd" "$warm") > /dev/null 2>&1 || { echo "killtest: the uninterrupted $cmd failed" >&2; exit 1; }
    t=$(( ($(date +%s%N) - t0) / 1000000 ))
    { [ $ref_ms -eq 0 ] || [ $t -lt $ref_ms ]; } && ref_ms=$t
    rm -rf "$warm"
  done
  echo "killtest: $cmd uninterrupted: ${ref_ms} ms; previz_output_check finds every damaged output" >&2
  killed=0 finished=0 incomplete=0 differ=0 temporaries=0 left_after=0
  for ((i = 1; i <= points; i++)); do
    out="$work/${cmd}_$i"
    prepare "$cmd" "$out"
    delay_ms=$(( (RANDOM * 32768 + RANDOM) % (ref_ms > 0 ? ref_ms : 1) ))
    # A process group of its own: the kill takes the command and every child (batch tasks).
    setsid $(command_line "$cmd" "$out") > "$work/${cmd}_$i.log" 2>&1 &
    pid=$!
    sleep "$(printf '%d.%03d' $((delay_ms / 1000)) $((delay_ms % 1000)))"
    if kill -0 "$pid" 2> /dev/null; then
      kill -9 -- "-$pid" 2> /dev/null || kill -9 "$pid" 2> /dev/null || true
      state=killed
      killed=$((killed + 1))
    else
      state="finished before the kill"
      finished=$((finished + 1))
    fi
    wait "$pid" 2> /dev/null || true
    # The group's other members (batch tasks) die with it; wait until none is left.
    for _ in $(seq 100); do kill -0 -- "-$pid" 2> /dev/null || break; sleep 0.05; done
    c=$("$check" $(checked "$cmd" "$out")) || true
    n_bad=$(python3 -c 'import json,sys; print(len(json.loads(sys.argv[1])["incomplete"]))' "$c")
    n_tmp=$(python3 -c 'import json,sys; print(len(json.loads(sys.argv[1])["temporaries"]))' "$c")
    n_files=$(python3 -c 'import json,sys; print(json.loads(sys.argv[1])["files"])' "$c")
    incomplete=$((incomplete + n_bad))
    temporaries=$((temporaries + n_tmp))
    [ "$n_bad" -eq 0 ] || echo "killtest: $cmd #$i: INCOMPLETE: $c" >&2
    # Resume: the same command again, to the end.
    if ! $(command_line "$cmd" "$out") >> "$work/${cmd}_$i.log" 2>&1; then
      echo "killtest: $cmd #$i: the re-run failed (log $work/${cmd}_$i.log)" >&2
      differ=$((differ + 1))
      continue
    fi
    if [ "$cmd" = batch ]; then
      "$previz" batch status "$out" --json > "$work/${cmd}_$i.status.json" 2> /dev/null || true
      python3 -c 'import json,sys; j=json.load(open(sys.argv[1])); sys.exit(0 if all(s["state"]=="done" for s in j["shards"]) else 1)' \
        "$work/${cmd}_$i.status.json" || { echo "killtest: batch #$i: not every shard done after resume" >&2; differ=$((differ + 1)); }
    fi
    r=$(compare "$(data_dir "$cmd" "$ref")" "$(data_dir "$cmd" "$out")")
    left=$({ "$check" $(checked "$cmd" "$out") || true; } | python3 -c 'import json,sys; print(len(json.load(sys.stdin)["temporaries"]))')
    left_after=$((left_after + left))
    verdict=${r% *}
    [ "$verdict" = identical ] || differ=$((differ + 1))
    echo "killtest: $cmd #$i at ${delay_ms} ms: $state; $n_files outputs present, $n_bad incomplete, $n_tmp temporaries; resumed: $verdict (${r##* } files equal without timings); temporaries left after: $left" >&2
  done
  total_incomplete=$((total_incomplete + incomplete))
  total_differ=$((total_differ + differ))
  [ $first -eq 1 ] || summary+=","
  first=0
  summary+="\"$cmd\": {\"points\": $points, \"killed\": $killed, \"finished_before_kill\": $finished, \"uninterrupted_ms\": $ref_ms, \"incomplete_files\": $incomplete, \"temporaries_after_kill\": $temporaries, \"temporaries_after_resume\": $left_after, \"resumes_differing\": $differ}"
done
summary+=", \"ok\": $([ $total_incomplete -eq 0 ] && [ $total_differ -eq 0 ] && echo true || echo false)}"
echo "$summary"
[ $total_incomplete -eq 0 ] && [ $total_differ -eq 0 ]
