#!/usr/bin/env bash
# A database demcal may read but not write (a colleague's results, a read-only share):
# status and query still answer, run refuses with the reason and exit 2, and nothing
# is left beside the file. Permissions do not bind root, so the commands run as the
# unprivileged user `nobody`; skipped (77) where that cannot be arranged.
#   readonly_db.sh DEMCAL
set -u
DEMCAL=$1
if [[ $(id -u) != 0 ]] || ! command -v runuser > /dev/null || ! id nobody > /dev/null 2>&1; then
  echo "skipped: needs root, runuser and the user nobody to test permissions"
  exit 77
fi
T=$(mktemp -d /tmp/demcal-readonly.XXXXXX)
trap 'chmod -R u+w "$T"; rm -rf "$T"' EXIT
chmod 755 "$T"
cp "$DEMCAL" "$T/demcal"  # the build folder may not be open to nobody
cmp -s "$DEMCAL" "$T/demcal" || { echo "FAIL: $DEMCAL changed while it was copied (rebuilt during ctest?)"; exit 1; }
# A run of the owner's that must succeed; its output is shown when it does not.
owner_run() {
  "$T/demcal" run "$@" > "$T/owner.log" 2>&1 && return 0
  echo "the owner's run failed: demcal run $*"
  cat "$T/owner.log"
  return 1
}
cat > "$T/j.json" << 'JOB'
{"name": "ro", "scene": "collision", "material": {"kn": 3e7, "diameter": {"min": 0.001, "max": 0.002}},
 "collision": {"particles": 20, "steps": 200, "sample_every": 20}, "grid": {"dt_factor": [0.1, 0.2]},
 "seed": 1, "threads": 1}
JOB
# A (theta, eta) grid whose stored metric a fit can invert (instant: 20 grains).
cat > "$T/f.json" << 'JOB'
{"name": "rofit", "scene": "collision", "material": {"kn": 3e7, "diameter": {"min": 0.001, "max": 0.002}},
 "collision": {"particles": 20, "steps": 200, "sample_every": 20, "keep_friction": true},
 "grid": {"theta_deg": [10, 20, 30], "eta": [0.0, 0.1, 0.2]}, "seed": 1, "threads": 1}
JOB
mkdir "$T/shut" "$T/open" "$T/outs"
chmod 777 "$T/outs"  # where the refused runs would have put their HDF5 files
owner_run "$T/j.json" --db "$T/shut/x.db" --out "$T/out" || exit 1
owner_run "$T/f.json" --db "$T/shut/x.db" --out "$T/out" || exit 1
cp "$T/shut/x.db" "$T/open/x.db"
chmod 444 "$T/shut/x.db" "$T/open/x.db"
chmod 555 "$T/shut"   # a folder nobody may write: SQLite cannot make its -shm file there
chmod 777 "$T/open"   # a writable folder, a read-only file
sum=$(md5sum < "$T/shut/x.db")
fail=0
as_nobody() { runuser -u nobody -- "$T/demcal" "$@"; }
expect() {  # expect RC PATTERN -- ARGS...: exit code RC and PATTERN in stdout+stderr
  local rc=$1 pat=$2; shift 3
  local out got
  out=$(cd "$T" && as_nobody "$@" 2>&1); got=$?
  if [[ $got != "$rc" || "$out" != *"$pat"* ]]; then
    echo "FAIL: demcal $* gave exit $got (expected $rc) without '$pat':"; echo "$out"; fail=1
  fi
}
for dir in shut open; do
  expect 0 "ro" -- status --db "$T/$dir/x.db"
  expect 0 "dt_factor" -- query --db "$T/$dir/x.db"
  expect 2 "cannot write database" -- run "$T/j.json" --db "$T/$dir/x.db" --out "$T/outs/$dir"
  # A fit reads and answers, and says it could not store itself.
  expect 0 "fit (not stored)" -- fit --db "$T/$dir/x.db" --job rofit --target max_relative_error=0.002
  expect 0 "the fit is not stored" -- fit --db "$T/$dir/x.db" --job rofit --target max_relative_error=0.002
done
expect 2 "the file is read-only" -- run "$T/j.json" --db "$T/open/x.db" --out "$T/outs/open"
expect 2 "is not writable" -- run "$T/j.json" --db "$T/shut/new.db" --out "$T/outs/new"
# A log its writer never checkpointed (killed, or still running) in a folder where no
# -shm can be made: reading the file alone would show old results without a word.
if command -v python3 > /dev/null; then
  mkdir "$T/logged"
  cp "$T/open/x.db" "$T/logged/x.db"
  python3 - "$T/logged/x.db" << 'PY'
import os, sqlite3, sys
c = sqlite3.connect(sys.argv[1])
c.execute("PRAGMA journal_mode=WAL")
c.execute("UPDATE tasks SET status = 'failed'")
c.commit()
os._exit(0)  # no close: the change stays in the -wal
PY
  rm -f "$T/logged/x.db-shm"
  chmod 444 "$T/logged/x.db" "$T/logged/x.db-wal"
  chmod 555 "$T/logged"
  if [[ -s "$T/logged/x.db-wal" ]]; then
    expect 2 "write-ahead log" -- status --db "$T/logged/x.db"
  else
    echo "note: python's sqlite3 checkpointed on exit; the -wal case was not exercised"
  fi
fi
# A read-only file in a writable folder: reading it leaves nothing beside it (files
# made with the database's read-only permissions would make its owner's next run fail).
left=$(ls "$T/open")
[[ "$left" == "x.db" ]] || { echo "FAIL: files left beside the read-only database: $left"; fail=1; }
chmod 644 "$T/open/x.db"
owner_run "$T/j.json" --db "$T/open/x.db" --out "$T/out" || { echo "FAIL: the owner's run after the readers failed"; fail=1; }
# The job's output folder left by an earlier run of someone else's: refused before
# any task runs, and nothing recorded.
mkdir -p "$T/outs2/ro" "$T/mine"
chmod 777 "$T/outs2"
chmod 755 "$T/outs2/ro"  # the job's folder, root's
chmod 777 "$T/mine"
expect 2 "cannot write into the output folder" -- run "$T/j.json" --db "$T/mine/n.db" --out "$T/outs2"
[[ ! -e "$T/mine/n.db" ]] || { echo "FAIL: a run refused for its output folder made its database"; fail=1; }
# A database nobody may read at all: the reason is in the message.
cp "$T/shut/x.db" "$T/mine/z.db"
chmod 000 "$T/mine/z.db"
expect 2 "Permission denied" -- status --db "$T/mine/z.db"
[[ $(md5sum < "$T/shut/x.db") == "$sum" ]] || { echo "FAIL: the read-only database changed"; fail=1; }
left=$(ls "$T/shut")
[[ "$left" == "x.db" ]] || { echo "FAIL: files left in the read-only folder: $left"; fail=1; }
[[ -z "$(ls "$T/outs")" ]] || { echo "FAIL: a refused run made its output folder"; fail=1; }
exit $fail
