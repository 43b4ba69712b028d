#!/usr/bin/env bash
# Benchmark of a whole `servo diagnose` on one minute of REAL logs (issue #28, item 7): the first
# 30 s of each of the two friction-identification runs of the Padova 2021 lab motor
# (padova2021-jacopisky: the PID follows load-angle ramps of 50 to 450 rpm, forwards and
# backwards; current logged), against the handout's nominal model (`servo params`). Nothing
# passes alone there and the joint search runs (a gear play is always one of its members). Then
# the two PID step logs of the same motor (54 s of closed loop), when present. The target is at
# most 10 s each on two cores. Prints the wall time and peak memory of each run (GNU time), the
# status and, with SERVO_DIAG_TIMING, the joint search's share.
#
#   crates/servo-cli/benches/diagnose_real_logs.sh [REALDATA] [SERVO] [RUNS]
#
#   REALDATA  the shared real-data directory (default ../shared/realdata); skipped when absent
#   SERVO     the servo binary (default target/release/servo)
#   RUNS      timed runs (default 3); quote the median, on a quiet machine
set -euo pipefail
REAL=${1:-../shared/realdata}
SERVO=${2:-target/release/servo}
RUNS=${3:-3}
DIR="$REAL/padova2021-jacopisky/csv"
if [ ! -f "$DIR/friction_pos.csv" ] || [ ! -f "$DIR/friction_neg.csv" ]; then
  echo "SKIP: no real logs at $DIR (the Padova data are not part of the project)"
  exit 0
fi
TIME=/usr/bin/time
[ -x "$TIME" ] || { echo "needs GNU time at $TIME (apt-get install time)"; exit 1; }
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
"$SERVO" params > "$WORK/model.toml"
. "$(dirname "$0")/timed_diagnose.sh"
# Two cases of about one minute each: the friction ramps (the first 30 s of each run, 60 s) and
# the two PID step logs (54 s of closed loop, the load held between steps: most of the simulated
# periods of a model with a gear play are held ones).
timed_diagnose "friction ramps (60 s)" "$RUNS" "$WORK" "$WORK/model.toml" "$DIR/friction_pos.csv" "$DIR/friction_neg.csv" --window 0..30
if [ -f "$DIR/pid_best_steps.csv" ] && [ -f "$DIR/pid_bode_steps.csv" ]; then
  timed_diagnose "PID step logs (54 s)" "$RUNS" "$WORK" "$WORK/model.toml" "$DIR/pid_best_steps.csv" "$DIR/pid_bode_steps.csv"
fi
