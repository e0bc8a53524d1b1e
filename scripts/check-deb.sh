#!/usr/bin/env bash
# Installs the Debian package (scripts/package.sh) with apt, bakes the Cornell box with the
# installed /usr/bin/hemirad from its installed scene, compares baked.bin with FULL_HEMIRAD's, and
# removes the package again unless it was installed before. Needs root or sudo (CI runs it).
#
# Usage: scripts/check-deb.sh DEB FULL_HEMIRAD
set -euo pipefail
[ $# -eq 2 ] || { echo "usage: scripts/check-deb.sh DEB FULL_HEMIRAD" >&2; exit 2; }
deb=$(cd "$(dirname "$1")" && pwd)/$(basename "$1")
full=$(cd "$(dirname "$2")" && pwd)/$(basename "$2")
sudo=""
if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
fail() { echo "check-deb: FAIL: $*" >&2; exit 1; }

work=$(mktemp -d "${TMPDIR:-/tmp}/hemirad-deb.XXXXXX")
had=0
dpkg-query -W -f='${Status}' hemirad 2>/dev/null | grep -q "install ok installed" && had=1
cleanup() {
    rm -rf "$work"
    if [ "$had" = 0 ]; then $sudo apt-get remove -y -qq hemirad > /dev/null 2>&1 || true; fi
}
trap cleanup EXIT

DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "$deb" > "$work/apt.log" 2>&1 ||
    fail "apt install $deb: $(tail -3 "$work/apt.log")"
[ -x /usr/bin/hemirad ] || fail "the package installed no /usr/bin/hemirad"
(cd "$work" && HEMIRAD_CACHE_DIR=off /usr/bin/hemirad bake /usr/share/hemirad/scenes/cornell_box.gltf -o installed 2> installed.log) ||
    fail "the installed hemirad's bake: $(tail -3 "$work/installed.log")"
(cd "$work" && HEMIRAD_CACHE_DIR=off "$full" bake /usr/share/hemirad/scenes/cornell_box.gltf -o built 2> built.log) ||
    fail "the built hemirad's bake: $(tail -3 "$work/built.log")"
cmp -s "$work/installed/baked.bin" "$work/built/baked.bin" || fail "the installed hemirad's baked.bin differs from the build's"
echo "check-deb: apt installed $(basename "$deb") ($(dpkg-query -W -f='${Depends}' hemirad | tr ',' '\n' | wc -l) dependencies); /usr/bin/hemirad baked the Cornell box: baked.bin $(md5sum < "$work/installed/baked.bin" | cut -c1-32), the build's"
