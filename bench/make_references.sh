#!/usr/bin/env bash
# Renders the converged path-traced references `hemirad bench --accuracy` compares against, into
# bench/reference/<scene>/ (reference.exr, reference.json). Offline, once: the results are
# committed. Needs the build's hemirad_pathtrace (built when Embree 3 is found):
#   cmake --preset release && cmake --build --preset release --target hemirad_pathtrace
#   bench/make_references.sh
# 1728 paths a pixel (192 at each of the renderer's 3 × 3 sample positions) and 16384 points ×
# 256 paths a face: about 6 minutes on 2 cores for the Cornell box, 8 for the double-sided cylinder
# (its 640 × 480 reference: 2.5% noise a pixel, which the comparison takes out). The leaf canopy
# has 515 faces (every card is one), so 2048 points a face. The night street is lit only by
# hundreds of small emitting cards in the open, whose light the tracer samples by area: at 640 × 480
# and 192 paths a sample its pixels kept 7.9% noise, so it is rendered at 320 × 240 with 1536 a
# sample (13,824 paths a pixel, 3.5% noise; about 4.5 minutes on 2 cores).
set -euo pipefail
cd "$(dirname "$0")/.."
tracer=${HEMIRAD_PATHTRACE:-build/release/hemirad_pathtrace}
# name:face points:width:paths a sample
for scene in cornell_box:16384:640:192 double_sided_cylinder:16384:640:192 leaf_canopy:2048:640:192 \
             night_street:2048:320:1536; do
  IFS=: read -r name points width spp <<< "$scene"
  "$tracer" "scenes/$name.gltf" --out "bench/reference/$name" --width "$width" --spp "$spp" \
    --face-points "$points" --face-spp 256 --seed 1
done
