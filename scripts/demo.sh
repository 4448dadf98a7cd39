#!/usr/bin/env bash
# README command 1: set up, build, then run the demo on the built-in synthetic studio.
# Extra arguments go to `previz demo` (see `build/app/previz demo --help`).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
bash "$here/scripts/setup.sh"
build="${PREVIZ_BUILD_DIR:-$here/build}"
"$build/app/previz" demo --out "$here/out/demo" "$@"
