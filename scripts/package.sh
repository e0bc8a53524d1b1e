#!/usr/bin/env bash
# Packages hemirad from a release build tree:
#   dist/hemirad-<version>-linux-x86_64.tar.gz   the relocatable bundle: bin/hemirad, the libraries it
#                                                 needs in lib/ (found through $ORIGIN/../lib), the
#                                                 bundled scenes, gpu-check.sh and a README of its own
#   dist/hemirad_<version>_amd64.deb             the full build under /usr, its Debian dependencies
#                                                 declared (apt install ./dist/hemirad_<version>_amd64.deb)
#
# Usage: scripts/package.sh [--bundle-only] [--build DIR] [--out DIR]
#   --build DIR   the build tree (default build/release, configured with the release preset when
#                 it is missing)
#   --out DIR     where the packages go (default dist/)
# Before writing the bundle it checks that the bundled executable resolves every library inside
# the bundle but the C and C++ runtime (scripts/check-bundle.sh runs it as a bare machine would).
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD

build=build/release
out=dist
deb=1
while [ $# -gt 0 ]; do
    case "$1" in
        --bundle-only) deb=0 ;;
        --build) build=$2; shift ;;
        --out) out=$2; shift ;;
        *) echo "package.sh: unknown argument '$1' (usage: scripts/package.sh [--bundle-only] [--build DIR] [--out DIR])" >&2
           exit 2 ;;
    esac
    shift
done

if [ ! -f "$build/CMakeCache.txt" ]; then
    [ "$build" = build/release ] || { echo "package.sh: $build is not a configured build tree" >&2; exit 2; }
    cmake --preset release
fi
cmake --build "$build" --target hemirad hemirad_bundle

version=$(sed -n 's/^project(hemirad VERSION \([0-9.]*\).*/\1/p' CMakeLists.txt)
name=hemirad-$version-linux-x86_64
stage=$build/package
rm -rf "$stage"
mkdir -p "$stage" "$out"
cmake --install "$build" --component bundle --prefix "$stage/$name" >/dev/null
scripts/check-bundle.sh --libraries-only "$stage/$name"

# The same bytes for the same files: names sorted, owners and times fixed.
tar -C "$stage" --sort=name --owner=0 --group=0 --numeric-owner --mtime=@0 -cf - "$name" | gzip -n -9 > "$out/$name.tar.gz"
echo "package.sh: wrote $out/$name.tar.gz ($(du -h "$out/$name.tar.gz" | cut -f1))"

if [ "$deb" = 1 ]; then
    cpack --config "$build/CPackConfig.cmake" -B "$root/$stage/deb" >/dev/null
    mv "$stage/deb/hemirad_${version}_amd64.deb" "$out/"
    echo "package.sh: wrote $out/hemirad_${version}_amd64.deb ($(du -h "$out/hemirad_${version}_amd64.deb" | cut -f1)): $(dpkg-deb -f "$out/hemirad_${version}_amd64.deb" Depends)"
fi
