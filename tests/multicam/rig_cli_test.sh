#!/usr/bin/env bash
# `previz rig` as a user meets it: a small synthetic rig take calibrated against its truth (the
# CLI's --compare prints every camera's error; awk checks the bound), the observations cache,
# YAML and picture outputs, bad inputs whose message names the culprit, a delayed camera caught
# by `rig check` (exit 3), and a bumped camera re-surveyed from a short capture.
#   rig_cli_test.sh PREVIZ_BIN SHARED_DATA TMPDIR
set -uo pipefail
bin="$1"; data="$2"; tmp="$3"
rm -rf "$tmp"; mkdir -p "$tmp"
source "$(dirname "${BASH_SOURCE[0]}")/../cli/checks.sh"

# A number from a one-line JSON summary: json_num KEY TEXT (first occurrence).
json_num() { grep -o "\"$1\":[-0-9.e+]*" <<<"$2" | head -n 1 | cut -d: -f2; }
# below VALUE LIMIT: VALUE is a number and < LIMIT.
below() { awk -v v="$1" -v l="$2" 'BEGIN { exit !(v != "" && v + 0 == v && v < l) }'; }

# The rig preset, small: 4 witnesses 1280x720 + main, ChArUco (detected ~5x faster than an
# AprilGrid; at 960x540 the floor board's markers are too small for most witnesses).
synth_rig() {  # synth_rig OUT FRAMES [extra synth flags...]
  local out="$1" frames="$2"; shift 2
  "$bin" synth --preset rig --cams 4 --size 1280x720 --frames "$frames" --board charuco --noise 2 \
    --out "$out" --quiet "$@" >/dev/null 2>"$out.log"
}

take="$tmp/take"
if ! synth_rig "$take" 40; then
  fail "synth rig take: $(tail -n 3 "$take.log")"
  finish; exit 1
fi
[ -s "$take/floor.json" ] && ok "synth writes floor.json" || fail "synth rig take has no floor.json"

# 1. Calibrate with the true intrinsics; positions against the truth, same world frame (floor).
if out=$("$bin" rig calibrate --take "$take" --intrinsics "$take/truth/rig.json" --out "$tmp/cal/rig.json" \
           --yaml "$tmp/cal/yaml" --picture "$tmp/cal/stage" --observations "$tmp/cal/obs.json" \
           --compare "$take/truth/rig.json" --json --quiet 2>"$tmp/cal.err"); then
  ok "rig calibrate runs"
  pos=$(json_num max_position_error_m "$out"); rot=$(json_num max_rotation_error_deg "$out")
  echo "   worst camera: ${pos} m, ${rot} deg"
  # 37 waved frames, 6-16 views a camera, noise 2 grey levels: measured 3.3 mm / 0.046 deg at
  # worst with sigma 1.1-1.9 mm; plumbing errors (world frame, camera order, units) are metres.
  below "$pos" 0.01 && ok "every camera within 1 cm of the truth ($pos m)" || fail "position error $pos m"
  below "$rot" 0.1 && ok "every camera within 0.1 deg of the truth ($rot deg)" || fail "rotation error $rot deg"
  grep -q '"world_from_floor":true' <<<"$out" && ok "world frame from the floor board" || fail "world frame not from the floor: $out"
  grep -q '"sync_ok":true' <<<"$out" && ok "sync check: in sync" || fail "sync check on a synchronous take: $out"
  for f in rig.json rig.report.json stage.png stage.svg obs.json yaml/witness01.yaml yaml/main.yaml; do
    [ -s "$tmp/cal/$f" ] && ok "calibrate wrote $f" || fail "calibrate did not write $f"
  done
  grep -q "rig detect: " "$tmp/cal.err" && ok "human summary on stderr" || fail "no summary on stderr"
  # Importable as OpenCV YAML by previz itself.
  "$bin" camera import --opencv "$tmp/cal/yaml/witness01.yaml" --out "$tmp/cal/w1.json" >/dev/null 2>&1 \
    && ok "YAML imports" || fail "YAML does not import"
else
  fail "rig calibrate: $(tail -n 5 "$tmp/cal.err")"
fi

# 2. The observations cache is reused; intrinsics from a folder of per-camera files.
"$bin" camera export --rig "$take/truth/rig.json" --opencv-dir "$tmp/intr" >/dev/null 2>&1
if out=$("$bin" rig calibrate --take "$take" --intrinsics "$tmp/intr" --out "$tmp/cal2/rig.json" \
           --observations "$tmp/cal/obs.json" --json --quiet 2>"$tmp/cal2.err"); then
  grep -q '"cached":true' <<<"$out" && ok "observations cache reused" || fail "cache not reused: $out"
else
  fail "rig calibrate from an intrinsics folder: $(tail -n 3 "$tmp/cal2.err")"
