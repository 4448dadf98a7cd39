#!/usr/bin/env bash
# `previz run`, `previz composite` and `previz bench run` as a user meets them: the documented
# files (docs/formats.md, "Run output" and "Composite output"), the same composite from both
# commands, the JSON summaries, and clear failures that name the culprit.
#   run_cli_test.sh PREVIZ_BIN TMPDIR
set -uo pipefail
bin="$1"; tmp="$2"
rm -rf "$tmp"; mkdir -p "$tmp"
source "$(dirname "${BASH_SOURCE[0]}")/../cli/checks.sh"

# A small studio take: 4 witnesses at 320x180, main 480x270, 3 frames.
if ! "$bin" synth --preset studio --out "$tmp/take" --frames 3 --cams 4 --size 320x180 --no-meshes --quiet >/dev/null 2>&1; then
  fail "synth studio take"; finish; exit 1
fi
take="$tmp/take"

if "$bin" run --take "$take" --out "$tmp/run" --voxel 0.02 --layers --meshes --video composite.avi --json --quiet \
    > "$tmp/run.json" 2> "$tmp/run.err"; then ok "run exits 0"; else fail "run: $(cat "$tmp/run.err")"; fi
missing=0
for f in 000000 000001 000002; do
  for p in composite/$f.png depth/$f.exr mesh/$f.ply layers/alpha/$f.exr layers/actor_depth/$f.exr \
           layers/cg_depth/$f.exr layers/front/$f.png; do
    [ -s "$tmp/run/$p" ] || { missing=1; echo "missing $p"; }
  done
done
[ $missing -eq 0 ] && ok "run writes composites, depth, meshes and layers" || fail "run outputs missing"
[ -s "$tmp/run/composite.avi" ] && ok "run writes the video" || fail "no video"
[ "$(wc -l < "$tmp/run/poses.jsonl")" -eq 3 ] && ok "poses.jsonl has one line per frame" || fail "poses.jsonl"
if python3 - "$tmp/run.json" "$tmp/run/run.jsonl" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
assert s["command"] == "run" and s["frames"] == [0, 1, 2], s
for k in ("key", "carve", "depth", "props", "composite", "read", "write"):
    assert s["mean_ms"][k] > 0, k
lines = [json.loads(l) for l in open(sys.argv[2])]
assert [l["frame"] for l in lines] == [0, 1, 2]
assert all(l["composite"]["actor_px"] > 100 for l in lines), lines
assert all(l["ms"]["props"] > 0 for l in lines), lines
assert s["stages"] == ["read", "key", "carve", "depth", "props", "composite", "write"], s
PY
then ok "run JSON summary and run.jsonl (props stage timed)"; else fail "run JSON"; fi
[ "$(wc -l < "$tmp/run/props.jsonl")" -eq 3 ] && ok "props.jsonl has one line per frame" || fail "props.jsonl"
if "$bin" run --take "$take" --out "$tmp/run_noprops" --voxel 0.02 --no-props --frames 0 --json --quiet > "$tmp/np.json" 2>/dev/null \
   && [ ! -e "$tmp/run_noprops/props.jsonl" ] && python3 -c "import json,sys; j=json.load(open(sys.argv[1])); assert 'props' not in j['stages'] and j['props'] is None, j" "$tmp/np.json"; then
  ok "--no-props: no props stage, no props.jsonl"; else fail "--no-props"; fi

# Props tracked by run: at 320x180 the tags are too small to decode, so a take whose witnesses
# see them (4 x 1280x720, main 960x540, 2 frames): run's props.jsonl is `previz track`'s format
# and poses (the same PropTracker, the moving main camera set per frame), and the poses meet
# the truth. Measured: 0.11 and 0.29 mm, sigma 0.2 mm, from 5 cameras.
if "$bin" synth --preset studio --out "$tmp/ptake" --frames 2 --cams 4 --size 1280x720 --main-size 960x540 --no-meshes --quiet >/dev/null 2>&1 \
   && "$bin" run --take "$tmp/ptake" --out "$tmp/prun" --voxel 0.04 --quiet 2> "$tmp/prun.err" \
   && "$bin" run --take "$tmp/ptake" --out "$tmp/prun_own" --voxel 0.04 --props-own-pool --quiet 2>> "$tmp/prun.err" \
   && "$bin" track --take "$tmp/ptake" --rig "$tmp/ptake/truth/rig.json" --props "$tmp/ptake/props.json" \
        --main-poses "$tmp/ptake/truth/main_poses.jsonl" --out "$tmp/ptrack" --quiet 2> "$tmp/ptrack.err"; then
  ok "run and track on the props take"; else fail "props take: $(cat "$tmp/prun.err" "$tmp/ptrack.err" 2>/dev/null)"; fi
