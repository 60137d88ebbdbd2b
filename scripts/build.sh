#!/usr/bin/env bash
# Configures and builds travbench (Release, -O3 -march=native, profile-guided) into build/.
#
#   scripts/build.sh [CMAKE_ARGS...]      # e.g. -DTRAVBENCH_MARCH=znver3
#   BUILD_DIR=build-znver3 scripts/build.sh -DTRAVBENCH_MARCH=znver3
#   TRAVBENCH_PGO=0 scripts/build.sh      # without profile-guided optimisation
#
# Profile-guided (GCC) by default: first an instrumented travbench in <BUILD_DIR>-pgo (the same
# CMake arguments, only the app and its library), then scripts/pgo_train.sh on built-in scenes,
# then the real build with those counts. Primary rays of the single-ray kernels run 2-11% faster
# for it on 12 of 13 scenes (crytek within its noise); bounce rays, packets and batches within the
# noise (docs/PERFORMANCE.md, session 31). The arithmetic is unchanged (ctest runs on this build).
set -euo pipefail
cd "$(dirname "$0")/.."
dir="${BUILD_DIR:-build}"
# ccache, when installed, makes rebuilds across checkouts cheap (CI has none: a plain build).
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
pgo=(-DTRAVBENCH_PGO_USE=)
if [ "${TRAVBENCH_PGO:-1}" = 1 ]; then
  gen="$dir-pgo"
  cmake -S . -B "$gen" -DCMAKE_BUILD_TYPE=Release -DTRAVBENCH_PGO_GENERATE=ON -DTRAVBENCH_BUILD_TESTS=OFF \
    -DTRAVBENCH_BUILD_BENCH=OFF "${launcher[@]}" "$@" >/dev/null
  cmake --build "$gen" -j "$(nproc)" --target travbench
  rm -rf "$gen/pgo-profile"  # counts add up across runs: train from zero
  scripts/pgo_train.sh "$gen"
  pgo=(-DTRAVBENCH_PGO_USE="$PWD/$gen/pgo-profile")
fi
cmake -S . -B "$dir" -DCMAKE_BUILD_TYPE=Release "${launcher[@]}" "${pgo[@]}" "$@" >/dev/null
# A profile is not a dependency make sees: objects compiled with another training's counts would
# be kept (session 34: a changed training script changed nothing until the sources did). So when
# the training script differs from the one the build last used, or the PGO setting does,
# everything is recompiled. (The counts themselves differ a little from run to run, threads and
# timing loops, so they cannot be the key.)
stamp="$dir/pgo-training.sha1"
want="pgo=${TRAVBENCH_PGO:-1} $(sha1sum scripts/pgo_train.sh | cut -d' ' -f1)"
if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
  cmake --build "$dir" --target clean
fi
cmake --build "$dir" -j "$(nproc)"
echo "$want" >"$stamp"
