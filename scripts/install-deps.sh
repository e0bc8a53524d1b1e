#!/usr/bin/env bash
# Installs hemirad's dependencies from Debian packages (bookworm or later).
#
# Usage: scripts/install-deps.sh [--bake]
#   (default)  everything the full build and its tests need (what CI installs)
#   --bake     only what building and running `hemirad` with the codecs image back-end needs
#              (the README's bake command, `cmake --preset bake`): no OpenImageIO, test, MPI,
#              Embree, fuzzing or plotting packages
set -euo pipefail

# What `hemirad` itself needs.
packages=(
  build-essential cmake ninja-build pkg-config
  ocl-icd-opencl-dev opencl-clhpp-headers pocl-opencl-icd
  libglm-dev
  libtinygltf-dev nlohmann-json3-dev libstb-dev
  # Compressed glTF geometry: EXT_meshopt_compression and KHR_draco_mesh_compression.
  libmeshoptimizer-dev libdraco-dev
  # The codecs image back-end (src/image/codecs.cpp; the bundle's): PNG, JPEG, WebP, EXR.
  libpng-dev libjpeg-dev libwebp-dev libopenexr-dev
  libcli11-dev libfmt-dev
  # The host stages' threads (src/core/parallel.h).
  libtbb-dev
)
case "${1:-}" in
  --bake) ;;
  "") packages+=(
  clinfo
  # The full build's image back-end. OpenImageIO's CMake config also names openimageio-tools,
  # python3-imath and OpenCV's headers.
  libopenimageio-dev openimageio-tools python3-imath libopencv-core-dev
  catch2
  # The ray-casting peer engine of bench/ (optional in CMake, installed here so CI builds it).
  libembree-dev
  # Bakes across MPI ranks (optional in CMake, installed here so CI builds and tests it).
  libopenmpi-dev openmpi-bin
  # tests/fuzz: the libFuzzer targets of the loader and the bake (clang, and the runtime of
  # libFuzzer and the sanitizers, which clang only recommends).
  clang libclang-rt-dev
  # bench/plot.py: PNG plots from the benchmark's JSON.
  python3 python3-matplotlib
  ) ;;
  *) echo "install-deps.sh: unknown argument '$1' (usage: scripts/install-deps.sh [--bake])" >&2; exit 2 ;;
esac

sudo=""
if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#packages[@]} packages present"
  exit 0
fi
echo "install-deps: installing ${missing[*]}"
$sudo apt-get update -qq
DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
