#!/usr/bin/env bash
# Installs the Debian 12 packages previz needs (only those missing), then configures and builds
# previz into build/ (Ninja + ccache when present). Safe to run again: it only does what is left.
#   PREVIZ_BUILD_DIR  build folder (default: build)
#   PREVIZ_JOBS       parallel build jobs (default: number of cores)
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
build="${PREVIZ_BUILD_DIR:-$here/build}"
jobs="${PREVIZ_JOBS:-$(nproc)}"

packages=(
  build-essential cmake ninja-build ccache pkg-config
  libeigen3-dev libceres-dev libopencv-dev libopencv-contrib-dev libopenexr-dev
  nlohmann-json3-dev libcli11-dev libapriltag-dev libpcl-dev
  libpng-dev libjpeg-dev   # PNG and JPEG read and written without OpenCV's imgcodecs (core/detail/image_codecs.h)
  libavformat-dev libavcodec-dev libavutil-dev libswscale-dev   # video takes: containers, timecode
  libgtest-dev libgmock-dev libbenchmark-dev
  slurm-wlm munge chromium   # batch tests: a loopback Slurm cluster, the summary page in Chromium
  python3 python3-jsonschema   # OpenTrackIO tests: payloads checked against the SMPTE schema
  qemu-user   # tests/live/wide_test.sh: the hot loops' baseline versions run on an emulated CPU without AVX
  clang libclang-rt-14-dev libomp-dev   # scripts/fuzz.sh: clang with libFuzzer and the sanitizers (a Recommends of clang, not installed by --no-install-recommends), OpenMP for clang
)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if ((${#missing[@]})); then
  echo "setup: installing ${missing[*]}" >&2
  sudo=""
  if [ "$(id -u)" -ne 0 ]; then
    command -v sudo >/dev/null || { echo "setup: need root or sudo to apt-get install ${missing[*]}" >&2; exit 1; }
    sudo="sudo"
  fi
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
else
  echo "setup: all ${#packages[@]} Debian packages present" >&2
fi

generator=()
command -v ninja >/dev/null && generator=(-G Ninja)
if [ ! -f "$build/CMakeCache.txt" ]; then
  cmake -S "$here" -B "$build" "${generator[@]}" -DCMAKE_BUILD_TYPE=Release
fi
cmake --build "$build" --parallel "$jobs"
echo "setup: built into $build" >&2
