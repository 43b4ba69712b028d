#!/usr/bin/env bash
# Benchmark of a whole `servo diagnose` that ends "unexplained" (issue #28, item 7): for each
# mechanism outside the catalogue, one minute of logs (30 s open loop on a PRBS voltage, 30 s
# closed loop on a square reference) of the lab plant with that mechanism as a user effect of the
# plant file, diagnosed against the lab model (viscous + Coulomb). Prints, per case and run, the
# wall time and the peak memory (GNU time), the joint search's time (SERVO_DIAG_TIMING) and the
# status, which must be "unexplained". The target is at most 10 s each on two cores.
#
#   crates/servo-cli/benches/diagnose_unexplained.sh DIR [SERVO] [RUNS] [CASE...]
#
#   DIR    work directory (plants, gains and logs; reused when the logs exist)
#   SERVO  the servo binary (default target/release/servo)
#   RUNS   timed runs per case (default 3); quote the median, on a quiet machine
#   CASE   drag (a fluid drag c w_l |w_l|), ripple (a torque ripple of 7.5 cycles per motor
#          revolution: no harmonic of either angle, so every simulation holding a cogging or an
#          imbalance candidate runs in sub-steps), slopes (a viscous slope forwards only),
#          torque_friction (a friction growing with |i_a|); default: all four
set -euo pipefail
DIR=${1:?usage: diagnose_unexplained.sh DIR [SERVO] [RUNS] [CASE...]}
SERVO=${2:-target/release/servo}
RUNS=${3:-3}
shift $(($# < 3 ? $# : 3))
CASES=("$@")
[ ${#CASES[@]} -gt 0 ] || CASES=(drag ripple slopes torque_friction)
TIME=/usr/bin/time
[ -x "$TIME" ] || { echo "needs GNU time at $TIME (apt-get install time)"; exit 1; }
mkdir -p "$DIR"
. "$(dirname "$0")/timed_diagnose.sh"
"$SERVO" params > "$DIR/model.toml"
[ -f "$DIR/gains.toml" ] || "$SERVO" design --wc 30 --pm 60 -o "$DIR/gains.toml" > /dev/null

# The user effect of each case (a [custom.*] section of the plant file): its place, expression,
# description and parameter.
section() { # NAME ACTS_ON EXPR DESCRIPTION PARAM
  printf '[custom.%s]\nacts_on = "%s"\nexpr = "%s"\ndescription = "%s"\n[custom.%s.params]\n%s\n' \
    "$1" "$2" "$3" "$4" "$1" "$5"
}
effect() {
  case $1 in
    drag) section drag load_torque "c * omega_l * abs(omega_l)" \
      "a fluid drag rising with the square of speed" \
      'c = { value = 5e-5, unit = "N m s^2/rad^2" }' ;;
    ripple) section ripple motor_torque "a * sin(7.5 * theta_m + 0.3)" \
      "a torque ripple of 7.5 cycles per motor revolution" 'a = { value = 4e-4, unit = "N m" }' ;;
    slopes) section slopes load_torque "b * max(omega_l, 0)" "a viscous slope forwards only" \
      'b = { value = 5e-4, unit = "N m s/rad" }' ;;
    torque_friction) section torque_friction load_torque "mu * abs(i_a) * sign(omega_l)" \
      "a friction growing with the transmitted torque" 'mu = { value = 0.025, unit = "N m/A" }' ;;
    *) echo "unknown case $1 (drag, ripple, slopes, torque_friction)" >&2; exit 1 ;;
  esac
}

for c in "${CASES[@]}"; do
  d="$DIR/$c"
  mkdir -p "$d"
  if [ ! -f "$d/open.mcap" ] || [ ! -f "$d/closed.mcap" ]; then
    { cat "$DIR/model.toml"; echo; effect "$c"; } > "$d/truth.toml"
    "$SERVO" run --plant "$d/truth.toml" --voltage prbs:amp=5,bit=0.2 --duration 30 --seed 1 \
      --log "$d/open.mcap" > /dev/null 2>&1
    "$SERVO" run --plant "$d/truth.toml" --gains "$DIR/gains.toml" --ref square:amp=2,period=3 \
      --duration 30 --seed 2 --log "$d/closed.mcap" > /dev/null 2>&1
  fi
  timed_diagnose "$c" "$RUNS" "$d" "$DIR/model.toml" "$d/open.mcap" "$d/closed.mcap"
done
