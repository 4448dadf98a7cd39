#!/usr/bin/env bash
# `previz calib` as a user meets it: help, errors that name the culprit (unreadable image, no
# board anywhere, bad board JSON, missing folder), images without a board listed but not fatal,
# the camera + OpenCV YAML + report written, a printable board, and a synthetic end-to-end run.
#   calib_cli_test.sh PREVIZ_BIN SHARED_DATA TMPDIR
set -uo pipefail
bin="$1"; data="$2"; tmp="$3"
rm -rf "$tmp"; mkdir -p "$tmp"
source "$(dirname "${BASH_SOURCE[0]}")/../cli/checks.sh"
# A flat grey 64 x 48 PGM: a readable image with no board in it.
blank() { { printf 'P5\n64 48\n255\n'; head -c 3072 /dev/zero | tr '\0' '\200'; } > "$1"; }

for sub in "calib" "calib intrinsics" "calib board" "calib detect"; do
  if $bin $sub --help 2>&1 | grep -q "Usage"; then ok "$sub --help"; else fail "$sub --help"; fi
done

printf '{"type": "chessboard", "rows": 7, "cols": 10, "square_m": 1.0, "margin_m": 0.5}\n' > "$tmp/board.json"
printf '{"type": "chessboard", "rows": 7, "cols": ' > "$tmp/broken_board.json"
printf '{"type": "chessboard", "rows": -7, "cols": 10, "square_m": 1.0}\n' > "$tmp/negative_board.json"

mkdir -p "$tmp/blank"; blank "$tmp/blank/a.pgm"; blank "$tmp/blank/b.pgm"
expect_fail "no board in any image names the folder and the board" "blank.*board.json.*found in none of the 2 images" \
  "$bin" calib intrinsics --images "$tmp/blank" --board "$tmp/board.json" --out "$tmp/x.json" --quiet
expect_fail "malformed board JSON names the file" "broken_board.json" \
  "$bin" calib intrinsics --images "$tmp/blank" --board "$tmp/broken_board.json" --out "$tmp/x.json" --quiet
expect_fail "invalid board JSON names the file and field" "negative_board.json.*rows|rows.*negative_board.json" \
  "$bin" calib intrinsics --images "$tmp/blank" --board "$tmp/negative_board.json" --out "$tmp/x.json" --quiet
expect_fail "missing folder names it" "nosuchdir" \
  "$bin" calib intrinsics --images "$tmp/nosuchdir" --board "$tmp/board.json" --out "$tmp/x.json" --quiet
expect_fail "unknown lock names it" "fix_k9" \
  "$bin" calib intrinsics --images "$tmp/blank" --board "$tmp/board.json" --out "$tmp/x.json" --lock fix_k9 --quiet

expect_fail "unknown lens model names it" "mei.*--model|--model.*mei" \
  "$bin" calib intrinsics --images "$tmp/blank" --board "$tmp/board.json" --out "$tmp/x.json" --model mei --quiet

