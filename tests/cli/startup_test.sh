#!/usr/bin/env bash
# previz's start-up (issue 31): the executable links no more than 80 shared libraries, and the
# heavy ones (FFmpeg, OpenCV's videoio and imgcodecs, PCL) load only with the plugin that needs
# them, when a command needs it (core/plugin.h). What loads is read from the dynamic loader
# (LD_DEBUG=files); how fast it starts is measured by `previz bench run`, not here.
#   startup_test.sh PREVIZ_BIN TMPDIR
set -uo pipefail
bin="$1"; tmp="$2"
rm -rf "$tmp"; mkdir -p "$tmp"
source "$(dirname "${BASH_SOURCE[0]}")/checks.sh"

# loaded NAME CMD...: runs CMD with the loader's log; leaves in $tmp/NAME.loaded the paths of
# every object it loaded (also with dlopen) and fails the check when CMD fails.
loaded() {
  local name="$1"; shift
  rm -f "$tmp/ld.$name".*
  if LD_DEBUG=files LD_DEBUG_OUTPUT="$tmp/ld.$name" "$@" >"$tmp/$name.out" 2>&1; then
    ok "$name runs"
  else
    fail "$name runs: $(tail -n 5 "$tmp/$name.out")"
  fi
  cat "$tmp/ld.$name".* 2>/dev/null | grep -o 'calling init: [^ ]*' | awk '{print $3}' | sort -u >"$tmp/$name.loaded"
  rm -f "$tmp/ld.$name".*
}
# has NAME PATTERN / lacks NAME PATTERN [WHAT]: whether a loaded object's file name matches PATTERN.
has()   { grep -Eq "/$2" "$tmp/$1.loaded" && ok "$1 loads $2" || fail "$1 does not load $2"; }
lacks() {
  local hits; hits=$(grep -E "/$2" "$tmp/$1.loaded" | xargs -r -n1 basename | tr '\n' ' ')
  [ -z "$hits" ] && ok "$1 does not load ${3:-$2}" || fail "$1 loads $hits"
}
heavy='(previz_[a-z_]+\.so|libopencv_(videoio|imgcodecs)|libav(format|codec)|libpcl_|libvtk|libgdal)'

n=$(ldd "$bin" | wc -l)
[ "$n" -le 80 ] && ok "ldd previz: $n libraries (<= 80)" || fail "ldd previz: $n libraries (> 80): $(ldd "$bin" | awk '{print $1}' | tr '\n' ' ')"

loaded version "$bin" --version
lacks version "$heavy" "plugins, videoio, imgcodecs, FFmpeg, PCL, VTK, GDAL"
[ "$(wc -l < "$tmp/version.loaded")" -le 80 ] && ok "--version maps <= 80 objects" || fail "--version maps $(wc -l < "$tmp/version.loaded")"

# A small take of PNG sequences: reading it loads neither video nor imgcodecs.
loaded synth "$bin" synth --preset studio --out "$tmp/take" --frames 1 --cams 2 --size 160x90 --main-size 240x135 --no-meshes --quiet
lacks synth "$heavy" "plugins, videoio, imgcodecs, FFmpeg, PCL, VTK, GDAL"
carve=("$bin" carve --take "$tmp/take" --rig "$tmp/take/truth/rig.json" --masks "$tmp/take/truth/masks" --voxel 0.05 --quiet)
loaded carve_no_points "${carve[@]}" --out "$tmp/carve_no_points" --no-points
lacks carve_no_points "$heavy" "plugins, videoio, imgcodecs, FFmpeg, PCL, VTK, GDAL"
[ ! -e "$tmp/carve_no_points/points" ] && [ -s "$tmp/carve_no_points/mesh/000000.ply" ] \
  && ok "carve --no-points writes the mesh, no point cloud" || fail "carve --no-points outputs: $(ls "$tmp/carve_no_points")"
loaded carve_points "${carve[@]}" --out "$tmp/carve_points"
has carve_points 'previz_pointcloud\.so'
has carve_points 'libpcl_io'
lacks carve_points '(previz_video|previz_imgcodecs|libopencv_videoio|libavformat)'
[ -s "$tmp/carve_points/points/000000.pcd" ] && ok "carve writes the point cloud" || fail "carve: no points/000000.pcd"

# Videos load the video plugin (and with it FFmpeg and videoio), then only.
loaded synth_video "$bin" synth --preset studio --out "$tmp/video_take" --frames 2 --cams 2 --size 160x90 \
  --main-size 240x136 --format ffv1 --no-meshes --quiet
has synth_video 'previz_video\.so'
has synth_video 'libavformat'
lacks synth_video '(previz_pointcloud|previz_imgcodecs|libpcl_)'

finish
