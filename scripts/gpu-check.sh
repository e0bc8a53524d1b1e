#!/usr/bin/env bash
# The GPU check: on a machine with a GPU, its driver and nothing but this bundle, lists the OpenCL
# devices, bakes the Cornell box on the GPU with --verify (every shot against the scalar
# reference) and at default settings, and runs the throughput benchmark at batches of 1 and 64 to 1024,
# writing everything it measured into one folder.
#
# Usage: gpu-check.sh [--quick] [OUT_DIR]
#   OUT_DIR   default ./gpu-check-<host>-<date>; summary.txt there says what ran and how it ended
#   --quick   the benchmark without the 1M-triangle scene (about 2 minutes less)
# Environment: HEMIRAD the executable (default bin/hemirad beside this script, as in the bundle);
# OCL_ICD_VENDORS as the ICD loader reads it. Without it and without /etc/OpenCL/vendors/*.icd,
# the script looks for NVIDIA's and AMD's OpenCL libraries and writes .icd files for them into
# OUT_DIR/icd (a driver installed without its ICD file, as on some bare GPU images).
set -uo pipefail

here=$(cd "$(dirname "$0")" && pwd)
quick=0
if [ "${1:-}" = --quick ]; then quick=1; shift; fi
out=${1:-gpu-check-$(hostname)-$(date +%Y%m%d-%H%M%S)}
exe=${HEMIRAD:-$here/bin/hemirad}
scenes=$here/scenes
[ -d "$scenes" ] || scenes=$here/../scenes  # run from a source tree: scripts/gpu-check.sh
mkdir -p "$out"
out=$(cd "$out" && pwd)
summary=$out/summary.txt
: > "$summary"
say() { echo "$*" | tee -a "$summary"; }

if [ -z "${OCL_ICD_VENDORS:-}" ] && ! ls /etc/OpenCL/vendors/*.icd > /dev/null 2>&1; then
    mkdir -p "$out/icd"
    for lib in libnvidia-opencl.so.1 libamdocl64.so; do
        path=$(ldconfig -p 2>/dev/null | awk -v l="$lib" '$1 == l {print $NF; exit}')
        [ -n "$path" ] || path=$(find /usr /lib /lib64 /opt -maxdepth 5 -name "$lib" 2>/dev/null | head -1)
        [ -z "$path" ] || { echo "$path" > "$out/icd/${lib%%.so*}.icd"; say "icd: $path (no /etc/OpenCL/vendors; written to icd/)"; }
    done
    export OCL_ICD_VENDORS=$out/icd
fi

{
    date -u
    uname -a
    echo "cores: $(nproc)"
    grep -m1 "model name" /proc/cpuinfo
    nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader 2>/dev/null
    "$exe" --version
} > "$out/machine.txt" 2>&1

# Runs one step with a time limit, its output in OUT_DIR/<name>.log, and says how it ended.
step() {
    local name=$1 limit=$2
    shift 2
    local start end code
    start=$(date +%s%3N)
    timeout "$limit" "$@" > "$out/$name.log" 2>&1
    code=$?
    end=$(date +%s%3N)
    say "$(printf '%-16s exit %-3s %8.2f s' "$name" "$code" "$(( end - start ))e-3")"
    return $code
}

step devices 60 "$exe" devices
cat "$out/devices.log" >> "$summary"
if ! grep -q "| gpu |" "$out/devices.log"; then
    say "no OpenCL GPU found (devices.log); the bakes and the benchmark below run on what there is"
fi
step cornell_verify 300 "$exe" bake "$scenes/cornell_box.gltf" -o "$out/cornell_verify" --device opencl --verify
step cornell_default 300 "$exe" bake "$scenes/cornell_box.gltf" -o "$out/cornell_default" --device opencl
cmp -s "$out/cornell_verify/baked.bin" "$out/cornell_default/baked.bin" &&
    say "cornell: baked.bin $(md5sum < "$out/cornell_default/baked.bin" | cut -c1-32), the same with and without --verify"

engines=opencl
grep -q "^embree .*built in" "$out/devices.log" && engines=opencl,embree
bench_scenes=("$scenes/cornell_box.gltf" procedural:10k city:100k)
[ "$quick" = 1 ] || bench_scenes+=(city:1M)
# One shot a call (latency), then batches of hundreds to a thousand (what fills a GPU): the second
# run ends with a table of shots/s against batch size.
step bench_batch1 600 "$exe" bench "${bench_scenes[@]}" --hemicube 64,256 --engines "$engines" \
    --shots 8 --repeats 3 --batch 1 --json "$out/bench_batch1.json"
step bench_batches 600 "$exe" bench "${bench_scenes[@]}" --hemicube 64,256 --engines "$engines" \
    --shots 1024 --repeats 3 --batch 64,256,1024 --json "$out/bench_batches.json"
say "done: $out"
