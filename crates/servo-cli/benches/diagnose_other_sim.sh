#!/usr/bin/env bash
# Benchmark of a whole `servo diagnose` on one minute of logs of the other simulator (the e2e
# tests' RK4 plant with a smooth Coulomb friction, not servo's simulator; issue #28, item 7):
# for each mechanism outside the catalogue, the logs of two seeds (16 s open loop on voltage steps
# and 12 s closed loop on position steps each, 56 s in all), identified from the first open-loop
# log and diagnosed together. Prints, per case and run, the wall time and the peak memory (GNU
# time), the joint search's time (SERVO_DIAG_TIMING) and the status. The target for an
# "unexplained" verdict is at most 10 s on two cores.
#
#   crates/servo-cli/benches/diagnose_other_sim.sh DIR [SERVO] [RUNS] [CASE...]
#
#   DIR    work directory (logs and models; reused when the logs exist)
#   SERVO  the servo binary (default target/release/servo)
#   RUNS   timed runs per case (default 3); quote the median, on a quiet machine
#   CASE   ripple (a torque ripple of 7.5 cycles per motor revolution), encoder (an eccentric
#          load encoder, twice per revolution), offset (a current sensor offset), shaft (a
#          compliant shaft: a resonance), none (nothing missing: "complete"), and hump, of the
#          second family (a two-mass drive train with LuGre friction and a Stribeck hump behind
#          bristles of 3 N m/rad); default: all six
#
# The logs come from the ignored e2e tests `write_other_simulator_logs` and `write_two_mass_logs`
# (seeds in OTHER_SEEDS, default "44 45"); they are built and run when DIR holds no logs yet.
set -euo pipefail
DIR=${1:?usage: diagnose_other_sim.sh DIR [SERVO] [RUNS] [CASE...]}
SERVO=${2:-target/release/servo}
RUNS=${3:-3}
shift $(($# < 3 ? $# : 3))
CASES=("$@")
[ ${#CASES[@]} -gt 0 ] || CASES=(ripple encoder offset shaft none hump)
SEEDS=(${OTHER_SEEDS:-44 45})
TIME=/usr/bin/time
[ -x "$TIME" ] || { echo "needs GNU time at $TIME (apt-get install time)"; exit 1; }
mkdir -p "$DIR"
. "$(dirname "$0")/timed_diagnose.sh"

if [ ! -f "$DIR/ripple_${SEEDS[0]}_open.csv" ] || [ ! -f "$DIR/hump_${SEEDS[0]}_open.csv" ]; then
  OTHER_OUT="$DIR" OTHER_SEEDS="${SEEDS[*]}" cargo test --release -q -p servo-e2e --test e2e \
    -- --ignored --exact diagnose::write_other_simulator_logs two_mass::write_two_mass_logs \
    > /dev/null
fi

for c in "${CASES[@]}"; do
  [ -f "$DIR/${c}_${SEEDS[0]}_open.csv" ] || { echo "unknown case $c (no $DIR/${c}_${SEEDS[0]}_open.csv)" >&2; exit 1; }
  mkdir -p "$DIR/$c"
  "$SERVO" identify "$DIR/${c}_${SEEDS[0]}_open.csv" -o "$DIR/$c/model.toml" > /dev/null
  logs=()
  for s in "${SEEDS[@]}"; do logs+=("$DIR/${c}_${s}_open.csv" "$DIR/${c}_${s}_closed.csv"); done
  timed_diagnose "$c" "$RUNS" "$DIR/$c" "$DIR/$c/model.toml" "${logs[@]}"
done
