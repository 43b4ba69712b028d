# Shared by the diagnose benchmarks (sourced; needs SERVO, the servo binary, and TIME, GNU time).
#
#   timed_diagnose NAME RUNS WORK MODEL LOG... [FLAG...]
#
# Runs `servo diagnose LOG... --model MODEL` RUNS times under GNU time (output in WORK) and prints,
# per run, the wall time, the peak memory, the joint search's time (SERVO_DIAG_TIMING) and the
# status.
timed_diagnose() {
  local name=$1 runs=$2 work=$3 model=$4
  shift 4
  for ((k = 1; k <= runs; k++)); do
    SERVO_DIAG_TIMING=1 "$TIME" -v "$SERVO" diagnose "$@" --model "$model" \
      > "$work/diagnose.txt" 2> "$work/diagnose.time"
    wall=$(grep 'Elapsed (wall clock)' "$work/diagnose.time" | awk '{print $NF}')
    rss=$(grep 'Maximum resident set size' "$work/diagnose.time" | awk '{print $NF}')
    joint=$(grep -o '[0-9.]* s  backward elimination' "$work/diagnose.time" | awk '{print $1}' || true)
    status=$(grep -o '^Status: [a-z]*' "$work/diagnose.txt" || echo "Status: ?")
    echo "$name run $k: wall $wall, peak RSS $((rss / 1024)) MiB, joint search ${joint:-0} s; $status"
  done
}