# The tag searches run among the keys by default; --props-own-pool runs them at the props stage
# in a pool of their own: the same lines.
if python3 - "$tmp/prun/props.jsonl" "$tmp/ptrack/poses.jsonl" "$tmp/ptake/truth/props.jsonl" "$tmp/prun_own/props.jsonl" <<'PY'
import json, math, sys
run = [json.loads(l) for l in open(sys.argv[1])]
track = [json.loads(l) for l in open(sys.argv[2])]
truth = {j["frame"]: {p["id"]: p["T_world_prop"] for p in j["props"]} for j in map(json.loads, open(sys.argv[3]))}
own = [json.loads(l) for l in open(sys.argv[4])]
assert [j["frame"] for j in run] == [0, 1] == [j["frame"] for j in track], (run, track)
def strip(j):  # timings differ run to run
    j = dict(j); j.pop("ms"); return j
assert [strip(j) for j in run] == [strip(j) for j in track], "run's props.jsonl differs from previz track's"
assert [strip(j) for j in own] == [strip(j) for j in run], "run --props-own-pool differs from run"
assert all(j["ms"]["detect"] > 0 and j["ms"]["total"] >= j["ms"]["detect"] for j in run + own), run + own
for j in run:
    for p in j["props"]:
        assert p["state"] == "tracked" and len(p["cameras"]) >= 3, p
        t = truth[j["frame"]][p["id"]]
        d = 1000 * math.dist(p["T_world_prop"]["t"], t["t"])
        R, Rt = p["T_world_prop"]["R"], t["R"]
        tr = sum(R[i][k] * Rt[i][k] for i in range(3) for k in range(3))
        deg = math.degrees(math.acos(max(-1, min(1, (tr - 1) / 2))))
        print(f"  run props: frame {j['frame']} prop {p['id']}: {d:.2f} mm, {deg:.3f} deg from truth")
        assert d <= 2.0 and deg <= 0.5, (d, deg)
PY
then ok "run's prop poses equal previz track's (searches pooled with the keys or not) and meet the truth (<= 2 mm, 0.5 deg)"; else fail "run prop poses"; fi

# previz composite on run's depth: the same key and depth give the same composites, bit for bit.
# previz composite keys every main frame whole, so run does too here (--key-main-whole); by
# default run keys the main camera's consecutive frames by region, whose alpha differs from the
# whole key's only on stray pixels outside the regions (tests/carving/keyer_test.cpp).
"$bin" run --take "$take" --out "$tmp/run_whole" --voxel 0.02 --key-main-whole --no-props --quiet 2> "$tmp/runw.err" \
  || fail "run --key-main-whole: $(cat "$tmp/runw.err")"
if "$bin" composite --take "$take" --depth "$tmp/run_whole/depth" --out "$tmp/comp" --json --quiet > "$tmp/comp.json" 2> "$tmp/comp.err"; then
  ok "composite exits 0"; else fail "composite: $(cat "$tmp/comp.err")"; fi
same=1
for f in 000000 000001 000002; do
  cmp -s "$tmp/run_whole/composite/$f.png" "$tmp/comp/composite/$f.png" || same=0
  cmp -s "$tmp/run_whole/depth/$f.exr" "$tmp/run/depth/$f.exr" || same=0  # the same silhouettes
done
[ $same -eq 1 ] && ok "composite equals run's composite" || fail "composite differs from run's"
python3 -c "import json,sys; j=json.load(open(sys.argv[1])); assert j['command']=='composite' and j['actor_px'] > 1000 and j['fallback_px'] < 0.01 * j['actor_px'], j" "$tmp/comp.json" \
  && ok "composite JSON" || fail "composite JSON"

