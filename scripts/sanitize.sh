#!/usr/bin/env bash
# The unit tests under AddressSanitizer + UndefinedBehaviorSanitizer (CMake option
# TRAVBENCH_SANITIZE): a separate build in build-asan/ (Release, -march=native, no microbenchmarks),
# then ctest on everything but the slow sweeps listed below (their kernels are also run, on
# smaller inputs, by the suites that stay). Called by scripts/test.sh after the normal build and
# tests; runs on its own too:
#
#   scripts/sanitize.sh                 # build + reduced suite
#   SANITIZE_ALL=1 scripts/sanitize.sh  # build + every test (slow: ~3x the normal suite)
#
# Any sanitizer report fails the test it happens in: UBSan halts on the first error
# (-fno-sanitize-recover), ASan and LeakSanitizer exit non-zero. Embree and its TBB are Debian's
# uninstrumented libraries: ASan still checks our side of every call (the buffers we hand Embree
# are ours), and no report from inside them has been seen, leaks included (tests/README.md). Should
# one appear, pass a suppressions file through LSAN_OPTIONS / ASAN_OPTIONS (kept when set) rather
# than excluding the Embree schemes.
set -euo pipefail
cd "$(dirname "$0")/.."
start=$(date +%s)

cmake -S . -B build-asan -DCMAKE_BUILD_TYPE=Release -DTRAVBENCH_SANITIZE=ON -DTRAVBENCH_NATIVE=ON \
  -DTRAVBENCH_BUILD_BENCH=OFF >/dev/null
cmake --build build-asan -j "$(nproc)"
built=$(date +%s)

# Excluded: the parameter/scene sweeps, which repeat code the remaining tests already run under
# the sanitizers (every scheme still runs Registry/SchemeAccuracy.* and its own unit tests) but take
# 20-300 s each under ASan on 2 cores (tests/README.md): every scheme x hard case x 5 scenes
# against the double-precision reference, the kd-tree and RayGrid kernel/parameter grids, the
# 200k-triangle kd-tree build and the MBVH collapse grid. Measured on 2 shared cores: ASan build
# ~6.5 min wall; tests with only SchemeRobustness excluded ~370 s wall, this reduced set ~70 s.
SLOW='^Registry/SchemeRobustness\.'
SLOW+='|^KDTraversal\.(KernelVariantsAndParameters|NoLeaksOnHardCases)$'
SLOW+='|^RayGrid\.(MatchesReferenceOnEveryWorkloadAndParameter|NoLeaksWithHugeOffsets)$'
SLOW+='|^KDTree\.BuildsTwoHundredThousandTriangles$|^MBVH\.CollapseInvariants$'
# The exact-reference sweeps (every scheme x hard case x scene against GMP rationals): minutes each
# under ASan; the oracle's own unit and property tests (ExactOracle.*) stay.
SLOW+='|^Registry/ExactKinds\.|^ExactReference\.|^SpatialBVH\.SchemesStayWatertight$'
EXCLUDE=${SANITIZE_EXCLUDE:-$SLOW}
[ "${SANITIZE_ALL:-0}" = 1 ] && EXCLUDE='^$'

export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=0:strict_string_checks=1:detect_stack_use_after_return=0}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}

cd build-asan
ctest --output-on-failure -j "$(nproc)" --timeout 900 -E "$EXCLUDE"
end=$(date +%s)
echo "sanitize: ASan+UBSan build $((built - start)) s, tests $((end - built)) s (excluded: $EXCLUDE)" >&2
