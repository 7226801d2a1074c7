#!/usr/bin/env bash
# Runs every `vmap` command shown in README.md, examples/*.md and examples/results/*.md,
# as written, and fails when one exits non-zero. A command is a line inside a fenced code block that starts
# with `vmap `, `$ vmap ` or `build/release/examples/vmap ` (continued over lines ending
# in a backslash); synopsis lines (with `[`, `INPUT` or `IMAGE...`) are not commands.
# A program run from another build folder (`build/test/examples/...`) fails the test:
# the README's set-up commands build only build/release, so it would not run as pasted.
# The program is replaced by the built one; the commands run in a scratch folder laid
# out like the repository (examples/ and ../shared reached through links), so their
# outputs land there and relative paths resolve as in the docs.
#
#   run_doc_commands.sh VMAP_BINARY SOURCE_DIR SCRATCH_DIR [SHARED_DIR] [--list]
#
# VMAP_DOC_ONLY=REGEX runs only the commands whose "file<TAB>command" line matches.
# Two comments on a command line change how it is run: `# by hand` marks a benchmark
# that takes minutes (the full-sequence XFeat and A-KAZE sweeps), skipped unless
# VMAP_DOC_ALL=1 (CI's time budget; run them by hand after changing what they show);
# `# fails` marks a documented error, which must exit with one of the codes of a failed
# run (1, or 3 to 8 by the error's kind: README.md, "Exit codes") and vmap's one-line
# error, not crash. A `vmap sweep` identical to one that already passed is not run again:
# it only reads, so the same line gives the same result (the pages quote one sweep often).
# Commands on a fleet's memory name its server "$VMAP_FLEET": with VMAP_PG_BIN (the folder
# of PostgreSQL's server programs) set, a server of the test's own is started on
# loopback for them (as `nobody` when run as root) and stopped at the end; without it
# they are skipped.
set -uo pipefail
vmap_bin=$1 src=$2 scratch=$3 shared=${4:-}
list_only=${5:-}

