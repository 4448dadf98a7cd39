#!/usr/bin/env bash
# A relocatable previz: OUT/previz and, in OUT/lib, every shared library it loads beyond glibc
# and the C++ runtime (libc, libm, libpthread, libdl, librt, the dynamic loader, libstdc++,
# libgcc_s), so that it runs on a newer Linux that has none of previz's Debian packages (its
# glibc and libstdc++ at least as new as this machine's). previz finds them through its RPATH,
# $ORIGIN/lib, set when it is linked (app/CMakeLists.txt; DT_RPATH, so that it also serves the
# libraries those libraries load), and its plugins in OUT/lib (core/plugin.h).
#
#   bash scripts/bundle.sh OUT [--previz BIN] [--plugins none|all|LIST] [--max-mib N]
#
#   --previz   the executable to bundle (default: $PREVIZ_BUILD_DIR/app/previz, build/app/previz)
#   --plugins  which plugins to add, with every library they load: previz_video,
#              previz_composite_video, previz_pointcloud, previz_imgcodecs (names or all; the
#              previz_ prefix may be left out). Default none: FFmpeg, OpenCV's videoio, PCL and
#              OpenCV's imgcodecs are 115 to 285 MiB each with what they load; without them a
#              command that needs one (a video take, a carve's point cloud, a TIFF) says which
#              plugin is missing, and everything else works.
#   --max-mib  the size the folder must not exceed (default 64)
#
# Then checks the folder, failing when any check fails: its size (printed); every library it
# needs resolves inside it; `previz --version` and a short `previz bench run` (on a small take
# previz synth renders) run under `env -i` (no LD_LIBRARY_PATH, no PATH), loading nothing from
# outside the folder but glibc and the C++ runtime.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"

usage() { sed -n '9,19p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//' >&2; exit 2; }
[ $# -ge 1 ] || usage
out="$1"; shift
bin="${PREVIZ_BUILD_DIR:-$here/build}/app/previz"
plugins="none"
max_mib=64
while [ $# -gt 0 ]; do
  case "$1" in
    --previz) bin="$2"; shift 2 ;;
    --plugins) plugins="$2"; shift 2 ;;
    --max-mib) max_mib="$2"; shift 2 ;;
    *) usage ;;
  esac
done
die() { echo "bundle: $*" >&2; exit 1; }
[ -x "$bin" ] || die "no previz executable at $bin (build it: cmake --build build --target previz, or --previz BIN)"
bin="$(readlink -f "$bin")"
plugin_dir="$(dirname "$bin")/../lib"

all_plugins=(previz_video previz_composite_video previz_pointcloud previz_imgcodecs)
chosen=()
case "$plugins" in
  none) ;;
  all) chosen=("${all_plugins[@]}") ;;
  *) IFS=, read -ra names <<<"$plugins"
     for n in "${names[@]}"; do
       n="previz_${n#previz_}"
       [[ " ${all_plugins[*]} " == *" $n "* ]] || die "unknown plugin '$n' (${all_plugins[*]})"
       chosen+=("$n")
     done ;;
esac

# Never empty a folder that is not a bundle.
if [ -e "$out" ]; then
  if [ -n "$(ls -A "$out" 2>/dev/null)" ] && [ ! -f "$out/previz" ]; then
    die "$out exists and is not a previz bundle: refusing to replace it"
  fi
  rm -rf "$out"
fi
mkdir -p "$out/lib"
out="$(cd "$out" && pwd)"

# glibc, the dynamic loader and the C++ runtime: the target system's own.
is_system() {
  case "$(basename "$1")" in
    linux-vdso.so.*|ld-linux*.so.*|libc.so.*|libm.so.*|libpthread.so.*|libdl.so.*|librt.so.*|libstdc++.so.*|libgcc_s.so.*) return 0 ;;
    *) return 1 ;;
  esac
}

# Every library 'elf' loads (ldd: the whole closure), copied under the name it is loaded by.
copy_closure() {
  local elf="$1" line name path
  while IFS= read -r line; do
    name="$(awk '{print $1}' <<<"$line")"
    is_system "$name" && continue
    [[ "$line" == *"=> not found"* ]] && die "$elf needs $name, which is not found on this machine"
    path="$(awk '$2 == "=>" {print $3}' <<<"$line")"
    [ -n "$path" ] || continue
    [ -e "$out/lib/$name" ] || cp -L "$path" "$out/lib/$name"
  done < <(ldd "$elf")
}

