#!/usr/bin/env bash
# Kills (SIGKILL) commands that write a memory at pseudo-random moments and checks what
# each kill left at the memory's path: the old memory unchanged (the same key images and
# the same bytes), or the complete new one; anything else is counted as lost or broken.
#
#   examples/bench/kill_trials.sh VMAP_BINARY OUTDIR [TRIALS=25] [SEED=1] [KINDS="convert merge build build-new convert-new"]
#
# The commands, each TRIALS times, on the repository's 60 sample frames:
#   convert      memory convert A OUT --force        (OUT: an older memory)
#   merge        memory merge A B --out OUT --force  (OUT: an older memory)
#   build        build FRAMES --memory OUT --force   (OUT: an older memory)
#   build-new    build FRAMES --memory NEW           (no file at NEW before)
#   convert-new  memory convert A NEW                (no file at NEW before)
# A kill delay is drawn from bash's RANDOM seeded with SEED, between 0 and 1.2 times the
# command's uninterrupted duration (measured first), so some runs complete. For
# build-new the "old memory" is no file at all; a killed new build leaves a store written
# up to its last sync, which `--resume` continues (counted as "partial"). For
# convert-new too the "old memory" is no file: NEW must be absent or complete.
#
# Then, where strace is installed, the kills that come at each flush to disk: convert-new
# run under `strace -f -e inject=fdatasync:signal=KILL:when=N` (SQLite's flushes), then
# `inject=fsync` (vmap's own), for N = 1 .. the calls of an uninterrupted run (at most
# 12), each kill checked as above.
set -euo pipefail

if [[ $# -lt 2 ]]; then
  echo "usage: $0 VMAP_BINARY OUTDIR [TRIALS=25] [SEED=1]" >&2
  exit 2
fi
VMAP=$(realpath "$1")
OUT_DIR=$2
TRIALS=${3:-25}
SEED=${4:-1}
KINDS=${5:-convert merge build build-new convert-new}
REPO=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
FRAMES=$REPO/examples/data/tum_fr1_rpy_60/rgb.txt
RANDOM=$SEED

mkdir -p "$OUT_DIR"
OUT_DIR=$(realpath "$OUT_DIR")
WORK=$OUT_DIR/work
rm -rf "$WORK"
mkdir -p "$WORK"

now_ms() { date +%s%3N; }

# "KEYS FRAMES" of a memory, or nothing when `memory info` refuses it.
summary() {
  "$VMAP" memory info "$1" --json 2>/dev/null |
    python3 -c 'import json, sys; j = json.load(sys.stdin); print(len(j["key_images"]), j["frames"])' 2>/dev/null || true
}

sha() { sha256sum "$1" | cut -d' ' -f1; }

# The inputs and the old memory every replacing trial starts from.
"$VMAP" build "$FRAMES" --memory "$WORK/a.vmdb" --end 40 >/dev/null 2>&1
"$VMAP" build "$FRAMES" --memory "$WORK/b.vmdb" --start 20 >/dev/null 2>&1
"$VMAP" build "$FRAMES" --memory "$WORK/old.vmdb" --end 15 --threshold 0.5 >/dev/null 2>&1
OLD_SUMMARY=$(summary "$WORK/old.vmdb")
OLD_SHA=$(sha "$WORK/old.vmdb")

# The command of each kind writing OUT.
command_of() {
  local kind=$1 out=$2
  case $kind in
    convert) echo "memory convert $WORK/a.vmdb $out --force" ;;
    merge) echo "memory merge $WORK/a.vmdb $WORK/b.vmdb --out $out --force" ;;
    build) echo "build $FRAMES --memory $out --force" ;;
    build-new) echo "build $FRAMES --memory $out" ;;
    convert-new) echo "memory convert $WORK/a.vmdb $out" ;;
  esac
}

# Prepares a trial folder: the old memory at OUT (none for build-new).
prepare() {
  local kind=$1 dir=$2
  rm -rf "$dir"
  mkdir -p "$dir"
  if [[ $kind != build-new && $kind != convert-new ]]; then cp "$WORK/old.vmdb" "$dir/out.vmdb"; fi
}

