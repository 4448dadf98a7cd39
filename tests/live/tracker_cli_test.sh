#!/usr/bin/env bash
# `previz tracker` and `previz run --tracker` as a user meets them (issue 32):
#  - every OpenTrackIO datagram previz sends (camera samples in JSON and CBOR, with and without
#    timecode, as `tracker simulate` encodes and `tracker replay` sends them) passes the SMPTE
#    reference code's header check and Debian's python3-jsonschema against the official schema;
#    one stream is sent over loopback UDP to an independent listener;
#  - record + replay over loopback: the recording holds what was sent, byte for byte;
#  - bad URLs and options fail with a message naming the flag.
# Loopback (127.0.0.1) only.
#   tracker_cli_test.sh PREVIZ_BIN SHARED_DATA TMPDIR
bin="$1"; shared="$2"; tmp="$3"
. "$(dirname "$0")/../cli/checks.sh"
here="$(cd "$(dirname "$0")" && pwd)"
otio="$shared/opentrackio"
rm -rf "$tmp"; mkdir -p "$tmp"

[ -f "$otio/schema.json" ] && [ -f "$otio/opentrackio_lib.py" ] && ok "SMPTE schema and reference code present" \
  || { fail "missing $otio/schema.json or opentrackio_lib.py"; finish; exit 1; }
python3 -c "import jsonschema" 2>/dev/null && ok "python3-jsonschema importable" \
  || fail "python3-jsonschema is not installed (scripts/setup.sh installs it)"

# A small studio take for the simulated dolly (its take.json says how the main camera moves).
if ! "$bin" synth --preset studio --out "$tmp/take" --frames 3 --fps 2 --cams 2 --size 160x90 --main-size 240x135 \
     --no-meshes --quiet >/dev/null 2>&1; then
  fail "synth studio take"; finish; exit 1
fi

