#!/usr/bin/env bash
# Benchmark of `servo trend` (issue #31, item 2): N one-minute open-loop logs of 4 simulated
# actuators (one with a growing gear play), then `servo trend` on them with 1 and with 2 workers
# (cold cache each), and once more on the warm cache. Prints the per-log cost, the parallel
# speed-up and the peak memory (GNU time's "Maximum resident set size").
#
#   crates/servo-cli/benches/trend_fleet.sh N DIR [SERVO]
#
#   N      logs (1000 for the issue's figure; run it on an idle machine)
#   DIR    work directory (logs in DIR/fleet, caches in DIR/cache-*); reused when the logs exist
#   SERVO  the servo binary (default target/release/servo)
#
# RUNS (environment) picks the runs, in order, default "serial 1 2 warm":
#   serial  one worker pinned to one core (`taskset -c 0`): no parallelism at all, the baseline
#   1       one worker on every core (a fit splits its own work onto an idle core)
#   2       two workers
#   warm    two workers again on the cache of run 2 (needs run 2 first)
set -euo pipefail
N=${1:?usage: trend_fleet.sh N DIR [SERVO]}
DIR=${2:?usage: trend_fleet.sh N DIR [SERVO]}
SERVO=${3:-target/release/servo}
TIME=/usr/bin/time
[ -x "$TIME" ] || { echo "needs GNU time at $TIME (apt-get install time)"; exit 1; }
mkdir -p "$DIR/fleet"
# The fleet's model: the default plant file (`servo params`) and a gear play to size.
"$SERVO" params > "$DIR/model.toml"
printf '\n[effects.backlash]\ngap = 0.01\n' >> "$DIR/model.toml"
have=$(find "$DIR/fleet" -name '*.mcap' | wc -l)
if [ "$have" -lt "$N" ]; then
  echo "simulating $N one-minute logs in $DIR/fleet ..."
  start=$(date +%s)
  for ((k = 0; k < N; k++)); do
    a=$((k % 4)); week=$((k / 4))
    mkdir -p "$DIR/fleet/act-$a"
    f="$DIR/fleet/act-$a/run_$(printf %05d "$week").mcap"
    [ -f "$f" ] && continue
    effect=()
    if [ "$a" = 0 ]; then
      effect=(--plant-effect "backlash:gap=$(awk -v w="$week" 'BEGIN{printf "%.5f", 0.01 + 0.0002 * w}')")
    fi
    "$SERVO" run --voltage prbs:amp=4,bit=0.2 --duration 60 --seed "$((k + 1))" "${effect[@]}" \
      --log "$f" > /dev/null
  done
  echo "simulated in $(( $(date +%s) - start )) s"
fi
RUNS=${RUNS:-serial 1 2 warm}
rm -f "$DIR"/serial.time "$DIR"/one_worker.time "$DIR"/two_workers.time "$DIR"/warm.time
run() { # workers cache label [pinned|warm]
  local pin=()
  [ "${4:-}" = pinned ] && pin=(taskset -c 0)
  [ "${4:-}" = warm ] || rm -rf "$DIR/$2"
  "${pin[@]}" "$TIME" -v "$SERVO" trend "$DIR/fleet" --model "$DIR/model.toml" --jobs "$1" --cache "$DIR/$2" \
    --time-from mtime --quiet > "$DIR/$3.txt" 2> "$DIR/$3.time"
  local wall rss
  wall=$(grep 'Elapsed (wall clock)' "$DIR/$3.time" | awk '{print $NF}')
  rss=$(grep 'Maximum resident set size' "$DIR/$3.time" | awk '{print $NF}')
  echo "$3: wall $wall, peak RSS $((rss / 1024)) MiB; $(grep -o '[0-9]* from the cache, [0-9]* fitted, [0-9]* failed' "$DIR/$3.txt")"
}
secs() { awk -F: '{ if (NF == 3) print $1 * 3600 + $2 * 60 + $3; else print $1 * 60 + $2 }' <<< "$1"; }
for r in $RUNS; do
  case "$r" in
    serial) run 1 cache-s serial pinned ;;
    1) run 1 cache-1 one_worker ;;
    2) run 2 cache-2 two_workers ;;
    warm) run 2 cache-2 warm warm ;; # the cache of run 2, kept
    *) echo "RUNS: unknown run \`$r\` (expected serial, 1, 2 or warm)"; exit 1 ;;
  esac
done
wall_of() { [ -f "$DIR/$1.time" ] && secs "$(grep 'Elapsed (wall clock)' "$DIR/$1.time" | awk '{print $NF}')"; }
ws=$(wall_of serial || true); w1=$(wall_of one_worker || true); w2=$(wall_of two_workers || true)
awk -v n="$N" -v s="$ws" -v a="$w1" -v b="$w2" 'BEGIN {
  if (s != "") printf "per log: %.3f s serial (one core)\n", s / n
  if (a != "") printf "per log: %.3f s wall, 1 worker\n", a / n
  if (b != "") printf "per log: %.3f s wall, 2 workers\n", b / n
  if (s != "" && b != "") printf "speed-up serial -> 2 workers: %.2fx\n", s / b
  if (a != "" && b != "") printf "speed-up 1 -> 2 workers: %.2fx\n", a / b
}'