extract() {
  awk '
    /^```/ { inblock = !inblock; next }
    !inblock { next }
    {
      line = $0
      if (cont != "") { line = cont " " line; cont = "" }
      if (line ~ /\\$/) { sub(/\\$/, "", line); cont = line; next }
      sub(/^[ \t]*\$ /, "", line)
      mark = ""
      if (line ~ /#[ \t]*by hand/) mark = "HAND:"
      else if (line ~ /#[ \t]*fails/) mark = "FAILS:"
      if (line ~ /^[ \t]*build\/[a-z]+\/examples\// && line !~ /^[ \t]*build\/release\//) { print FILENAME "\tWRONGDIR:" line; next }
      if (line !~ /^[ \t]*(vmap|build\/release\/examples\/vmap) (bag|build|sweep|match|detect|loops|localize|vocabulary|memory|view) /) next
      if (line ~ /\[|INPUT|IMAGE\.\.\./) next
      sub(/[ \t]+#.*$/, "", line)
      gsub(/[ \t]+/, " ", line)
      sub(/^[ \t]*(vmap|build\/release\/examples\/vmap) /, "", line)
      print FILENAME "\t" mark line
    }' "$@"
}

cd "$src" || exit 1
mapfile -t commands < <(extract README.md examples/*.md examples/results/*.md | grep -E -- "${VMAP_DOC_ONLY:-.}")
if [ "$list_only" = "--list" ]; then printf '%s\n' "${commands[@]}"; exit 0; fi

rm -rf "$scratch"
mkdir -p "$scratch/repo"
ln -s "$src/examples" "$scratch/repo/examples"
if [ -n "$shared" ] && [ -d "$shared" ]; then ln -s "$shared" "$scratch/shared"; fi
cd "$scratch/repo" || exit 1

# A stand-in for a user's EuRoC recording (README, "Your own data"): the sample TUM
# frames in the EuRoC layout (data.csv with nanosecond times, data/ beside it, the
# camera as sensor.yaml) and, when ../shared is there, TUM's ground truth written as
# EuRoC's state_groundtruth_estimate0/data.csv (17 columns, the quaternion's w first).
ns() { awk '{ split($1, t, "."); printf "%s%s", t[1], substr(t[2] "000000000", 1, 9) }' <<<"$1"; }
mkdir -p mav0/cam0 mav0/state_groundtruth_estimate0
ln -s "$src/examples/data/tum_fr1_rpy_60/rgb" mav0/cam0/data
cp "$src/examples/data/tum_fr1_sensor.yaml" mav0/cam0/sensor.yaml
{
  echo "#timestamp [ns],filename"
  grep -v '^#' "$src/examples/data/tum_fr1_rpy_60/rgb.txt" | while read -r t f; do echo "$(ns "$t"),${f#rgb/}"; done
} >mav0/cam0/data.csv
if [ -f "$shared/data/tum_fr1_rpy/groundtruth.txt" ]; then
  {
    echo "#timestamp, p_RS_R_x [m], p_RS_R_y [m], p_RS_R_z [m], q_RS_w [], q_RS_x [], q_RS_y [], q_RS_z []"
    grep -v '^#' "$shared/data/tum_fr1_rpy/groundtruth.txt" |
      awk '{ split($1, t, "."); printf "%s%s,%s,%s,%s,%s,%s,%s,%s,0,0,0,0,0,0,0,0,0\n", t[1], substr(t[2] "000000000", 1, 9), $2, $3, $4, $8, $5, $6, $7 }'
  } >mav0/state_groundtruth_estimate0/data.csv
fi

fleet_started=0
if [ -n "${VMAP_PG_BIN:-}" ] && [ -x "$VMAP_PG_BIN/pg_ctl" ]; then
  pg_dir=$(mktemp -d /tmp/vmap-doc-pg-XXXXXX)
  as_server=()
  if [ "$(id -u)" -eq 0 ]; then chown nobody:nogroup "$pg_dir"; as_server=(setpriv --reuid=nobody --regid=nogroup --clear-groups); fi
  pg_port=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
  if "${as_server[@]}" "$VMAP_PG_BIN/initdb" -D "$pg_dir/data" -U vmap --auth=trust --no-sync -E UTF8 --locale=C >"$scratch/pg.log" 2>&1 &&
     "${as_server[@]}" "$VMAP_PG_BIN/pg_ctl" -D "$pg_dir/data" -l "$pg_dir/log" -w \
       -o "-p $pg_port -k $pg_dir -c listen_addresses=127.0.0.1" start >>"$scratch/pg.log" 2>&1; then
    export VMAP_FLEET="postgresql://vmap@127.0.0.1:$pg_port/postgres"
    fleet_started=1
    trap '"${as_server[@]}" "$VMAP_PG_BIN/pg_ctl" -D "$pg_dir/data" -m immediate -w stop >/dev/null 2>&1; rm -rf "$pg_dir"' EXIT
  else
    echo "FAIL: the fleet's server did not start:"; sed 's/^/    /' "$scratch/pg.log" | tail -5
    exit 1
  fi
fi

passed=0 failed=0 skipped=0
declare -A swept=()
for entry in "${commands[@]}"; do
  file=${entry%%$'\t'*} cmd=${entry#*$'\t'}
  if [[ "$cmd" == sweep\ * ]] && [ -n "${swept[$cmd]:-}" ]; then
    echo "ok   ($file, the same sweep passed on ${swept[$cmd]}): vmap $cmd"
    passed=$((passed + 1))
    continue
  fi
  expect_fail=0
  if [[ "$cmd" == WRONGDIR:* ]]; then
    echo "FAIL ($file): '${cmd#WRONGDIR:}' uses a build folder the README does not build (use build/release)"
    failed=$((failed + 1))
    continue
  fi
  if [[ "$cmd" == HAND:* ]]; then
    cmd=${cmd#HAND:}
    if [ "${VMAP_DOC_ALL:-0}" != 1 ]; then
      echo "skip ($file, by hand; VMAP_DOC_ALL=1 runs it): vmap $cmd"
      skipped=$((skipped + 1))
      continue
    fi
  elif [[ "$cmd" == FAILS:* ]]; then
    cmd=${cmd#FAILS:} expect_fail=1
  fi
  if [[ "$cmd" == *'$VMAP_FLEET'* ]] && [ "$fleet_started" = 0 ]; then
    echo "skip ($file, needs a PostgreSQL server: VMAP_PG_BIN): vmap $cmd"
    skipped=$((skipped + 1))
    continue
  fi
  if { [[ "$cmd" == *../shared/* ]] && [ ! -d ../shared ]; } ||
     { [[ "$cmd" == *state_groundtruth_estimate0* ]] && [ ! -f mav0/state_groundtruth_estimate0/data.csv ]; }; then
    echo "skip ($file, needs ../shared): vmap $cmd"
    skipped=$((skipped + 1))
    continue
  fi
  start=$(date +%s)
  if [ "$expect_fail" = 1 ]; then
    eval "\"$vmap_bin\" $cmd" >"$scratch/last.out" 2>"$scratch/last.err"
    rc=$?
    # A failed run's code with vmap's one-line error (OpenCV may log warnings of its own
    # before it); 2 would be a usage error, above 8 a signal or a crash.
    if [[ "$rc" =~ ^[13-8]$ ]] && grep -qE '^vmap( [a-z]+)?: error: ' "$scratch/last.err" && ! grep -q 'terminate called' "$scratch/last.err"; then
      echo "ok   ($file, fails as documented): vmap $cmd"
      passed=$((passed + 1))
    else
      echo "FAIL ($file, exit $rc, expected 1 or 3..8 with a one-line error): vmap $cmd"
      sed 's/^/    /' "$scratch/last.err" | tail -5
      failed=$((failed + 1))
    fi
    continue
  fi
  if eval "\"$vmap_bin\" $cmd" >"$scratch/last.out" 2>"$scratch/last.err"; then
    echo "ok   ($file, $(( $(date +%s) - start )) s): vmap $cmd"
    passed=$((passed + 1))
    if [[ "$cmd" == sweep\ * ]]; then swept[$cmd]=$file; fi
  else
    rc=$?
    echo "FAIL ($file, exit $rc): vmap $cmd"
    sed 's/^/    /' "$scratch/last.err" | tail -5
    failed=$((failed + 1))
  fi
done
echo "$passed passed, $failed failed, $skipped skipped"
[ "$failed" -eq 0 ] || exit 1
[ "$passed" -gt 0 ] || exit 77
