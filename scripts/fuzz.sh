#!/usr/bin/env bash
# Builds the libFuzzer targets of tests/fuzz (clang, -fsanitize=fuzzer,address,undefined; a
# standalone CMake project in build-fuzz/, independent of the main build) and runs each for the
# given number of seconds.
#
#   scripts/fuzz.sh [SECONDS] [TARGET...]     # default: 60 s each, every target
#   FUZZ_JOBS=2 scripts/fuzz.sh 600 mesh gltf # run two targets at a time (default: one per core)
#
# Targets: mesh (OBJ/OFF/PLY/STL), gltf (.gltf/.glb), rays (ray and hit files), din (din traces and
# cachesim --config). Each target reads the committed seeds of tests/fuzz/corpus/<target>/ and
# grows a working corpus in build-fuzz/corpus/<target>/ (kept between runs, not committed). A
# finding is written to build-fuzz/artifacts/<target>/ (crash-*, leak-*, timeout-*, oom-*) and makes
# the script exit non-zero; copy it to tests/fuzz/regressions/<target>/ so that the unit tests
# replay it (BadInput.FuzzRegressionsLoadOrRaiseInputError).
set -euo pipefail
cd "$(dirname "$0")/.."

SECONDS_EACH=${1:-60}
[ $# -gt 0 ] && shift
TARGETS=("$@")
[ ${#TARGETS[@]} -eq 0 ] && TARGETS=(mesh gltf rays din)
JOBS=${FUZZ_JOBS:-$(nproc)}
for t in "${TARGETS[@]}"; do
  [ -f "tests/fuzz/fuzz_$t.cpp" ] || { echo "fuzz: unknown target '$t' (mesh, gltf, rays, din)" >&2; exit 2; }
done

if ! command -v clang++ >/dev/null || ! ls /usr/lib/llvm-*/lib/clang/*/lib/linux/libclang_rt.fuzzer-x86_64.a >/dev/null 2>&1; then
  echo "fuzz: installing clang and its runtime libraries (libFuzzer)" >&2
  SUDO=""
  [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends clang libclang-rt-dev >/dev/null
fi
scripts/setup.sh  # the Debian libraries the loaders link (tinygltf, OpenMesh, nlohmann-json)

CC=clang CXX=clang++ cmake -S tests/fuzz -B build-fuzz >/dev/null
cmake --build build-fuzz -j "$(nproc)" --target $(printf 'fuzz_%s ' "${TARGETS[@]}")

max_len() {
  case $1 in
    din) echo 4096 ;;
    *) echo 16384 ;;
  esac
}

export ASAN_OPTIONS=${ASAN_OPTIONS:-abort_on_error=1:detect_leaks=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}

run_one() {
  local t=$1
  mkdir -p "build-fuzz/corpus/$t" "build-fuzz/artifacts/$t" build-fuzz/logs
  # stdin is /dev/null: a glTF buffer URI naming /dev/stdin must not block the run.
  local dict=()
  [ -f "tests/fuzz/$t.dict" ] && dict=(-dict="tests/fuzz/$t.dict")
  build-fuzz/fuzz_"$t" "build-fuzz/corpus/$t" "tests/fuzz/corpus/$t" "${dict[@]}" \
    -max_total_time="$SECONDS_EACH" -timeout=10 -rss_limit_mb=2048 -max_len="$(max_len "$t")" \
    -print_final_stats=1 -artifact_prefix="build-fuzz/artifacts/$t/" </dev/null >"build-fuzz/logs/$t.log" 2>&1
}

status=0
pids=()
names=()
for t in "${TARGETS[@]}"; do
  while [ "$(jobs -rp | wc -l)" -ge "$JOBS" ]; do sleep 1; done
  echo "fuzz: $t for ${SECONDS_EACH}s (log: build-fuzz/logs/$t.log)" >&2
  run_one "$t" &
  pids+=($!)
  names+=("$t")
done
for i in "${!pids[@]}"; do
  t=${names[$i]}
  if wait "${pids[$i]}"; then res=ok; else res="FINDING (see build-fuzz/artifacts/$t/)"; status=1; fi
  execs=$(grep -o 'stat::number_of_executed_units: [0-9]*' "build-fuzz/logs/$t.log" | awk '{print $2}' | tail -1)
  echo "fuzz: $t: ${execs:-?} executions, corpus $(ls "build-fuzz/corpus/$t" | wc -l) files: $res"
done
exit $status
