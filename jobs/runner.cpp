#include "runner.hpp"
#include "job_error.hpp"

#include "child_process.hpp"
#include "leftover_files.hpp"
#include "liveness.hpp"
#include "physics_version.hpp"
#include "stop_signal.hpp"
#include "progress.hpp"
#include "work_forecast.hpp"
#include "worker.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <deque>
#include <filesystem>
#include <iostream>
#include <sstream>
#include <sched.h>
#include <sys/wait.h>
#include <thread>
#include <unordered_map>
#include <malloc.h>
#include <unistd.h>

namespace demcal::jobs {
namespace {

// The CPUs this process may run on: a batch scheduler's allocation (Slurm's
// --cpus-per-task, taskset, a cgroup cpuset) is an affinity mask, which
// hardware_concurrency() ignores (it counts the machine's cores).
int usable_cores() {
  cpu_set_t set;
  CPU_ZERO(&set);
  if (sched_getaffinity(0, sizeof set, &set) == 0 && CPU_COUNT(&set) > 0) return CPU_COUNT(&set);
  return static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
}

struct Running {
  std::int64_t task_id;
  std::size_t index;
  pid_t pid;
  std::string result_path;
  std::chrono::steady_clock::time_point start;
};

class Runner {
 public:
  Runner(db::Store& store, const Job& job, const RunOptions& opt)
      : store_(store), job_(job), opt_(opt), token_(runner_token()),
        progress_(*opt.log, opt.terminal), dir_(task_output_dir(job, opt)) {}

  RunSummary run();

 private:
  void prepare();
  void refill_queue();
  // Whether another run has recorded a different job file under this job's name.
  bool superseded();
  void launch(const db::TaskRow& row);
  void reap(bool stopping);
  void handle_exit(const Running& r, int wstatus, bool stopping);
  void stop_all();
  RunSummary run_loop();
  // Claims and starts queued tasks while a worker is free.
  void launch_queued();
  // Other runners are judged on a timer, whatever this run's own queue holds: a dead
  // one's tasks come back within kRunnerConfirmS of the first look, not when this
  // run's queue runs dry. Whether any came back.
  bool judge_other_runners(bool idle, std::chrono::steady_clock::time_point now);
  // After the loop: an interrupted or lost run stops its tasks; the summary's counts.
  void finish_run(RunSummary& s);
  std::chrono::steady_clock::time_point last_judged_, last_swept_;
  // The database could not be written (a full disk, a lock): the workers are stopped without
  // storing anything, this run's tasks go back to pending if the database still
  // takes that, and the error is rethrown saying what became of them.
  [[noreturn]] void abandon(const db::DbError& e);
  std::string unstored_;  // the task whose result the database would not take
  // The job's counts read from the database: a GROUP BY over its tasks, ~13 ms at
  // 10,000 tasks, so a run reads them every 2 s and keeps its own tally between
  // (`Counts::ended`); other runners' progress shows at the next read.
  Counts read_counts();
  std::string describe_task(std::size_t index, std::int64_t task_id) const;
  // Says, once per change, which other runners hold the tasks this run waits on.
  void say_holders(std::string& said);
  // Wall seconds left for this run's queued and running tasks: their forecast at the
  // speed measured in the database (re-measured as tasks finish); without a forecast,
  // the mean of the tasks this run finished. A bound while the forecast is one.
  // Cached for a second (the loop asks every 20 ms, and a forecast walks the whole
  // queue: ~5 ms at 100,000 tasks); a finished task makes it stale at once.
  Eta eta();
  Eta eta_now();
  double forecast_eta(bool bound) const;  // bound: every task to its limit, at the yardstick
  void forecast_new_tasks();
  // After a task finishes: its CPU time is in the database now. At most every 2 s once
  // a speed is known (the query reads every done task of the scene).
  void measure_speed_now();

