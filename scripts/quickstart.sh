#!/usr/bin/env bash
# Installs what is missing, builds, and runs a small calibration end to end: dense
# triaxial tests over a 3 x 3 grid of (theta, eta) into demcal.db (about 1 min on
# 2 cores), the inversion of target angles into (theta, eta) with its 95% region,
# and contour maps of phi_peak and phi_cv with that region drawn on them.
#   PHI_PEAK=42 PHI_CV=30 scripts/quickstart.sh      # your own target angles [deg]
#   JOB=examples/collision.json DB=my.db scripts/quickstart.sh
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
BUILD_DIR=${BUILD_DIR:-build}
JOB=${JOB:-examples/quickstart.json}
DB=${DB:-demcal.db}
PHI_PEAK=${PHI_PEAK:-40}
PHI_CV=${PHI_CV:-27}
demcal="$BUILD_DIR/cli/demcal"
"$demcal" validate "$JOB" | head -n 2
# Progress goes to stderr; the full results table (every parameter and metric) is
# left out here, the query below shows the headline columns.
"$demcal" run "$JOB" --db "$DB" > /dev/null
name=$(sed -n 's/^ *"name": *"\([^"]*\)".*/\1/p' "$JOB" | head -n 1)
scene=$(sed -n 's/^ *"scene": *"\([^"]*\)".*/\1/p' "$JOB" | head -n 1)
out=$(dirname "$DB")
echo
echo "== results of job '$name' in $DB =="
if [ "$scene" != triaxial ]; then
  "$demcal" query --db "$DB" --job "$name" --format table
  echo
  echo "Series (HDF5) are under $out/demcal-out/$name/; plot one with:"
  echo "  $demcal plot 1 --db $DB --series $scene --x step --y total --out series.png"
  exit 0
fi
"$demcal" query --db "$DB" --job "$name" --format table \
  --metrics phi_peak_deg,phi_cv_deg,phi_diff_deg,porosity_initial,eps_v_final,max_inertial_number,wall_s
echo
echo "== inversion: which (theta, eta) give phi_peak = $PHI_PEAK deg and phi_cv = $PHI_CV deg? =="
"$demcal" fit --db "$DB" --job "$name" --target "phi_peak=$PHI_PEAK" --target "phi_cv=$PHI_CV"
echo
echo "== maps (the fit's 95% region drawn on them) =="
for metric in phi_peak phi_cv; do
  "$demcal" map --db "$DB" --job "$name" --metric "$metric" --out "$out/map_$metric.png" | head -n 1
done
echo
echo "Stress-strain series (HDF5) are under $out/demcal-out/$name/; plot one task's with:"
echo "  $demcal plot 1 --db $DB --series triaxial --x eps1 --y phi_mob_deg --out phi_mob.png"
echo "This grid is the 'quick' preset (400 grains): a smoke test, ±2-3 deg. For a real"
echo "calibration use \"fidelity\": \"standard\" (README, 'Scenes') and a grid around the answer."
