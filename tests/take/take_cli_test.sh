#!/usr/bin/env bash
# The take model as a user meets it (issue 29 item 1): the studio take of the composite tests
# (5 frames, 8 witnesses 640x360, main 960x540, PNG) re-written as lossless FFV1 videos with a
# start timecode and one witness that started recording a frame late, and as image sequences of
# another pattern from 1001; `take info` says what it found; carve, track, run and batch read
# every form through the same model and give the same bytes where the pixels are the same.
#   take_cli_test.sh PREVIZ_BIN STUDIO_TAKE TMPDIR
set -uo pipefail
bin="$1"; take="$2"; tmp="$3"
rm -rf "$tmp"; mkdir -p "$tmp"
source "$(dirname "${BASH_SOURCE[0]}")/../cli/checks.sh"
rig="$take/truth/rig.json"; poses="$take/truth/main_poses.jsonl"

if "$bin" take info "$take" --json > "$tmp/info.json" 2> "$tmp/info.err" && python3 - "$tmp/info.json" <<'PY'
import json, sys
j = json.load(open(sys.argv[1]))
assert j["frames"] == 5 and j["frame_range"] == [0, 4] and j["main"] == "main", j
cams = {c["camera"]: c for c in j["cameras"]}
assert len(cams) == 9, cams.keys()
for c in cams.values():
    assert c["kind"] == "sequence" and c["pattern"] == "%06d.png" and c["frames"] == 5, c
    assert c["offset"] == 0 and c["offset_from"] == "none" and c["bit_depth"] == 8, c
assert j["mismatches"] == [], j["mismatches"]
PY
then ok "take info on the PNG take"; else fail "take info: $(cat "$tmp/info.err")"; fi

# FFV1 with timecode, witness03 late by one frame: the timecode puts it back in place.
if "$bin" take convert "$take" --out "$tmp/ffv1" --format ffv1 --timecode 01:00:00:00 --late witness03=1 --quiet \
     2> "$tmp/conv.err" && "$bin" take info "$tmp/ffv1" --json > "$tmp/finfo.json" 2>/dev/null \
   && python3 - "$tmp/finfo.json" <<'PY'
import json, sys
j = json.load(open(sys.argv[1]))
cams = {c["camera"]: c for c in j["cameras"]}
w3 = cams["witness03"]
assert w3["kind"] == "video" and w3["format"] == "ffv1" and w3["path"] == "cams/witness03.mkv", w3
# The take runs at 0.5 fps: timecode counts it at the nominal rate 1, a frame a second.
assert w3["start_timecode"] == "01:00:01:00" and w3["timecode_from"] == "container", w3
assert w3["offset_from"] == "timecode" and w3["offset"] == -1 and w3["take_range"] == [1, 4], w3
assert cams["main"]["start_timecode"] == "01:00:00:00" and cams["main"]["take_range"] == [0, 4], cams["main"]
assert j["frames"] == 5, j
PY
then ok "take convert to FFV1 with timecode: take info gives each camera's offset from its timecode"
else fail "take convert ffv1: $(cat "$tmp/conv.err")"; fi

# Sequences of another name from 1001 (no timecode in PNG: take.json offsets say it).
if "$bin" take convert "$take" --out "$tmp/seq" --format png --pattern "{camera}_A001C003.####" --start-number 1001 \
     --quiet 2> "$tmp/conv2.err" && [ -f "$tmp/seq/cams/witness01/witness01_A001C003.1001.png" ] \
   && "$bin" take info "$tmp/seq" --json > "$tmp/sinfo.json" 2>/dev/null \
   && python3 -c "
import json,sys; j=json.load(open(sys.argv[1])); c={c['camera']:c for c in j['cameras']}['main']
assert c['pattern']=='main_A001C003.%04d.png' and c['offset']==1001 and c['offset_from']=='take.json' and c['take_range']==[0,4], c" "$tmp/sinfo.json"
then ok "take convert to {camera}_A001C003.#### from 1001"; else fail "take convert seq: $(cat "$tmp/conv2.err")"; fi

# The studio writes those forms itself: FFV1 videos and float EXR sequences from 1001, each with
# timecode, witness02 starting a frame late: the take model puts every camera in place.
for form in "ffv1" "exr --pattern {camera}.#### --start-number 1001"; do
  name="synth_${form%% *}"
  if "$bin" synth --preset studio --out "$tmp/$name" --frames 3 --cams 3 --size 160x90 --no-meshes --quiet \
       --format $form --timecode 10:00:00:00 --late witness02=1 > /dev/null 2> "$tmp/$name.err" \
     && "$bin" take info "$tmp/$name" --json > "$tmp/$name.json" 2>> "$tmp/$name.err" \
     && python3 - "$tmp/$name.json" "${form%% *}" <<'PY'
