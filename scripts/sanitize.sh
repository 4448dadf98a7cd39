#!/usr/bin/env bash
# The test suite built with AddressSanitizer + UndefinedBehaviorSanitizer (its own build folder,
# build-sanitize/) and run through CTest: every test must pass clean (any report fails its test:
# the sanitizers abort the process).
#   bash scripts/sanitize.sh [ctest arguments]      e.g. -R tracking, or -E 'batch|multicam'
#   PREVIZ_SANITIZE_DIR  build folder (default: build-sanitize)
#   PREVIZ_JOBS          parallel build jobs and tests (default: number of cores)
#   PREVIZ_SANITIZE_TARGETS  only these build targets (default: all), e.g. "core_tests tracking_tests"
# The Debian packages are those of scripts/setup.sh (run it first on a fresh machine).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${PREVIZ_SANITIZE_DIR:-$here/build-sanitize}"
jobs="${PREVIZ_JOBS:-$(nproc)}"

flags="-fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=undefined"
generator=()
command -v ninja >/dev/null && generator=(-G Ninja)
if [ ! -f "$build/CMakeCache.txt" ]; then
  # RelWithDebInfo: optimised as the shipped build is (-O2), with line tables only (-g1: the reports
  # name file and line; full debug information would double the build time on 2 cores).
  cmake -S "$here" -B "$build" "${generator[@]}" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DPREVIZ_BUILD_BENCH=OFF -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O2 -g1 -DNDEBUG" -DCMAKE_C_FLAGS_RELWITHDEBINFO="-O2 -g1 -DNDEBUG" -DCMAKE_CXX_FLAGS="$flags" -DCMAKE_C_FLAGS="$flags" \
    -DCMAKE_EXE_LINKER_FLAGS="-fsanitize=address,undefined" \
    -DCMAKE_SHARED_LINKER_FLAGS="-fsanitize=address,undefined" \
    -DCMAKE_MODULE_LINKER_FLAGS="-fsanitize=address,undefined"
fi
targets=()
for t in ${PREVIZ_SANITIZE_TARGETS:-}; do targets+=(--target "$t"); done
cmake --build "$build" --parallel "$jobs" "${targets[@]}"

# abort_on_error: a report ends the test as a crash would. detect_leaks with the suppressions of
# scripts/sanitize.supp (what libgomp's thread pool and the system libraries keep for the
# process's life). libgomp: OMP_WAIT_POLICY=passive, so that idle worker threads sleep instead of
# spinning (ASan makes their spin loops slow enough to starve the tests on 2 cores).
export ASAN_OPTIONS="abort_on_error=1:detect_leaks=1:detect_odr_violation=0:allocator_may_return_null=0${ASAN_OPTIONS:+:$ASAN_OPTIONS}"
export LSAN_OPTIONS="suppressions=$here/scripts/sanitize.supp:print_suppressions=0${LSAN_OPTIONS:+:$LSAN_OPTIONS}"
export UBSAN_OPTIONS="print_stacktrace=1:halt_on_error=1${UBSAN_OPTIONS:+:$UBSAN_OPTIONS}"
export OMP_WAIT_POLICY=passive
# Sanitized code runs 2-4x slower (more on a loaded machine): every test's own time limit (the
# TIMEOUT properties in the generated CTest files) is multiplied by PREVIZ_SANITIZE_TIMEOUT_SCALE
# (default 4), from a pristine copy so that a second run does not multiply again; tests without
# a limit of their own get 30 minutes. A fixture that times out (multicam.capture renders and
# detects 10,000 images) would otherwise fail every test that needs it.
scale="${PREVIZ_SANITIZE_TIMEOUT_SCALE:-4}"
while IFS= read -r -d '' f; do
  if [ ! -f "$f.unscaled" ] || [ "$f" -nt "$f.unscaled" ]; then cp "$f" "$f.unscaled"; fi
  perl -pe 's/(\bTIMEOUT\s+"?)(\d+)/$1 . ($2 * '"$scale"')/ge' "$f.unscaled" > "$f.scaled"
  mv "$f.scaled" "$f"
  touch -r "$f.unscaled" "$f"
done < <(find "$build" \( -name CTestTestfile.cmake -o -name '*_tests.cmake' \) -print0)
ctest --test-dir "$build" --output-on-failure --parallel "$jobs" --timeout 1800 "$@"
