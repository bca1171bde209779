#pragma once
// `demcal merge part-*.db --into demcal.db`: joins databases written by sharded
// runs (or any demcal databases of the same schema) into one.
//
// Rules, per task key (the content key, so the same work is one row everywhere):
// - a key new to the destination is copied with its status, timings, metrics and
//   artifacts (HDF5 paths); a part's pending or running task arrives as pending;
// - a finished result replaces a pending, running or failed one in the destination;
// - done in both with identical metrics (bit for bit), or failed in both, is a
//   no-op, so merging the same part twice changes nothing;
// - done in both with different metrics is a conflict: reported, the destination
//   keeps its result;
// - jobs join by name and their task lists (job_tasks) are united; a job whose
//   spec differs from the destination's job of that name stops the merge.
// Timing metrics (is_timing_metric: wall-clock and CPU time, throughput, the thread
// count it ran on) measure the machine, not the physics; they differ between two runs
// of the same task and are left out of the comparison.
// Fits are copied unless an identical row is there. Every part is checked before
// anything is written (it must exist and be a demcal database of this schema
// version), and the whole merge is one transaction: on any error nothing is written.
// A destination that does not exist yet is built beside it (`<into>.merging-<pid>.part`)
// and renamed when whole, so a merge killed part-way leaves no empty database.
#include <functional>
#include <string>
#include <vector>

namespace demcal::db {

struct MergeReport {
  int parts = 0;
  int jobs_added = 0;
  int tasks_added = 0;     // keys new to the destination
  int results_taken = 0;   // finished results copied (new keys or replacing unfinished/failed)
  int identical = 0;       // finished in both, same result: nothing to do
  int kept = 0;            // the destination's finished result kept over a part's failed/unfinished one
  int links_added = 0;     // job_tasks rows
  int fits_added = 0;
  std::vector<std::string> conflicts;  // one line each: which part, job, index, key, what differs
};

// wall_s, wall_s_*, cpu_s and particle_steps_per_s: what the scenes report about speed.
bool is_timing_metric(const std::string& name);

// Throws DbError(bad_input) naming the file and the reason for a part that cannot
// be merged, DbError (runtime) for a job-spec conflict or an I/O failure. `stop`,
// asked once per task row, ends the merge with nothing written when it says so
// (the command line asks whether SIGINT/SIGTERM arrived).
MergeReport merge_databases(const std::string& into, const std::vector<std::string>& parts,
                            const std::function<bool()>& stop = {});

}  // namespace demcal::db
