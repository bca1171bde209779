#!/usr/bin/env bash
# demcal against LAMMPS on the same dense pack, one core, same number of steps.
#
#   bash bench/peers/run_lammps_compare.sh [BUILD_DIR] [N] [STEPS] [REPEAT]
#
# Needs the Debian package lammps (lmp with the GRANULAR package: pair_style
# granular, hooke / tangential linear_history / rolling sds). The pack is the one
# bench_engine_throughput prepares (N grains, diameters uniform in [1, 2] mm,
# ~100 kPa, theta 30 deg, eta 0.1), cached in $BENCH_PACK_DIR (default: a
# temporary folder). Both codes start from the same positions at rest, run 200
# untimed steps (contact springs build up), then STEPS timed steps. Prints ns per
# particle-step for each and the ratio. Parameter mapping: docs/performance.md.
#
# REPEAT (default 1) runs the pair REPEAT times, alternating the two codes (and which
# of them goes first), so that both meet the same minutes of a shared machine; it then prints each code's best
# (noise on a VM only ever adds time) and the median of the pairs' ratios.
set -euo pipefail
here=$(cd "$(dirname "$0")/../.." && pwd)
build=${1:-$here/build}
n=${2:-2000}
steps=${3:-2000}
repeat=${4:-1}
[[ $repeat =~ ^[0-9]{1,4}$ ]] && ((10#$repeat > 0)) || { echo "REPEAT must be an integer from 1 to 9999, got '$repeat'" >&2; exit 2; }
repeat=$((10#$repeat))
command -v lmp >/dev/null || { echo "lmp not found: apt-get install -y lammps" >&2; exit 2; }
for b in bench_engine_throughput bench_lammps_compare; do
  [ -x "$build/bench/$b" ] || { echo "$build/bench/$b missing: build first (cmake --build $build)" >&2; exit 2; }
done
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
export BENCH_PACK_DIR=${BENCH_PACK_DIR:-$work}
export OMP_NUM_THREADS=1
# The name prepared_pack() in bench/engine_throughput.cpp caches it under.
pack=$BENCH_PACK_DIR/demcal-pack-v2-$n.bin
if [ ! -f "$pack" ]; then
  echo "preparing the $n-grain pack (cached in $BENCH_PACK_DIR) ..." >&2
  "$build/bench/bench_engine_throughput" "$n" --steps 10 --threads 1 >/dev/null
fi
run_demcal() {
  demcal_line=$("$build/bench/bench_lammps_compare" "$pack" --steps "$steps" --lammps-dir "$work")
  echo "$demcal_line"
}
run_lammps() {
  (cd "$work" && lmp -in in.compare -log log.lammps -screen none) || { echo "lmp failed; see its log:" >&2; tail -20 "$work/log.lammps" >&2; exit 1; }
}
demcal_all=() lammps_all=() ratios=()
for ((k = 1; k <= repeat; k++)); do
  # demcal writes LAMMPS's input in the first pair; from then on every second pair
  # runs LAMMPS first, so that neither code always takes the first minutes of a pair.
  ((repeat == 1)) || echo "pair $k of $repeat: $( ((k % 2 == 1)) && echo demcal || echo LAMMPS) first"
  if ((k % 2 == 1)); then
    run_demcal
    run_lammps
  else
    run_lammps
    run_demcal
  fi
  # The second "Loop time" is the timed run.
  loop=$(grep '^Loop time' "$work/log.lammps" | tail -1)
  lsec=$(echo "$loop" | awk '{print $4}')
  lammps_ns=$(awk -v s="$lsec" -v n="$n" -v k="$steps" 'BEGIN{printf "%.2f", s*1e9/(n*k)}')
  echo "lammps: $loop -> $lammps_ns ns/particle-step"
  demcal_ns=$(echo "$demcal_line" | sed -E 's/.* ([0-9.]+) ns\/particle-step.*/\1/')
  for v in "$demcal_ns" "$lammps_ns"; do
    [[ $v =~ ^[0-9]+(\.[0-9]+)?$ ]] && [[ ! $v =~ ^0+(\.0+)?$ ]] || { echo "could not read a time from the run (got '$v'); see the lines above" >&2; exit 1; }
  done
  awk -v a="$lammps_ns" -v b="$demcal_ns" 'BEGIN{printf "ratio LAMMPS / demcal: %.2f (demcal is %.2fx %s per particle-step)\n", a/b, (a>b?a/b:b/a), (a>b?"faster":"slower")}'
  demcal_all+=("$demcal_ns") lammps_all+=("$lammps_ns")
  ratios+=("$(awk -v a="$lammps_ns" -v b="$demcal_ns" 'BEGIN{printf "%.6f", a/b}')")
done
[ "$repeat" -gt 1 ] || exit 0
# min / median / max of the arguments (awk only: no early-closing pipe under pipefail).
stats() { printf '%s\n' "$@" | sort -g | awk '{v[NR] = $1} END {m = NR % 2 ? v[(NR + 1) / 2] : (v[NR / 2] + v[NR / 2 + 1]) / 2; printf "%.2f %.2f %.2f", v[1], m, v[NR]}'; }
read -r bd _ _ <<<"$(stats "${demcal_all[@]}")"
read -r bl _ _ <<<"$(stats "${lammps_all[@]}")"
read -r rlo rmed rhi <<<"$(stats "${ratios[@]}")"
echo "over $repeat alternations: demcal best $bd, LAMMPS best $bl ns/particle-step;" \
  "ratio of the bests $(awk -v a="$bl" -v b="$bd" 'BEGIN{printf "%.2f", a/b}'), median of the pairs' ratios $rmed (range $rlo-$rhi)"
