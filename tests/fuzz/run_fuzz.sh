#!/usr/bin/env bash
# Builds the libFuzzer targets (tests/fuzz: fuzz_loader, fuzz_bake) with clang, AddressSanitizer
# and UBSan in a CMake build of their own (-DHEMIRAD_FUZZ=ON, WORK_DIR/build, shared: the first
# test there builds it while the others wait on a lock), then fuzzes one target for a fixed number
# of inputs from a fixed seed and a fresh seed corpus (so a run does not depend on the machine's
# speed), with a time limit only as a safety cap:
#   loader  the scene loader, from the malformed-scene corpus (tests/corpus) and the bundled scenes;
#   bake    the whole bake of generated scenes (fuzz_bake.cpp), from 16 seeded inputs.
# Exit 0: nothing found; 1: a finding (the input is saved in WORK_DIR/TARGET/findings and the
# report printed) or a build failure; 77: no clang with libFuzzer here (CTest reports a skip).
#   run_fuzz.sh loader|bake SOURCE_DIR WORK_DIR RUNS MAX_SECONDS
set -uo pipefail
target=$1 src=$2 work=$3 runs=${4:-1000} seconds=${5:-600}
case "$target" in loader|bake) ;; *) echo "run_fuzz: unknown target '$target' (loader or bake)"; exit 2 ;; esac
cxx=$(command -v clang++ || command -v clang++-14 || true)
if [ -z "$cxx" ]; then echo "run_fuzz: no clang++: skipped"; exit 77; fi
mkdir -p "$work"

# libFuzzer is a separate runtime (libclang-rt-dev on Debian): without it, skip.
probe="$work/probe"
echo 'extern "C" int LLVMFuzzerTestOneInput(const unsigned char*, unsigned long) { return 0; }' > "$probe.cpp"
if ! "$cxx" -fsanitize=fuzzer,address,undefined "$probe.cpp" -o "$probe" > "$probe.log" 2>&1; then
  echo "run_fuzz: $cxx has no libFuzzer runtime: skipped"; cat "$probe.log"; exit 77
fi

# One instrumented build for every target: -O1 with asserts on, line tables for the sanitizers'
# reports (full debug information only made the build slower).
build="$work/build"
launcher=()
if command -v ccache > /dev/null; then launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache); fi
generator=()
if command -v ninja > /dev/null; then generator=(-G Ninja); fi
start=$(date +%s)
(
  flock 9
  if [ -f "$build/CMakeCache.txt" ]; then generator=(); fi  # the generator is fixed at the first run
  cmake -S "$src" -B "$build" "${generator[@]}" -DCMAKE_CXX_COMPILER="$cxx" "${launcher[@]}" \
    -DHEMIRAD_FUZZ=ON -DCMAKE_BUILD_TYPE=RelWithDebInfo -DCMAKE_CXX_FLAGS_RELWITHDEBINFO="-O1 -gline-tables-only" \
    && cmake --build "$build" --target fuzz_loader fuzz_bake -j 2
) 9> "$work/build.lock" > "$work/build-$target.log" 2>&1  # one log per target: the other may wait on the lock
if [ $? -ne 0 ]; then echo "run_fuzz: the fuzz targets do not build:"; tail -n 60 "$work/build-$target.log"; exit 1; fi
echo "run_fuzz: fuzz targets built or up to date in $(( $(date +%s) - start )) s"

run="$work/$target"
rm -rf "$run/corpus"
mkdir -p "$run/corpus" "$run/findings"
args=(-seed=1 -runs="$runs" -max_total_time="$seconds" -print_final_stats=1 -artifact_prefix="$run/findings/")
case "$target" in
  loader)
    cp "$src"/tests/corpus/*.gltf "$src"/tests/corpus/*.glb "$src"/scenes/*.gltf "$run/corpus/"
    args+=(-timeout=10 -rss_limit_mb=2048 -max_len=65536)
    # Leaks are checked after each input, against lsan.supp (a corrupt PNG leaks a string inside
    # OpenImageIO's reader): a suppression matches only a whole stack, which libstdc++'s frames,
    # built without frame pointers, cut short under the fast unwinder.
    export LSAN_OPTIONS="suppressions=$src/tests/fuzz/lsan.supp:print_suppressions=0:${LSAN_OPTIONS:-}"
    export ASAN_OPTIONS="fast_unwind_on_malloc=0:${ASAN_OPTIONS:-}"
    ;;
  bake)
    # Seed inputs: 16 byte strings from a fixed pseudo-random sequence (the bytes the generator
    # reads), each a different scene; libFuzzer mutates them from there.
    if command -v python3 > /dev/null; then
      python3 - "$run/corpus" <<'PY'
import random, sys
for k in range(1, 17):
    r = random.Random(k)  # an integer seed gives the same bytes on every Python 3
    with open("%s/seed%d" % (sys.argv[1], k), "wb") as f:
        f.write(bytes(r.getrandbits(8) for _ in range(256 * k)))
PY
    fi
    # PoCL runs in the process under AddressSanitizer as it is. Leaks are checked once, at exit
    # (LeakSanitizer; the suppressions spare the OpenCL runtime's own allocations), not after
    # every input: libFuzzer's per-input check reruns each input that allocated more than it
    # freed, which PoCL's and OpenImageIO's caches make most of them, and halved the inputs run.
    # Thread-local storage is not scanned (use_tls=0): clang 14's LeakSanitizer crashed at exit
    # ("Tracer caught signal 11") scanning the dynamic TLS of the libraries PoCL and OpenImageIO
    # load, on some runs; what only TLS refers to is their per-thread data (lsan.supp).
    export LSAN_OPTIONS="suppressions=$src/tests/fuzz/lsan.supp:print_suppressions=0:use_tls=0:${LSAN_OPTIONS:-}"
    args+=(-detect_leaks=0 -timeout=120 -rss_limit_mb=4096 -max_len=4096)
    ;;
esac
"$build/tests/fuzz/fuzz_$target" "${args[@]}" "$run/corpus" > "$run/fuzz.log" 2>&1
status=$?
grep -E "^fuzz_bake:|FINDING|ERROR|SUMMARY" "$run/fuzz.log" | head -n 40
tail -n 15 "$run/fuzz.log"
if [ $status -ne 0 ]; then
  echo "run_fuzz: finding(s) in $run/findings:"; ls -l "$run/findings"
  exit 1
fi
done_line=$(grep -E "^Done [0-9]+ runs" "$run/fuzz.log" | tail -n 1)
echo "run_fuzz: nothing found (${done_line:-no summary}; asked for $runs runs within $seconds s)"
if [ -n "$done_line" ] && [ "$(echo "$done_line" | awk '{print $2}')" -lt "$runs" ]; then
  echo "run_fuzz: warning: the time cap ended the run before its $runs inputs: on this machine the run depends on its speed"
fi
