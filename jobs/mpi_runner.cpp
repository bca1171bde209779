#include "mpi_runner.hpp"

#include "leftover_files.hpp"
#include "liveness.hpp"
#include "stop_signal.hpp"
#include "progress.hpp"
#include "worker.hpp"

#include <mpi.h>

#include <algorithm>
#include <chrono>
#include <csignal>
#include <cstdlib>
#include <deque>
#include <filesystem>
#include <iostream>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <thread>
#include <unistd.h>

namespace demcal::jobs::mpi {
namespace {

using Clock = std::chrono::steady_clock;

// Worker -> rank 0
constexpr int kTagReady = 1;      // empty: give me work
constexpr int kTagHeartbeat = 2;  // empty: still running my task
constexpr int kTagResult = 3;     // "<task id>\n<result JSON text>"
// Rank 0 -> worker
constexpr int kTagTask = 10;  // the task as JSON
constexpr int kTagStop = 11;  // empty: leave

bool g_dismissed = false;  // rank 0 told every worker to stop
bool g_rank_lost = false;  // rank 0 declared a worker rank lost


void check(int rc, const char* what) {
  if (rc == MPI_SUCCESS) return;
  char msg[MPI_MAX_ERROR_STRING] = {};
  int len = 0;
  MPI_Error_string(rc, msg, &len);
  throw std::runtime_error(std::string("MPI ") + what + " failed: " + msg);
}

void send(int dest, int tag, const std::string& text) {
  check(MPI_Send(text.data(), static_cast<int>(text.size()), MPI_CHAR, dest, tag, MPI_COMM_WORLD), "send");
}

// The message Iprobe found, received whole.
std::string receive(const MPI_Status& probed) {
  int n = 0;
  MPI_Status st = probed;
  check(MPI_Get_count(&st, MPI_CHAR, &n), "get_count");
  std::string text(static_cast<std::size_t>(std::max(0, n)), '\0');
  check(MPI_Recv(text.data(), n, MPI_CHAR, probed.MPI_SOURCE, probed.MPI_TAG, MPI_COMM_WORLD, MPI_STATUS_IGNORE),
        "recv");
  return text;
}

double seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

double heartbeat_interval(const MpiOptions& o) { return std::clamp(o.timeout_s / 5, 0.05, 5.0); }

// Test-only hook: a worker rank that receives the task with this expansion index
// kills itself (SIGKILL), to test that rank 0 survives losing a rank.
void test_kill_rank_hook(std::size_t index) {
  const char* env = std::getenv("DEMCAL_TEST_KILL_RANK_TASK");
  if (env && *env && std::to_string(index) == env) raise(SIGKILL);
}

// Test hook: rank 0 stalls this long after handing out each task, as a database
// write on a loaded disk can.
void test_root_stall_hook() {
  const char* env = std::getenv("DEMCAL_TEST_ROOT_STALL_S");
  if (env && *env) std::this_thread::sleep_for(std::chrono::duration<double>(std::atof(env)));
}

}  // namespace

Session::Session() {
  int inited = 0;
  MPI_Initialized(&inited);
  if (!inited) check(MPI_Init(nullptr, nullptr), "init");
  // Errors come back as return codes: a lost peer must not abort rank 0.
  MPI_Comm_set_errhandler(MPI_COMM_WORLD, MPI_ERRORS_RETURN);
  MPI_Comm_rank(MPI_COMM_WORLD, &rank_);
  MPI_Comm_size(MPI_COMM_WORLD, &size_);
}

Session::~Session() {
  if (rank_ == 0 && !g_dismissed) {
    // Rank 0 failed before or during the farm (bad job, unusable database): the
    // workers are waiting for work; tell them to leave.
    for (int r = 1; r < size_; ++r) MPI_Send(nullptr, 0, MPI_CHAR, r, kTagStop, MPI_COMM_WORLD);
    g_dismissed = true;
  }
  std::cout.flush();
  std::cerr.flush();
  if (rank_ == 0 && g_rank_lost) {
    // MPI_Finalize synchronises every rank, the lost one too: survivors that entered
    // it waited for a dead process and the run never ended (1 in 5 runs of the
    // killed-rank test under mpirun --enable-recovery). Everything is in the
    // database by now; the runtime ends the others.
    std::cerr << "demcal: a worker rank was lost: ending the MPI job with MPI_Abort instead of MPI_Finalize (results "
                 "are saved)\n";
    std::cerr.flush();
    MPI_Abort(MPI_COMM_WORLD, 1);
  }
  MPI_Finalize();
}

int serve(const MpiOptions& options) {
  int rank = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  const double hb = heartbeat_interval(options);
  const std::string who = "demcal: rank " + std::to_string(rank) + ": ";
  try {
    send(0, kTagReady, "");
    // Rank 0 answers every READY or RESULT at once (a task or STOP), except at the
    // start while it records the job; silence far beyond that means it is gone.
    double limit = std::max(600.0, 10 * options.timeout_s);
    for (;;) {
      const auto wait_start = Clock::now();
      MPI_Status st{};
      int flag = 0;
      while (!flag) {
        check(MPI_Iprobe(0, MPI_ANY_TAG, MPI_COMM_WORLD, &flag, &st), "iprobe");
        if (flag) break;
        if (seconds(Clock::now() - wait_start) > limit) {
          std::cerr << who << "no word from rank 0 for " << limit << " s; leaving\n";
          return 1;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
      }
      const std::string text = receive(st);
      if (st.MPI_TAG == kTagStop) return 0;
      if (st.MPI_TAG != kTagTask) continue;
      const nlohmann::json j = nlohmann::json::parse(text);
      WorkerTask t;
      t.task_id = j.at("task_id").get<std::int64_t>();
      t.index = j.at("index").get<std::size_t>();
      t.scene = j.at("scene").get<std::string>();
      t.params = j.at("params");
      t.threads = j.at("threads").get<int>();
      t.snapshots = j.at("snapshots").get<bool>();
      t.task_key = j.at("task_key").get<std::string>();
      t.h5_path = j.at("h5_path").get<std::string>();
      // Beside the task's HDF5 file, as the local runner keeps them: a rank killed
      // mid-task (a lost node, MPI_Abort) leaves no folder of its own in /tmp, and
      // the rank in the name keeps a re-sent task's file apart from a lost rank's.
      t.result_path = (std::filesystem::path(t.h5_path).parent_path() /
                       (".task-" + std::to_string(t.task_id) + "." + j.value("run_tag", std::string("")) + ".rank" +
                        std::to_string(rank) + ".result.json"))
                          .string();
      test_kill_rank_hook(t.index);
      const std::string beat = std::to_string(t.task_id);
      const std::string result = run_forked(t, hb, [&] { send(0, kTagHeartbeat, beat); });
      send(0, kTagResult, std::to_string(t.task_id) + "\n" + result);
      limit = std::max(60.0, 10 * options.timeout_s);
    }
  } catch (const std::exception& e) {
    std::cerr << who << e.what() << "\n";
    return 1;
  }
}

namespace {

// A database error on rank 0 (a full disk, a lock held past the busy timeout,
// damage) ends the farm: what this run held goes back to the queue if the database
// takes it, and the message says what became of the work. The worker ranks are told
// to stop as rank 0 leaves (Session); one busy with a task finishes it first, and
// that result has nowhere to go.
[[noreturn]] void abandon(db::Store& store, const std::string& token, const db::DbError& e) {
  int requeued = -1;
  try {
    requeued = store.requeue_dead([&](const std::string& worker) { return worker != token; });
  } catch (const std::exception&) {
    // the database takes no writes at all: the next run re-queues them
  }
  if (requeued == 0) throw e;  // nothing held yet (the job was being recorded): the error as it is
  const std::string what =
      requeued > 0 ? std::to_string(requeued) + " task(s) this run held are back in the queue; "
                   : "the tasks this run held are left 'running', and the next run of the job puts them back in the queue; ";
  throw db::DbError(std::string(e.what()) + " (the run stopped: " + what +
                        "a worker rank busy with a task finishes it and leaves, and that result is not stored; once "
                        "the database can be written again, run the job again: finished tasks are kept)",
                    e.bad_input());
}

// Rank 0's side of the task farm once the job is recorded and its queue read: it
// answers the worker ranks' messages, declares silent ranks lost, hands out the
// queued tasks, and ends when no rank is busy or still serving.
class Farm {
 public:
  Farm(db::Store& store, const Job& job, const RunOptions& options, const MpiOptions& mpi, const std::string& token,
       const std::filesystem::path& dir, std::deque<db::TaskRow> queue, RunSummary& s)
      : store_(store), job_(job), shard_(options.shard), mpi_(mpi), token_(token), dir_(dir),
        log_(options.log ? *options.log : std::cerr), progress_(log_, options.terminal), spec_(job.spec.dump()),
        threads_(job.threads > 0 ? job.threads : 1), queue_(std::move(queue)), s_(s) {
    MPI_Comm_size(MPI_COMM_WORLD, &size_);
    // The job's counts read the whole job (~13 ms for 10,000 tasks): once here, then
    // kept up to date by hand, so rank 0's time per task does not grow with the grid.
    const Counts start = job_counts(store_, job_.name, shard_);
    live_ = start;
    s_.reused = start.done;
    if (start.done > 0) log_ << start.done << " of " << start.total << " task(s) already done, reused\n";
    log_ << "MPI task farm: " << size_ - 1 << " worker rank(s), " << queue_.size() << " task(s) to run, lost-rank timeout "
         << mpi_.timeout_s << " s\n";
    const auto t0 = Clock::now();
    ranks_.resize(static_cast<std::size_t>(size_));
    for (auto& r : ranks_) r.last_seen = t0;
    last_file_check_ = t0;
  }

  // Until every rank has stopped or is lost, or a stop signal arrives.
  void serve(Heartbeat& heartbeat) {
    for (;;) {
      if (stop_signal()) break;
      const bool got = drain();
      // Lost ranks are judged right after the drain, so that a heartbeat which
      // arrived while rank 0 was busy is read first.
      const auto now = Clock::now();
      heartbeat.tick();  // rank 0's own, for runs on other hosts
      watch_database(now);
      judge_silence(now);
      hand_out();
      if (!busy_or_serving()) break;
      progress_.update(live_, Eta{});
      if (!got) std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
  }

  // After serve: a stop signal's running tasks back to the queue, every rank told to
  // leave, and the summary's counts.
  void close() {
    if (stop_signal()) release_running();
    for (int r = 1; r < size_; ++r) {
      try {
        stop_rank(r);
      } catch (const std::exception&) {
        // a rank that is gone: nothing to tell
      }
    }
    g_dismissed = true;
    if (s_.database_lost.empty()) s_.database_lost = database_lost(store_);  // a run shorter than 2 s, or its end
    if (!queue_.empty() && !s_.interrupted && s_.output_failure.empty() && s_.database_lost.empty())
      log_ << "no worker rank left: " << queue_.size() << " task(s) stay pending for the next run\n";
    progress_.finish();
    record_final_counts(job_counts(store_, job_.name, shard_), s_);
    s_.ran = ran_;
    // The job's counts and table are another file's if a run re-recorded the name
    // meanwhile (the hand-out stopped then).
    s_.superseded = store_.job_spec(job_.name) != spec_;
    save_lost_database(store_, s_);
  }

 private:
  struct Rank {
    bool ready = false, stopped = false, lost = false, started = false;
    std::optional<db::TaskRow> task;
    Clock::time_point last_seen, task_start;
  };

  Rank& rank(int r) { return ranks_[static_cast<std::size_t>(r)]; }
  std::string what(const Rank& k) const {
    return describe_task(job_, static_cast<std::size_t>(k.task->index), k.task->id);
  }

  // Reads every message that has arrived; whether there was any.
  bool drain() {
    bool got = false;
    for (;;) {
      MPI_Status st{};
      int flag = 0;
      check(MPI_Iprobe(MPI_ANY_SOURCE, MPI_ANY_TAG, MPI_COMM_WORLD, &flag, &st), "iprobe");
      if (!flag) return got;
      got = true;
      const std::string text = receive(st);
      const int r = st.MPI_SOURCE;
      if (r <= 0 || r >= size_) continue;
      Rank& k = rank(r);
      k.last_seen = Clock::now();
      k.started = true;
      if (k.lost) {
        // Declared lost but alive after all (slower than the timeout): its task is
        // already failed; send it away so it does not wait for work.
        if (st.MPI_TAG == kTagResult || st.MPI_TAG == kTagReady) {
          if (st.MPI_TAG == kTagResult) log_ << "late result from rank " << r << " (declared lost) ignored\n";
          if (!k.stopped) send(r, kTagStop, "");
          k.stopped = true;
        }
        continue;
      }
      if (st.MPI_TAG == kTagReady) {
        k.ready = true;
      } else if (st.MPI_TAG == kTagResult) {
        on_result(r, text);
        k.ready = true;
      }
    }
  }

  // "<task id>\n<result JSON>" from rank r: stored, or the task back in the queue when
  // only its files could not be written.
  void on_result(int r, const std::string& text) {
    Rank& k = rank(r);
    const auto nl = text.find('\n');
    const std::int64_t id = nl == std::string::npos ? -1 : std::stoll(text.substr(0, nl));
    if (!k.task || k.task->id != id) {
      log_ << "unexpected result for task id " << id << " from rank " << r << " ignored\n";
      return;
    }
    std::optional<db::Outcome> out = parse_worker_result(text.substr(nl + 1));
    if (out && nlohmann::json::parse(text.substr(nl + 1)).value(kOutputUnwritableKey, false)) {
      // Not the task's failure: back to the queue, for the run after the folder is fixed.
      const std::string task = what(k);
      if (s_.output_failure.empty()) s_.output_failure = task + ": " + out->error;
      store_.release(k.task->id, token_, "could not write its files: " + out->error + "; will be retried");
      live_.ended("pending");
      progress_.line(task + " could not write its files, back in the queue: " + out->error, live_);
      k.task.reset();
      return;
    }
    if (!out) {
      fail_task(r, "rank " + std::to_string(r) + " sent an unreadable result");
      return;
    }
    if (store_.finish(k.task->id, token_, *out)) live_.ended(out->status);
    ++ran_;
    std::ostringstream msg;
    msg << what(k) << " " << out->status << " in " << format_duration(out->wall_s) << " on rank " << r;
    if (!out->error.empty()) msg << ": " << out->error;
    progress_.line(msg.str(), live_);
    k.task.reset();
  }

  // A deleted database takes every result stored from now on with it: hand out no
  // more work. The running tasks' results are still received (a rank blocked sending
  // a large one would hang the job), and the loop ends when no rank is busy.
  void watch_database(Clock::time_point now) {
    if (!s_.database_lost.empty() || now - last_file_check_ <= std::chrono::seconds(2)) return;
    last_file_check_ = now;
    s_.database_lost = database_lost(store_);
    if (!s_.database_lost.empty()) {
      queue_.clear();
      log_ << "\n" << s_.database_lost << ": no more tasks handed out; the running ones finish first\n";
    }
  }

  // Lost ranks: silent beyond the timeout while holding a task, or never started.
  void judge_silence(Clock::time_point now) {
    for (int r = 1; r < size_; ++r) {
      Rank& k = rank(r);
      if (k.lost || k.stopped) continue;
      const double silent = seconds(now - k.last_seen);
      if (k.task && silent > mpi_.timeout_s) {
        k.lost = true;
        g_rank_lost = true;
        log_ << "worker rank " << r << " lost: no message for " << plain_number(mpi_.timeout_s) << " s\n";
        fail_task(r, "worker rank " + std::to_string(r) + " lost (no heartbeat for " + plain_number(mpi_.timeout_s) +
                         " s); rerun with --retry-failed");
      } else if (!k.started && silent > std::max(600.0, 10 * mpi_.timeout_s)) {
        k.lost = true;
        g_rank_lost = true;
        log_ << "worker rank " << r << " never reported; not used\n";
      }
    }
  }

  // Work to every ready rank; with none left, idle ranks leave at once (a lost rank's
  // task is failed, not re-queued, so no work appears later).
  void hand_out() {
    const auto deaf_from = Clock::now();
    for (int r = 1; r < size_; ++r) {
      Rank& k = rank(r);
      if (!k.ready || k.lost || k.stopped) continue;
      if (!s_.output_failure.empty()) {  // the tasks left could not write their files either
        if (!k.task) stop_rank(r);
        continue;
      }
      while (!queue_.empty() && !k.task) give_next_task(r);
      if (!k.task && queue_.empty()) stop_rank(r);
    }
    // Rank 0 read no messages while it handed out work (database writes a loaded
    // disk can stall for seconds, and a result larger than MPI's eager limit only
    // arrives while rank 0 polls): that time is not a worker's silence.
    const auto deaf_to = Clock::now();
    for (auto& k : ranks_) k.last_seen = std::min(deaf_to, k.last_seen + (deaf_to - deaf_from));
  }

  // The queue's next task to rank r, unless another runner claimed it first.
  void give_next_task(int r) {
    // Another run recorded a different job file under this name: the queued tasks
    // left the job, so none more is handed out.
    if (store_.job_spec(job_.name) != spec_) {
      queue_.clear();
      return;
    }
    db::TaskRow row = queue_.front();
    queue_.pop_front();
    if (!store_.claim(row.id, token_)) return;  // another runner took it
    ++live_.running;
    nlohmann::json t = {{"task_id", row.id},
                        {"index", row.index},
                        {"scene", row.scene},
                        {"params", nlohmann::json::parse(row.params_json)},
                        {"threads", threads_},
                        {"snapshots", job_.snapshots},
                        {"task_key", row.key},
                        {"h5_path", (dir_ / task_file_name(row.id, row.key)).string()},
                        {"run_tag", file_name_safe(token_)}};
    send(r, kTagTask, t.dump());
    Rank& k = rank(r);
    k.task = std::move(row);
    k.task_start = k.last_seen = Clock::now();
    k.ready = false;
    progress_.line(what(k) + " started on rank " + std::to_string(r), live_);
    test_root_stall_hook();
  }

  bool busy_or_serving() {
    bool busy = false, serving = false;
    for (int r = 1; r < size_; ++r) {
      const Rank& k = rank(r);
      busy = busy || k.task.has_value();
      serving = serving || (!k.lost && !k.stopped);
    }
    return busy || serving;
  }

  // Plain mpirun ends the whole job with SIGTERM when any rank dies (see
  // docs/scaling.md): what was running goes back to pending for the next run.
  void release_running() {
    log_ << "\n" << (stop_signal() == SIGTERM ? "terminated (SIGTERM: what mpirun sends on Ctrl-C, scancel, or when a rank dies)"
                                               : stop_signal_words(stop_signal()))
         << ": running task(s) go back to the queue\n";
    for (int r = 1; r < size_; ++r) {
      Rank& k = rank(r);
      if (k.task) {
        store_.release(k.task->id, token_, "interrupted; will be retried");
        live_.ended("pending");
      }
      k.task.reset();
    }
    s_.interrupted = true;
  }

  void fail_task(int r, const std::string& why) {
    Rank& k = rank(r);
    db::Outcome out;
    out.status = "failed";
    out.wall_s = seconds(Clock::now() - k.task_start);
    out.error = why;
    if (store_.finish(k.task->id, token_, out)) live_.ended("failed");
    ++ran_;
    progress_.line(what(k) + " failed: " + why, live_);
    k.task.reset();
  }

  void stop_rank(int r) {
    Rank& k = rank(r);
    if (k.stopped || k.lost) return;
    send(r, kTagStop, "");
    k.stopped = true;
    k.ready = false;
  }

  db::Store& store_;
  const Job& job_;
  const Shard shard_;
  const MpiOptions& mpi_;
  const std::string& token_;
  const std::filesystem::path dir_;
  std::ostream& log_;
  Progress progress_;
  const std::string spec_;  // as record_job stores it
  const int threads_;
  std::deque<db::TaskRow> queue_;
  RunSummary& s_;
  int size_ = 1;
  Counts live_;
  std::vector<Rank> ranks_;
  int ran_ = 0;
  Clock::time_point last_file_check_;
};

RunSummary farm(db::Store& store, const Job& job, const RunOptions& options, const MpiOptions& mpi,
                const std::string& token) {
  std::ostream& log = options.log ? *options.log : std::cerr;
  StopSignalGuard guard;
  const std::filesystem::path dir = make_task_output_dir(job, options);
  const std::int64_t job_id = record_job(store, job, options.shard, log);
  Heartbeat heartbeat(store, token);  // before the re-queue of dead runners' tasks
  if (options.requeue_running) requeue_running_tasks(store, job_id, log);
  if (int n = requeue_dead_runners(store))
    log << "re-queued " << n << " task(s) left running by a runner that is gone\n";
  if (int n = remove_leftovers_of_dead_runners(dir, store, file_name_safe(token), nullptr))
    log << leftovers_removed_line(n, dir) << "\n";
  if (options.retry_failed)
    if (int n = store.reset_failed(job_id)) log << "retrying " << n << " failed task(s)\n";
  std::deque<db::TaskRow> queue;
  for (auto& row : store.tasks(job.name))
    if (row.status == "pending" && options.shard.contains(static_cast<std::size_t>(row.index)))
      queue.push_back(std::move(row));
  RunSummary s;
  Farm f(store, job, options, mpi, token, dir, std::move(queue), s);
  f.serve(heartbeat);
  f.close();
  return s;
}

}  // namespace

RunSummary run_job_root(db::Store& store, const Job& job, const RunOptions& options, const MpiOptions& mpi) {
  int size = 1;
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  if (size < 2)
    throw std::runtime_error(
        "--mpi needs at least 2 ranks: rank 0 coordinates and the others run tasks (mpirun -n 3 demcal run JOB --mpi)");
  const std::string token = runner_token();
  try {
    return farm(store, job, options, mpi, token);
  } catch (const db::DbError& e) {
    abandon(store, token, e);
  }
}

}  // namespace demcal::jobs::mpi
