#!/usr/bin/env bash
# Renders the converged path-traced references `hemirad bench --accuracy` compares against, into
# bench/reference/<scene>/ (reference.exr, reference.json). Offline, once: the results are
# committed. Needs the build's hemirad_pathtrace (built when Embree 3 is found):
#   cmake --preset release && cmake --build --preset release --target hemirad_pathtrace
#   bench/make_references.sh
# 1728 paths a pixel (192 at each of the renderer's 3 × 3 sample positions) and 16384 points ×
# 256 paths a face: about 6 minutes on 2 cores for the Cornell box, 8 for the double-sided cylinder
# (its 640 × 480 reference: 2.5% noise a pixel, which the comparison takes out). The leaf canopy
# has 515 faces (every card is one), so 2048 points a face.
set -euo pipefail
cd "$(dirname "$0")/.."
tracer=${HEMIRAD_PATHTRACE:-build/release/hemirad_pathtrace}
for scene in cornell_box:16384 double_sided_cylinder:16384 leaf_canopy:2048; do
  name=${scene%%:*}
  "$tracer" "scenes/$name.gltf" --out "bench/reference/$name" --width 640 --spp 192 \
    --face-points "${scene##*:}" --face-spp 256 --seed 1
done