# Counts what a killed run of `kind` left in `dir` (kept, complete, partial, lost, temp).
judge() {
  local kind=$1 dir=$2 new_summary=$3
  if compgen -G "$dir/.*.vmap-new-*" >/dev/null; then temp=$((temp + 1)); fi
  local file=$dir/out.vmdb got
  if [[ ! -e $file ]]; then
    if [[ $kind == build-new || $kind == convert-new ]]; then kept=$((kept + 1)); else lost=$((lost + 1)); fi
    return
  fi
  got=$(summary "$file")
  if [[ $kind != build-new && $kind != convert-new && $got == "$OLD_SUMMARY" && $(sha "$file") == "$OLD_SHA" ]]; then
    kept=$((kept + 1))
  elif [[ -n $got && $got == "$new_summary" ]]; then
    complete=$((complete + 1))
  elif [[ $kind == build-new ]] && { [[ -n $got ]] || "$VMAP" build "$FRAMES" --memory "$file" --resume >/dev/null 2>&1 ||
                                     "$VMAP" build "$FRAMES" --memory "$file" --force >/dev/null 2>&1; }; then
    # A new run's store written up to its last sync (or before its first): continued
    # with --resume (or, holding nothing yet, started again with --force).
    partial=$((partial + 1))
  else
    lost=$((lost + 1))
  fi
}

printf '%-11s %7s %9s %13s %8s %12s %10s\n' command trials "old kept" "new complete" partial "lost/broken" "temp left"
for kind in $KINDS; do
  # The complete new memory, and how long the command takes uninterrupted.
  ref=$WORK/ref-$kind
  prepare "$kind" "$ref"
  t0=$(now_ms)
  # shellcheck disable=SC2046
  "$VMAP" $(command_of "$kind" "$ref/out.vmdb") >/dev/null 2>&1
  duration=$(($(now_ms) - t0))
  new_summary=$(summary "$ref/out.vmdb")
  kept=0 complete=0 partial=0 lost=0 temp=0
  for ((trial = 0; trial < TRIALS; ++trial)); do
    dir=$WORK/trial-$kind
    prepare "$kind" "$dir"
    delay=$((RANDOM * duration * 12 / 10 / 32768))
    # shellcheck disable=SC2046
    "$VMAP" $(command_of "$kind" "$dir/out.vmdb") >/dev/null 2>&1 &
    pid=$!
    sleep "$(printf '%d.%03d' $((delay / 1000)) $((delay % 1000)))"
    kill -9 "$pid" 2>/dev/null || true
    wait "$pid" 2>/dev/null || true
    judge "$kind" "$dir" "$new_summary"
  done
  printf '%-11s %7d %9d %13d %8d %12d %10d\n' "$kind" "$TRIALS" "$kept" "$complete" "$partial" "$lost" "$temp"
done
read -r old_keys old_frames <<<"$OLD_SUMMARY"
echo "(seed $SEED; the old memory: $old_keys key images of $old_frames frames; kills drawn over 1.2x each command's duration;"
echo " temp left: trials that left a .NAME.vmap-new-PID-N file beside OUT, which nothing reads)"

# Kills at each flush to disk of a new convert's run: SQLite flushes with fdatasync, vmap's
# own renames with fsync; each kind's calls are counted in an uninterrupted run, and the
# run is killed at its N-th call of that kind, N = 1 .. that count (at most 12).
if command -v strace >/dev/null && [[ " $KINDS " == *" convert-new "* ]]; then
  new_summary=$(summary "$WORK/ref-convert-new/out.vmdb")
  echo
  for call in fdatasync fsync; do
    dir=$WORK/flush-count
    prepare convert-new "$dir"
    # shellcheck disable=SC2046
    calls=$(strace -f -c -e trace=$call "$VMAP" $(command_of convert-new "$dir/out.vmdb") 2>&1 >/dev/null |
            awk -v c=$call '$NF == c { print $4 }')
    calls=${calls:-0}
    n_max=$((calls < 12 ? calls : 12))
    kept=0 complete=0 partial=0 lost=0 temp=0
    for ((n = 1; n <= n_max; ++n)); do
      dir=$WORK/flush-$call-$n
      prepare convert-new "$dir"
      # shellcheck disable=SC2046
      # (in a subshell that outlives strace, so the shell's "Killed" goes to /dev/null; set -e
      # would end it with strace, killed with its tracee)
      (strace -f -o /dev/null -e trace=$call -e inject=$call:signal=KILL:when=$n \
        "$VMAP" $(command_of convert-new "$dir/out.vmdb") >/dev/null 2>&1 || true) 2>/dev/null
      judge convert-new "$dir" "$new_summary"
    done
    printf 'killed at %s N = 1..%d of a new convert (an uninterrupted run makes %d): %d left no file, %d complete, %d lost/broken, %d left a temporary file\n' \
      "$call" "$n_max" "$calls" "$kept" "$complete" "$lost" "$temp"
  done
fi
