#pragma once
// The demcal store: jobs, their tasks, metrics, artifacts and fits in one SQLite
// file. It stores strings and numbers; what a job or a parameter means is the jobs
// layer's business. Only the runner's parent process writes to it.
#include "sqlite.hpp"

#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace demcal::db {

struct NewTask {
  std::string key;
  std::string scene;
  std::string params_json;
  std::int64_t idx = -1;  // position in the job's expansion; -1: its position in the list
};

struct TaskRow {
  std::int64_t id = 0;
  std::string job;         // the job this row was listed for
  std::int64_t index = -1; // position in that job's expansion
  std::string scene, params_json, key, status;
  int attempts = 0;
  std::string worker;
  std::int64_t pid = 0;
  double started_at = 0, finished_at = 0, wall_s = 0;  // NaN when unset
  std::string error;  // why a failed task failed; a done task's warnings ("warning: ..."), if any
};

struct Outcome {
  std::string status;  // "done" or "failed"
  double wall_s = 0;
  std::string error;  // failed: why; done: its warnings, or empty
  std::vector<std::pair<std::string, double>> metrics;
  std::vector<std::pair<std::string, std::string>> artifacts;  // kind, path
};

using StatusCounts = std::map<std::string, std::map<std::string, int>>;  // job -> status -> n

struct FitRow {
  std::int64_t id = 0;
  double created_at = 0;
  std::string targets_json, method, result_json;
};

class Store {
 public:
  // Checks the file read-only first (see check_file), then opens it read-write,
  // switches on WAL and migrates. `read_only` skips the write part entirely.
  explicit Store(const std::string& path, bool read_only = false);
  ~Store();
  Store(const Store&) = delete;
  Store& operator=(const Store&) = delete;

  // Records the job (by name; a changed spec replaces the old one) and links it to
  // its tasks, creating those whose key is new. Returns the job id.
  // partial (a shard, `demcal run --shard`): `tasks` is part of the job, linked at
  // their idx; links already there are kept unless the spec changed. `dropped`, if
  // given, receives the tasks the job held before and no longer does (a changed
  // spec); they and their results stay in the database.
  std::int64_t put_job(const std::string& name, const std::string& spec_json, const std::vector<NewTask>& tasks,
                       bool partial = false, std::vector<std::int64_t>* dropped = nullptr);
  std::optional<std::int64_t> find_job(const std::string& name);

  // Tasks of a job in expansion order, or every task when job is empty.
  std::vector<TaskRow> tasks(const std::string& job = "");
  std::optional<TaskRow> task(std::int64_t id);

  // Atomic: succeeds for exactly one caller while the task is pending.
  bool claim(std::int64_t task_id, const std::string& worker);
  void set_pid(std::int64_t task_id, std::int64_t pid);
  // Results and the status change in one transaction; ignored if the task is no
  // longer held by `worker` (it was re-queued meanwhile).
  bool finish(std::int64_t task_id, const std::string& worker, const Outcome& out);
  // Back to pending (interrupted): attempts are kept.
  void release(std::int64_t task_id, const std::string& worker, const std::string& note);
  // Running tasks whose worker `alive` says is gone go back to pending. Returns count.
  int requeue_dead(const std::function<bool(const std::string& worker)>& alive);
  int reset_failed(std::int64_t job_id);
  // The job's running tasks back to pending, but those whose holder `keep` says to
  // leave (the user says no runner is at work on them). Returns count.
  int requeue_running(std::int64_t job_id, const std::function<bool(const std::string& worker)>& keep);
  // A runner's heartbeat: `worker` (its token) is alive now. last_seen: when it last
  // beat (unix seconds), nullopt if it never did.
  void beat(const std::string& worker);
  std::optional<double> last_seen(const std::string& worker);
  // Every runner that ever beat into this database.
  std::vector<std::string> runner_tokens();
  // Workers holding running tasks of `job`, with how many each.
  std::vector<std::pair<std::string, int>> running_holders(const std::string& job);

  StatusCounts counts(const std::string& job = "");
  // Each task of `job` as (its index in the job, status), unordered: what a shard's
  // runner counts its part by, every few seconds, without reading whole rows.
  std::vector<std::pair<std::int64_t, std::string>> task_statuses(const std::string& job);
  std::vector<std::pair<std::string, double>> metrics(std::int64_t task_id);
  std::vector<std::pair<std::string, std::string>> artifacts(std::int64_t task_id);
  // What the `limit` done tasks of `scene` that finished last and carry a CPU time
  // cost (what the machine now costs per task).
  struct DoneCost {
    std::string params_json;
    double cpu_s = 0, wall_s = 0;  // metric cpu_s; the task's wall time (NaN: none)
    int threads = 0;               // metric threads; 0: not recorded (an older demcal)
  };
  std::vector<DoneCost> latest_done_costs(const std::string& scene, int limit);

  // The spec_json recorded for a job, if the job exists.
  std::optional<std::string> job_spec(const std::string& name);
  // Calibration results (the fits table): append one, list all (oldest first).
  std::int64_t add_fit(const std::string& targets_json, const std::string& method, const std::string& result_json);
  std::vector<FitRow> fits();

  const std::string& path() const { return path_; }
  // Reads until the snapshot ends see one state of the file (ReadSnapshot).
  ReadSnapshot snapshot() { return ReadSnapshot(conn_); }
  // Empty while `path` still names the file this store opened; else what became of
  // it ("deleted", "replaced by another file"). A run whose database file is deleted
  // writes on into the unlinked file and its results vanish with it.
  std::string file_lost() const;
  // After file_lost: copies what this store still holds (the lost file, with this
  // run's results) beside the path. Returns the copy's path, "" when none could be
  // written. (The store's write-ahead log is emptied when the store closes, so that
  // it is not replayed into the file now at the path.)
  std::string save_lost_file();

 private:
  // Running tasks (of one job, or all) whose holder `take` names go back to pending
  // with `note` as their error. A task without a holder (NULL) is holder "".
  void empty_log_of_lost_file();
  int requeue_held(std::optional<std::int64_t> job_id, const std::function<bool(const std::string& worker)>& take,
                   const char* note);
  std::string path_;
  Connection conn_;
  // A file's identity (device, inode); ino 0: none seen.
  struct FileId {
    unsigned long long dev = 0, ino = 0;
    static FileId of(const std::string& path);  // none where the path cannot be read
    bool operator==(const FileId& o) const { return dev == o.dev && ino == o.ino; }
  };
  FileId db_id_, wal_id_, shm_id_;  // the opened file's, its write-ahead log's, the log index's
};

double unix_now();

// A task's message column holds a failed task's reason, or a done task's warnings
// marked "warning: ". These say which, so that no reader parses the mark itself.
std::string warning_message(const std::string& warnings);  // what a done task with warnings stores
struct TaskMessage {
  std::string error, warning;  // at most one is set; the warning without its mark
};
TaskMessage task_message(const TaskRow& t);

}  // namespace demcal::db
