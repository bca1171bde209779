#!/usr/bin/env bash
# A collision task with snapshots, opened in ParaView (pvpython) through both readers
# (paraview_snapshots.py). Skipped (77) where ParaView is not installed: CI does not
# install it (apt-get install paraview xvfb to run this here).
set -euo pipefail
demcal=$1
here=$(cd "$(dirname "$0")" && pwd)
command -v pvpython >/dev/null || { echo "pvpython not found: skipped"; exit 77; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cd "$work"
echo '{"name": "pv", "scene": "collision", "snapshots": true, "collision": {"particles": 40}}' > pv.json
"$demcal" run pv.json > /dev/null 2>&1
xmf=$(ls demcal-out/pv/*.xmf)
ln -s "$(ls demcal-out/pv/*.h5)" pv.h5part
run=(pvpython)
if [ -z "${DISPLAY:-}" ] && command -v xvfb-run >/dev/null; then run=(xvfb-run -a pvpython); fi
"${run[@]}" "$here/paraview_snapshots.py" "$xmf" pv.h5part 40 2>&1 | grep -v '^$' | tail -5 | tee out.txt
grep -q '^ok:' out.txt
