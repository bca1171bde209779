#pragma once
// The local runner: a pool of worker processes, one task per process, so a crash
// or abort fails that task only. Only this (parent) process writes the store.
#include "db/store.hpp"
#include "job_spec.hpp"

#include <ostream>
#include <string>

namespace demcal::jobs {

struct RunOptions {
  int workers = 0;           // 0: the core count
  std::string out_dir;       // HDF5 files go to <out_dir>/<job>/<task-id>.h5
  bool retry_failed = false; // put the job's failed tasks back in the queue first
  bool terminal = false;     // draw a progress bar
  std::ostream* log = nullptr;  // progress and state changes (stderr)
};

struct RunSummary {
  int total = 0, done = 0, failed = 0, unfinished = 0;
  int reused = 0;   // already done when the run started (this job or another)
  int ran = 0;      // finished by this run
  bool interrupted = false;
};

// Records the job, re-queues tasks of dead runners, runs what is pending until
// every task of the job is done or failed, or SIGINT/SIGTERM arrives: then the
// running tasks are stopped and put back to pending, finished ones are kept.
RunSummary run_job(db::Store& store, const Job& job, const RunOptions& options);

}  // namespace demcal::jobs
