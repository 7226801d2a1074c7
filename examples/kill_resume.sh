#!/usr/bin/env bash
# Kills `vmap memory build` with SIGKILL at seeded random moments and resumes each killed
# memory; counts the trials whose memory equals the one of an uninterrupted run (frames,
# key images, loop edges as `vmap memory info --json` lists them).
#
#   bash examples/kill_resume.sh [INPUT] [TRIALS] [SEED]
#
# INPUT defaults to ../shared/data/rtabmap_loop/images, TRIALS to 20, SEED to 1; the
# program is $VMAP (default build/release/examples/vmap). The kill moments are spread
# uniformly over one uninterrupted run's duration, measured first.
set -euo pipefail
vmap=${VMAP:-build/release/examples/vmap}
input=${1:-../shared/data/rtabmap_loop/images}
trials=${2:-20}
seed=${3:-1}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

summary() { "$vmap" memory info "$1" --json | python3 -c 'import json, sys; j = json.load(sys.stdin); print(json.dumps([j["frames"], j["key_images"], j["loops"]]))'; }

start=$(date +%s.%N)
"$vmap" memory build "$input" --memory "$work/ref.vmdb" --images jpeg >/dev/null
duration=$(python3 -c "print($(date +%s.%N) - $start)")
reference=$(summary "$work/ref.vmdb")

RANDOM=$seed
equal=0 started_again=0 resumed=0 complete=0
for trial in $(seq 1 "$trials"); do
  delay=$(python3 -c "print(round(0.02 + $RANDOM / 32767 * $duration, 3))")
  rm -f "$work/k.vmdb" "$work/k.vmdb-wal" "$work/k.vmdb-shm"
  (timeout -s KILL "$delay" "$vmap" memory build "$input" --memory "$work/k.vmdb" --images jpeg) >/dev/null 2>&1 || true
  if [ ! -e "$work/k.vmdb" ] || ! "$vmap" memory info "$work/k.vmdb" >/dev/null 2>&1; then
    # Killed before the first key image was written: nothing to resume.
    "$vmap" memory build "$input" --memory "$work/k.vmdb" --images jpeg --force >/dev/null
    started_again=$((started_again + 1))
  elif "$vmap" memory build "$input" --memory "$work/k.vmdb" --resume >/dev/null 2>"$work/err"; then
    resumed=$((resumed + 1))
  elif grep -q "already holds every frame" "$work/err"; then
    complete=$((complete + 1))  # killed after the last frame was written
  else
    cat "$work/err" >&2
  fi
  if [ "$(summary "$work/k.vmdb")" = "$reference" ]; then equal=$((equal + 1)); else echo "trial $trial (kill at $delay s): differs" >&2; fi
done
printf '%s: %d trials (kills at seeded moments in %.2f s), %d equal to the uninterrupted run (%d resumed, %d killed before the first key image, %d after the last frame)\n' \
  "$input" "$trials" "$duration" "$equal" "$resumed" "$started_again" "$complete"
