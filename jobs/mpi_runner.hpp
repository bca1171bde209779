#pragma once
// The MPI task farm (`mpirun -n N demcal run JOB --mpi`), built with DEMCAL_MPI=ON.
//
// Rank 0 owns the SQLite database and coordinates only: it records the job,
// hands the next pending task to whichever worker rank asks, receives the result
// as the worker's JSON text and commits it. Worker ranks never open the database;
// each runs its task in a forked child (run_forked, as the local runner does, so a
// crash fails that task only) and sends a heartbeat every timeout/5 while it runs.
// A worker rank silent for longer than the timeout is declared lost: its task is
// marked failed ("worker rank R lost ...", rerun with --retry-failed) and the rank
// gets no more work. See docs/scaling.md for what OpenMPI does when a rank dies.
#include "db/store.hpp"
#include "job_spec.hpp"
#include "runner.hpp"

namespace demcal::jobs::mpi {

struct MpiOptions {
  double timeout_s = 60;  // silence after which a busy worker rank counts as lost
};

// MPI_Init (errors returned, not fatal) ... MPI_Finalize. On rank 0 the destructor
// first dismisses workers that were never told to stop (rank 0 failed early).
class Session {
 public:
  Session();
  ~Session();
  Session(const Session&) = delete;
  Session& operator=(const Session&) = delete;
  int rank() const { return rank_; }
  int size() const { return size_; }

 private:
  int rank_ = 0, size_ = 1;
};

// Worker ranks: serve tasks until rank 0 says stop (or falls silent). Exit code.
int serve(const MpiOptions& options);

// Rank 0: run the job over the worker ranks (throws if there are none).
RunSummary run_job_root(db::Store& store, const Job& job, const RunOptions& options, const MpiOptions& mpi);

}  // namespace demcal::jobs::mpi
