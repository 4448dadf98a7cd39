#!/usr/bin/env bash
# scripts/bundle.sh as a user meets it: a folder that runs `previz --version` and `previz bench
# run` under `env -i` (the script checks that, its size and that every library resolves inside
# it); a plugin left out is named when a command needs it; a plugin put in loads from the folder.
#   bundle_test.sh PREVIZ_BIN PROJECT_DIR TMPDIR
set -uo pipefail
bin="$1"; project="$2"; tmp="$3"
rm -rf "$tmp"; mkdir -p "$tmp"
source "$(dirname "${BASH_SOURCE[0]}")/checks.sh"
# The size limits are the shipped build's; a sanitized build scales them (tests/cli/CMakeLists.txt).
scale="${PREVIZ_BUNDLE_MIB_SCALE:-1}"

if bash "$project/scripts/bundle.sh" "$tmp/bundle" --previz "$bin" --max-mib $((64 * scale)) >"$tmp/bundle.log" 2>&1; then
  ok "bundle.sh: $(grep 'MiB' "$tmp/bundle.log")"
else
  fail "bundle.sh: $(tail -n 5 "$tmp/bundle.log")"; finish; exit 1
fi
expect_fail "bundle.sh refuses to replace a folder that is not a bundle" "not a previz bundle" \
  bash -c "mkdir -p '$tmp/other' && touch '$tmp/other/keep' && bash '$project/scripts/bundle.sh' '$tmp/other' --previz '$bin'"

b="$tmp/bundle/previz"
# bundled NAME BUNDLE ARGS...: runs BUNDLE/previz ARGS under env -i with the loader's log in
# $tmp/NAME.ld.*; true when it succeeds.
bundled() {
  local name="$1" dir="$2"; shift 2
  rm -f "$tmp/$name".ld.*
  env -i LD_DEBUG=files LD_DEBUG_OUTPUT="$tmp/$name.ld" "$dir/previz" "$@" >/dev/null 2>&1
}
# outside NAME BUNDLE: what the run NAME loaded from outside BUNDLE but glibc and the C++ runtime.
outside() {
  cat "$tmp/$1".ld.* 2>/dev/null | grep -o 'calling init: [^ ]*' | awk '{print $3}' | grep -v "^$2/" |
    grep -Ev '/(libc|libm|libpthread|libdl|librt|libstdc\+\+|libgcc_s|ld-linux[^/]*)\.so' | sort -u | tr '\n' ' '
}
env -i "$b" synth --preset studio --out "$tmp/take" --frames 1 --cams 2 --size 160x90 --main-size 240x135 --no-meshes \
  --quiet >/dev/null 2>&1 && ok "env -i bundled synth" || fail "env -i bundled synth"
carve=(carve --take "$tmp/take" --rig "$tmp/take/truth/rig.json" --masks "$tmp/take/truth/masks" --voxel 0.05 --quiet)
bundled c1 "$tmp/bundle" "${carve[@]}" --out "$tmp/c1" --no-points && ok "env -i bundled carve --no-points" \
  || fail "env -i bundled carve --no-points"
o=$(outside c1 "$tmp/bundle")
[ -z "$o" ] && ok "carve loads nothing from outside the bundle" || fail "carve loaded $o"
# TBB looks for its allocator beside itself, by name (no ldd shows it): the bundle has it.
if [ -e "$tmp/bundle/lib/libtbb.so.12" ]; then
  grep -q "calling init: $tmp/bundle/lib/libtbbmalloc.so.2" "$tmp"/c1.ld.* 2>/dev/null \
    && ok "TBB's allocator loads from the bundle" || fail "TBB's allocator not loaded from the bundle"
fi
expect_fail "a plugin left out of the bundle is named with where it was looked for" \
  "previz_pointcloud plugin .*not installed: no .*$tmp/bundle/lib/previz_pointcloud.so" env -i "$b" "${carve[@]}" --out "$tmp/c2"

# With the point-cloud plugin (and PCL with it: over the default 64 MiB) the carve writes its
# cloud, loading PCL from the folder.
if bash "$project/scripts/bundle.sh" "$tmp/bundle_pcl" --previz "$bin" --plugins pointcloud --max-mib $((512 * scale)) \
    >"$tmp/bundle_pcl.log" 2>&1; then
  ok "bundle.sh --plugins pointcloud: $(grep 'MiB' "$tmp/bundle_pcl.log")"
else
  fail "bundle.sh --plugins pointcloud: $(tail -n 5 "$tmp/bundle_pcl.log")"
fi
if bundled c3 "$tmp/bundle_pcl" "${carve[@]}" --out "$tmp/c3" && [ -s "$tmp/c3/points/000000.pcd" ]; then
  ok "env -i bundled carve with the point-cloud plugin writes its cloud"
else
  fail "env -i bundled carve with the point-cloud plugin"
fi
o=$(outside c3 "$tmp/bundle_pcl")
[ -z "$o" ] && ok "the plugin and PCL load from the bundle" || fail "loaded from outside the bundle: $o"
grep -q "calling init: $tmp/bundle_pcl/lib/previz_pointcloud.so" "$tmp"/c3.ld.* 2>/dev/null \
  && ok "previz_pointcloud.so loaded from the bundle's lib/" || fail "previz_pointcloud.so not loaded from the bundle"

finish
