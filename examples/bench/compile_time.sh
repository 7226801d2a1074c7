#!/usr/bin/env bash
# Compile time of a program that uses vmap, against the dependency floor (a file that
# includes only the OpenCV and Eigen headers such a program needs), one after the other
# on the same machine with the same flags; the ratio is the figure (the machine is
# shared and noisy). Three programs: the probe of SHARED/bench/compile (consumer.cpp:
# an OrbVisualMemory fed from a folder, one localization) header-only and as it compiles
# in a program linking vmap::stacks (-DVMAP_COMPILED_STACKS), the same work on AnyMemory
# (tests/consumer/light.cpp), and a run-time-layer program
# (tests/consumer/stacks.cpp: AnyMemory on a store) both ways. Peak compiler memory too.
#
#   bash examples/bench/compile_time.sh [SHARED_DIR=../shared] [ROUNDS=1]
set -euo pipefail
cd "$(dirname "$0")/../.."
shared=${1:-../shared}
rounds=${2:-1}
flags=(-std=c++20 -O2 -Iinclude -isystem /usr/include/opencv4 -isystem /usr/include/eigen3 -c -o /dev/null)

# seconds and peak KB of one compile, the best of `rounds`
measure() {
  local best_s="" best_kb="" out
  out=$(mktemp)
  for ((r = 0; r < rounds; r++)); do
    /usr/bin/time -o "$out" -f "%e %M" g++ "${flags[@]}" "$@"
    local s kb
    read -r s kb <"$out"
    if [ -z "$best_s" ] || awk -v a="$s" -v b="$best_s" 'BEGIN { exit !(a < b) }'; then best_s=$s best_kb=$kb; fi
  done
  rm -f "$out"
  echo "$best_s $best_kb"
}

printf '%-44s %8s %8s %8s\n' "translation unit" "seconds" "x floor" "peak MB"
read -r floor_s floor_kb < <(measure "$shared/bench/compile/floor.cpp")
row() {
  local name=$1; shift
  read -r s kb < <(measure "$@")
  printf '%-44s %8.1f %8.2f %8.0f\n' "$name" "$s" "$(awk -v a="$s" -v b="$floor_s" 'BEGIN { print a / b }')" "$((kb / 1024))"
}
printf '%-44s %8.1f %8.2f %8.0f\n' "floor (OpenCV + Eigen headers)" "$floor_s" 1 "$((floor_kb / 1024))"
row "consumer.cpp, header-only" "$shared/bench/compile/consumer.cpp"
row "consumer.cpp, linking vmap::stacks" -DVMAP_COMPILED_STACKS "$shared/bench/compile/consumer.cpp"
row "consumer light.cpp, header-only" tests/consumer/light.cpp
row "consumer light.cpp, linking vmap::stacks" -DVMAP_COMPILED_STACKS tests/consumer/light.cpp
row "AnyMemory program, header-only" tests/consumer/stacks.cpp
row "AnyMemory program, linking vmap::stacks" -DVMAP_COMPILED_STACKS tests/consumer/stacks.cpp
