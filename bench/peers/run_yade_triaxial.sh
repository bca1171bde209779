#!/usr/bin/env bash
# demcal's dense triaxial test against YADE's, same contact law, same protocol.
#
#   bash bench/peers/run_yade_triaxial.sh [BUILD_DIR] [N] [ETA] [RATE]
#
# Defaults: build, 2000 grains, eta 0.1, 3e-4 /s (theta 30 deg, p0 100 kPa, dense).
# Needs the Debian package yade (2023.02a on Debian 12). Runs both codes side by
# side, one core each (YADE at 2,000 grains took 61-65 min here; demcal ~2-6 min), and
# prints both summaries. Parameter mapping and caveats: bench/peers/yade_triaxial.py.
set -euo pipefail
here=$(cd "$(dirname "$0")/../.." && pwd)
build=${1:-$here/build}
n=${2:-2000}
eta=${3:-0.1}
rate=${4:-3e-4}
command -v yade >/dev/null || { echo "yade not found: apt-get install -y --no-install-recommends yade" >&2; exit 2; }
[ -x "$build/bench/bench_triaxial_validation" ] || { echo "$build/bench/bench_triaxial_validation missing: build first" >&2; exit 2; }
out=${YADE_COMPARE_DIR:-$(mktemp -d)}
mkdir -p "$out"
echo "series and logs in $out" >&2
OMP_NUM_THREADS=1 yade -n -j1 -x "$here/bench/peers/yade_triaxial.py" "$n" "$eta" "$rate" "$out/yade.csv" \
  >"$out/yade.log" 2>&1 &
ypid=$!
"$build/bench/bench_triaxial_validation" particles="$n" eta="$eta" rate="$rate" threads=1 quiet=1 \
  csv="$out/demcal.csv" >"$out/demcal.log" 2>&1 || { echo "demcal run failed; see $out/demcal.log" >&2; }
wait "$ypid" || { echo "yade run failed; see $out/yade.log" >&2; tail -20 "$out/yade.log" >&2; exit 1; }
echo "demcal N $n eta $eta rate $rate: $(grep -E '^  phi_(peak|cv)_deg|^  phi_cv_se_deg' "$out/demcal.log" | awk '{printf "%s %.2f  ", $1, $2}')"
grep -E '^wall time' "$out/demcal.log"
grep -E '^(prepared|yade N)' "$out/yade.log"