  db::Store& store_;
  const Job& job_;
  RunOptions opt_;
  std::string token_;
  Progress progress_;
  std::filesystem::path dir_;
  std::deque<db::TaskRow> queue_;
  std::vector<Running> running_;
  int workers_ = 1, threads_ = 1, ran_ = 0;
  double busy_s_ = 0;  // summed wall time of tasks this run finished
  const SceneDef* scene_ = find_scene(job_.scene);
  std::unordered_map<std::int64_t, double> yardstick_s_;  // task id -> its forecast core-seconds at factor 1
  MeasuredSpeed speed_;
  BeatWatch beats_;  // other hosts' heartbeats, watched on this process's clock
  bool work_is_bound_ = false;  // the scene's forecast is every stage to its limit (a bound until measured)
  Counts counts_;
  Eta eta_;
  bool eta_stale_ = true;
  std::chrono::steady_clock::time_point eta_at_, speed_at_;
  const std::string spec_ = job_.spec.dump();  // as record_job stores it
  bool superseded_ = false;  // another run recorded another spec under this job's name
  std::string output_failure_;  // the first task that could not write into the output folder, and why
  // In the result files' names: two databases whose runs share an output folder both
  // number their tasks from 1, and a name of the task id alone let one run read the
  // other's result as its own (metrics stored under the wrong task).
  const std::string result_tag_ = file_name_safe(token_);
};

void Runner::prepare() {
  make_task_output_dir(job_, opt_);
  const std::int64_t job_id = record_job(store_, job_, opt_.shard, *opt_.log);
  if (opt_.shard.active())
    *opt_.log << "shard " << opt_.shard.label() << ": tasks with index k where k mod " << opt_.shard.count
              << " = " << opt_.shard.index - 1 << "\n";
  if (opt_.requeue_running) requeue_running_tasks(store_, job_id, *opt_.log);
  if (int n = requeue_dead_runners(store_, &beats_))
    *opt_.log << "re-queued " << n << " task(s) left running by a runner that is gone\n";
  if (int n = remove_leftovers_of_dead_runners(dir_, store_, result_tag_, &beats_))
    *opt_.log << leftovers_removed_line(n, dir_) << "\n";
  if (opt_.retry_failed)
    if (int n = store_.reset_failed(job_id)) *opt_.log << "retrying " << n << " failed task(s)\n";
  refill_queue();
  const int cores = usable_cores();
  workers_ = opt_.workers > 0 ? opt_.workers : cores;
  const int todo = std::max<int>(1, static_cast<int>(queue_.size()));
  // Fewer tasks than cores: give each task's engine the spare cores as threads.
  // Otherwise one thread per task: the engine synchronises every step, and
  // oversubscribed cores turn each barrier into a scheduler time slice. "Spare"
  // means not busy with other work either (the 1-minute load average): a
  // two-thread task beside another program ran 50x slower than a one-thread one.
  const int parallel = std::min(workers_, todo);
  if (job_.threads > 0) {
    threads_ = job_.threads;
  } else if (todo < cores) {
    double load = 0.0;
    const int busy = ::getloadavg(&load, 1) == 1 ? static_cast<int>(std::lround(load)) : 0;
    threads_ = std::max(parallel, cores - busy) / parallel;  // >= 1
    if (threads_ < cores / parallel) {
      char avg[32];
      std::snprintf(avg, sizeof avg, "%.1f", load);
      *opt_.log << "engine threads per task: " << threads_ << " (load average " << avg << " on " << cores
                << " cores; set \"threads\" in the job to choose)\n";
    }
  } else {
    threads_ = 1;
  }
  if (queue_.empty()) return;
  *opt_.log << "HDF5 files of this run: " << dir_.string() << "/\n";
  // A forecast only: a stored task it cannot read (a damaged or hand-edited database)
  // is left for its worker to fail and name.
  try {
    if (scene_ && scene_->work) {
      std::vector<nlohmann::json> params;
      for (const auto& t : queue_) params.push_back(nlohmann::json::parse(t.params_json));
      speed_ = measure_speed(store_, *scene_, threads_);
      speed_at_ = std::chrono::steady_clock::now();
      const WorkForecast w = forecast_work(*scene_, params, speed_);
      for (std::size_t k = 0; k < queue_.size(); ++k) yardstick_s_[queue_[k].id] = w.task_core_seconds[k] / w.factor();
      work_is_bound_ = w.bounded_scene;
      *opt_.log << "work of the " << queue_.size() << " task(s) to run: " << describe(w, parallel) << "\n";
    }
  } catch (const std::exception&) {
  }
  // The job's expansion, the queue and the forecast's parsed parameters took ~460 MB
  // at 100,000 tasks, and freed heap stays mapped: every fork copies its page tables.
  malloc_trim(0);
}

// Tasks queued since the start (re-queued from a runner that is gone) get their
// forecast too, or the ETA would have none for them.
void Runner::forecast_new_tasks() {
  if (yardstick_s_.empty()) return;
  std::vector<std::int64_t> ids;
  std::vector<nlohmann::json> params;
  try {
    for (const auto& t : queue_)
      if (!yardstick_s_.count(t.id)) ids.push_back(t.id), params.push_back(nlohmann::json::parse(t.params_json));
    if (ids.empty()) return;
    const WorkForecast w = forecast_work(*scene_, params);
    for (std::size_t k = 0; k < ids.size(); ++k) yardstick_s_[ids[k]] = w.task_core_seconds[k];
  } catch (const std::exception&) {  // a forecast only
  }
}

bool Runner::superseded() {
  if (!superseded_) superseded_ = store_.job_spec(job_.name) != spec_;
  return superseded_;
}

void Runner::refill_queue() {
  queue_.clear();
  // Another run may record a different job file under the same name while this one
  // works: the job's tasks are then that file's, which this run must not take up
  // (nor report as its own).
  if (superseded()) return;
  for (auto& row : store_.tasks(job_.name))
    if (row.status == "pending" && opt_.shard.contains(static_cast<std::size_t>(row.index))) queue_.push_back(std::move(row));
}

void Runner::say_holders(std::string& said) {
  std::string text, key;  // the key: holders, counts and a clock lag found, not the seconds since they beat
  for (const auto& [w, n] : store_.running_holders(job_.name))
    if (w != token_) {
      text += "  " + std::to_string(n) + " held by " + describe_holder(store_, w, &beats_) + "\n";
      key += w + "=" + std::to_string(n) + (beats_.clock_behind(w) ? "~" : "") + ";";
    }
  if (text.empty() || key == said) return;
  said = key;
  *opt_.log << "waiting for tasks of job " << job_.name << " that other runners hold:\n" << text;
}

std::string Runner::describe_task(std::size_t index, std::int64_t task_id) const {
  return jobs::describe_task(job_, index, task_id);
}

void Runner::launch(const db::TaskRow& row) {
  WorkerTask t;
  t.task_id = row.id;
  t.task_key = row.key;
  t.index = static_cast<std::size_t>(row.index);
  t.scene = row.scene;
  t.params = nlohmann::json::parse(row.params_json);
  t.threads = threads_;
  t.snapshots = job_.snapshots;
  t.h5_path = (dir_ / task_file_name(row.id, row.key)).string();
  t.result_path = (dir_ / (".task-" + std::to_string(row.id) + "." + result_tag_ + ".result.json")).string();
  std::error_code gone;  // the folder may be gone: the worker then says so
  std::filesystem::remove(t.result_path, gone);
  std::cout.flush();
  std::cerr.flush();
  std::fflush(nullptr);
  // fork() rather than re-exec: the child already holds the resolved task and the
  // engine, nothing needs serialising, and start-up costs nothing. The child never
  // uses the inherited SQLite connection and leaves with _exit().
  const pid_t pid = fork_bound_to_parent(4);  // a runner killed with -9 takes its workers along
  if (pid < 0) {
    store_.release(row.id, token_, "fork failed");
    throw std::runtime_error("fork failed");
  }
  if (pid == 0) {
    signal(SIGINT, SIG_IGN);  // the parent decides what an interrupt means
    signal(SIGTERM, SIG_DFL);
    _exit(run_worker(t));
  }
  // Listed before the database hears of it: if that write fails, abandon() stops and
  // reaps this worker with the others.
  running_.push_back(Running{row.id, t.index, pid, t.result_path, std::chrono::steady_clock::now()});
  store_.set_pid(row.id, pid);
  progress_.set_eta(eta());
  ++counts_.running;
  progress_.line(describe_task(t.index, row.id) + " started", counts_);
}

Counts Runner::read_counts() {
  counts_ = job_counts(store_, job_.name, opt_.shard);
  return counts_;
}

double Runner::forecast_eta(bool bound) const {
  // Each task's wall time: at the wall-time speed of done tasks that ran on as many
  // threads as this run gives its own (the machine's load and the threads' overlap
  // are in it); else its CPU forecast spread over the threads.
  // The bound: every task to its limits at one thread's yardstick (no credit for the
  // threads' overlap).
  const bool measured = speed_.tasks > 0 && !bound;
  const bool wall_measured = measured && speed_.wall_factor > 0 && speed_.threads == threads_;
  const double per_yardstick =
      bound ? 1.0 : wall_measured ? speed_.wall_factor : (measured ? speed_.factor : 1.0) / threads_;
  const auto now = std::chrono::steady_clock::now();
  std::vector<double> queued, free_at;  // wall seconds of each queued task; when each worker is free
  for (const auto& t : queue_) {
    const auto it = yardstick_s_.find(t.id);
    if (it == yardstick_s_.end()) return -1;  // a task queued since (re-queued): no forecast for it
    queued.push_back(it->second * per_yardstick);
  }
  for (const auto& r : running_) {
    const auto it = yardstick_s_.find(r.task_id);
    if (it == yardstick_s_.end()) return -1;
    free_at.push_back(std::max(0.0, it->second * per_yardstick - std::chrono::duration<double>(now - r.start).count()));
  }
  return makespan(queued, free_at, workers_);
}

void Runner::measure_speed_now() {
  if (yardstick_s_.empty()) return;
  const auto now = std::chrono::steady_clock::now();
  if (speed_.tasks > 0 && now - speed_at_ < std::chrono::seconds(2)) return;
  try {
    speed_ = measure_speed(store_, *scene_, threads_);
    speed_at_ = now;
  } catch (const std::exception&) {  // a forecast only
  }
}

Eta Runner::eta() {
  const auto now = std::chrono::steady_clock::now();
  if (eta_stale_ || now - eta_at_ > std::chrono::seconds(1)) {
    eta_ = eta_now();
    eta_at_ = now;
    eta_stale_ = false;
  }
  return eta_;
}

Eta Runner::eta_now() {
  if (!yardstick_s_.empty()) {
    const double s = forecast_eta(false);
    // A scene whose forecast is a bound keeps it in sight once measured: the tasks
    // measured first are the ones that ended soonest. A bound under the estimate (a
    // machine slower than the yardstick's) is no bound.
    double bound = work_is_bound_ && speed_.tasks > 0 ? forecast_eta(true) : -1;
    if (bound < s) bound = -1;  // a slower machine than the yardstick's: no bound to show
    // Nothing left by the forecast, yet tasks run: "0.0 s" would stand still on the bar.
    if (s == 0 && !running_.empty()) return Eta{-1, false, true, bound};
    if (s >= 0) return Eta{s, work_is_bound_ && speed_.tasks == 0, false, bound};
  }
  if (ran_ == 0) return Eta{};
  const double per_task = busy_s_ / ran_;
  const int left = counts_.total - counts_.done - counts_.failed;
  return Eta{per_task * left / std::max(1, std::min(workers_, left)), false};
}

void Runner::handle_exit(const Running& r, int wstatus, bool stopping) {
  const double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - r.start).count();
  std::optional<db::Outcome> out;
  if (worker_left_result(wstatus)) out = read_worker_result(r.result_path);
  std::error_code gone;  // the folder may be gone: the worker then says so
  std::filesystem::remove(r.result_path, gone);
  if (!out && stopping) {
    store_.release(r.task_id, token_, "interrupted; will be retried");
    counts_.ended("pending");
    progress_.line(describe_task(r.index, r.task_id) + " interrupted, back in the queue", counts_);
    return;
  }
  if (!out) {
    out = db::Outcome{};
    out->status = "failed";
    out->wall_s = wall;
    out->error = worker_failure(wstatus, r.result_path);
  }
  if (worker_output_unwritable(wstatus)) {
    // Not the task's failure: it goes back to the queue, for the run after the folder is fixed.
    if (output_failure_.empty()) output_failure_ = describe_task(r.index, r.task_id) + ": " + out->error;
    store_.release(r.task_id, token_, "could not write its files: " + out->error + "; will be retried");
    counts_.ended("pending");
    progress_.line(describe_task(r.index, r.task_id) + " could not write its files, back in the queue: " + out->error,
                   counts_);
    return;
  }
  bool stored = false;
  try {
    stored = store_.finish(r.task_id, token_, *out);
  } catch (const db::DbError&) {
    unstored_ = describe_task(r.index, r.task_id) + " " + out->status;
    throw;
  }
  if (!stored) {
    // This run was judged gone (silent past the lease) and another took the task over.
    counts_.ended("running");
    progress_.line(describe_task(r.index, r.task_id) + " " + out->status + " here, but another runner took it over "
                   "meanwhile (this run's heartbeat was judged stale): its result is that runner's, this one is dropped",
                   counts_);
    return;
  }
  ++ran_;
  busy_s_ += out->wall_s;
  measure_speed_now();
  eta_stale_ = true;
  progress_.set_eta(eta());
  std::ostringstream msg;
  msg << describe_task(r.index, r.task_id) << " " << out->status << " in " << format_duration(out->wall_s);
  if (!out->error.empty()) msg << ": " << out->error;
  counts_.ended(out->status);
  progress_.line(msg.str(), counts_);
}

void Runner::reap(bool stopping) {
  for (std::size_t i = 0; i < running_.size();) {
    int st = 0;
    const pid_t w = waitpid(running_[i].pid, &st, stopping ? 0 : WNOHANG);
    if (w == running_[i].pid) {
      const Running r = running_[i];
      running_.erase(running_.begin() + static_cast<std::ptrdiff_t>(i));
      handle_exit(r, st, stopping);
    } else {
      ++i;
    }
  }
}

void Runner::stop_all() {
  for (const auto& r : running_) kill(r.pid, SIGTERM);
  reap(/*stopping=*/true);  // a worker that finished meanwhile still has its result kept
}

RunSummary Runner::run() {
  try {
    return run_loop();
  } catch (const db::DbError& e) {
    abandon(e);
  }
}

void Runner::abandon(const db::DbError& e) {
  const std::size_t stopped = running_.size();
  std::string what = unstored_.empty() ? "" : unstored_ + ", but its result could not be stored; ";
  if (stopped > 0) what += std::to_string(stopped) + " running task(s) were stopped; ";
  for (const auto& r : running_) kill(r.pid, SIGTERM);
  for (const auto& r : running_) {
    int st = 0;
    waitpid(r.pid, &st, 0);
    std::error_code gone;
    std::filesystem::remove(r.result_path, gone);
  }
  running_.clear();
  progress_.finish();
  try {
    const int n = store_.requeue_dead([&](const std::string& worker) { return worker != token_; });
    if (n > 0) what += std::to_string(n) + " task(s) this run held are back in the queue; ";
  } catch (const std::exception&) {
    what += "the tasks this run held are left 'running', and the next run of the job puts them back in the queue; ";
  }
  // Any error of the database's: a full disk, a lock held past the busy timeout, damage.
  throw db::DbError(std::string(e.what()) + " (the run stopped: " + what +
                        "once the database can be written again, run the job again: finished tasks are kept)",
                    e.bad_input());
}

void Runner::launch_queued() {
  while (static_cast<int>(running_.size()) < workers_ && !queue_.empty() && !stop_signal() && output_failure_.empty()) {
    if (superseded()) {  // checked per task: the queued tasks left the job with the old spec
      queue_.clear();
      break;
    }
    const db::TaskRow row = queue_.front();
    queue_.pop_front();
    if (store_.claim(row.id, token_)) launch(row);
  }
}

bool Runner::judge_other_runners(bool idle, std::chrono::steady_clock::time_point now) {
  if (!idle && now - last_judged_ <= std::chrono::duration<double>(kRunnerBeatS)) return false;
  last_judged_ = now;
  bool requeued = false;
  if (int n = requeue_dead_runners(store_, &beats_)) {
    progress_.line("re-queued " + std::to_string(n) + " task(s) left running by a runner that is gone", read_counts());
    requeued = true;
  }
  // Another host's runner is judged dead only once its silence has been watched
  // (kRunnerConfirmS): its files go then, not at this run's start.
  if (requeued || now - last_swept_ > std::chrono::duration<double>(kRunnerBeatS)) {
    last_swept_ = now;
    if (int n = remove_leftovers_of_dead_runners(dir_, store_, result_tag_, &beats_))
      progress_.line(leftovers_removed_line(n, dir_), read_counts());
  }
  return requeued;
}

RunSummary Runner::run_loop() {
  StopSignalGuard guard;
  Heartbeat heartbeat(store_, token_);  // before the re-queue of dead runners' tasks
  prepare();
  RunSummary s;
  const Counts start = read_counts();
  s.reused = start.done;
  if (start.done > 0)
    *opt_.log << start.done << " of " << start.total << " task(s) already done, reused\n";
  auto last_refresh = std::chrono::steady_clock::now(), last_file_check = last_refresh, last_counts = last_refresh;
  last_judged_ = last_swept_ = last_refresh;
  std::string holders_said;  // the other runners this run last said it waits on
  while (!stop_signal()) {
    launch_queued();
    reap(false);
    if (!output_failure_.empty() && running_.empty()) break;  // the tasks left could not write their files either
    const bool idle = running_.empty() && queue_.empty();
    const auto now = std::chrono::steady_clock::now();
    heartbeat.tick();
    const bool requeued = judge_other_runners(idle, now);
    if (now - last_file_check > std::chrono::seconds(2)) {
      last_file_check = now;
      s.database_lost = database_lost(store_);
      if (!s.database_lost.empty()) break;
    }
    if (requeued || idle || (queue_.empty() && now - last_refresh > std::chrono::seconds(2))) {
      last_refresh = now;
      refill_queue();
      forecast_new_tasks();
      last_counts = now;
      const Counts c = read_counts();
      if (queue_.empty() && running_.empty() && (c.running == 0 || superseded_)) break;  // all done or failed
      if (queue_.empty() && running_.empty()) {
        say_holders(holders_said);
        std::this_thread::sleep_for(std::chrono::milliseconds(200));  // another runner holds the rest
        continue;
      }
    }
    if (now - last_counts > std::chrono::seconds(2)) {
      last_counts = now;
      read_counts();
    }
    progress_.update(counts_, eta());
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  finish_run(s);
  return s;
}

void Runner::finish_run(RunSummary& s) {
  if (stop_signal()) {
    *opt_.log << "\n" << stop_signal_words(stop_signal()) << ": stopping " << running_.size()
              << " running task(s); they will be retried by the next run\n";
    stop_all();
    s.interrupted = true;
  }
  if (s.database_lost.empty()) s.database_lost = database_lost(store_);  // a run shorter than the 2 s, or its end
  if (!s.database_lost.empty()) {
    *opt_.log << "\n" << s.database_lost << ": stopping " << running_.size() << " running task(s)\n";
    stop_all();
  }
  progress_.finish();
  const Counts c = read_counts();
  record_final_counts(c, s);
  s.ran = ran_;
  s.superseded = superseded_;
  s.output_failure = output_failure_;
  save_lost_database(store_, s);
}

}  // namespace

std::int64_t record_job(db::Store& store, const Job& job, const Shard& shard, std::ostream& log) {
  std::vector<db::NewTask> tasks;
  for (const auto& t : job.tasks)
    if (shard.contains(t.index))
      tasks.push_back({t.key, job.scene, t.params.dump(), static_cast<std::int64_t>(t.index)});
  std::vector<std::int64_t> dropped;
  const std::string spec = job.spec.dump();
  const std::optional<std::string> earlier = store.job_spec(job.name);
  const bool edited = earlier && *earlier != spec;
  const int had = edited ? job_counts(store, job.name, Shard{}).total : 0;
  const std::int64_t id = store.put_job(job.name, spec, tasks, shard.active(), &dropped);
  if (!dropped.empty()) {
    // A job is its latest spec; without this line the tasks of an edited grid
    // would leave the job (and its fits and maps) unannounced.
    std::string ids;
    for (std::size_t k = 0; k < dropped.size() && k < 10; ++k) ids += (k ? "," : "") + std::to_string(dropped[k]);
    if (dropped.size() > 10) ids += ",...";
    const std::string kept = " task(s) of the last run are no longer part of it (ids " + ids +
                             "; they and their results stay in the database: demcal query --where task=ID)";
    if (earlier && *earlier == spec)
      // The same file: the keys moved because this build computes the scene differently.
      log << "job " << job.name << ": the same spec as the last run's, but this build's physics for scene \""
          << job.scene << "\" is version " << physics_version(job.scene)
          << " (jobs/physics_version.hpp says what changed) or its defaults moved, so its tasks are new work (run now, or "
             "reused where another job already ran them with this build); "
          << dropped.size() << kept << "\n";
    else
      log << "job " << job.name << ": its spec differs from the last run's in this database; " << dropped.size()
          << kept << ". Give the job another name to keep both\n";
  } else if (edited) {
    // A grown grid. (An edit that moves no task, a description or 2650 written as
    // 2650.0, is not worth a line.)
    const int now = job_counts(store, job.name, Shard{}).total;
    if (now > had)
      log << "job " << job.name << ": its spec differs from the last run's in this database; " << now - had
          << " task(s) are new, and every task of the last run is still part of it (its results are kept)\n";
  }
  return id;
}

std::string file_name_safe(std::string s) {
  for (char& c : s)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_') c = '-';
  return s;
}

void throw_if_stopped_short(const RunSummary& s, const std::string& context) {
  if (!s.database_lost.empty()) throw std::runtime_error(context + ": " + s.database_lost + ": " + lost_database_advice(s));
  if (!s.output_failure.empty())
    throw std::runtime_error(context + " stopped: " + s.output_failure +
                             "; free space in (or fix) the output folder and run it again: those tasks are pending");
}

std::string database_lost(const db::Store& store) {
  const std::string lost = store.file_lost();
  return lost.empty() ? "" : "the database " + store.path() + " was " + lost + " while this run was writing it";
}

void save_lost_database(db::Store& store, RunSummary& s) {
  if (!s.database_lost.empty()) s.database_saved = store.save_lost_file();
}

std::string lost_database_advice(const RunSummary& s) {
  if (s.database_saved.empty())
    return "this run's results since then went with the old file, and the run stopped. Run the job again into a "
           "database that stays put";
  return "the run stopped, and the old file with this run's results is saved as " + s.database_saved +
         " (demcal merge --into DATABASE " + s.database_saved + " adds them to a database; a rerun of the job "
         "there reuses them)";
}

void make_folder(const std::string& dir, const std::string& flag, const std::string& what) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec || !std::filesystem::is_directory(dir))
    throw JobError(flag, "cannot create the " + what + " " + dir + ": " +
                             (ec ? ec.message() : std::string("a file of that name is in the way")));
}

