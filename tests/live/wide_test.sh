#!/usr/bin/env bash
# The hot loops' AVX2 and baseline versions (core/simd.h, PREVIZ_WIDE) give the same bits:
# `previz run` (key, carve, depth, props, composite; once with the debug layers, once as live
# preview: witnesses binned 2 x 2, the composite without layers, whose CG-only pixels go two at a
# time) and `previz carve` (the 5 mm hull, its mesh and main-view depth) on a small studio take, natively (the AVX2 versions: the test needs a CPU
# with AVX2) and under qemu-x86_64 emulating a CPU without AVX (Nehalem: the baseline versions).
# Every output file is compared byte for byte, the JSON lines with their timings taken out.
#   wide_test.sh PREVIZ_BIN TMPDIR
bin="$1"; tmp="$2"
. "$(dirname "$0")/../cli/checks.sh"
rm -rf "$tmp"; mkdir -p "$tmp"

if ! grep -qw avx2 /proc/cpuinfo; then
  echo "skipped: this CPU has no AVX2, so the native run is the baseline version too"
  exit 77
fi
qemu=$(command -v qemu-x86_64) || { fail "qemu-x86_64 not found (scripts/setup.sh installs qemu-user)"; finish; exit 1; }
emulated() { QEMU_CPU=Nehalem "$qemu" "$@"; }
[ "$(emulated "$bin" --version 2>/dev/null)" = "$("$bin" --version)" ] && ok "previz runs under qemu-x86_64 -cpu Nehalem" \
  || { fail "previz does not run under qemu-x86_64 -cpu Nehalem"; finish; exit 1; }

# 4 witnesses at 640x360 and the main camera at 960x540 (tags large enough to decode), 2 frames.
if ! "$bin" synth --preset studio --out "$tmp/take" --frames 2 --cams 4 --size 640x360 --main-size 960x540 \
     --no-meshes --quiet >/dev/null 2>&1; then
  fail "synth studio take"; finish; exit 1
fi
take="$tmp/take"

# Both runs with the same thread count: the work split is the same, so the only difference is
# the code the CPU runs.
for who in native emulated; do
  run=(); [ $who = emulated ] && run=(emulated)
  "${run[@]}" "$bin" run --take "$take" --out "$tmp/run_$who" --layers --threads 2 --quiet 2> "$tmp/run_$who.err" \
    && ok "run ($who)" || fail "run ($who): $(grep -v '^qemu' "$tmp/run_$who.err")"
  "${run[@]}" "$bin" run --take "$take" --out "$tmp/preview_$who" --witness-bin 2 --threads 2 --quiet \
      2> "$tmp/preview_$who.err" \
    && ok "run --witness-bin 2 ($who)" || fail "run --witness-bin 2 ($who): $(grep -v '^qemu' "$tmp/preview_$who.err")"
  "${run[@]}" "$bin" carve --take "$take" --rig "$take/truth/rig.json" --main-poses "$take/truth/main_poses.jsonl" \
      --out "$tmp/carve_$who" --no-points --threads 2 --quiet 2> "$tmp/carve_$who.err" \
    && ok "carve ($who)" || fail "carve ($who): $(grep -v '^qemu' "$tmp/carve_$who.err")"
done

# Every file of both outputs, the same list and the same bytes; JSON lines compared without
# their timings.
for out in run preview carve; do
  a="$tmp/${out}_native" b="$tmp/${out}_emulated"
  if python3 - "$a" "$b" <<'PY'
import json, os, sys
a, b = sys.argv[1:3]
def files(root):
    return sorted(os.path.relpath(os.path.join(d, f), root) for d, _, fs in os.walk(root) for f in fs)
fa, fb = files(a), files(b)
assert fa == fb, (set(fa) ^ set(fb))
assert any(f.endswith(".png") for f in fa) and any(f.endswith(".exr") for f in fa), fa
def strip(x):  # the timings: "ms" (per stage) and "total_ms"
    if isinstance(x, dict):
        return {k: strip(v) for k, v in x.items() if k != "ms" and not k.endswith("_ms")}
    if isinstance(x, list):
        return [strip(v) for v in x]
    return x
bad = []
for f in fa:
    pa, pb = os.path.join(a, f), os.path.join(b, f)
    if f.endswith(".jsonl") or f.endswith(".json"):
        la = [strip(json.loads(l)) for l in open(pa) if l.strip()]
        lb = [strip(json.loads(l)) for l in open(pb) if l.strip()]
        if la != lb:
            bad.append(f)
    elif open(pa, "rb").read() != open(pb, "rb").read():
        bad.append(f)
print(f"{len(fa)} files compared", file=sys.stderr)
assert not bad, bad
PY
  then ok "$out: AVX2 and baseline versions give the same bytes"; else fail "$out: AVX2 and baseline outputs differ"; fi
done
finish
