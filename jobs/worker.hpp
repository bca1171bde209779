#pragma once
// What a worker process does: run one task's scene, write its HDF5 file and leave
// the outcome in a small result file that the parent commits to the store. The
// worker never touches the database: only the runner's parent process writes it.
#include "db/store.hpp"

#include <cstdint>
#include <functional>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

namespace demcal::jobs {

struct WorkerTask {
  std::int64_t task_id = 0;
  std::string task_key;   // written into the HDF5 file: which task it belongs to
  std::size_t index = 0;  // position in the job's expansion (for the test hook)
  std::string scene;
  nlohmann::json params;
  int threads = 1;
  bool snapshots = false;
  std::string h5_path;
  std::string result_path;
};

// A task's HDF5 file name, "<id>-<first 8 of its key>.h5": task ids are per database,
// so two databases sharing an output folder must not write the same name.
std::string task_file_name(std::int64_t task_id, const std::string& task_key);

// Runs the task and writes result_path (atomically, via rename). Returns the
// process exit status to use: 0 when a result was written.
//
// Test-only hook: if the environment variable DEMCAL_TEST_ABORT_TASK equals the
// task's index, the worker calls abort() first, to test that a crashing worker
// fails its task only.
int run_worker(const WorkerTask& task);

// The exit status of a worker that ran its task but could not write the result
// file (disk full, folder gone): the parent says so instead of "no result".
constexpr int kWorkerResultUnwritable = 3;
// The exit status of a worker that wrote its result (the task failed, saying why)
// but not the task's HDF5 or Xdmf file.
constexpr int kWorkerOutputUnwritable = 5;
// Whether a worker that ended with `wait_status` left a result to read.
bool worker_left_result(int wait_status);
// Whether it could not write into the output folder: the tasks after it would not either.
bool worker_output_unwritable(int wait_status);
// Why a worker that left no result failed, from its wait status.
std::string worker_failure(int wait_status, const std::string& result_path);

// The result a worker left, or nullopt when there is none or it is unreadable.
std::optional<db::Outcome> read_worker_result(const std::string& path);
// The same from the result's JSON text (as the MPI task farm sends it).
std::optional<db::Outcome> parse_worker_result(const std::string& text);

// Runs the task in a forked child, as the local runner does (a crash fails the
// task only), waiting for it while calling `tick` about every tick_s seconds (the
// MPI heartbeat). Returns the result's JSON text; when the child left none, a
// failed result naming the signal or exit status; with kOutputUnwritableKey true
// when the child could not write into the output folder. task.result_path is used
// and removed.
constexpr const char* kOutputUnwritableKey = "output_unwritable";
std::string run_forked(const WorkerTask& task, double tick_s, const std::function<void()>& tick);

}  // namespace demcal::jobs