import json, sys
j = json.load(open(sys.argv[1])); form = sys.argv[2]
c = {x["camera"]: x for x in j["cameras"]}
assert not j["mismatches"] and j["frames"] == 3, j
for name, x in c.items():
    late = name == "witness02"
    assert x["offset_from"] == "timecode" and x["take_range"] == [1 if late else 0, 2], x
    assert x["start_timecode"] == ("10:00:00:01" if late else "10:00:00:00"), x
    if form == "ffv1":
        assert x["kind"] == "video" and x["format"] == "ffv1" and x["offset"] == (-1 if late else 0), x
    else:
        assert x["kind"] == "sequence" and x["pattern"] == name + ".%04d.exr" and x["bit_depth"] == 32, x
        assert x["source_range"][0] == 1001 and x["offset"] == (1000 if late else 1001), x
PY
  then ok "synth --format ${form%% *} with timecode and a late camera: every camera in place"
  else fail "synth $form: $(tail -3 "$tmp/$name.err")"; fi
done

# carve: bit-identical depth wherever the same cameras give the same pixels.
carve() { "$bin" carve --take "$1" --rig "$rig" --main-poses "$poses" --voxel 0.02 --out "$2" --quiet --json > "$2.json" 2> "$2.err"; }
carve "$take" "$tmp/c_png"; carve "$tmp/ffv1" "$tmp/c_ffv1"; carve "$tmp/seq" "$tmp/c_seq"
same=1
for f in 000000 000001 000002 000003 000004; do
  cmp -s "$tmp/c_png/depth/$f.exr" "$tmp/c_seq/depth/$f.exr" || { same=0; echo "seq depth $f differs"; }
  cmp -s "$tmp/c_png/mesh/$f.ply" "$tmp/c_seq/mesh/$f.ply" || { same=0; echo "seq mesh $f differs"; }
done
for f in 000001 000002 000003 000004; do
  cmp -s "$tmp/c_png/depth/$f.exr" "$tmp/c_ffv1/depth/$f.exr" || { same=0; echo "ffv1 depth $f differs"; }
done
[ $same -eq 1 ] && ok "carve: depth and meshes bit-identical from PNG, FFV1 (late camera in place) and #### sequences" \
  || fail "carve outputs differ ($(cat "$tmp/c_ffv1.err" | tail -3))"
if python3 - "$tmp/c_ffv1/report/000000.json" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
d = {x["camera"]: x["reason"] for x in r["cameras_dropped"]}
assert list(d) == ["witness03"] and "cams/witness03.mkv" in d["witness03"], d
PY
then ok "carve: the late camera's missing take frame 0 is dropped, naming its video"; else fail "late camera frame 0"; fi

# track (frames on their own, so the poses do not depend on earlier frames): same poses.
track() { "$bin" track --take "$1" --rig "$rig" --props "$take/props.json" --main-poses "$poses" --frame-files \
            --out "$2" --quiet > /dev/null 2> "$2.err"; }
track "$take" "$tmp/t_png"; track "$tmp/ffv1" "$tmp/t_ffv1"; track "$tmp/seq" "$tmp/t_seq"
if python3 - "$tmp/t_png/frames" "$tmp/t_ffv1/frames" "$tmp/t_seq/frames" <<'PY'
import json, os, sys
def poses(d, f):
    j = json.load(open(os.path.join(d, "%06d.json" % f)))
    return {p["id"]: p.get("T_world_prop") for p in j["props"]}
def close(a, b):
    if a is None or b is None: return a == b
    return all(abs(x - y) <= 1e-9 for k in ("R", "t") for x, y in zip(sum(a[k], []) if k == "R" else a[k], sum(b[k], []) if k == "R" else b[k]))
tracked = 0
for f in range(5):
    a = poses(sys.argv[1], f)
    for other, frames in ((sys.argv[3], range(5)), (sys.argv[2], range(1, 5))):
        if f not in frames: continue
        b = poses(other, f)
        assert a.keys() == b.keys() and all(close(a[k], b[k]) for k in a), (f, other)
    tracked += sum(v is not None for v in a.values())
assert tracked >= 3, tracked
PY
then ok "track: prop poses within 1e-9 from every form"; else fail "track poses differ: $(tail -3 "$tmp/t_ffv1.err")"; fi