n=0
for variant in "json" "cbor --cbor" "timecode --timecode 01:00:00:00" "cbortc --cbor --timecode 23:59:59:00"; do
  name=${variant%% *}; extra=${variant#"$name"}
  if "$bin" tracker simulate --take "$tmp/take" --protocol otio --rate 60 --zoom 0.5 --focus 0.25 $extra \
       --out "$tmp/otio_$name.jsonl" 2>"$tmp/sim.err"; then n=$((n + 1)); else fail "simulate otio $name: $(cat "$tmp/sim.err")"; fi
done
[ $n -eq 4 ] && ok "tracker simulate writes OpenTrackIO recordings (JSON, CBOR, with timecode)"
if out=$(python3 "$here/validate_opentrackio.py" "$otio" recording "$tmp"/otio_*.jsonl 2>&1); then
  ok "every OpenTrackIO camera datagram: header per the SMPTE reference, payload valid against schema.json ($out)"
else
  fail "OpenTrackIO validation: $out"
fi

# The same bytes through a socket: tracker replay to an independent listener.
port=47311
rm -f "$tmp/heard.hex" "$tmp/heard.hex.ready"
count=$(($(wc -l < "$tmp/otio_json.jsonl") - 1))
python3 "$here/validate_opentrackio.py" "$otio" listen $port "$count" 20 "$tmp/heard.hex" > "$tmp/listen.out" 2>&1 &
listener=$!
for _ in $(seq 50); do [ -f "$tmp/heard.hex.ready" ] && break; sleep 0.1; done
"$bin" tracker replay "$tmp/otio_json.jsonl" --to otio://127.0.0.1:$port --speed 4 --quiet || fail "tracker replay"
wait $listener && ok "replayed over UDP: $(cat "$tmp/listen.out")" || fail "listener: $(cat "$tmp/listen.out")"
python3 - "$tmp/otio_json.jsonl" "$tmp/heard.hex" <<'PY' && ok "replay sent the recorded datagrams byte for byte, in order" || fail "replay bytes differ"
import json, sys
rec = [json.loads(l)["bytes"] for l in list(open(sys.argv[1]))[1:]]
heard = [l.strip() for l in open(sys.argv[2]) if l.strip()]
assert heard == rec, (len(heard), len(rec))
PY

# record <- replay over loopback: FreeD, every datagram kept with its arrival time; the
# recording replays the same bytes.
"$bin" tracker simulate --take "$tmp/take" --protocol freed --rate 120 --out "$tmp/freed.jsonl" 2>/dev/null \
  || fail "simulate freed"
port=47312
"$bin" tracker record --listen freed://127.0.0.1:$port --out "$tmp/recorded.jsonl" --seconds 8 \
  --packets "$(($(wc -l < "$tmp/freed.jsonl") - 1))" --json --quiet > "$tmp/record.json" 2>"$tmp/record.err" &
recorder=$!
sleep 0.5
"$bin" tracker replay "$tmp/freed.jsonl" --to freed://127.0.0.1:$port --speed 2 --quiet || fail "replay freed"
wait $recorder || fail "tracker record: $(cat "$tmp/record.err")"
python3 - "$tmp/freed.jsonl" "$tmp/recorded.jsonl" "$tmp/record.json" <<'PY' && ok "tracker record captured the replayed FreeD stream byte for byte, decoded" || fail "record/replay FreeD"
import json, sys
sent = [json.loads(l) for l in list(open(sys.argv[1]))[1:]]
got = [json.loads(l) for l in open(sys.argv[2])]
assert got[0]["format"] == "previz-tracker-recording" and got[0]["protocol"] == "freed", got[0]
got = got[1:]
assert [g["bytes"] for g in got] == [s["bytes"] for s in sent], (len(got), len(sent))
assert all("T_stage_tracker" in g and "pan_tilt_roll_deg" in g and "zoom_raw" in g for g in got), got[0]
assert all(b["arrival_s"] >= a["arrival_s"] for a, b in zip(got, got[1:]))
s = json.load(open(sys.argv[3]))
assert s["counts"]["accepted"] == len(sent) and s["counts"]["malformed"] == 0, s
PY

# previz track --tracker: the main camera's poses from the recording (FreeD, arrival - 40 ms)
# meet the truth.
if "$bin" track --take "$tmp/take" --rig "$tmp/take/truth/rig.json" --props "$tmp/take/props.json" --tracker "$tmp/freed.jsonl" \
     --tracker-delay 0.040 --out "$tmp/track" --quiet 2>"$tmp/track.err" && python3 - "$tmp/track/tracker_main_poses.jsonl" "$tmp/take/truth/main_poses.jsonl" <<'PY'
import json, math, sys
got = [json.loads(l) for l in open(sys.argv[1])]
truth = {j["frame"]: j["T_world_cam"]["t"] for j in map(json.loads, open(sys.argv[2]))}
assert [g["frame"] for g in got] == sorted(truth) and all(g["state"] == "tracked" for g in got), got
worst = max(1000 * math.dist(g["T_world_cam"]["t"], truth[g["frame"]]) for g in got)
print("  track --tracker: main camera within %.3f mm of the truth" % worst)
assert worst < 1.5, worst
PY
then ok "track --tracker: the main camera's poses from the recording meet the truth"; else fail "track --tracker: $(cat "$tmp/track.err")"; fi

# Failures that name the flag.
expect_fail "run: a hostname in --tracker names the flag" "--tracker" \
  "$bin" run --take "$tmp/take" --out "$tmp/o" --tracker freed://localhost:40000 --quiet
expect_fail "run: a bad port names the flag" "--tracker.*port" \
  "$bin" run --take "$tmp/take" --out "$tmp/o" --tracker otio://127.0.0.1:99999 --quiet
expect_fail "run: an unknown scheme names the flag" "--tracker.*scheme" \
  "$bin" run --take "$tmp/take" --out "$tmp/o" --tracker udp://127.0.0.1:4000 --quiet
expect_fail "run: a missing recording names the flag" "--tracker" \
  "$bin" run --take "$tmp/take" --out "$tmp/o" --tracker "$tmp/none.jsonl" --quiet
expect_fail "run: --tracker with --main-poses" "--tracker" \
  "$bin" run --take "$tmp/take" --out "$tmp/o" --tracker "$tmp/freed.jsonl" --main-poses "$tmp/take/truth/main_poses.jsonl" --quiet
expect_fail "run: a bad --tracker-match names the flag" "--tracker-match" \
  "$bin" run --take "$tmp/take" --out "$tmp/o" --tracker "$tmp/freed.jsonl" --tracker-match sometimes --quiet
expect_fail "record: a bad multicast group names the flag" "--listen" \
  "$bin" tracker record --listen otio://239.135.1:55555 --out "$tmp/x.jsonl" --seconds 1
expect_fail "replay: the wrong protocol names the flag" "--to" \
  "$bin" tracker replay "$tmp/freed.jsonl" --to otio://127.0.0.1:47313
expect_fail "replay: 0.0.0.0 is no destination" "--to" \
  "$bin" tracker replay "$tmp/freed.jsonl" --to freed://0.0.0.0:47313
# A stream that stops: frames after its end fail with the reason, the others are composited.
head -n 40 "$tmp/freed.jsonl" > "$tmp/short.jsonl"
"$bin" run --take "$tmp/take" --out "$tmp/short" --tracker "$tmp/short.jsonl" --tracker-delay 0.04 --no-props --voxel 0.04 \
   --json --quiet > "$tmp/short.json" 2>/dev/null
rc=$?
python3 - "$tmp/short.json" <<'PY' && [ $rc -eq 1 ] && ok "frames without a tracker pose are failed with the reason, exit 1" || fail "short stream (rc=$rc)"
import json, sys
j = json.load(open(sys.argv[1]))
assert j["frames"] == [0], j["frames"]
assert [f["frame"] for f in j["failed"]] == [1, 2] and all("no tracker pose" in f["reason"] for f in j["failed"]), j["failed"]
assert j["tracker"]["counts"]["frames_without_pose"] == 2, j["tracker"]
PY
finish
