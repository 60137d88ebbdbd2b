#!/usr/bin/env bash
# Builds the travbench that valgrind can run and prints its path (build-valgrind/travbench):
# Release with -DTRAVBENCH_NATIVE=OFF (AVX2+FMA only), because valgrind 3.19 cannot run the AVX-512
# code that -march=native may emit. Shared by the callgrind scripts (instruction_counts.sh,
# loads_per_ray.sh, divergence_counts.sh, pathtrace_reads.sh); the build log is build-valgrind/build.log.
set -euo pipefail
cd "$(dirname "$0")/.."
command -v valgrind >/dev/null || { echo "$(basename "$0"): valgrind is not installed (scripts/setup.sh)" >&2; exit 2; }
cmake -S . -B build-valgrind -DCMAKE_BUILD_TYPE=Release -DTRAVBENCH_NATIVE=OFF >/dev/null
cmake --build build-valgrind -j "$(nproc)" --target travbench >build-valgrind/build.log 2>&1 ||
  { tail -40 build-valgrind/build.log >&2; exit 1; }
echo build-valgrind/travbench