# run: the live loop's depth and composite, byte for byte.
run() { "$bin" run --take "$1" --rig "$rig" --out "$2" --voxel 0.02 --no-props --quiet > /dev/null 2> "$2.err"; }
run "$take" "$tmp/r_png"; run "$tmp/seq" "$tmp/r_seq"; run "$tmp/ffv1" "$tmp/r_ffv1"
same=1
for f in 000000 000001 000002 000003 000004; do
  for p in depth/$f.exr composite/$f.png; do
    cmp -s "$tmp/r_png/$p" "$tmp/r_seq/$p" || { same=0; echo "run seq $p differs"; }
  done
done
for f in 000001 000002 000003 000004; do
  cmp -s "$tmp/r_png/composite/$f.png" "$tmp/r_ffv1/composite/$f.png" || { same=0; echo "run ffv1 $f differs"; }
done
[ $same -eq 1 ] && ok "run: depth and composites bit-identical from every form" || fail "run outputs differ"

# batch: a carve-only plan over the PNG take and its #### copy gives the same depth.
batch() {
  "$bin" batch plan --takes "$1" --rig "$rig" --main-poses "$poses" --quality preview --depth-cameras main \
    --out "$2" > /dev/null 2> "$2.err" && "$bin" batch submit "$2" --jobs 1 --quiet > /dev/null 2>> "$2.err"
}
if batch "$take" "$tmp/b_png" && batch "$tmp/seq" "$tmp/b_seq"; then
  same=1; n=0
  for f in "$tmp/b_png/work/$(basename "$take")/carve/depth/"*.exr; do
    n=$((n + 1))
    cmp -s "$f" "$tmp/b_seq/work/seq/carve/depth/$(basename "$f")" || { same=0; echo "batch $(basename "$f") differs"; }
  done
  [ $same -eq 1 ] && [ $n -eq 5 ] && ok "batch: 5 frames of depth bit-identical from PNG and #### sequences" \
    || fail "batch depth differs (n=$n)"
else fail "batch: $(tail -3 "$tmp/b_png.err" "$tmp/b_seq.err")"; fi

# A clean plate the keyer cannot use (another size) drops its camera, named; the take goes on.
# The take names the PNG take's cameras through take.json "sources" (nothing copied).
mkdir -p "$tmp/badplate/clean"
python3 -c "
import json,sys; j=json.load(open(sys.argv[1])); j['sources']={'*': sys.argv[2] + '/cams/{camera}/%06d.png'}
json.dump(j, open(sys.argv[3], 'w'))" "$take/take.json" "$take" "$tmp/badplate/take.json"
python3 -c "
import struct, zlib, sys
# a 10x10 grey PNG
raw = b''.join(b'\x00' + b'\x80' * 30 for _ in range(10))
def chunk(t, d): return struct.pack('>I', len(d)) + t + d + struct.pack('>I', zlib.crc32(t + d) & 0xffffffff)
open(sys.argv[1], 'wb').write(b'\x89PNG\r\n\x1a\n' + chunk(b'IHDR', struct.pack('>IIBBBBB', 10, 10, 8, 2, 0, 0, 0)) + chunk(b'IDAT', zlib.compress(raw)) + chunk(b'IEND', b''))" "$tmp/badplate/clean/witness01.png"
if "$bin" carve --take "$tmp/badplate" --rig "$rig" --main-poses "$poses" --voxel 0.05 --frames 0:1 --out "$tmp/c_badplate" \
     --quiet > /dev/null 2> "$tmp/badplate.err" && python3 - "$tmp/c_badplate/report/000000.json" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
d = {x["camera"]: x["reason"] for x in r["cameras_dropped"]}
assert list(d) == ["witness01"] and "clean plate unusable" in d["witness01"] and "witness01.png" in d["witness01"], d
PY
then ok "carve: a clean plate of another size drops its camera, named; the frame is carved"
else fail "bad clean plate: $(cat "$tmp/badplate.err")"; fi

# The world's scale against the crate's tags (props.json, 0.12 m): metric with the true rig; a rig
# whose world is 10 % too large (every camera centre x 1.1: as a rig solved on a board printed
# 10 % small) is flagged, though its cameras agree with each other as well as before.
python3 - "$rig" "$tmp/rig_x1.1.json" <<'PY'
import json, sys
rig = json.load(open(sys.argv[1]))
for c in rig["cameras"]:
    c["T_world_cam"]["t"] = [1.1 * v for v in c["T_world_cam"]["t"]]