fi

# 3. Bad inputs: non-zero exit, the message names the culprit, --out left alone.
printf '{"type": "aprilgrid", "rows": ' > "$tmp/bad_board.json"
expect_fail "malformed board names the file" "bad_board.json" \
  "$bin" rig calibrate --take "$take" --board "$tmp/bad_board.json" --intrinsics "$take/truth/rig.json" --out "$tmp/x/rig.json"
rm -f "$tmp/intr/witness03.yaml"
expect_fail "missing intrinsics name the camera" "witness03" \
  "$bin" rig calibrate --take "$take" --intrinsics "$tmp/intr" --out "$tmp/x/rig.json"
mkdir -p "$tmp/take_missing/cams"
cp "$take/take.json" "$take/board.json" "$take/floor.json" "$tmp/take_missing/"
for cam in witness01 witness03 witness04 main; do ln -s "$take/cams/$cam" "$tmp/take_missing/cams/$cam"; done
expect_fail "missing camera folder names the camera and folder" "witness02.*take_missing/cams/witness02|take_missing/cams/witness02.*witness02" \
  "$bin" rig calibrate --take "$tmp/take_missing" --intrinsics "$take/truth/rig.json" --out "$tmp/x/rig.json" --quiet
expect_fail "unknown camera to re-survey is named" "nosuchcam" \
  "$bin" rig resurvey --take "$take" --rig "$take/truth/rig.json" --camera nosuchcam --out "$tmp/x/rig.json"
[ ! -e "$tmp/x/rig.json" ] && ok "no rig.json written by failed runs" || fail "a failed run wrote rig.json"

# 4. rig check: the take it was calibrated on passes; a take with the main camera two frames
#    late (a genlock fault) exits 3 naming it. Main shares board views with most witnesses; in
#    a 4-witness ring neighbours share too few for a witness's offset to be told.
if [ -s "$tmp/cal/rig.json" ]; then
  "$bin" rig check --take "$take" --rig "$tmp/cal/rig.json" --observations "$tmp/cal/obs.json" --quiet >/dev/null 2>"$tmp/check0.err"
  rc=$?; [ $rc -eq 0 ] && ok "rig check passes on the calibration take" || fail "rig check rc=$rc: $(tail -n 12 "$tmp/check0.err")"
  if synth_rig "$tmp/late" 40 --delay main=2 --board-seed 7; then
    out=$("$bin" rig check --take "$tmp/late" --rig "$tmp/cal/rig.json" --json --quiet 2>"$tmp/check.err"); rc=$?
    if [ $rc -eq 3 ] && grep -q "main is OUT OF SYNC by 2 frames" "$tmp/check.err"; then
      ok "rig check exits 3 naming the late camera and its offset"
    else fail "rig check on a delayed take: rc=$rc, $(tail -n 12 "$tmp/check.err")"; fi
    grep -q '"camera":"main","in_sync":false,"offset_frames":2' <<<"$out" \
      && ok "rig check --json has the offset" || fail "rig check --json: $out"
  else fail "synth delayed take: $(tail -n 3 "$tmp/late.log")"; fi

  # 5. Re-survey: witness01 knocked by 3 cm and 1 degree, 30 new frames without floor.
  if synth_rig "$tmp/bumped" 30 --bump witness01=0.03,0,0,0,1,0 --no-floor --board-seed 11; then
    out=$("$bin" rig resurvey --take "$tmp/bumped" --rig "$tmp/cal/rig.json" --camera witness01 \
            --out "$tmp/resurvey/rig.json" --compare "$tmp/bumped/truth/rig.json" --json --quiet 2>"$tmp/resurvey.err")
    if [ $? -eq 0 ]; then
      moved=$(json_num moved_m "$out"); pos=$(json_num max_position_error_m "$out"); rot=$(json_num max_rotation_error_deg "$out")
      echo "   re-survey: moved ${moved} m, error ${pos} m, ${rot} deg"
      below "$pos" 0.01 && ok "re-surveyed camera within 1 cm of its new truth" || fail "re-survey position error $pos m"
      below "$rot" 0.1 && ok "re-surveyed camera within 0.1 deg" || fail "re-survey rotation error $rot deg"
      awk -v m="$moved" 'BEGIN { exit !(m > 0.025 && m < 0.035) }' && ok "re-survey saw the 3 cm move" || fail "moved $moved m"
    else fail "rig resurvey: $(tail -n 5 "$tmp/resurvey.err")"; fi
  else fail "synth bumped take: $(tail -n 3 "$tmp/bumped.log")"; fi
fi

leftovers=$(find "$tmp" -name '*.tmp*' | head -n 3)
[ -z "$leftovers" ] && ok "no temporary files left" || fail "temporary files left: $leftovers"
finish
