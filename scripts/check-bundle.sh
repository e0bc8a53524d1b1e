#!/usr/bin/env bash
# Checks a relocatable bundle (scripts/package.sh) as a bare machine would run it.
#
# Usage: scripts/check-bundle.sh [--libraries-only] BUNDLE [FULL_HEMIRAD]
#   BUNDLE        the bundle's .tar.gz (unpacked here into an empty folder) or its folder
#   FULL_HEMIRAD  a full build's hemirad: the bundle's bakes must give its baked.bin byte for byte,
#                 and bad input its exit codes and messages
#
# 1. Libraries: with an empty environment (no LD_LIBRARY_PATH), every library the executable
#    loads resolves inside the bundle, except the C and C++ runtime (glibc, libstdc++, libgcc_s).
# 2. Bakes (unless --libraries-only), from an empty working folder with an empty environment:
#    `hemirad devices`, the Cornell box and the textured lit room at default settings.
# 3. Bad input: a missing file, a broken glTF and broken PNG and JPEG textures (under
#    --strict-textures) give exit 2 and the full build's message.
set -euo pipefail

libraries_only=0
if [ "${1:-}" = --libraries-only ]; then libraries_only=1; shift; fi
[ $# -ge 1 ] || { echo "usage: scripts/check-bundle.sh [--libraries-only] BUNDLE [FULL_HEMIRAD]" >&2; exit 2; }
source_dir=$(cd "$(dirname "$0")/.." && pwd)
bundle=$1
full=${2:-}
[ -z "$full" ] || full=$(cd "$(dirname "$full")" && pwd)/$(basename "$full")

work=$(mktemp -d "${TMPDIR:-/tmp}/hemirad-bundle.XXXXXX")
trap 'rm -rf "$work"' EXIT
if [ -f "$bundle" ]; then
    mkdir "$work/unpacked"
    tar -C "$work/unpacked" -xzf "$bundle"
    bundle=$(echo "$work"/unpacked/*)
fi
bundle=$(cd "$bundle" && pwd)
exe=$bundle/bin/hemirad
fail() { echo "check-bundle: FAIL: $*" >&2; exit 1; }

# 1. What the dynamic loader resolves, in an empty environment.
rpath=$(readelf -d "$exe" | sed -n 's/.*(RPATH).*\[\(.*\)\]/\1/p')
[ "$rpath" = '$ORIGIN/../lib' ] || fail "bin/hemirad has RPATH '$rpath', not \$ORIGIN/../lib"
runtime='^(linux-vdso\.so|/?lib64/ld-linux-x86-64\.so|ld-linux-x86-64\.so|lib(c|m|dl|pthread|rt|resolv|util|anl|stdc\+\+|gcc_s)\.so)'
outside=0
while read -r line; do
    soname=$(echo "$line" | awk '{print $1}')
    path=$(echo "$line" | sed -n 's/.*=> \([^ ]*\) (.*/\1/p')
    case "$line" in *"not found"*) echo "  $soname: not found" >&2; outside=1; continue ;; esac
    [ -n "$path" ] || continue  # the vdso and the loader itself
    path=$(readlink -f "$path")
    case "$path" in
        "$bundle"/lib/*) ;;
        *) if ! echo "$soname" | grep -Eq "$runtime"; then echo "  $soname => $path (outside the bundle)" >&2; outside=1; fi ;;
    esac
done < <(env -i ldd "$exe")
[ "$outside" = 0 ] || fail "bin/hemirad needs libraries from outside the bundle (above)"
echo "check-bundle: $(ls "$bundle/lib" | wc -l) files in lib/; bin/hemirad resolves every library inside the bundle but the C/C++ runtime"
[ "$libraries_only" = 0 ] || exit 0

# 2. Bakes from an empty folder with an empty environment (PATH for nothing but the tools below).
bare() { (cd "$work/empty" && env -i PATH=/usr/bin:/bin HOME="$work/home" HEMIRAD_CACHE_DIR=off "$@"); }
mkdir -p "$work/empty" "$work/home"
bare "$exe" --version >/dev/null || fail "hemirad --version"
bare "$exe" devices > "$work/devices.txt" || fail "hemirad devices"
grep -q "OpenCL" "$work/devices.txt" || fail "hemirad devices lists no OpenCL platform: $(cat "$work/devices.txt")"
for scene in cornell_box lit_room; do
    start=$(date +%s%3N)
    bare "$exe" bake "$bundle/scenes/$scene.gltf" -o "$work/bundle_$scene" 2> "$work/bundle_$scene.log" ||
        fail "the bundle's bake of $scene: $(tail -3 "$work/bundle_$scene.log")"
    took=$(( $(date +%s%3N) - start ))
    for f in baked.bin baked.gltf report.json render.png render.exr; do
        [ -s "$work/bundle_$scene/$f" ] || fail "the bundle's bake of $scene wrote no $f"
    done
    line="$scene: baked in $((took / 1000)).$(printf %03d $((took % 1000))) s"
    if [ -n "$full" ]; then
        bare "$full" bake "$source_dir/scenes/$scene.gltf" -o "$work/full_$scene" 2> "$work/full_$scene.log" ||
            fail "the full build's bake of $scene: $(tail -3 "$work/full_$scene.log")"
        cmp -s "$work/bundle_$scene/baked.bin" "$work/full_$scene/baked.bin" ||
            fail "$scene: the bundle's baked.bin differs from the full build's"
        line="$line, baked.bin equal to the full build's ($(md5sum < "$work/bundle_$scene/baked.bin" | cut -c1-32))"
    fi
    echo "check-bundle: $line"
done

# 3. Bad input: exit 2 and one line naming the file, as the full build says it. Broken textures
#    under --strict-textures too: the image back-ends word their decoders' reasons alike.
textured() {  # a floor textured with image $1 under an emissive ceiling
    cat > "$work/$2" <<'GLTF'
{"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[0,1]}],"nodes":[{"mesh":0},{"mesh":1}],"buffers":[{"uri":"data:application/octet-stream;base64,AACAvwAAAAAAAIC/AACAPwAAAAAAAIC/AACAPwAAAAAAAIA/AACAvwAAAAAAAIA/AACAvwAAAEAAAIC/AACAvwAAAEAAAIA/AACAPwAAAEAAAIA/AACAPwAAAEAAAIC/AAAAAAAAAAAAAIA/AAAAAAAAgD8AAIA/AAAAAAAAgD8AAAAAAAAAAAAAgD8AAAAAAACAPwAAgD8AAAAAAACAPwAAAgABAAAAAwACAAQABgAFAAQABwAGAA==","byteLength":184}],"bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":96},{"buffer":0,"byteOffset":96,"byteLength":64},{"buffer":0,"byteOffset":160,"byteLength":24}],"accessors":[{"bufferView":0,"componentType":5126,"count":4,"type":"VEC3","min":[-1,0,-1],"max":[1,0,1]},{"bufferView":0,"byteOffset":48,"componentType":5126,"count":4,"type":"VEC3","min":[-1,2,-1],"max":[1,2,1]},{"bufferView":1,"componentType":5126,"count":4,"type":"VEC2"},{"bufferView":2,"componentType":5123,"count":6,"type":"SCALAR"},{"bufferView":2,"byteOffset":12,"componentType":5123,"count":6,"type":"SCALAR"}],"materials":[{"pbrMetallicRoughness":{"baseColorTexture":{"index":0}}},{"emissiveFactor":[1,1,1]}],"textures":[{"source":0}],"images":[{"uri":"TEX"}],"meshes":[{"primitives":[{"attributes":{"POSITION":0,"TEXCOORD_0":2},"indices":3,"material":0}]},{"primitives":[{"attributes":{"POSITION":1},"indices":4,"material":1}]}]}
GLTF
    sed -i "s/TEX/$1/" "$work/$2"
}
head -c 2000 "$work/bundle_cornell_box/render.png" > "$work/cut.png"
printf '\211PNG\r\n\032\nnot the chunks of a PNG at all' > "$work/noise.png"
printf '\377\330\377\340\000\020JFIF\000' > "$work/header.jpg"
printf '\377\330\377not the markers of a JPEG' > "$work/noise.jpg"
textured cut.png cut_png.gltf
textured noise.png noise_png.gltf
textured header.jpg header_jpg.gltf
textured noise.jpg noise_jpg.gltf
printf '{"asset": {"version": "2.0"}, "nodes": [' > "$work/broken.gltf"
for input in "$work/missing.gltf" "$work/broken.gltf" "$work"/*_png.gltf "$work"/*_jpg.gltf; do
    set +e
    bare "$exe" bake "$input" -o "$work/out_bad" --strict-textures > /dev/null 2> "$work/bad.txt"
    code=$?
    set -e
    [ "$code" = 2 ] || fail "bake $(basename "$input"): exit $code, not 2"
    [ ! -e "$work/out_bad/baked.bin" ] || fail "bake $(basename "$input") left a partial output"
    if [ -n "$full" ]; then
        set +e
        bare "$full" bake "$input" -o "$work/out_bad" --strict-textures > /dev/null 2> "$work/bad_full.txt"
        set -e
        cmp -s "$work/bad.txt" "$work/bad_full.txt" ||
            fail "bake $(basename "$input"): the bundle says '$(cat "$work/bad.txt")', the full build '$(cat "$work/bad_full.txt")'"
    fi
done
echo "check-bundle: bad input (a missing file, a broken glTF, 4 broken textures): exit 2, one line$([ -z "$full" ] || echo ", the full build's")"
