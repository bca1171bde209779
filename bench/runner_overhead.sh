#!/bin/bash
# The local runner's own cost per task (docs/scaling.md): a job of TASKS trivial
# collision tasks (10 grains, 10 steps; the fork, HDF5 file and database work are all
# that is left), run for SECONDS on 2 workers in a scratch folder; prints the tasks
# finished and the runner process's own CPU time (its workers' excluded), for each
# demcal binary given, one after the other.
#
#   bash bench/runner_overhead.sh [TASKS=10000] [SECONDS=30] DEMCAL [DEMCAL ...]
set -euo pipefail
tasks=${1:-10000}
secs=${2:-30}
shift 2 || true
[ $# -gt 0 ] || set -- build/cli/demcal
replicas=$(( (tasks + 99) / 100 ))
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
factors=$(awk 'BEGIN { for (k = 0; k < 100; k++) printf "%s%.4f", (k ? "," : ""), 0.01 + 0.0029 * k }')
cat > "$dir/job.json" <<EOF
{ "name": "overhead", "scene": "collision",
  "material": { "kn": 3e7, "ks": 2.7e7, "density": 2650, "diameter": { "min": 0.001, "max": 0.002 } },
  "collision": { "particles": 10, "solid_fraction": 0.2, "velocity_max": 1.0, "steps": 10, "sample_every": 10 },
  "grid": { "dt_factor": [$factors] }, "replicas": $replicas, "seed": 1 }
EOF
tick=$(getconf CLK_TCK)
for bin in "$@"; do
  rm -f "$dir"/o.db*
  rm -rf "$dir/demcal-out"
  "$bin" run "$dir/job.json" --db "$dir/o.db" --workers 2 >/dev/null 2>&1 &
  pid=$!
  stat=""
  end=$((SECONDS + secs))
  while [ $SECONDS -lt $end ] && kill -0 $pid 2>/dev/null; do
    s=$(cat /proc/$pid/stat 2>/dev/null) && stat=$s
    sleep 0.5
  done
  kill -INT $pid 2>/dev/null || true
  wait $pid || true
  done_n=$(sqlite3 "$dir/o.db" "SELECT count(*) FROM tasks WHERE status = 'done'")
  total=$(sqlite3 "$dir/o.db" "SELECT count(*) FROM tasks")
  # Fields 14 and 15 of /proc/PID/stat: user and system time of the process itself.
  echo "$stat" | awk -v tk="$tick" -v n="$done_n" -v t="$total" -v s="$secs" -v b="$bin" \
    '{ cpu = ($14 + $15) / tk; printf "%s: %d of %d tasks done in %d s, runner CPU %.2f s (%.1f ms per task)\n", b, n, t, s, cpu, 1000 * cpu / (n > 0 ? n : 1) }'
done