std::string make_task_output_dir(const Job& job, const RunOptions& options) {
  const std::string dir = task_output_dir(job, options);
  make_folder(dir, options.out_flag, "output folder");
  // An earlier run's folder owned by someone else: found now, not after every task
  // has run and failed to write its result.
  if (::access(dir.c_str(), W_OK) != 0)
    throw JobError(options.out_flag, "cannot write into the output folder " + dir + " (check its owner and permissions)");
  return dir;
}

std::string task_output_dir(const Job& job, const RunOptions& options) {
  // Shards write next to each other (often one out dir for all parts) and their
  // task ids overlap, so each shard gets its own folder.
  std::filesystem::path dir = std::filesystem::absolute(options.out_dir) / job.name;
  if (options.shard.active())
    dir /= "shard-" + std::to_string(options.shard.index) + "-of-" + std::to_string(options.shard.count);
  return dir.string();
}

Counts job_counts(db::Store& store, const std::string& job, const Shard& shard) {
  Counts c;
  if (shard.active()) {
    for (const auto& [index, status] : store.task_statuses(job))
      if (shard.contains(static_cast<std::size_t>(index))) c.add(status);
    return c;
  }
  for (const auto& [name, by_status] : store.counts(job))
    for (const auto& [status, n] : by_status) c.add(status, n);
  return c;
}