# Libraries loaded at run time by name rather than needed: TBB's scalable allocator, which libtbb
# looks for beside itself (without it TBB falls back to malloc, unlike previz in its build tree).
companions=("libtbb.so.12 libtbbmalloc.so.2")
copy_companions() {
  local pair lib companion from
  for pair in "${companions[@]}"; do
    read -r lib companion <<<"$pair"
    [ -e "$out/lib/$lib" ] && [ ! -e "$out/lib/$companion" ] || continue
    from="$(dirname "$(ldconfig -p | awk -v l="$lib" '$1 == l {print $NF; exit}')")/$companion"
    [ -e "$from" ] || continue
    cp -L "$from" "$out/lib/$companion"
    copy_closure "$out/lib/$companion"
  done
}

cp "$bin" "$out/previz"
copy_closure "$out/previz"
for p in "${chosen[@]}"; do
  [ -f "$plugin_dir/$p.so" ] || die "no plugin $plugin_dir/$p.so (build it: cmake --build build --target $p)"
  cp "$plugin_dir/$p.so" "$out/lib/$p.so"
  copy_closure "$out/lib/$p.so"
done
copy_companions

# ---- checks --------------------------------------------------------------------------------
bytes=$(du -sb "$out" | awk '{print $1}')
mib=$(awk -v b="$bytes" 'BEGIN {printf "%.1f", b / 1048576}')
count=$(find "$out/lib" -name '*.so*' | wc -l)
echo "bundle: $out: previz, $count libraries (plugins: ${chosen[*]:-none}), $mib MiB" >&2
awk -v b="$bytes" -v m="$max_mib" 'BEGIN {exit !(b <= m * 1048576)}' ||
  die "$mib MiB is over the $max_mib MiB limit (--max-mib)"

# Every library previz and its plugins need resolves inside the folder (previz's RPATH; the
# plugins' own, $ORIGIN).
for elf in "$out/previz" "$out"/lib/previz_*.so; do
  [ -e "$elf" ] || continue
  while IFS= read -r line; do
    name="$(awk '{print $1}' <<<"$line")"
    is_system "$name" && continue
    path="$(awk '$2 == "=>" {print $3}' <<<"$line")"
    [[ "$(readlink -f "$path")" == "$out/lib/"* ]] || die "$(basename "$elf") resolves $name outside the bundle: $line"
  done < <(env -i /usr/bin/ldd "$elf")
done

# Runs OUT/previz ARGS under env -i; fails when it fails or loads a library from outside the
# folder (other than glibc and the C++ runtime).
run_clean() {
  local log="$work/loader.log" rc=0
  env -i LD_DEBUG=files LD_DEBUG_OUTPUT="$work/ld" "$out/previz" "$@" >"$work/stdout" 2>"$work/stderr" || rc=$?
  cat "$work"/ld.* > "$log" 2>/dev/null || true
  rm -f "$work"/ld.*
  if [ $rc -ne 0 ]; then
    cat "$work/stderr" >&2
    die "env -i previz $* exited with $rc"
  fi
  local outside
  outside=$(grep -o 'calling init: [^ ]*' "$log" | awk '{print $3}' | while read -r lib; do
    case "$lib" in "$out"/*) ;; *) is_system "$(basename "$lib")" || echo "$lib" ;; esac
  done | sort -u)
  [ -z "$outside" ] || die "env -i previz $* loaded libraries from outside the bundle: $outside"
}
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
run_clean --version
echo "bundle: env -i previz --version: $(cat "$work/stdout")" >&2
# A small studio take (2 witnesses 320x180, main 480x270, 2 frames), then the frame loop on it.
run_clean synth --preset studio --out "$work/take" --frames 2 --cams 2 --size 320x180 --main-size 480x270 \
  --no-meshes --quiet
run_clean bench run --take "$work/take" --frames 1 --repeats 1 --out "$work/bench"
echo "bundle: env -i previz bench run: $(tail -n 1 "$work/stdout" | head -c 200)..." >&2
echo "bundle: ok: $out" >&2
