#!/usr/bin/env bash
# Installs what is missing, builds, and runs a small calibration end to end: dense
# triaxial tests over a 3 x 3 grid of (theta, eta) into demcal.db (1-1.5 min on
# 2 cores, after the first install and build), the inversion of target angles into (theta, eta) with its 95% region,
# and contour maps of phi_peak and phi_cv with that region drawn on them.
#   PHI_PEAK=42 PHI_CV=30 scripts/quickstart.sh      # your own target angles [deg]
#   JOB=examples/collision.json DB=my.db scripts/quickstart.sh
# JOB and DB are read from where the script is started (JOB also from the clone, for
# its examples/); the database, its results and the maps go next to DB. BUILD_DIR
# (default build) is the clone's.
set -euo pipefail
caller=$PWD
cd "$(dirname "$0")/.."
BUILD_DIR=${BUILD_DIR:-build}
# The command-line tool only (the tests and benchmarks are scripts/test.sh's), its
# compiler output in a log.
mkdir -p "$BUILD_DIR"
BUILD_DIR="$BUILD_DIR" BUILD_TARGETS=${BUILD_TARGETS:-demcal} BUILD_LOG=${BUILD_LOG:-$BUILD_DIR/build.log} \
  bash scripts/setup.sh
JOB=${JOB:-examples/quickstart.json}
DB=${DB:-demcal.db}
case "$JOB" in /*) ;; *) if [ -e "$caller/$JOB" ] || [ ! -e "$JOB" ]; then JOB="$caller/$JOB"; fi ;; esac
case "$DB" in /*) ;; *) DB="$caller/$DB" ;; esac
PHI_PEAK=${PHI_PEAK:-40}
PHI_CV=${PHI_CV:-27}
demcal="$BUILD_DIR/cli/demcal"
case "$demcal" in /*) ;; *) demcal="$PWD/$demcal" ;; esac  # printed for use from anywhere
summary=$("$demcal" validate "$JOB")
echo "$summary" | head -n 2
# The job's name and scene as demcal read them ("job NAME: scene SCENE, fidelity F"),
# whatever the file's layout.
name=$(echo "$summary" | sed -n '1s/^job \(.*\): scene .*/\1/p')
scene=$(echo "$summary" | sed -n '1s/^job .*: scene \([a-z_]*\).*/\1/p')
# Progress goes to stderr; the full results table (every parameter and metric) is
# left out here, the query below shows the headline columns.
"$demcal" run "$JOB" --db "$DB" > /dev/null
out=$(dirname "$DB")
# The job's first task id (a database holding other jobs numbers its tasks on).
first=$("$demcal" query --db "$DB" --job "$name" --format csv | sed -n 2p | cut -d, -f1)
echo
echo "== results of job '$name' in $DB =="
if [ "$scene" != triaxial ]; then
  "$demcal" query --db "$DB" --job "$name" --format table
  echo
  echo "Series (HDF5) are under $out/demcal-out/$name/; plot one with:"
  case "$scene" in
    collision) plot_args="--series energy --x step --y kinetic,elastic,total" ;;
    repose) plot_args="--series energy --x time --y kinetic,front_x" ;;
    *) plot_args="--series NAME --x COLUMN --y COLUMN (the task's HDF5 file lists them)" ;;
  esac
  echo "  $(printf '%q' "$demcal") plot $first --db $(printf '%q' "$DB") $plot_args --out series.png"
  exit 0
fi
# (A sample too small for an interior stores no interior porosity: the table is then
# refused, and the fit and maps below still come.)
"$demcal" query --db "$DB" --job "$name" --format table \
  --metrics phi_peak_deg,phi_cv_deg,phi_diff_deg,porosity_interior_initial,eps_v_final,max_inertial_number,wall_s ||
  echo "(no table: see the error above)"
echo
echo "== inversion: which (theta, eta) give phi_peak = $PHI_PEAK deg and phi_cv = $PHI_CV deg? =="
# A refused fit (targets out of the grid's reach, too few values on an axis) still
# gets its maps, and its exit status is the script's.
rc=0
"$demcal" fit --db "$DB" --job "$name" --target "phi_peak=$PHI_PEAK" --target "phi_cv=$PHI_CV" || rc=$?
echo
echo "== maps (the fit's 95% region drawn on them) =="
map_out=$(mktemp)
trap 'rm -f "$map_out"' EXIT
for metric in phi_peak phi_cv; do
  # A map refused (fewer than 2 values on an axis) is said, and the script goes on.
  map_rc=0
  "$demcal" map --db "$DB" --job "$name" --metric "$metric" --out "$out/map_$metric.png" > "$map_out" || map_rc=$?
  head -n 1 "$map_out"
  if [ "$rc" -eq 0 ]; then rc=$map_rc; fi
done
echo
echo "Stress-strain series (HDF5) are under $out/demcal-out/$name/; plot one task's with:"
echo "  $(printf '%q' "$demcal") plot $first --db $(printf '%q' "$DB") --series triaxial --x eps1 --y phi_mob_deg --out phi_mob.png"
echo "This grid is the 'quick' preset (400 grains): a smoke test, ±2-3 deg. For a real"
echo "calibration use \"fidelity\": \"standard\" (README, 'Scenes') and a grid around the answer."
exit "$rc"