json.dump(rig, open(sys.argv[2], "w"))
PY
"$bin" take check "$take" --rig "$rig" --main-poses "$poses" --json --quiet > "$tmp/scale1.json" 2> "$tmp/scale1.err"; rc1=$?
"$bin" take check "$take" --rig "$tmp/rig_x1.1.json" --json --quiet > "$tmp/scale2.json" 2> "$tmp/scale2.err"; rc2=$?
if [ $rc1 -eq 0 ] && [ $rc2 -eq 3 ] && python3 - "$tmp/scale1.json" "$tmp/scale2.json" <<'PY'
import json, sys
a, b = (json.load(open(f)) for f in sys.argv[1:3])
print("scale: true rig %.4f (%d edges), rig x1.1 %.4f" % (a["scale"]["ratio"], a["scale"]["edges"], b["scale"]["ratio"]))
assert a["scale"]["edges"] >= 8 and abs(a["scale"]["ratio"] - 1) < 0.01 and not a["scale"]["flagged"], a["scale"]
assert abs(b["scale"]["ratio"] - 1.1) < 0.015 and b["scale"]["flagged"], b["scale"]
assert not any(c["flagged"] for c in a["cameras"]), [c["camera"] for c in a["cameras"] if c["flagged"]]
PY
then ok "take check: the world's scale from the tags is metric with the true rig, flagged at x1.1"
else fail "take check scale (rc $rc1, $rc2): $(tail -3 "$tmp/scale1.err" "$tmp/scale2.err")"; fi

# Bad input: a take whose cameras previz cannot read at all fails, it does not "succeed" empty.
mkdir -p "$tmp/unreadable/cams"
for c in $(python3 -c "import json; print(' '.join(c['name'] for c in json.load(open('$rig'))['cameras']))"); do
  mkdir -p "$tmp/unreadable/cams/$c"; echo "not an image" > "$tmp/unreadable/cams/$c/000000.png"
done
cp "$take/take.json" "$tmp/unreadable/"
expect_fail "carve: every camera unreadable fails the frames and exits non-zero" "failed|usable" \
  "$bin" carve --take "$tmp/unreadable" --rig "$rig" --out "$tmp/c_bad" --voxel 0.05 --quiet
[ ! -e "$tmp/c_bad/depth/000000.exr" ] && ok "carve: no depth written for a failed frame" || fail "depth written for a failed frame"
expect_fail "take info: no take folder" "take folder not found" "$bin" take info "$tmp/nope"
expect_fail "take convert: unknown format" "format" "$bin" take convert "$take" --out "$tmp/x" --format webp
mkdir -p "$tmp/empty_take"
expect_fail "take info: a folder with no camera in it exits non-zero" "no camera found" "$bin" take info "$tmp/empty_take"
expect_fail "take convert: a corrupt frame names its file and camera" "000000.png': camera '[a-z0-9]+': frame 0: cannot convert" \
  "$bin" take convert "$tmp/unreadable" --out "$tmp/conv_bad" --format png --quiet
[ ! -e "$tmp/conv_bad" ] && ok "take convert: a failed conversion leaves no half-written take" || fail "take convert left $tmp/conv_bad"
mkdir -p "$tmp/nostream" && cp "$take/take.json" "$tmp/nostream/"
for c in $(ls "$take/cams"); do mkdir -p "$tmp/nostream/cams/$c"; done
expect_fail "take convert: no camera with a stream is an error" "no camera of the take has a usable stream" \
  "$bin" take convert "$tmp/nostream" --out "$tmp/conv_none" --format png --quiet
[ ! -e "$tmp/conv_none" ] && ok "take convert: nothing written when no camera has a stream" || fail "take convert wrote $tmp/conv_none"
# One camera without frames: the others are converted, the camera is named, and the status says so.
cp -r "$take" "$tmp/partial" && rm -rf "$tmp/partial/out"
bad=$(ls "$tmp/partial/cams" | head -1)
rm -f "$tmp/partial/cams/$bad"/*
"$bin" take convert "$tmp/partial" --out "$tmp/conv_part" --format png --quiet 2> "$tmp/conv_part.err"; rc=$?
if [ $rc -eq 3 ] && grep -q "left out $bad" "$tmp/conv_part.err" && [ -e "$tmp/conv_part/take.json" ]; then
  ok "take convert: a camera left out is named and exits 3, the rest converted"
else fail "take convert partial (rc $rc): $(cat "$tmp/conv_part.err")"; fi

finish
