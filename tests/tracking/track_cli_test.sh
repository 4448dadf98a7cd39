#!/usr/bin/env bash
# `previz track` as a user meets it: a small synthetic studio take (2 witnesses + main at full
# size, 2 frames, noise 2), tracked with the take's props.json and the main camera's poses, the
# errors against truth/props.jsonl; `track prop` writes a props file that tracks the same crate;
# bad input fails with a message naming the field. Streaming goes to 127.0.0.1 only.
bin="$1"; tmp="$3"
. "$(dirname "$0")/../cli/checks.sh"
rm -rf "$tmp"; mkdir -p "$tmp"

if ! "$bin" synth --preset studio --out "$tmp/take" --frames 2 --cams 2 --noise 2 --no-meshes --quiet >/dev/null 2>&1; then
  fail "synth studio take"; finish; exit 1
fi
T="$tmp/take"
if out=$("$bin" track --take "$T" --rig "$T/truth/rig.json" --props "$T/props.json" --main-poses "$T/truth/main_poses.jsonl" \
         --truth "$T/truth/props.jsonl" --out "$tmp/out" --udp 127.0.0.1:47999 --freed --json --quiet 2>"$tmp/err"); then
  ok "track runs"
  grep -q '"frames":2' <<<"$out" && ok "track --json summary" || fail "track --json summary: $out"
  grep -q '"tracked":2' <<<"$out" && ok "crate tracked in both frames" || fail "crate not tracked: $out"
  # Median error against the truth under 2 mm: the number after median_position_error_mm.
  err_mm=$(grep -o '"median_position_error_mm":[0-9.e+-]*' <<<"$out" | cut -d: -f2)
  awk -v e="$err_mm" 'BEGIN { exit !(e != "" && e < 2.0) }' && ok "error vs truth $err_mm mm < 2 mm" || fail "error vs truth: '$err_mm'"
  grep -q '"packets_sent":2' <<<"$out" && ok "two FreeD packets sent" || fail "FreeD packets: $out"
  [ "$(wc -l < "$tmp/out/poses.jsonl")" -eq 2 ] && ok "poses.jsonl has one line a frame" || fail "poses.jsonl lines"
  grep -q '"state":"tracked"' "$tmp/out/poses.jsonl" && ok "poses.jsonl states" || fail "poses.jsonl states"
  [ -f "$tmp/out/track.json" ] && ok "track.json written" || fail "track.json missing"
  ls -a "$tmp/out" | grep -q '\.tmp' && fail "temporary files left" || ok "no temporary files left"
else
  fail "track runs: $(cat "$tmp/err")"
fi

# Issue 32: what `track --otio` sends is OpenTrackIO: each datagram's header checked with the SMPTE
# reference code, its payload with python3-jsonschema against the official schema (1.0.1).
validator="$(dirname "$0")/../live/validate_opentrackio.py"
rm -f "$tmp/otio.hex" "$tmp/otio.hex.ready" "$tmp/otio.hex.stop"
python3 "$validator" "$2/opentrackio" listen 47998 1000 120 "$tmp/otio.hex" > "$tmp/otio.out" 2>&1 &
listener=$!
for _ in $(seq 50); do [ -f "$tmp/otio.hex.ready" ] && break; sleep 0.1; done
"$bin" track --take "$T" --rig "$T/truth/rig.json" --props "$T/props.json" --main-poses "$T/truth/main_poses.jsonl" \
  --out "$tmp/out_otio" --udp 127.0.0.1:47998 --otio --quiet 2>"$tmp/err_otio" || fail "track --otio: $(cat "$tmp/err_otio")"
touch "$tmp/otio.hex.stop"
if wait $listener; then ok "track --otio datagrams are valid OpenTrackIO: $(cat "$tmp/otio.out")"; else fail "track --otio: $(cat "$tmp/otio.out")"; fi

# A main camera pose the camera tracker lost (camera_poses.jsonl's "lost" line): the main camera
# sits that frame out, named with the reason; the witnesses still track the crate.
{ head -n 1 "$T/truth/main_poses.jsonl"; echo '{"frame":1,"camera":"main","state":"lost","reason":"no studio tag seen"}'; } > "$tmp/lost_poses.jsonl"
if out=$("$bin" track --take "$T" --rig "$T/truth/rig.json" --props "$T/props.json" --main-poses "$tmp/lost_poses.jsonl" \
         --out "$tmp/out_lost" --json --quiet 2>"$tmp/err"); then
  grep -q '"tracked":2' <<<"$out" && ok "lost main pose: crate still tracked" || fail "lost main pose: $out"
  grep -q "camera 'main': frame 1: no pose at this frame in .*lost_poses.jsonl (no studio tag seen)" <<<"$out" \
    && ok "lost main pose named" || fail "lost main pose not reported: $out"
  grep -q "camera 'main': frame 0" <<<"$out" && fail "frame 0's main pose was there: $out" || ok "frame 0 uses its pose"
