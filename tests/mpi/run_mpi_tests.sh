#!/usr/bin/env bash
# MPI bakes (CTest, tests/CMakeLists.txt): run_mpi_tests.sh CASE HEMIRAD SOURCE_DIR WORK_DIR BUILT_WITH_MPI
#   ranks   mpirun -n 2 and -n 3 bakes of bundled scenes (a sunlit one too) are byte for byte one process's
#   resume  a bake killed under 2 ranks (a worker killed) resumes under 3 with one process's bytes
#   input   bad input under mpirun: one line from rank 0, exit 2, nothing written
#   scaling bench --scaling under 2 ranks measures both counts, with the same rows
# Exits 77 (skipped, visibly) where hemirad was built without MPI or mpirun is missing.
set -euo pipefail
case_name=$1 exe=$2 src=$3 work=$4 built=$5
if [ "$built" != "1" ]; then echo "skipped: hemirad was built without MPI (install libopenmpi-dev)"; exit 77; fi
if ! command -v mpirun > /dev/null; then echo "skipped: no mpirun (install openmpi-bin)"; exit 77; fi

# Root in CI containers; more ranks than cores; no cross-memory attach, which containers forbid.
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 OMPI_MCA_rmaps_base_oversubscribe=1
export OMPI_MCA_btl_vader_single_copy_mechanism=none HEMIRAD_CACHE_DIR=off
# One PoCL thread per rank: oversubscribed ranks need not fight over the cores.
mpi() { POCL_MAX_PTHREAD_COUNT=1 mpirun -x POCL_MAX_PTHREAD_COUNT -x HEMIRAD_CACHE_DIR -n "$@"; }
rm -rf "$work/$case_name" && mkdir -p "$work/$case_name" && cd "$work/$case_name"
fail() { echo "FAILED: $*"; exit 1; }
same() {  # same OUT_A OUT_B: baked.bin byte for byte
  cmp "$1/baked.bin" "$2/baked.bin" || fail "$1/baked.bin and $2/baked.bin differ"
  echo "ok: $1 = $2"
}
batch_of() { python3 -c "import json,sys; print(json.load(open(sys.argv[1]))['settings']['batch'])" "$1/report.json"; }

case "$case_name" in
ranks)
  cornell=$src/scenes/cornell_box.gltf lit=$src/scenes/lit_room.gltf
  # The default path: the planned batch grows with the ranks (16 a rank).
  mpi 2 "$exe" bake "$cornell" -o cornell_n2 --quiet
  mpi 3 "$exe" bake "$cornell" -o cornell_n3 --quiet
  [ "$(batch_of cornell_n2)" = 32 ] || fail "2 ranks planned batch $(batch_of cornell_n2), not 32"
  [ "$(batch_of cornell_n3)" = 48 ] || fail "3 ranks planned batch $(batch_of cornell_n3), not 48"
  "$exe" bake "$cornell" -o cornell_b32 --batch 32 --quiet
  "$exe" bake "$cornell" -o cornell_b48 --batch 48 --quiet
  same cornell_n2 cornell_b32
  same cornell_n3 cornell_b48
  python3 - cornell_n3/report.json <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))["device"]
assert d["ranks"] == 3, d
ids = [m["id"] for m in d["members"]]
assert ids[1:] == ["rank 1", "rank 2"], ids
assert all(m["shots"] > 0 for m in d["members"]), d["members"]
print("ok: 3 members each took shots:", [m["shots"] for m in d["members"]])
PY
  # The progressive solver's default batch (the patches that hold about as much as the most)
  # does not grow with the ranks: the same bytes as one process.
  mpi 2 "$exe" bake "$lit" -o lit_default_n2 --solver progressive --quality draft --quiet
  "$exe" bake "$lit" -o lit_default_one --solver progressive --quality draft --quiet
  same lit_default_n2 lit_default_one
  # Punctual lights and the progressive solver, at a batch given.
  mpi 3 "$exe" bake "$lit" -o lit_n3 --solver progressive --batch 8 --quality draft --quiet
  "$exe" bake "$lit" -o lit_one --solver progressive --batch 8 --quality draft --quiet
  same lit_n3 lit_one
  # Suns (the atrium's, and one from --sun): their parallel shots go to the ranks like any shots
  # (the worker's mesh carries the suns). Without refinement and the gather every shot is the
  # solve's: the row cache's requests are the passes and the 2 suns' shots (and up to batch − 1
  # of a last batch cut short), and what it did not hold went to the members.
  sun_args=(--solver progressive --batch 2 --gather 0 --refine-levels 0 --sun 135,40,10 --quality draft --quiet)
  mpi 2 "$exe" bake "$src/scenes/atrium.gltf" -o atrium_n2 "${sun_args[@]}"
  "$exe" bake "$src/scenes/atrium.gltf" -o atrium_one "${sun_args[@]}"
  same atrium_n2 atrium_one
  python3 - atrium_n2/report.json <<'PY'
