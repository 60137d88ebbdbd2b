#!/usr/bin/env bash
# Configures and builds travbench (Release, -O3 -march=native) into build/.
set -euo pipefail
cd "$(dirname "$0")/.."
# ccache, when installed, makes rebuilds across checkouts cheap (CI has none: a plain build).
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
cmake -S . -B build -DCMAKE_BUILD_TYPE=Release "${launcher[@]}" "$@" >/dev/null
cmake --build build -j "$(nproc)"
