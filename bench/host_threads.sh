#!/usr/bin/env bash
# The host stages on one thread against every core (--threads 1 against --threads 0): each bake
# run R times, the two alternating, from a release build; per stage the median seconds of each and
# their ratio, and a check that both baked the same bytes (exit 1 if not).
#   bench/host_threads.sh [-b BUILD_DIR] [-r R] -- SCENE [bake options...] [-- SCENE [options...]]...
#   (default: build/release, R = 3; without scenes: the Cornell box)
set -euo pipefail
cd "$(dirname "$0")/.."
build=build/release
repeats=3
while getopts "b:r:" opt; do
    case $opt in
        b) build=$OPTARG ;;
        r) repeats=$OPTARG ;;
        *) exit 2 ;;
    esac
done
shift $((OPTIND - 1))
[ "${1:-}" = "--" ] && shift
[ $# -eq 0 ] && set -- scenes/cornell_box.gltf
exe=$build/hemirad
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT

echo "machine: $(nproc) cores of $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ *//'); $("$exe" devices | sed -n 2p)"
bench() {
    local args=("$@")
    for ((i = 0; i < repeats; ++i)); do
        for threads in 1 0; do
            rm -rf "$out/run"
            local t
            t=$( { TIMEFORMAT="%R"; time "$exe" bake "${args[@]}" -o "$out/run" --threads "$threads" --quiet \
                   >/dev/null 2>"$out/err"; } 2>&1 ) || { cat "$out/err" >&2; exit 1; }
            python3 - "$out/run/report.json" "$t" "$(md5sum < "$out/run/baked.bin" | cut -c1-32)" \
                >> "$out/runs.$threads" <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
t = dict(r["timings_s"]); t["wall"] = float(sys.argv[2])
print(json.dumps({"threads": r["settings"]["threads"], "t": t, "md5": sys.argv[3]}))
PY
        done
    done
    python3 - "${args[*]}" "$out/runs.1" "$out/runs.0" <<'PY'
import json, statistics, sys
label = sys.argv[1]
one = [json.loads(l) for l in open(sys.argv[2])]
all_ = [json.loads(l) for l in open(sys.argv[3])]
md5s = {r["md5"] for r in one + all_}
print(f"\n`hemirad bake {label}`: {len(one)} runs each, 1 host thread against {all_[0]['threads']}")
print("\n| stage | 1 thread (s) | all threads (s) | ratio |\n|---|---|---|---|")
for stage in ["load", "mesh", "formfactors", "solve", "refine", "gather", "output", "total", "wall"]:
    a = statistics.median(r["t"][stage] for r in one)
    b = statistics.median(r["t"][stage] for r in all_)
    print(f"| {stage} | {a:.3f} | {b:.3f} | {a / b if b > 0 else float('nan'):.2f} |")
print(f"\nbaked.bin: {'the same bytes' if len(md5s) == 1 else 'DIFFERENT: ' + ', '.join(sorted(md5s))}"
      f" ({next(iter(md5s))})")
sys.exit(0 if len(md5s) == 1 else 1)
PY
    rm -f "$out/runs.1" "$out/runs.0"
}
args=()
for a in "$@"; do
    if [ "$a" = "--" ]; then
        bench "${args[@]}"
        args=()
    else
        args+=("$a")
    fi
done
[ ${#args[@]} -gt 0 ] && bench "${args[@]}"