import json, sys
r = json.load(open(sys.argv[1]))
members, cache = r["device"]["members"], r["row_cache"]
assert [m["id"] for m in members][1:] == ["rank 1"], members
assert sum(m["shots"] for m in members) == cache["shot"], (members, cache)
extra = cache["requests"] - r["passes"] - 2
assert 0 <= extra < 2, (cache, r["passes"])
print("ok: the suns' shots went through the ranks:", [m["shots"] for m in members], "of", cache["shot"])
PY
  ;;
resume)
  room=$src/scenes/closed_room.gltf
  args=(--solver progressive --batch 16 --quality draft --checkpoint-every 10 --quiet)
  "$exe" bake "$room" -o whole "${args[@]}"
  # Kill rank 1 once the first checkpoint is on disk: mpirun ends the job, naming the rank.
  set +e
  mpi 2 "$exe" bake "$room" -o killed --checkpoint ck "${args[@]}" > killed.log 2>&1 &
  job=$!
  for _ in $(seq 600); do [ -e ck ] && break; sleep 0.02; done
  [ -e ck ] || fail "no checkpoint appeared"
  # Rank 1 of this job only: a process of this test's directory (other tests may run beside it).
  for p in $(pgrep -f "$exe bake"); do
    [ "$(readlink "/proc/$p/cwd" 2> /dev/null)" = "$PWD" ] || continue
    if tr '\0' '\n' < "/proc/$p/environ" 2> /dev/null | grep -qx "OMPI_COMM_WORLD_RANK=1"; then kill -KILL "$p"; fi
  done
  wait "$job"
  code=$?
  set -e
  cat killed.log
  [ "$code" -ne 0 ] || fail "the bake finished before rank 1 was killed"
  grep -q "rank 1" killed.log || fail "nothing names the rank that died"
  [ ! -e killed/report.json ] || fail "a killed bake left a report"
  # Resumed under three ranks, without --batch: the checkpoint's batch is kept.
  mpi 3 "$exe" bake "$room" -o killed --resume ck --checkpoint ck --solver progressive --quality draft --quiet
  [ "$(batch_of killed)" = 16 ] || fail "the resumed bake took batch $(batch_of killed), not the checkpoint's 16"
  same killed whole
  python3 - killed/report.json whole/report.json <<'PY'
import json, sys
resumed, whole = (json.load(open(f)) for f in sys.argv[1:])
assert 0 < resumed["resumed_from_pass"] < whole["passes"], (resumed["resumed_from_pass"], whole["passes"])
assert resumed["passes"] == whole["passes"]
print("ok: resumed from pass", resumed["resumed_from_pass"], "of", whole["passes"])
PY
  ;;
input)
  set +e
  mpi 2 "$exe" bake "$src/scenes/no_such_scene.gltf" -o never > out.log 2> err.log
  code=$?
  set -e
  cat err.log
  [ "$code" -eq 2 ] || fail "exit $code, not 2"
  [ "$(grep -c '^hemirad: ' err.log)" -eq 1 ] || fail "not exactly one error line"
  grep -q "no_such_scene.gltf" err.log || fail "the error does not name the file"
  [ ! -e never ] || fail "bad input left an output directory"
  ;;
scaling)
  mpi 2 "$exe" bench --scaling procedural:5k --hemicube 64 --shots 16 --repeats 1 --json scaling.json
  python3 - scaling.json <<'PY'
import json, sys
runs = json.load(open(sys.argv[1]))["runs"]
assert [r["ranks"] for r in runs] == [1, 2], runs
assert all(r["rows_identical"] and r["shots_per_second"] > 0 for r in runs), runs
assert runs[1]["mesh_bytes"] > 0 and runs[1]["row_bytes"] > 0, runs[1]
print("ok: 1 and 2 ranks measured")
PY
  ;;
*) fail "unknown case $case_name" ;;
esac
