#!/usr/bin/env bash
# Faults of a fleet's memory on PostgreSQL (examples/results/fleet.md): robots killed
# with SIGKILL at seeded random moments, and the server restarted in the middle of a
# robot's run. Starts a PostgreSQL server of its own on loopback (as `nobody` when run as
# root), stops it at the end.
#
#   examples/bench/fleet_faults.sh VMAP_BINARY [INPUT] [TRIALS=20] [SEED=1] [PG_BIN=/usr/lib/postgresql/15/bin]
#
# Kills: each trial starts `vmap memory build INPUT --memory URI --robot kN` and kills it
# after a delay drawn from bash's RANDOM seeded with SEED, uniform over one uninterrupted
# run's duration (measured first); then it continues the robot (`--resume`, or `--force`
# when the kill came before its first sync) and compares the robot's memory with the
# uninterrupted run's (frames, key images, loop edges as `vmap memory info --json` lists
# them). Restart: a robot's run during which the server is restarted (pg_ctl restart -m
# fast) fails with exit code 9 (unavailable) or finishes; it is then continued with
# `--resume`, and compared the same way.
set -euo pipefail
vmap=$(realpath "$1")
repo=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
input=${2:-$repo/examples/data/tum_fr1_rpy_60/rgb.txt}
trials=${3:-20}
seed=${4:-1}
pg_bin=${5:-/usr/lib/postgresql/15/bin}

work=$(mktemp -d /tmp/vmap-fleet-faults-XXXXXX)
as_server=()
if [ "$(id -u)" -eq 0 ]; then chown nobody:nogroup "$work"; as_server=(setpriv --reuid=nobody --regid=nogroup --clear-groups); fi
port=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
pg_ctl() { "${as_server[@]}" "$pg_bin/pg_ctl" -D "$work/data" -l "$work/log" -w "$@" >/dev/null; }
"${as_server[@]}" "$pg_bin/initdb" -D "$work/data" -U vmap --auth=trust -E UTF8 --locale=C >/dev/null
server_options="-p $port -k $work -c listen_addresses=127.0.0.1"
pg_ctl -o "$server_options" start
trap 'pg_ctl -m immediate stop || true; rm -rf "$work"' EXIT
uri="postgresql://vmap@127.0.0.1:$port/postgres"

summary() { "$vmap" memory info "$uri" --robot "$1" --json | python3 -c 'import json, sys; j = json.load(sys.stdin); print(json.dumps([j["frames"], j["key_images"], j["loops"]]))'; }

start=$(date +%s.%N)
"$vmap" memory build "$input" --memory "$uri" --robot reference >/dev/null
duration=$(python3 -c "print($(date +%s.%N) - $start)")
reference=$(summary reference)

RANDOM=$seed
equal=0 resumed=0 started_again=0 complete=0
for trial in $(seq 1 "$trials"); do
  robot="k$trial"
  delay=$(python3 -c "print(round(0.02 + $RANDOM / 32767 * $duration, 3))")
  timeout -s KILL "$delay" "$vmap" memory build "$input" --memory "$uri" --robot "$robot" >/dev/null 2>&1 || true
  if "$vmap" memory build "$input" --memory "$uri" --robot "$robot" --resume >/dev/null 2>"$work/err"; then
    resumed=$((resumed + 1))
  elif grep -q "already holds every frame" "$work/err"; then
    complete=$((complete + 1))  # killed after its last frame was written
  else
    # Killed before its first sync: the robot holds nothing (or was never made).
    "$vmap" memory build "$input" --memory "$uri" --robot "$robot" --force >/dev/null
    started_again=$((started_again + 1))
  fi
  if [ "$(summary "$robot")" = "$reference" ]; then equal=$((equal + 1)); else echo "trial $trial (kill at $delay s): differs" >&2; fi
done
printf 'kills: %d trials (seeded moments in %.2f s), %d equal to the uninterrupted run (%d resumed, %d started again before their first sync, %d after their last frame)\n' \
  "$trials" "$duration" "$equal" "$resumed" "$started_again" "$complete"

# The server restarted in the middle of a run.
"$vmap" memory build "$input" --memory "$uri" --robot restarted >/dev/null 2>"$work/restart.err" &
robot_pid=$!
sleep "$(python3 -c "print(round($duration / 2, 3))")"
pg_ctl -m fast restart -o "$server_options"
set +e
wait "$robot_pid"
code=$?
set -e
message=$(tail -1 "$work/restart.err")
continued=no
if "$vmap" memory build "$input" --memory "$uri" --robot restarted --resume >/dev/null 2>"$work/err" || grep -q "already holds every frame" "$work/err"; then
  continued=yes
fi
same=no
if [ "$(summary restarted)" = "$reference" ]; then same=yes; fi
printf 'restart: the run exited with %d (%s); continued with --resume: %s; equal to the uninterrupted run: %s\n' \
  "$code" "${message:-no message}" "$continued" "$same"
