#pragma once
// The local runner: a pool of worker processes, one task per process, so a crash
// or abort fails that task only. Only this (parent) process writes the store.
#include "db/store.hpp"
#include "job_spec.hpp"
#include "progress.hpp"
#include "shard.hpp"

#include <ostream>
#include <string>

namespace demcal::jobs {

struct RunOptions {
  int workers = 0;           // 0: the core count
  std::string out_dir;       // HDF5 files go to <out_dir>/<job>/<task-id>-<key8>.h5
  bool retry_failed = false; // put the job's failed tasks back in the queue first
  bool requeue_running = false;  // put the job's running tasks back first (their runner is gone)
  bool terminal = false;     // draw a progress bar
  std::ostream* log = nullptr;  // progress and state changes (stderr)
  Shard shard;               // run only this shard's tasks (see shard.hpp)
  std::string out_flag = "--out";  // the option that set out_dir, named in errors about it
};

struct RunSummary {
  int total = 0, done = 0, failed = 0, unfinished = 0;
  int reused = 0;   // already done when the run started (this job or another)
  int ran = 0;      // finished by this run
  bool interrupted = false;
  // Another run recorded a different job file under this job's name meanwhile: this
  // run stopped taking tasks, and the job's counts are that file's, not this one's.
  bool superseded = false;
  // A task could not write its files into the output folder (disk full, folder not
  // writable): this run started no more tasks. What happened, else empty.
  std::string output_failure;
  // The database file was deleted or replaced while this run wrote to it: the run
  // stopped its tasks. What happened, else empty.
  std::string database_lost;
  // Where the lost file, with this run's results, was copied (Store::save_lost_file);
  // empty if it could not be.
  std::string database_saved;
};

// Records the job, re-queues tasks of dead runners, runs what is pending until
// every task of the job is done or failed, or SIGINT/SIGTERM arrives: then the
// running tasks are stopped and put back to pending, finished ones are kept.
RunSummary run_job(db::Store& store, const Job& job, const RunOptions& options);

// What the local and the MPI runner share.
// Records the job and its tasks (restricted to options.shard, with their expansion
// index) and returns its id. When the job's spec changed since the last run into
// this database, says on `log` which tasks of the earlier spec it no longer holds.
std::int64_t record_job(db::Store& store, const Job& job, const Shard& shard, std::ostream& log);
// A runner token ("host/pidns...:pid:start") as part of a file name: the runs'
// result files in a shared output folder are told apart by it.
std::string file_name_safe(std::string s);
// A run that stopped short for a reason a caller must not read as "some tasks
// failed": the database file lost, or the output folder unwritable. Throws
// std::runtime_error starting with `context`; returns otherwise.
void throw_if_stopped_short(const RunSummary& s, const std::string& context);
// Empty while the database file `store` opened is still at its path; else a sentence
// saying it was deleted or replaced during the run.
std::string database_lost(const db::Store& store);
// At the end of a run whose database was lost: its write-ahead log emptied, so the
// file now at the path is not overwritten by it, and the lost file saved
// (s.database_saved). What the user reads after s.database_lost: what became of the
// run's results and how to get them back.
void save_lost_database(db::Store& store, RunSummary& s);
std::string lost_database_advice(const RunSummary& s);
// Where a run's HDF5 files go: <out_dir>/<job>[/shard-i-of-N], absolute.
std::string task_output_dir(const Job& job, const RunOptions& options);
// Creates `dir` and its parents: throws JobError(flag) naming the `what` ("folder",
// "output folder") and why, when it cannot be made or a file is in its way.
void make_folder(const std::string& dir, const std::string& flag, const std::string& what);
// Creates task_output_dir before the job is recorded, so that a folder that cannot
// be made (a file in its way, no permission) leaves the database as it was: throws
// JobError(options.out_flag) naming the folder and the reason.
std::string make_task_output_dir(const Job& job, const RunOptions& options);
// The job's task counts at the end of a run, into the summary.
void record_final_counts(const Counts& c, RunSummary& s);
// The job's task counts from the database; a shard's own tasks only, when `shard` is
// active (a part started as a copy of the main database holds the whole job).
Counts job_counts(db::Store& store, const std::string& job, const Shard& shard);
// "task 7 (#3: dt_factor=0.1)" for progress lines: the task id that query, status and
// plot take, then the position in the job's grid and its values.
std::string describe_task(const Job& job, std::size_t index, std::int64_t task_id);

}  // namespace demcal::jobs
