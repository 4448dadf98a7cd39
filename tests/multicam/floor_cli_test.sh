#!/usr/bin/env bash
# Static witnesses from the floor board, as a user meets them (issue 30): a take of two still
# frames of the board lying on the floor (synth --floor-only) calibrated with known intrinsics
# against its truth; a camera turned away from the board named.
#   floor_cli_test.sh PREVIZ_BIN SHARED_DATA TMPDIR
set -uo pipefail
bin="$1"; data="$2"; tmp="$3"
rm -rf "$tmp"; mkdir -p "$tmp"
source "$(dirname "${BASH_SOURCE[0]}")/../cli/checks.sh"

json_num() { grep -o "\"$1\":[-0-9.e+]*" <<<"$2" | head -n 1 | cut -d: -f2; }
below() { awk -v v="$1" -v l="$2" 'BEGIN { exit !(v != "" && v + 0 == v && v < l) }'; }
# The rig preset with 4 witnesses + main, ChArUco, two still frames of the floor board. At
# 1280x720 the board lying 3-6 m away at grazing angles is found with 8-12 corners by most
# witnesses (too few to place a camera by the board alone); at
# 1920x1080, 12-54 (worst camera 8.7 mm / 0.09 deg); at 2560x1440, 37-54 of its 54 corners.
synth_floor() {  # synth_floor OUT [extra synth flags...]
  local out="$1"; shift
  "$bin" synth --preset rig --cams 4 --size 2560x1440 --frames 2 --board charuco --noise 2 --floor-only \
    --out "$out" --quiet "$@" >/dev/null 2>"$out.log"
}

take="$tmp/take"
if ! synth_floor "$take"; then
  fail "synth --floor-only: $(tail -n 3 "$take.log")"
  finish; exit 1
fi
grep -q '"frames": *\[ *0, *1 *\]' <(tr -d '\n' < "$take/floor.json") && ok "every frame is a floor frame" \
  || fail "floor.json: $(cat "$take/floor.json")"
expect_fail "--floor-only with --no-floor names the option" "floor_only" \
  "$bin" synth --preset rig --frames 2 --floor-only --no-floor --out "$tmp/x" --quiet
expect_fail "--floor-only outside the rig preset names the option" "floor_only" \
  "$bin" synth --preset intrinsics --frames 2 --floor-only --out "$tmp/x" --quiet

# 1. Static witnesses: every camera from the still floor board, true intrinsics.
if out=$("$bin" rig calibrate --take "$take" --intrinsics "$take/truth/rig.json" --out "$tmp/cal/rig.json" \
           --compare "$take/truth/rig.json" --json --quiet 2>"$tmp/cal.err"); then
  ok "rig calibrate on a floor-only take runs"
  pos=$(json_num max_position_error_m "$out"); rot=$(json_num max_rotation_error_deg "$out")
  echo "   worst camera: ${pos} m, ${rot} deg"
  # The 1.5 x 1.05 m ChArUco seen still from 3-6 m, noise 2 grey levels: measured 4.8 mm /
  # 0.046 deg at worst (a second or third frame of the same still board does not help: the
  # detector's error at grazing angles repeats, the noise is not what limits). Bounds 1 cm /
  # 0.1 deg, as the waved take's CLI test; plumbing errors are metres.
  below "$pos" 0.01 && ok "every camera within 1 cm of the truth ($pos m)" || fail "position error $pos m"
  below "$rot" 0.1 && ok "every camera within 0.1 deg of the truth ($rot deg)" || fail "rotation error $rot deg"
  grep -q '"world_from_floor":true' <<<"$out" && ok "world frame from the floor board" || fail "world frame: $out"
else
  fail "rig calibrate on a floor-only take: $(tail -n 5 "$tmp/cal.err")"
fi

# 2. A witness turned to look up (90 deg about its x axis) does not see the board: named, no rig written.
if synth_floor "$tmp/away" --bump witness03=0,0,0,90,0,0; then
  expect_fail "a camera not seeing the floor board is named" "witness03.*does not see the floor board" \
    "$bin" rig calibrate --take "$tmp/away" --intrinsics "$take/truth/rig.json" --out "$tmp/away_cal/rig.json" --quiet
  [ ! -e "$tmp/away_cal/rig.json" ] && ok "no rig.json written" || fail "a failed calibration wrote rig.json"
else
  fail "synth take with witness03 turned away: $(tail -n 3 "$tmp/away.log")"
fi

leftovers=$(find "$tmp" -name '*.tmp*' | head -n 3)
[ -z "$leftovers" ] && ok "no temporary files left" || fail "temporary files left: $leftovers"
finish
