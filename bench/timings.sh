#!/usr/bin/env bash
# The README's "Timings on this machine" table: wall-clock and CPU seconds of each bake it lists,
# each run N times (default 3; the median's row is printed), from a release build.
#   bench/timings.sh [BUILD_DIR] [N]      (default: build/release 3)
set -euo pipefail
cd "$(dirname "$0")/.."
exe=${1:-build/release}/hemirad
repeats=${2:-3}
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT

echo "machine: $(nproc) cores of $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ *//'); $("$exe" devices | sed -n 2p)"
echo
echo "| bake | patches / elements | solver, hemicubes | wall | CPU (user + sys) |"
echo "|---|---|---|---|---|"
row() {
    local label=$1
    shift
    local times=()
    for ((i = 0; i < repeats; ++i)); do
        rm -rf "$out/run"
        local t
        t=$( { TIMEFORMAT="%R %U %S"; time "$exe" bake "$@" -o "$out/run" --quiet >/dev/null 2>&1; } 2>&1 )
        times+=("$t")
    done
    python3 - "$label" "$out/run/report.json" "${times[@]}" <<'PY'
import json, statistics, sys
label, report = sys.argv[1], json.load(open(sys.argv[2]))
runs = sorted((float(w), float(u) + float(s)) for w, u, s in (t.split() for t in sys.argv[3:]))
wall, cpu = runs[len(runs) // 2]
c = report["counts"]
solver = report["settings"]["solver"]
shots = f'{report["passes"]} {"rows" if solver == "matrix" else "passes"}'
engine = {"opencl": "OpenCL", "ref": "reference", "analytic": "exact form factors"}.get(report["device"]["backend"],
                                                                                       report["device"]["backend"])
print(f'| {label} | {c["patches"]} / {c["elements_before_refinement"]} → {c["elements"]} | {solver}, {shots} '
      f'({engine}) | {wall:.1f} s | {cpu:.1f} s |')
PY
}
row "Cornell box, default settings" scenes/cornell_box.gltf
row "Cornell box, default settings, \`--device ref\`" scenes/cornell_box.gltf --device ref
row "Cornell box, default settings, \`--solver progressive\`" scenes/cornell_box.gltf --solver progressive
row "empty room, default settings" scenes/empty_room.gltf
