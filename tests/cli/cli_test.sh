#!/usr/bin/env bash
# CLI checks a user would do by hand: exit codes, error messages that name the culprit, and a
# tiny synthetic take written completely (no temporary files left behind).
#   cli_test.sh PREVIZ_BIN SHARED_DATA TMPDIR
set -uo pipefail
bin="$1"; data="$2"; tmp="$3"
rm -rf "$tmp"; mkdir -p "$tmp"
source "$(dirname "${BASH_SOURCE[0]}")/checks.sh"

expect_fail "unknown command fails" "nosuch|not expected|Extras" "$bin" nosuch
expect_fail "frames 0 names the field" "frames" "$bin" synth --out "$tmp/x" --frames 0 --quiet
expect_fail "bad size names the flag" "--size" "$bin" synth --out "$tmp/x" --size 0x5 --quiet
expect_fail "unknown board names the field" "board" "$bin" synth --preset intrinsics --board nosuch --out "$tmp/x" --quiet
expect_fail "unknown intrinsics camera names the field" "camera" "$bin" synth --preset intrinsics --camera witness04 --cams 3 --out "$tmp/x" --quiet
if "$bin" synth --preset intrinsics --camera witness03 --cams 3 --frames 1 --size 160x90 --out "$tmp/intr3" --quiet >/dev/null 2>&1 \
   && [ -s "$tmp/intr3/cams/witness03/000000.png" ] && grep -q '"witness03"' "$tmp/intr3/truth/rig.json" \
   && ! grep -q '"witness01"' "$tmp/intr3/truth/rig.json"; then
  ok "synth intrinsics films the witness --camera names"
else fail "synth intrinsics --camera witness03"; fi
printf '{"units": "m", "cameras": [ {"name": "a", "width": 10' > "$tmp/broken.json"
expect_fail "malformed rig names the file" "broken.json" "$bin" camera info --rig "$tmp/broken.json"
printf 'cam0 1 2 3\n' > "$tmp/short.txt"
expect_fail "short KRt row names the file" "short.txt" "$bin" camera import --krt "$tmp/short.txt" --size 640x480 --out "$tmp/r.json"
expect_fail "KRt without size names the flag" "--size" "$bin" camera import --krt "$tmp/short.txt" --out "$tmp/r.json"

# A tiny studio take, then its files.
if out=$("$bin" synth --preset studio --out "$tmp/take" --frames 2 --cams 3 --size 160x90 --json --quiet); then
  grep -q '"frames":2' <<<"$out" && ok "synth --json summary" || fail "synth --json summary: $out"
  for f in take.json props.json truth/rig.json truth/main_poses.jsonl truth/props.jsonl \
           cams/main/000000.png cams/witness01/000001.png truth/depth/main/000000.exr \
           truth/masks/witness03/000001.png truth/mesh/actor.000001.ply truth/mesh/actor.000001.obj \
           truth/composite/000001.png cg/color/000000.exr cg/depth/000001.exr; do
    [ -s "$tmp/take/$f" ] && ok "take has $f" || fail "take lacks $f"
  done
  leftovers=$(find "$tmp/take" -name '*.tmp*' | head -n 3)
  [ -z "$leftovers" ] && ok "no temporary files left" || fail "temporary files left: $leftovers"
  if "$bin" camera stmap --rig "$tmp/take/truth/rig.json" --camera main --overscan 0.1 --out "$tmp/st" --json >/dev/null 2>&1 \
     && [ -s "$tmp/st/main_distort.exr" ] && [ -s "$tmp/st/main_undistort.exr" ]; then ok "camera stmap"; else fail "camera stmap"; fi
  # A lens table from two calibrations (OpenCV YAML), queried and exported.
  if "$bin" camera export --rig "$tmp/take/truth/rig.json" --opencv-dir "$tmp/cams" >/dev/null 2>&1 \
     && out=$("$bin" calib lens --name cine --entry "0,0,$tmp/cams/main.yaml,0.1" --entry "1,0,$tmp/cams/main.yaml,0.2" \
              --sensor-mm 24.9,14.0 --out "$tmp/lens/cine.json" --ulens "$tmp/lens/cine.ulens" \
              --opentrackio "$tmp/lens/cine_otio.json" --at 0.5,0 --json 2>/dev/null) \
     && grep -q '"entrance_pupil_m":0.15' <<<"$out" && grep -q '"clamped":false' <<<"$out" \
     && [ -s "$tmp/lens/cine.ulens" ] && [ -s "$tmp/lens/cine_otio.json" ]; then
    ok "calib lens builds, interpolates and exports a table"
  else fail "calib lens: $out"; fi
  expect_fail "calib lens names a malformed entry" "--entry" "$bin" calib lens --entry 0,0 --out "$tmp/lens/x.json"
  expect_fail "stmap of an unknown camera names it" "nosuchcam" "$bin" camera stmap --rig "$tmp/take/truth/rig.json" --camera nosuchcam --out "$tmp/st2"
else
  fail "synth studio take"
fi

