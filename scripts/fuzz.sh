#!/usr/bin/env bash
# Fuzzes every parser of outside input (fuzz/<harness>.cpp) with libFuzzer, AddressSanitizer and
# UndefinedBehaviorSanitizer, SECONDS each (default 60), one after the other:
#   bash scripts/fuzz.sh [SECONDS] [HARNESS...]
# Builds build-fuzz/ with clang (-DPREVIZ_FUZZ=ON: the previz libraries with
# -fsanitize=fuzzer-no-link,address,undefined, the harnesses with -fsanitize=fuzzer), only the
# harness targets. Each harness runs on a fresh copy of its seed corpus fuzz/corpus/<harness>/
# (build-fuzz/fuzz-run/<harness>/corpus: the repo's corpus is never written); the inputs that
# found new coverage are listed and left there (merge the useful ones into fuzz/corpus with
# `fuzz_<harness> -merge=1 fuzz/corpus/<harness> build-fuzz/fuzz-run/<harness>/corpus`).
# Prints per harness executions/s, corpus size and any finding (crash, leak, UB report, timeout,
# out-of-memory: the input is kept under build-fuzz/fuzz-run/<harness>/findings/); exits 1 when
# any harness found something.
#   PREVIZ_FUZZ_BUILD_DIR   build folder (default: build-fuzz)
#   PREVIZ_FUZZ_TIMEOUT_S   one input running longer is a finding (default 10)
#   PREVIZ_FUZZ_RSS_MB      memory limit (default 2048)
#   PREVIZ_FUZZ_SKIP_BUILD  1: run the harnesses as built (while another build uses build-fuzz/)
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${PREVIZ_FUZZ_BUILD_DIR:-$here/build-fuzz}"
seconds="${1:-60}"
shift || true
timeout_s="${PREVIZ_FUZZ_TIMEOUT_S:-10}"
rss_mb="${PREVIZ_FUZZ_RSS_MB:-2048}"
[[ "$seconds" =~ ^[0-9]+$ ]] || { echo "usage: scripts/fuzz.sh [SECONDS] [HARNESS...]" >&2; exit 2; }
command -v clang++ >/dev/null || { echo "fuzz: clang++ not found (scripts/setup.sh installs clang)" >&2; exit 2; }

skip_build="${PREVIZ_FUZZ_SKIP_BUILD:-0}"
if [ "$skip_build" != 1 ]; then
  generator=()
  command -v ninja >/dev/null && generator=(-G Ninja)
  # -O1 with line tables: sanitizer reports name file and line, and the build stays quick.
  cmake -S "$here" -B "$build" "${generator[@]}" -DCMAKE_CXX_COMPILER=clang++ \
    -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -gline-tables-only" \
    -DPREVIZ_FUZZ=ON -DPREVIZ_BUILD_TESTS=OFF -DPREVIZ_BUILD_BENCH=OFF >/dev/null
fi
if (($#)); then harnesses=("$@"); else mapfile -t harnesses < "$build/fuzz/harnesses.txt"; fi
targets=()
for h in "${harnesses[@]}"; do [ -n "$h" ] && targets+=("fuzz_$h"); done
if [ "$skip_build" != 1 ]; then
  nice cmake --build "$build" --target "${targets[@]}" -j "${PREVIZ_JOBS:-1}"
fi

export ASAN_OPTIONS="${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=1:symbolize=1}"
export UBSAN_OPTIONS="${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}"
status=0
summary=()
for h in "${harnesses[@]}"; do
  [ -n "$h" ] || continue
  exe="$build/fuzz/fuzz_$h"
  [ -x "$exe" ] || { echo "fuzz: no harness $h" >&2; status=1; continue; }
  run="$build/fuzz-run/$h"
  rm -rf "$run"
  mkdir -p "$run/corpus" "$run/findings"
  seeds=0
  if [ -d "$here/fuzz/corpus/$h" ]; then
    cp "$here/fuzz/corpus/$h/"* "$run/corpus/" 2>/dev/null || true
    seeds=$(find "$here/fuzz/corpus/$h" -type f | wc -l)
  fi
  echo "fuzz: $h for ${seconds} s ($seeds seeds)" >&2
  rc=0
  nice "$exe" "$run/corpus" -max_total_time="$seconds" -timeout="$timeout_s" -rss_limit_mb="$rss_mb" \
    -artifact_prefix="$run/findings/" -print_final_stats=1 >"$run/log.txt" 2>&1 || rc=$?
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$run/log.txt" | tail -1)
  rate=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$run/log.txt" | tail -1)
  corpus=$(find "$run/corpus" -type f | wc -l)
  new=$((corpus - seeds))
  found=$(find "$run/findings" -type f | wc -l)
  line=$(printf '%-18s %8s exec/s %9s execs  corpus %4d (%d new)' "$h" "${rate:-?}" "${execs:-?}" "$corpus" "$new")
  if ((rc != 0 || found > 0)); then
    status=1
    what=$(grep -m1 -E "ERROR: (AddressSanitizer|LeakSanitizer|libFuzzer)|runtime error:|SUMMARY:|previz fuzz|terminate called" "$run/log.txt" || true)
    line+="  FINDING (exit $rc): ${what:-see log}; input: $(find "$run/findings" -type f | head -1)"
  fi
  echo "$line" >&2
  summary+=("$line")
done

echo "" >&2
echo "fuzz: ${seconds} s per harness; logs and new inputs under $build/fuzz-run/<harness>/" >&2
printf '%s\n' "${summary[@]}"
exit "$status"