# A real fisheye (../shared/data/fisheye-chessboard, 6 x 4 inner corners) as Kannala-Brandt: the
# camera JSON names the model, the OpenCV YAML is cv::fisheye's (equidistant, 4 coefficients).
fisheye="$data/fisheye-chessboard"
if ls "$fisheye"/*.jpg >/dev/null 2>&1; then
  printf '{"type": "chessboard", "rows": 5, "cols": 7, "square_m": 1.0, "margin_m": 0.5}\n' > "$tmp/fisheye_board.json"
  if "$bin" calib intrinsics --images "$fisheye" --board "$tmp/fisheye_board.json" --out "$tmp/fish/fish.json" \
       --model fisheye --no-cross-validate --quiet 2>"$tmp/stderr_fish.txt"; then
    grep -q '"model": *"kannala-brandt"' "$tmp/fish/fish.json" && ok "fisheye camera JSON names kannala-brandt" \
      || fail "fisheye camera JSON: $(head -c 400 "$tmp/fish/fish.json")"
    grep -q "distortion_model: equidistant" "$tmp/fish/fish.yaml" && ok "fisheye OpenCV YAML is equidistant" \
      || fail "fisheye YAML: $(head -c 400 "$tmp/fish/fish.yaml")"
    grep -q "lens model           kannala-brandt" "$tmp/stderr_fish.txt" && ok "report names the lens model" \
      || fail "report lacks the lens model"
  else
    fail "calibrate the real fisheye: $(tail -5 "$tmp/stderr_fish.txt")"
  fi
else
  fail "real fisheye data missing: $fisheye"
fi

# A rendered fisheye board set, as the README runs it: the synthetic studio's first witness with
# a Kannala-Brandt lens (about 163 degrees diagonal), 24 views of the chessboard rendered and
# detected on the bent board, solved with --model fisheye. Every intrinsic within 3 sigma of the
# truth the take carries, fx within 0.3 px.
if "$bin" synth --preset intrinsics --board chessboard --camera witness01 --fisheye-witnesses 1 --out "$tmp/fishsynth" \
     --quiet 2>"$tmp/fishsynth.err" \
   && "$bin" calib intrinsics --images "$tmp/fishsynth/cams/witness01" --board "$tmp/fishsynth/board.json" \
     --out "$tmp/fishsynth/cal.json" --model fisheye --no-cross-validate --quiet --json > "$tmp/fishsynth.json" \
     2>>"$tmp/fishsynth.err"; then
  if python3 - "$tmp/fishsynth.json" "$tmp/fishsynth/truth/rig.json" <<'PY'
import json, sys
got = json.load(open(sys.argv[1]))
truth = [c for c in json.load(open(sys.argv[2]))["cameras"] if c["name"] == "witness01"][0]
cam, sigma = got["camera"], got["sigma"]
assert cam["model"] == "kannala-brandt" and truth["model"] == "kannala-brandt", (cam["model"], truth["model"])
assert got["views_used"] >= 20, got["views_used"]
worst = 0.0
for k in ["fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4"]:
    est = cam[k] if k in cam else cam["distortion"][k]
    tru = truth[k] if k in truth else truth["distortion"].get(k, 0.0)
    z = abs(est - tru) / sigma[k]
    worst = max(worst, z)
    assert z <= 3.0, f"{k}: {est} vs truth {tru}, sigma {sigma[k]} ({z:.2f} sigma)"
assert abs(cam["fx"] - truth["fx"]) <= 0.3, (cam["fx"], truth["fx"])
print(f"rendered fisheye: {got['views_used']} views, fx {cam['fx'] - truth['fx']:+.4f} px (sigma {sigma['fx']:.4f}), "
      f"RMS {got['rms_px']:.4f} px, worst {worst:.2f} sigma")
PY
  then ok "rendered fisheye board set calibrated within 3 sigma of the truth"
  else fail "rendered fisheye board set against the truth"
  fi
else
  fail "rendered fisheye board set: $(tail -5 "$tmp/fishsynth.err")"
fi

# --model rational on OpenCV's left sample camera: Brown-Conrady with k4 k5 k6 free; the camera
# JSON carries them, the OpenCV YAML is an 8-term D, the report lists k4..k6.
real="$data/opencv-chessboard"
if ls "$real"/left*.jpg >/dev/null 2>&1; then
  mkdir -p "$tmp/rational_in"; cp "$real"/left*.jpg "$tmp/rational_in/"
  if "$bin" calib intrinsics --images "$tmp/rational_in" --board "$tmp/board.json" --out "$tmp/rational/left.json" \
       --model rational --no-cross-validate --quiet 2>"$tmp/stderr_rational.txt"; then
    grep -q '"k6"' "$tmp/rational/left.json" && ok "rational camera JSON carries k6" \
      || fail "rational camera JSON: $(head -c 400 "$tmp/rational/left.json")"
    grep -A1 "distortion_coefficients" "$tmp/rational/left.yaml" | grep -q "rows: 8" && ok "rational OpenCV YAML has 8 coefficients" \
      || fail "rational YAML: $(grep -A3 distortion_coefficients "$tmp/rational/left.yaml")"
    grep -q "^  k5 " "$tmp/stderr_rational.txt" && ok "report lists k5" || fail "report lacks k5"
  else
    fail "calibrate with --model rational: $(tail -5 "$tmp/stderr_rational.txt")"
  fi
fi

if ls "$real"/left*.jpg >/dev/null 2>&1; then
  mkdir -p "$tmp/left"; cp "$real"/left*.jpg "$tmp/left/"
  printf 'this is not a jpeg' > "$tmp/left/left99.jpg"
  # An unreadable image is skipped and named (stderr, --json's "unreadable"); the rest calibrate.
  if "$bin" calib intrinsics --images "$tmp/left" --board "$tmp/board.json" --out "$tmp/skip/left.json" --quiet \
       --json > "$tmp/skip.json" 2> "$tmp/skip.err" \
     && grep -q "left99.jpg: unreadable (skipped)" "$tmp/skip.err" \
     && python3 -c 'import json,sys; j=json.load(open(sys.argv[1])); sys.exit(0 if j["unreadable"]==["left99.jpg"] else 1)' "$tmp/skip.json"; then
    ok "unreadable image skipped and named"
  else
    fail "unreadable image skipped and named: $(cat "$tmp/skip.err")"
  fi
  mkdir -p "$tmp/junk"; printf 'x' > "$tmp/junk/a.png"; printf 'y' > "$tmp/junk/b.png"
  expect_fail "no readable image names the folder" "junk.*none of the 2 images could be read" \
    "$bin" calib intrinsics --images "$tmp/junk" --board "$tmp/board.json" --out "$tmp/x.json" --quiet
  rm "$tmp/left/left99.jpg"; blank "$tmp/left/zz_blank.pgm"
  if out=$("$bin" calib intrinsics --images "$tmp/left" --board "$tmp/board.json" --out "$tmp/cam/left.json" \
           --lock fix_k3 --json --quiet 2>"$tmp/stderr.txt"); then
    ok "calibrate OpenCV's left images"
    grep -q "no board in zz_blank.pgm" "$tmp/stderr.txt" && ok "image without a board is listed" \
      || fail "image without a board not listed: $(cat "$tmp/stderr.txt")"
    for f in left.json left.yaml left.report.json left.residuals.png left.coverage.png left.views.png left.uncertainty.png; do
      [ -s "$tmp/cam/$f" ] && ok "wrote $f" || fail "did not write $f"
    done
    grep -q '"rms_px"' <<<"$out" && ok "--json report on stdout" || fail "--json report: $out"
    grep -q '"zz_blank.pgm"' "$tmp/cam/left.report.json" && ok "report lists the blank image" || fail "report lacks the blank image"
    "$bin" camera import --opencv "$tmp/cam/left.yaml" --out "$tmp/cam/rig.json" >/dev/null 2>&1 \
      && ok "OpenCV YAML reads back" || fail "OpenCV YAML does not read back"
    leftovers=$(find "$tmp/cam" -name '*.tmp*' | head -n 3)
    [ -z "$leftovers" ] && ok "no temporary files left" || fail "temporary files left: $leftovers"
  else
    fail "calibrate OpenCV's left images: $(cat "$tmp/stderr.txt")"
  fi
  if "$bin" calib intrinsics --images "$tmp/left" --board "$tmp/board.json" --out "$tmp/sel/left.json" \
       --select 6 --refine 1 --quiet 2>"$tmp/stderr_sel.txt" && grep -q "select (uncertainty): 6 of" "$tmp/stderr_sel.txt"; then
    ok "--select 6 --refine 1"
  else fail "--select 6 --refine 1: $(cat "$tmp/stderr_sel.txt")"; fi
else
  fail "real data missing: $real/left*.jpg"
fi

if "$bin" calib board --board "$tmp/board.json" --dpi 30 --out "$tmp/print/board" >/dev/null 2>&1 \
   && [ -s "$tmp/print/board.png" ] && [ -s "$tmp/print/board.svg" ] && [ -s "$tmp/print/board.json" ]; then
  ok "calib board writes PNG, SVG, JSON"
else fail "calib board"; fi
expect_fail "calib board with a bad DPI names it" "dpi" "$bin" calib board --board "$tmp/board.json" --dpi 1 --out "$tmp/print/x"

# calib detect on Kalibr's real boards, the board given as Kalibr's own aprilgrid.yaml: every tag
# of the EuRoC grid with Kalibr's point ids; a wrong board (the 6 x 11 print read as 6 x 6) says
# why, and no image with the board exits 1; an unreadable image is skipped and named.
kal="$data/aprilgrid-kalibr"
printf "target_type: 'aprilgrid' #gridtype\ntagCols: 6\ntagRows: 6\ntagSize: 0.088\ntagSpacing: 0.3\n" > "$tmp/euroc.yaml"
if [ -f "$kal/EuRoC.png" ]; then
  mkdir -p "$tmp/kal"; cp "$kal/EuRoC.png" "$tmp/kal/"; printf 'not a png' > "$tmp/kal/zz_broken.png"
  if "$bin" calib detect --images "$tmp/kal" --board "$tmp/euroc.yaml" --json > "$tmp/detect.json" 2> "$tmp/detect.err" \
     && python3 - "$tmp/detect.json" <<'PY'
import json, sys
j = json.load(open(sys.argv[1]))
assert j["command"] == "calib detect" and j["found"] == 1, j["found"]
e, broken = j["images"]
assert e["image"] == "EuRoC.png" and e["found"] and len(e["tags"]) == 36, e.get("why_not")
assert all(t["used"] and t["bit_errors"] == 0 for t in e["tags"])
ids = sorted(p["id"] for p in e["points"])
assert ids == list(range(144)), ids[:10]   # Kalibr's corner grid: 12 x 12 points
assert broken["image"] == "zz_broken.png" and not broken["found"] and "zz_broken.png" in broken["why_not"], broken
PY
  then ok "calib detect: Kalibr's EuRoC grid, 36 tags, Kalibr's 144 point ids; a broken image skipped and named"
  else fail "calib detect EuRoC: $(cat "$tmp/detect.err")"; fi
  expect_fail "calib detect: the wrong board says why and exits 1" "iphone.png: no board" \
    "$bin" calib detect --images "$kal/iphone.png" --board "$tmp/euroc.yaml"
  if "$bin" calib board --board "$tmp/euroc.yaml" --dpi 50 --out "$tmp/print/kalibr" 2> "$tmp/kboard.err" >/dev/null \
     && [ -s "$tmp/print/kalibr.yaml" ] && grep -q "kalibr layout, tag border 2 cells" "$tmp/kboard.err"; then
    ok "calib board of a Kalibr target writes Kalibr's yaml and says its layout"
  else fail "calib board kalibr: $(cat "$tmp/kboard.err")"; fi
else
  fail "real data missing: $kal/EuRoC.png"
fi

# End to end on the synthetic studio: an intrinsics take, calibrated, against its truth.
if "$bin" synth --preset intrinsics --board chessboard --frames 10 --size 640x360 --camera witness \
     --noise 1 --out "$tmp/take" --quiet >/dev/null 2>&1; then
  cam_dir=$(ls -d "$tmp"/take/cams/*/ | head -n 1)
  if "$bin" calib intrinsics --images "$cam_dir" --board "$tmp/take/board.json" --out "$tmp/take_cam.json" \
       --lock fix_k3 --no-cross-validate --quiet 2>"$tmp/stderr_take.txt"; then
    if python3 - "$tmp/take_cam.json" "$tmp/take/truth/rig.json" <<'PY'
import json, sys
est = json.load(open(sys.argv[1]))
truth = json.load(open(sys.argv[2]))["cameras"][0]
err = abs(est["fx"] - truth["fx"]) / truth["fx"]
print("fx", est["fx"], "truth", truth["fx"], "relative error", err)
sys.exit(0 if err < 0.01 else 1)
PY
    then ok "synthetic take: fx within 1 % of the truth"; else fail "synthetic take: fx off"; fi
  else fail "calibrate the synthetic take: $(tail -n 3 "$tmp/stderr_take.txt")"; fi
else
  fail "synth intrinsics take"
fi

finish
