#!/usr/bin/env bash
# Benchmark of a whole `servo diagnose` that ends "unexplained" (issue #28, item 7): one minute
# of logs (30 s open loop on a PRBS voltage, 30 s closed loop on a square reference) of a plant
# outside the catalogue: the lab plant with a fluid drag c w_l |w_l| (c = 5e-5 N m s^2/rad^2 at
# the load, a user effect of the plant file), diagnosed against the lab model (viscous +
# Coulomb). Prints the wall time and the peak memory of each run (GNU time), and the status,
# which must be "unexplained". The target is at most 10 s on two cores.
#
#   crates/servo-cli/benches/diagnose_unexplained.sh DIR [SERVO] [RUNS]
#
#   DIR    work directory (plant, gains and logs; reused when the logs exist)
#   SERVO  the servo binary (default target/release/servo)
#   RUNS   timed runs (default 3); quote the median, on a quiet machine
set -euo pipefail
DIR=${1:?usage: diagnose_unexplained.sh DIR [SERVO] [RUNS]}
SERVO=${2:-target/release/servo}
RUNS=${3:-3}
TIME=/usr/bin/time
[ -x "$TIME" ] || { echo "needs GNU time at $TIME (apt-get install time)"; exit 1; }
mkdir -p "$DIR"
"$SERVO" params > "$DIR/model.toml"
cp "$DIR/model.toml" "$DIR/truth.toml"
cat >> "$DIR/truth.toml" <<'TOML'

[custom.drag]
acts_on = "load_torque"
expr = "c * omega_l * abs(omega_l)"
description = "a fluid drag rising with the square of speed (outside the catalogue)"
[custom.drag.params]
c = { value = 5e-5, unit = "N m s^2/rad^2" }
TOML
if [ ! -f "$DIR/open.mcap" ] || [ ! -f "$DIR/closed.mcap" ]; then
  "$SERVO" design --wc 30 --pm 60 -o "$DIR/gains.toml" > /dev/null
  "$SERVO" run --plant "$DIR/truth.toml" --voltage prbs:amp=5,bit=0.2 --duration 30 --seed 1 \
    --log "$DIR/open.mcap" > /dev/null
  "$SERVO" run --plant "$DIR/truth.toml" --gains "$DIR/gains.toml" --ref square:amp=2,period=3 \
    --duration 30 --seed 2 --log "$DIR/closed.mcap" > /dev/null 2>&1
fi
for ((k = 1; k <= RUNS; k++)); do
  "$TIME" -v "$SERVO" diagnose "$DIR/open.mcap" "$DIR/closed.mcap" --model "$DIR/model.toml" \
    > "$DIR/diagnose.txt" 2> "$DIR/diagnose.time"
  wall=$(grep 'Elapsed (wall clock)' "$DIR/diagnose.time" | awk '{print $NF}')
  rss=$(grep 'Maximum resident set size' "$DIR/diagnose.time" | awk '{print $NF}')
  status=$(grep -o '^Status: [a-z]*' "$DIR/diagnose.txt" || echo "Status: ?")
  echo "run $k: wall $wall, peak RSS $((rss / 1024)) MiB; $status"
done
