#!/usr/bin/env bash
# README command 2: set up, build, then run every test (CTest: GoogleTest suites and CLI checks).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$here/scripts/setup.sh"
build="${PREVIZ_BUILD_DIR:-$here/build}"
ctest --test-dir "$build" --output-on-failure --parallel "${PREVIZ_JOBS:-$(nproc)}" "$@"
