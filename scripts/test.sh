#!/usr/bin/env bash
# Set-up + build + the test suite (the README's test command; .ci/run calls it), then the unit
# tests again under AddressSanitizer + UndefinedBehaviorSanitizer (scripts/sanitize.sh, build-asan/;
# SKIP_SANITIZE=1 skips that step).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh
scripts/build.sh
(cd build && ctest --output-on-failure -j "$(nproc)" --timeout 900)
[ "${SKIP_SANITIZE:-0}" = 1 ] || scripts/sanitize.sh