# Another tool's cameras (Middlebury K R t rows) in and out.
par="$data/middlebury-temple/templeSR_par.txt"
if [ -f "$par" ]; then
  if "$bin" camera import --krt "$par" --size 640x480 --out "$tmp/temple.json" >/dev/null 2>&1 \
     && [ "$("$bin" camera info --rig "$tmp/temple.json" --json 2>/dev/null | grep -o '"name"' | wc -l)" -eq 16 ]; then
    ok "import Middlebury K R t (16 cameras)"
  else fail "import Middlebury K R t"; fi
  if "$bin" camera export --rig "$tmp/temple.json" --opencv-dir "$tmp/yaml" >/dev/null 2>&1 \
     && "$bin" camera import --opencv "$tmp"/yaml/*.yaml --out "$tmp/back.json" >/dev/null 2>&1; then
    ok "export/import OpenCV YAML"
  else fail "export/import OpenCV YAML"; fi
else
  fail "real data missing: $par"
fi

if "$bin" demo --out "$tmp/demo" --frames 2 --cams 3 --size 160x90 --no-calibrate --quiet >/dev/null 2>&1 && [ -s "$tmp/demo/contact_sheet.png" ] && [ -s "$tmp/demo/report.html" ] && [ -s "$tmp/demo/run_true/composite/000001.png" ]; then
  ok "demo --no-calibrate writes a contact sheet, the composites and the report page"
else fail "demo --no-calibrate"; fi
# Every src/href of a report page is relative and exists.
links_ok() {
  local dir="$1" ref
  for ref in $(grep -o -E '(src|href)="[^"]+"' "$dir/report.html" | sed -E 's/^(src|href)="//; s/"$//'); do
    case "$ref" in /*|*://*) return 1 ;; esac
    [ -e "$dir/$ref" ] || return 1
  done
}
links_ok "$tmp/demo" && ok "demo --no-calibrate report links exist" || fail "demo --no-calibrate report links"
# The calibrating path at the smallest setting found to work, with two fisheye witnesses beside
# six Brown-Conrady ones and the main camera (each calibrated with its own lens model). The rig
# take's AprilGrid needs ~960 px wide Brown witnesses to decode, 1280 px fisheye ones (they see
# the tags at half the size: at 960 x 540 the demo stops, naming them), and 8 witnesses to chain
# every camera to the others: ~50 s. 4 board views and 24 rig frames: the figures are a smoke
# check here (fx within 3 px, every camera within 20 mm); the calib and multicam tests hold
# the precise bounds.
if "$bin" demo --out "$tmp/demo_cal" --frames 1 --cams 8 --size 1280x720 --views 4 --rig-frames 24 \
     --fisheye-witnesses 2 --quiet --json >"$tmp/demo_cal.json" 2>"$tmp/demo_cal.err" \
   && [ -s "$tmp/demo_cal/rig.json" ] && [ -s "$tmp/demo_cal/rig.png" ] && [ -s "$tmp/demo_cal/calib/main.residuals.png" ] \
   && [ -s "$tmp/demo_cal/calib/witness08.report.json" ] && [ -s "$tmp/demo_cal/tracked_main.jsonl" ] \
   && [ -s "$tmp/demo_cal/run/composite/000000.png" ] && [ -s "$tmp/demo_cal/run_true/composite/000000.png" ] \
   && grep -q "Rig calibration" "$tmp/demo_cal/report.html" && grep -q "kannala-brandt" "$tmp/demo_cal/report.html" \
   && links_ok "$tmp/demo_cal" && python3 - "$tmp/demo_cal.json" "$tmp/demo_cal/rig.json" <<'PY'
import json, sys
s = json.load(open(sys.argv[1]))
models = {c["camera"]: c["model"] for c in s["intrinsics"]}
assert models == {**{f"witness0{i}": "kannala-brandt" for i in (1, 2)},
                  **{f"witness0{i}": "brown-conrady" for i in range(3, 9)}, "main": "brown-conrady"}, models
assert all(abs(c["fx_error_px"]) <= 3 for c in s["intrinsics"]), s["intrinsics"]
assert all(c["position_error_m"] <= 0.02 for c in s["rig"]["cameras"]), s["rig"]["cameras"]
rig = {c["name"]: c for c in json.load(open(sys.argv[2]))["cameras"]}
assert rig["witness01"]["model"] == "kannala-brandt" and "k4" in rig["witness01"]["distortion"], rig["witness01"]
assert rig["witness03"].get("model", "brown-conrady").startswith("brown-conrady") and "k4" not in rig["witness03"]["distortion"], rig["witness03"]
PY
then
  ok "demo calibrates fisheye and Brown cameras and the rig, runs the take with it, report links exist"
else fail "demo (calibrating): $(tail -3 "$tmp/demo_cal.err")"; fi
rm -rf "$tmp/demo_cal"
expect_fail "demo --views 2 names the flag" "--views" "$bin" demo --out "$tmp/demo_bad" --frames 2 --cams 3 --size 160x90 --views 2 --quiet

finish
