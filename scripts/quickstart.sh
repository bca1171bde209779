#!/usr/bin/env bash
# Installs what is missing, builds, runs the quickstart job into demcal.db and
# prints its results.
#   JOB=examples/other.json DB=my.db scripts/quickstart.sh
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
BUILD_DIR=${BUILD_DIR:-build}
JOB=${JOB:-examples/quickstart.json}
DB=${DB:-demcal.db}
demcal="$BUILD_DIR/cli/demcal"
"$demcal" validate "$JOB"
"$demcal" run "$JOB" --db "$DB"
name=$(sed -n 's/^ *"name": *"\([^"]*\)".*/\1/p' "$JOB" | head -n 1)
echo
echo "== results of job '$name' in $DB =="
"$demcal" query --db "$DB" --job "$name" --format table
echo
echo "Series (HDF5) are under $(dirname "$DB")/demcal-out/$name/; plot one with:"
echo "  $demcal plot 1 --db $DB --series energy --x step --y total --out energy.png"