void record_final_counts(const Counts& c, RunSummary& s) {
  s.total = c.total;
  s.done = c.done;
  s.failed = c.failed;
  s.unfinished = c.total - c.done - c.failed;
}

namespace {
// An axis value for reading: a computed one (a refinement point) at 10 significant
// digits, not 0.15239000000000003; a whole real keeps its ".0", as the job wrote it.
std::string axis_text(const nlohmann::json& v) {
  if (!v.is_number_float()) return v.dump();
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.10g", v.get<double>());
  std::string s = buf;
  if (s.find_first_of(".eni") == std::string::npos) s += ".0";
  return s;
}
}  // namespace

std::string describe_task(const Job& job, std::size_t index, std::int64_t task_id) {
  const std::string s = "task " + std::to_string(task_id);
  if (index >= job.tasks.size()) return s;
  std::string axes;
  // An axis value that is the default may be left out of the resolved task (a
  // "uniform" grading keeps the key it always had).
  const nlohmann::json& p = job.tasks[index].params;
  for (const auto& a : job.axes) axes += " " + a + "=" + (p.contains(a) ? axis_text(p.at(a)) : std::string("default"));
  if (job.replicas > 1) axes += std::string(" seed=") + job.tasks[index].params.at("seed").dump();
  return s + " (#" + std::to_string(index) + (axes.empty() ? "" : ":" + axes) + ")";
}

RunSummary run_job(db::Store& store, const Job& job, const RunOptions& options) {
  RunOptions opt = options;
  if (!opt.log) opt.log = &std::cerr;
  Runner r(store, job, opt);
  return r.run();
}

}  // namespace demcal::jobs
