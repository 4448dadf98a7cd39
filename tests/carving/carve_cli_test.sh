#!/usr/bin/env bash
# `previz carve` as a user meets it: clear failures that name the culprit, a good run that
# writes the documented files (docs/formats.md, "Carve output"), resume, shards, a dropped
# camera, keyed plates. (Other tools' camera rows: tests/carving/take_test.cpp and the Middlebury
# test in run_test.cpp.)
#   carve_cli_test.sh PREVIZ_BIN SHARED_DATA TMPDIR
set -uo pipefail
bin="$1"; data="$2"; tmp="$3"
rm -rf "$tmp"; mkdir -p "$tmp"
source "$(dirname "${BASH_SOURCE[0]}")/../cli/checks.sh"

# A small studio take: 4 witnesses at 320x180, 3 frames (about 2 s to render).
if ! "$bin" synth --preset studio --out "$tmp/take" --frames 3 --cams 4 --size 320x180 --no-meshes --quiet >/dev/null 2>&1; then
  fail "synth studio take"; finish; exit 1
fi
take="$tmp/take"
common=(--take "$take" --rig "$take/truth/rig.json" --main-poses "$take/truth/main_poses.jsonl" --voxel 0.02 --quiet)

printf '{"units": "m", "cameras": [ {"name": "a", "width": 10' > "$tmp/broken.json"
expect_fail "malformed rig names the file" "broken.json" "$bin" carve --take "$take" --rig "$tmp/broken.json" --out "$tmp/o"
printf 'cam0 1 2 3\n' > "$tmp/rows.txt"
expect_fail "bad camera rows name the file" "rows.txt" "$bin" carve --take "$take" --rig "$tmp/rows.txt" --out "$tmp/o"
expect_fail "missing rig names the file" "nosuch.json" "$bin" carve --take "$take" --rig "$tmp/nosuch.json" --out "$tmp/o"
expect_fail "missing take names the folder" "nosuchtake" "$bin" carve --take "$tmp/nosuchtake" --rig "$take/truth/rig.json" --out "$tmp/o"
expect_fail "bad --frames names the flag" "--frames" "$bin" carve "${common[@]}" --frames 1-3 --out "$tmp/o"
expect_fail "empty --frames range names the flag" "--frames" "$bin" carve "${common[@]}" --frames 2:2 --out "$tmp/o"
expect_fail "bad --shard names the flag" "--shard" "$bin" carve "${common[@]}" --shard 2/2 --out "$tmp/o"
expect_fail "bad --volume names the flag" "--volume" "$bin" carve "${common[@]}" --volume 1,2,3 --out "$tmp/o"
expect_fail "missing masks folder names the flag" "--masks" "$bin" carve "${common[@]}" --masks "$tmp/nomasks" --out "$tmp/o"
expect_fail "unknown carving camera is named" "nosuchcam" "$bin" carve "${common[@]}" --cameras witness01,nosuchcam --out "$tmp/o"
expect_fail "voxel 0 names the field" "voxel" "$bin" carve "${common[@]}" --voxel 0 --out "$tmp/o"
expect_fail "carve threshold 1 names the field" "carve_threshold" "$bin" carve "${common[@]}" --carve-threshold 1 --out "$tmp/o"

# A good run with the true masks: every documented file per frame, report lines naming cameras.
out="$tmp/out"
if json=$("$bin" carve "${common[@]}" --masks "$take/truth/masks" --out "$out" --json); then
  ok "carve with masks exits 0"
  grep -q '"carved":3' <<<"$json" && ok "summary: 3 frames carved" || fail "summary: $json"
else fail "carve with masks: $json"; fi
for f in 000000 000001 000002; do
  for file in depth/$f.exr depth/$f.png mesh/$f.ply mesh/$f.obj points/$f.ply points/$f.pcd report/$f.json; do
    [ -s "$out/$file" ] && ok "wrote $file" || fail "missing $file"
  done
done
[ "$(wc -l < "$out/carve.jsonl" 2>/dev/null)" = 3 ] && ok "carve.jsonl has 3 lines" || fail "carve.jsonl"
grep -q '"cameras_used":\["witness01","witness02","witness03","witness04","main"\]' "$out/report/000001.json" \
  && ok "report names the cameras" || fail "report cameras: $(head -c 300 "$out/report/000001.json")"
leftovers=$(find "$out" -name '.*' -type f | head -n 3)
[ -z "$leftovers" ] && ok "no temporary files left" || fail "temporary files left: $leftovers"