else
  fail "track with a lost main pose: $(cat "$tmp/err")"
fi

# track prop: the studio crate by generator, then tracked with it.
if "$bin" track prop --shape box --name crate --size 0.3,0.3,0.3 --tag-size 0.12 --out "$tmp/props.json" \
     --sheets "$tmp/sheets" --json >/dev/null 2>"$tmp/err"; then
  ok "track prop writes props.json"
  [ "$(ls "$tmp/sheets" | grep -c '\.png$')" -eq 5 ] && ok "five tag sheets" || fail "tag sheets"
  if out=$("$bin" track --take "$T" --rig "$T/truth/rig.json" --props "$tmp/props.json" --cameras witness01,witness02 \
           --truth "$T/truth/props.jsonl" --out "$tmp/out2" --json --quiet 2>/dev/null); then
    grep -q '"tracked":2' <<<"$out" && ok "generated props track the crate" || fail "generated props: $out"
  else
    fail "track with generated props"
  fi
else
  fail "track prop: $(cat "$tmp/err")"
fi

expect_fail "duplicate tag ids across props" "duplicate tag tag36h11 id 0" \
  "$bin" track prop --shape plate --id 1 --name plate --out "$tmp/props.json" --append
expect_fail "negative tag size" "tag size must be > 0" "$bin" track prop --tag-size -0.1 --out "$tmp/p2.json"
expect_fail "unknown family" "unknown AprilTag family 'tag99h1'" "$bin" track prop --family tag99h1 --out "$tmp/p3.json"
printf '{"props":[{"id":0,"name":"a","tags":[{"family":"tag36h11","id":1,"size_m":0.1,"T_prop_tag":{"R":[[1,0,0],[0,1,0],[0,0,1]],"t":[0,0,0]}}]},{"id":1,"name":"b","tags":[{"family":"tag36h11","id":1,"size_m":0.1,"T_prop_tag":{"R":[[1,0,0],[0,1,0],[0,0,1]],"t":[0,0,0]}}]}]}' > "$tmp/dup.json"
expect_fail "track rejects a props file with a duplicate id" "dup.json.*duplicate tag tag36h11 id 1" \
  "$bin" track --take "$T" --rig "$T/truth/rig.json" --props "$tmp/dup.json" --out "$tmp/o3" --quiet
expect_fail "bad --udp names the flag" "--udp" \
  "$bin" track --take "$T" --rig "$T/truth/rig.json" --props "$T/props.json" --out "$tmp/o4" --udp localhost:1 --quiet
expect_fail "bad --shard names the flag" "--shard" \
  "$bin" track --take "$T" --rig "$T/truth/rig.json" --props "$T/props.json" --out "$tmp/o4" --shard 2/2 --quiet
expect_fail "--freed needs --udp" "--udp" \
  "$bin" track --take "$T" --rig "$T/truth/rig.json" --props "$T/props.json" --out "$tmp/o5" --freed --quiet
expect_fail "an unknown --detector key names the flag and the keys" "--detector.*refine-corners" \
  "$bin" track --take "$T" --rig "$T/truth/rig.json" --props "$T/props.json" --out "$tmp/o7" --detector witness01:blur=1 --quiet
# libapriltag's own corners on one camera, previz's on the other: still tracked.
if out=$("$bin" track --take "$T" --rig "$T/truth/rig.json" --props "$T/props.json" --cameras witness01,witness02 \
         --detector witness01:refine-corners=0 --out "$tmp/o8" --json --quiet 2>"$tmp/err"); then
  grep -q '"tracked":2' <<<"$out" && ok "--detector CAM:refine-corners=0 tracks" || fail "refine-corners=0: $out"
else
  fail "--detector CAM:refine-corners=0: $(cat "$tmp/err")"
fi
expect_fail "missing --props" "--props" "$bin" track --take "$T" --rig "$T/truth/rig.json" --out "$tmp/o6" --quiet
expect_fail "unknown camera" "nosuch" \
  "$bin" track --take "$T" --rig "$T/truth/rig.json" --props "$T/props.json" --cameras nosuch --out "$tmp/o7" --quiet
finish
