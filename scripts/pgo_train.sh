#!/usr/bin/env bash
# The training runs of travbench's profile-guided build (scripts/build.sh; CMake options
# TRAVBENCH_PGO_GENERATE / TRAVBENCH_PGO_USE): an instrumented travbench traces a few built-in
# scenes, and GCC lays out the real build's code by the counts. ~90 s on 2 cores.
#
#   scripts/pgo_train.sh BUILD_DIR     # BUILD_DIR: a TRAVBENCH_PGO_GENERATE build (its travbench)
#
# What is traced, and why these scenes: only built-in scenes, none of ../shared/scenes, so every
# committed scene stays held out from the training (docs/PERFORMANCE.md, session 31, measures the
# PGO build on those). Every registered scheme (`all`: a scheme added to the registry is trained
# without touching this file) traces the same rays on stadium (a few huge triangles among many small
# ones), spheres:300000 (a structure beyond the L2) and room (an interior), camera and bounce rays:
# so each scheme's code is counted in proportion to its own work on rays like those it will be
# timed on. Until session 40 only the schemes of the speed goals ran on the last two, the others
# on stadium's 128x128 rays alone, and the profile-guided build made several of those slower than a
# plain build (branches laid out for stadium's rays: bvh_single 0.60-0.67x on conference's camera
# rays and 0.44-0.48x on bounce rays, bvh_partition 0.70-0.77x, kd_single 0.83x; with
# simd::V<1>::min/max made branch-free, docs/PERFORMANCE.md, session 40). Counts only steer
# code layout, inlining, unrolling and register allocation; code the training never reaches is
# optimised as usual (-fprofile-partial-training).
set -euo pipefail
bin="$1/travbench"
[ -x "$bin" ] || { echo "pgo_train.sh: no travbench in $1" >&2; exit 1; }
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
run() { "$bin" run --threads 1 --csv "$out/train.csv" "$@" >"$out/log" 2>&1 || { cat "$out/log" >&2; return 1; }; }
run --scene stadium --schemes all --workloads primary,bounce:2,shadow --width 128 --height 128 --reps 1
for scene in spheres:300000 room; do
  run --scene "$scene" --schemes all --workloads primary,bounce:2,bounce:3 --width 256 --height 256 --reps 2
done