# Resume: nothing left to do.
json=$("$bin" carve "${common[@]}" --masks "$take/truth/masks" --out "$out" --json)
grep -q '"carved":0' <<<"$json" && grep -q '"skipped":\[0,1,2\]' <<<"$json" \
  && ok "second run skips every finished frame" || fail "resume: $json"

# Shards 0/2 and 1/2 cover the take once.
for s in 0/2 1/2; do "$bin" carve "${common[@]}" --masks "$take/truth/masks" --shard $s --out "$tmp/sharded" >/dev/null 2>&1; done
[ "$(wc -l < "$tmp/sharded/carve.jsonl" 2>/dev/null)" = 3 ] && ok "two shards cover 3 frames" || fail "shards"

# A missing witness frame is dropped and named, the frame still carved.
cp -r "$take/truth/masks" "$tmp/masks"
rm "$tmp/masks/witness02/000001.png"
if "$bin" carve "${common[@]}" --masks "$tmp/masks" --frames 1 --out "$tmp/dropped" 2>"$tmp/dropped.err" >/dev/null \
   && grep -q "frame 1: camera 'witness02' dropped: missing mask" "$tmp/dropped.err" \
   && grep -q '"camera":"witness02","frame":1,"reason":"missing mask' "$tmp/dropped/report/000001.json"; then
  ok "missing witness frame dropped and named"
else fail "dropped camera: $(cat "$tmp/dropped.err")"; fi

# --depth-cameras all: every other camera's hull depth in depth_cameras/<cam>/ (not the main one
# twice); an unknown camera is refused, named.
all_rc=0
"$bin" carve "${common[@]}" --masks "$take/truth/masks" --frames 1 --depth-cameras all --out "$tmp/alldepth" \
  >/dev/null 2>"$tmp/alldepth.err" || all_rc=1
for c in witness01 witness02 witness03 witness04; do
  [ -s "$tmp/alldepth/depth_cameras/$c/000001.exr" ] && [ -s "$tmp/alldepth/depth_cameras/$c/000001.png" ] || all_rc=1
done
if [ $all_rc = 0 ] && [ ! -e "$tmp/alldepth/depth_cameras/main" ] && [ -s "$tmp/alldepth/depth/000001.exr" ] \
   && grep -q '"extra_depths":\[{"camera":"witness01",' "$tmp/alldepth/report/000001.json"; then
  ok "--depth-cameras all writes every camera's depth"
else fail "--depth-cameras all: $(tail -n 3 "$tmp/alldepth.err")"; fi
if ! "$bin" carve "${common[@]}" --masks "$take/truth/masks" --frames 1 --depth-cameras witness09 \
     --out "$tmp/baddepth" >/dev/null 2>"$tmp/baddepth.err" && grep -q "witness09" "$tmp/baddepth.err"; then
  ok "unknown depth camera refused, named"
else fail "unknown depth camera: $(cat "$tmp/baddepth.err")"; fi

# --refine: the second depth layer beside the hull depth, from the plates (also with masks).
if "$bin" carve "${common[@]}" --masks "$take/truth/masks" --frames 1 --refine --out "$tmp/refined" >/dev/null 2>"$tmp/refined.err" \
   && [ -s "$tmp/refined/depth_refined/000001.exr" ] && [ -s "$tmp/refined/depth_refined/000001.png" ] \
   && [ -s "$tmp/refined/depth/000001.exr" ] \
   && grep -q '"refine":{"free_space":[0-9]*,"gains_estimated":\[\],"method":"photo hull","moved":[0-9]*,"ms":[0-9.e+-]*,"pixels":[1-9][0-9]*,"source":"plates","witnesses":\["witness01","witness02","witness03","witness04"\]}' "$tmp/refined/report/000001.json"; then
  ok "--refine writes depth_refined/ and reports it"
else fail "--refine: $(tail -n 3 "$tmp/refined.err") $(head -c 600 "$tmp/refined/report/000001.json" 2>/dev/null)"; fi

# Keyed plates (no masks), one frame.
if "$bin" carve "${common[@]}" --frames 0:1 --out "$tmp/keyed" >/dev/null 2>"$tmp/keyed.err" \
   && grep -q '"depth_silhouette":"key"' "$tmp/keyed/report/000000.json"; then
  ok "keyed carve exits 0"
else fail "keyed carve: $(tail -n 3 "$tmp/keyed.err")"; fi

finish
