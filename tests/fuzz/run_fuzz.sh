#!/usr/bin/env bash
# Builds tests/fuzz/fuzz_loader.cpp with clang's libFuzzer, AddressSanitizer and UBSan, and fuzzes
# the scene loader for a bounded time from the malformed-scene corpus (tests/corpus) and the
# bundled scenes. Exit 0: nothing found; 1: a finding (the input is saved in the work directory
# and printed); 77: no clang with libFuzzer here (CTest reports the test as skipped).
#   run_fuzz.sh SOURCE_DIR WORK_DIR SECONDS
set -uo pipefail
src=$1 work=$2 seconds=${3:-60}
cxx=$(command -v clang++ || command -v clang++-14 || true)
if [ -z "$cxx" ]; then echo "run_fuzz: no clang++: skipped"; exit 77; fi
mkdir -p "$work/corpus" "$work/findings"
flags=(-std=c++17 -O1 -g -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined
       -DGLM_FORCE_CXX17 -DGLM_ENABLE_EXPERIMENTAL -I"$src/src")
if ! "$cxx" "${flags[@]}" "$src/tests/fuzz/fuzz_loader.cpp" "$src/src/scene/scene.cpp" \
     -ltinygltf -lfmt -o "$work/fuzz_loader" 2> "$work/build.log"; then
  if grep -q "fuzzer" "$work/build.log" && grep -qi "no such file\|cannot find\|unsupported" "$work/build.log"; then
    echo "run_fuzz: clang++ has no libFuzzer runtime: skipped"; cat "$work/build.log"; exit 77
  fi
  echo "run_fuzz: the fuzz target does not build:"; cat "$work/build.log"; exit 1
fi
cp "$src"/tests/corpus/*.gltf "$src"/tests/corpus/*.glb "$src"/scenes/*.gltf "$work/corpus/"
# Deterministic: a fixed seed; bounded: total time, per-input time and memory.
"$work/fuzz_loader" -seed=1 -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -max_len=65536 \
    -artifact_prefix="$work/findings/" -print_final_stats=1 "$work/corpus" > "$work/fuzz.log" 2>&1
status=$?
tail -n 15 "$work/fuzz.log"
if [ $status -ne 0 ]; then
  echo "run_fuzz: finding(s) in $work/findings:"; ls -l "$work/findings"
  exit 1
fi
echo "run_fuzz: nothing found in $seconds s"