if "$bin" bench run --take "$take" --frames 2 --repeats 1 --voxel 0.02 --scaling 1,2 > "$tmp/bench.json" 2> "$tmp/bench.err" && python3 - "$tmp/bench.json" "$take/take.json" <<'PY'
import json, sys
j = json.loads(open(sys.argv[1]).read().strip().splitlines()[-1])
assert j["stage"] == "run" and j["ms"] > 0 and j["fps"] > 0 and j["target_ms"] == 20, j
assert [s["stage"] for s in j["stages"]] == ["key", "carve", "depth", "props", "composite"], j
assert j["largest_stage"] in ("key", "carve", "depth", "props", "composite")
assert [s["budget_ms"] for s in j["stages"] if s["stage"] == "props"] == [3], j
assert 0 <= j["props_full_frame_fraction"] <= 1, j
assert j["noise_sigma"] == json.load(open(sys.argv[2]))["options"]["noise_sigma"], j
assert j["latency_ms"] >= j["ms"] * 0.999, j
assert 0 < j["ms_mean"] <= j["ms_max"] and j["ms"] <= j["ms_p95"] <= j["ms_max"], j
assert j["key_region_margin_px"] == 48 and j["key_main_region"] is True and j["props_pooled_with_key"] is True, j
assert j["voxel_m"] == 0.02 and j["depth_step_m"] == 0.0025, j  # the live rays' step (live/frame_loop.h)
# The hot loops' version (core/simd.h): AVX2 exactly when this CPU has it, unless built without.
cpu_avx2 = " avx2" in open("/proc/cpuinfo").read()
# The floor the frame is measured against: a plain binary key of the same plates, far less work.
assert j["binary_key_floor_ms"] > 0 and j["frame_over_floor"] > 1, j
assert j["simd"] in ("avx2", "baseline", "off") and (j["simd"] == "avx2") == (cpu_avx2 and j["simd"] != "off"), j
# The frames' quality against the take's truth stays where it is (measured on this take: witness
# IoU min 0.963, median 0.985; depth within 0.05 mm of the exact hull at p95, 2 of 3778 pixels
# with depth in one only; composite PSNR over the actor 30.3 dB).
q = j["quality"]
assert q["witness_iou_min"] >= 0.95 and q["witness_iou_median"] >= 0.975, q
assert q["depth_vs_exact_hull_mm_p95"] <= 0.5 and q["depth_vs_exact_hull_px"] > 1000, q
assert q["depth_vs_exact_hull_mismatch_px"] <= 0.01 * q["depth_vs_exact_hull_px"], q
assert q["composite_actor_psnr_db_min"] >= 29.0, q
assert [r["threads"] for r in j["scaling"]] == [1, 2], j
assert all(r["ms"] > 0 and r["cpu_ms"] > 0 and r["fps"] > 0 and r["speedup"] > 0 for r in j["scaling"]), j
assert j["scaling"][0]["speedup"] == 1, j
PY
then ok "bench run JSON"; else fail "bench run: $(cat "$tmp/bench.err")"; fi
"$bin" bench run --take "$take" --frames 2 --repeats 1 --depth-step 0 --key-main-whole --props-own-pool 2>/dev/null |
  python3 -c 'import json, sys; j = json.loads(sys.stdin.read()); assert j["key_main_region"] is False and j["props_pooled_with_key"] is False and j["voxel_m"] == 0.02 and j["depth_step_m"] == 0, j' \
  && ok "bench run --key-main-whole --props-own-pool --depth-step 0" || fail "bench run --key-main-whole --props-own-pool --depth-step 0"

# Failures that name the culprit.
expect_fail "bad --frames names the flag" "--frames" "$bin" run --take "$take" --out "$tmp/o" --frames 3-1 --quiet
expect_fail "frames outside the take name the flag" "--frames" "$bin" run --take "$take" --out "$tmp/o" --frames 7:9 --quiet
expect_fail "bad --witness-bin names the field" "witness_bin" "$bin" run --take "$take" --out "$tmp/o" --witness-bin 0 --quiet
expect_fail "bench run: a bad --fps names the flag" "--fps" "$bin" bench run --out "$tmp/bench_out" --fps 0
expect_fail "bench run: a bad --noise names the flag" "--noise" "$bin" bench run --out "$tmp/bench_out" --noise -1
expect_fail "bench run: a bad --scaling names the flag" "--scaling" "$bin" bench run --out "$tmp/bench_out" --scaling 1,two
cp -r "$take" "$tmp/take_nocg"; rm "$tmp/take_nocg/cg/depth/000001.exr"
expect_fail "missing CG depth names the file and frame" "cg/depth/000001.exr.*frame 1|frame 1.*cg/depth/000001.exr" \
  "$bin" run --take "$tmp/take_nocg" --out "$tmp/o" --voxel 0.02 --quiet
rm "$tmp/take_nocg/cg/camera.json"
expect_fail "missing CG camera names the file" "camera.json" "$bin" composite --take "$tmp/take_nocg" --out "$tmp/o"
expect_fail "missing depth frame names the file" "nodepth/000000.exr" "$bin" composite --take "$take" --depth "$tmp/nodepth" --out "$tmp/o"
printf '{"tracked": 1}\n' > "$tmp/tracked.jsonl"
expect_fail "bad tracked poses name the file" "tracked.jsonl" "$bin" run --take "$take" --out "$tmp/o" --tracked-main-poses "$tmp/tracked.jsonl" --quiet
printf '{"props": [{"id": 0}]}\n' > "$tmp/badprops.json"
expect_fail "bad props names the file" "badprops.json" "$bin" run --take "$take" --out "$tmp/o" --props "$tmp/badprops.json" --quiet
expect_fail "bad depth band names the field" "depth_band_m" "$bin" composite --take "$take" --out "$tmp/o" --depth-band -1
finish
