#include "store.hpp"

#include "schema.hpp"

#include <sqlite3.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <set>
#include <thread>
#include <sys/stat.h>
#include <unistd.h>

namespace demcal::db {
namespace {

// Checking before opening read-write means a foreign or newer file is never touched.
const std::string& checked(const std::string& path) {
  check_file(path);
  return path;
}

const char* const kTaskColumns =
    "t.id, t.scene, t.params_json, t.key, t.status, t.attempts, t.worker, t.pid, t.started_at, "
    "t.finished_at, t.wall_s, t.error";

TaskRow read_task(const Statement& s, int first = 0) {
  TaskRow r;
  r.id = s.int64(first + 0);
  r.scene = s.text(first + 1);
  r.params_json = s.text(first + 2);
  r.key = s.text(first + 3);
  r.status = s.text(first + 4);
  r.attempts = static_cast<int>(s.int64(first + 5));
  r.worker = s.text(first + 6);
  r.pid = s.int64(first + 7);
  r.started_at = s.real(first + 8);
  r.finished_at = s.real(first + 9);
  r.wall_s = s.real(first + 10);
  r.error = s.text(first + 11);
  return r;
}

}  // namespace

namespace {
const std::string kWarningMark = "warning: ";
}  // namespace

std::string warning_message(const std::string& warnings) { return kWarningMark + warnings; }

TaskMessage task_message(const TaskRow& t) {
  if (t.status != "done") return {t.error, ""};
  if (t.error.rfind(kWarningMark, 0) == 0) return {"", t.error.substr(kWarningMark.size())};
  return {"", t.error};
}

double unix_now() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

Store::Store(const std::string& path, bool read_only) : path_(path), conn_(checked(path), read_only) {
  if (read_only) {
    // An empty file (or one SQLite made but no run filled) has no tables to read:
    // say so, instead of "no such table" from the first query.
    Statement v = conn_.prepare("PRAGMA user_version");
    if (!v.step() || v.int64(0) == 0)
      throw DbError(path + " holds no demcal results (an empty database: run a job into it first)", true);
    return;
  }
  // Switching a new file to WAL takes an exclusive lock, and SQLite may answer BUSY
  // at once, without the busy handler, while a second runner is creating the same
  // file (test Runner.TwoJobsConcurrentlyOnOneDatabase met it 1 run in ~20): retry.
  for (int tries = 0;; ++tries) {
    const int rc = sqlite3_exec(conn_.handle(), "PRAGMA journal_mode = WAL", nullptr, nullptr, nullptr);
    if (rc == SQLITE_OK) break;
    if ((rc != SQLITE_BUSY && rc != SQLITE_LOCKED) || tries >= 1500) {  // 30 s, as the busy timeout
      conn_.exec("PRAGMA journal_mode = WAL");  // throws with SQLite's message
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  conn_.exec("PRAGMA synchronous = NORMAL");  // WAL + NORMAL: durable across process kills
  conn_.exec("PRAGMA foreign_keys = ON");
  migrate(conn_);
  db_id_ = FileId::of(path_);
  // The log and its index, made by migrate's first read.
  wal_id_ = FileId::of(path_ + "-wal");
  shm_id_ = FileId::of(path_ + "-shm");
}

Store::FileId Store::FileId::of(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return {};
  return {static_cast<unsigned long long>(st.st_dev), static_cast<unsigned long long>(st.st_ino)};
}

Store::~Store() {
  if (!file_lost().empty()) empty_log_of_lost_file();
}

// The store's write-ahead log lies at the path beside whatever file is there now, and
// the next opener of that file would replay its frames into it (a restored backup read
// back as the lost file). SQLite itself keeps the log of a moved file when it closes,
// for fear of losing them. A truncating checkpoint writes them into the file this store
// holds open and leaves the log empty.
void Store::empty_log_of_lost_file() {
  // The pragma answers OK even when a reader kept it from truncating (its busy flag
  // in the result row): the call says so. A reader waits its turn for 2 s, not the
  // connection's 30.
  sqlite3_busy_timeout(conn_.handle(), 2000);
  int frames = 0, done = 0;
  if (sqlite3_wal_checkpoint_v2(conn_.handle(), nullptr, SQLITE_CHECKPOINT_TRUNCATE, &frames, &done) == SQLITE_OK)
    return;
  // Another connection to the lost file holds the log: the log and its index moved
  // from the path (an opener of the new file pairs a log with an index), if they are
  // still this store's.
  const auto move_aside = [](const std::string& file, const FileId& id) {
    if (id.ino != 0 && FileId::of(file) == id)
      std::rename(file.c_str(), (file + ".of-lost-file-" + std::to_string(::getpid())).c_str());
  };
  move_aside(path_ + "-wal", wal_id_);
  move_aside(path_ + "-shm", shm_id_);
}

std::string Store::save_lost_file() {
  if (file_lost().empty()) return "";
  sqlite3* db = conn_.handle();
  std::string saved = path_ + ".saved-" + std::to_string(::getpid());
  struct stat st {};
  for (int k = 2; ::stat(saved.c_str(), &st) == 0; ++k)
    saved = path_ + ".saved-" + std::to_string(::getpid()) + "-" + std::to_string(k);
  sqlite3* out = nullptr;
  bool ok = sqlite3_open_v2(saved.c_str(), &out, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE, nullptr) == SQLITE_OK;
  if (ok) {
    sqlite3_backup* b = sqlite3_backup_init(out, "main", db, "main");
    ok = b != nullptr && sqlite3_backup_step(b, -1) == SQLITE_DONE;
    if (b != nullptr) ok = sqlite3_backup_finish(b) == SQLITE_OK && ok;
  }
  sqlite3_close(out);
  if (ok) return saved;
  for (const char* suffix : {"", "-journal", "-wal", "-shm"}) std::remove((saved + suffix).c_str());
  return "";
}

std::string Store::file_lost() const {
  if (db_id_.ino == 0) return "";  // never seen (read-only stores are not asked)
  struct stat st {};
  // Only a name that is gone is a deleted file: a stat refused (a folder's permissions
  // changed, a network file system's hiccup) says nothing about it.
  if (::stat(path_.c_str(), &st) != 0) return errno == ENOENT || errno == ENOTDIR ? "deleted" : "";
  if (!(FileId{static_cast<unsigned long long>(st.st_dev), static_cast<unsigned long long>(st.st_ino)} == db_id_))
    return "replaced by another file";
  return "";
}

std::optional<std::int64_t> Store::find_job(const std::string& name) {
  Statement s = conn_.prepare("SELECT id FROM jobs WHERE name = ?");
  s.bind(1, name);
  if (s.step()) return s.int64(0);
  return std::nullopt;
}

std::int64_t Store::put_job(const std::string& name, const std::string& spec_json, const std::vector<NewTask>& tasks,
                            bool partial, std::vector<std::int64_t>* dropped) {
  Transaction t(conn_);
  const double now = unix_now();
  std::int64_t job_id;
  std::set<std::int64_t> before;
  auto linked = [this](std::int64_t id) {
    std::set<std::int64_t> ids;
    Statement s = conn_.prepare("SELECT task_id FROM job_tasks WHERE job_id = ?");
    s.bind(1, id);
    while (s.step()) ids.insert(s.int64(0));
    return ids;
  };
  if (auto id = find_job(name)) {
    if (dropped) before = linked(*id);
    job_id = *id;
    Statement old_spec = conn_.prepare("SELECT spec_json FROM jobs WHERE id = ?");
    old_spec.bind(1, job_id);
    const bool same_spec = old_spec.step() && old_spec.text(0) == spec_json;
    conn_.prepare("UPDATE jobs SET spec_json = ?, updated_at = ? WHERE id = ?").bind(1, spec_json).bind(2, now).bind(3, job_id).run();
    if (!partial || !same_spec) conn_.prepare("DELETE FROM job_tasks WHERE job_id = ?").bind(1, job_id).run();
  } else {
    conn_.prepare("INSERT INTO jobs(name, spec_json, created_at, updated_at) VALUES(?, ?, ?, ?)")
        .bind(1, name).bind(2, spec_json).bind(3, now).bind(4, now).run();
    job_id = conn_.last_insert_id();
  }
  Statement ins = conn_.prepare("INSERT OR IGNORE INTO tasks(job_id, scene, params_json, key) VALUES(?, ?, ?, ?)");
  Statement find = conn_.prepare("SELECT id FROM tasks WHERE key = ?");
  Statement link = conn_.prepare("INSERT OR REPLACE INTO job_tasks(job_id, idx, task_id) VALUES(?, ?, ?)");
  for (std::size_t i = 0; i < tasks.size(); ++i) {
    ins.reset();
    ins.bind(1, job_id).bind(2, tasks[i].scene).bind(3, tasks[i].params_json).bind(4, tasks[i].key).run();
    find.reset();
    find.bind(1, tasks[i].key);
    if (!find.step()) throw DbError("task vanished while inserting: " + tasks[i].key);
    const std::int64_t task_id = find.int64(0);
    find.reset();
    link.reset();
    link.bind(1, job_id).bind(2, tasks[i].idx >= 0 ? tasks[i].idx : static_cast<std::int64_t>(i)).bind(3, task_id).run();
  }
  if (dropped) {
    const std::set<std::int64_t> after = linked(job_id);
    dropped->clear();
    for (std::int64_t id : before)
      if (!after.count(id)) dropped->push_back(id);
  }
  t.commit();
  return job_id;
}

std::vector<TaskRow> Store::tasks(const std::string& job) {
  std::vector<TaskRow> out;
  if (job.empty()) {
    // Every task once, listed under the job that created it while that job holds it,
    // else under the first job that does (an edited job drops tasks it made; another
    // job may still share them), else under its creator with no index.
    const std::string sql = std::string("SELECT ") + kTaskColumns +
                            ", j.name, (SELECT min(idx) FROM job_tasks jt WHERE jt.task_id = t.id AND jt.job_id = t.shown)"
                            " FROM (SELECT *, COALESCE((SELECT jt.job_id FROM job_tasks jt WHERE jt.task_id = tasks.id"
                            " AND jt.job_id = tasks.job_id), (SELECT min(jt.job_id) FROM job_tasks jt WHERE jt.task_id ="
                            " tasks.id), tasks.job_id) AS shown FROM tasks) t"
                            " JOIN jobs j ON j.id = t.shown ORDER BY t.id";
    Statement s = conn_.prepare(sql.c_str());
    while (s.step()) {
      TaskRow r = read_task(s);
      r.job = s.text(12);
      r.index = s.is_null(13) ? -1 : s.int64(13);
      out.push_back(std::move(r));
    }
    return out;
  }
  const std::string sql = std::string("SELECT ") + kTaskColumns +
                          ", jt.idx FROM job_tasks jt JOIN jobs j ON j.id = jt.job_id JOIN tasks t ON t.id = jt.task_id"
                          " WHERE j.name = ? ORDER BY jt.idx";
  Statement s = conn_.prepare(sql.c_str());
  s.bind(1, job);
  while (s.step()) {
    TaskRow r = read_task(s);
    r.job = job;
    r.index = s.int64(12);
    out.push_back(std::move(r));
  }
  return out;
}

std::optional<TaskRow> Store::task(std::int64_t id) {
  const std::string sql = std::string("SELECT ") + kTaskColumns +
                          ", j.name FROM tasks t JOIN jobs j ON j.id = t.job_id WHERE t.id = ?";
  Statement s = conn_.prepare(sql.c_str());
  s.bind(1, id);
  if (!s.step()) return std::nullopt;
  TaskRow r = read_task(s);
  r.job = s.text(12);
  return r;
}

bool Store::claim(std::int64_t task_id, const std::string& worker) {
  conn_.prepare(
           "UPDATE tasks SET status = 'running', worker = ?, pid = NULL, attempts = attempts + 1, started_at = ?,"
           " finished_at = NULL, wall_s = NULL, error = NULL WHERE id = ? AND status = 'pending'")
      .bind(1, worker).bind(2, unix_now()).bind(3, task_id).run();
  return conn_.changes() == 1;
}

void Store::set_pid(std::int64_t task_id, std::int64_t pid) {
  conn_.prepare("UPDATE tasks SET pid = ? WHERE id = ?").bind(1, pid).bind(2, task_id).run();
}

bool Store::finish(std::int64_t task_id, const std::string& worker, const Outcome& out) {
  Transaction t(conn_);
  conn_.prepare(
           "UPDATE tasks SET status = ?, finished_at = ?, wall_s = ?, error = ?"
           " WHERE id = ? AND status = 'running' AND worker = ?")
      .bind(1, out.status).bind(2, unix_now()).bind(3, out.wall_s)
      .bind(4, out.error.empty() ? std::optional<std::string>() : std::optional<std::string>(out.error))
      .bind(5, task_id).bind(6, worker).run();
  if (conn_.changes() != 1) return false;  // rolled back: someone else owns it now
  conn_.prepare("DELETE FROM metrics WHERE task_id = ?").bind(1, task_id).run();
  conn_.prepare("DELETE FROM artifacts WHERE task_id = ?").bind(1, task_id).run();
  Statement m = conn_.prepare("INSERT INTO metrics(task_id, name, value) VALUES(?, ?, ?)");
  for (const auto& [name, value] : out.metrics) {
    m.reset();
    m.bind(1, task_id).bind(2, name).bind(3, value).run();
  }
  Statement a = conn_.prepare("INSERT OR IGNORE INTO artifacts(task_id, kind, path) VALUES(?, ?, ?)");
  for (const auto& [kind, path] : out.artifacts) {
    a.reset();
    a.bind(1, task_id).bind(2, kind).bind(3, path).run();
  }
  t.commit();
  return true;
}

void Store::release(std::int64_t task_id, const std::string& worker, const std::string& note) {
  conn_.prepare("UPDATE tasks SET status = 'pending', worker = NULL, pid = NULL, error = ?"
                " WHERE id = ? AND status = 'running' AND worker = ?")
      .bind(1, note).bind(2, task_id).bind(3, worker).run();
}

int Store::requeue_held(std::optional<std::int64_t> job_id, const std::function<bool(const std::string&)>& take,
                        const char* note) {
  // A NULL job id binds as NULL: every job's tasks.
  const char* in_job = " AND (?1 IS NULL OR id IN (SELECT task_id FROM job_tasks WHERE job_id = ?1))";
  auto bind_job = [&](Statement& s) -> Statement& { return job_id ? s.bind(1, *job_id) : s.bind_null(1); };
  std::set<std::string> workers;
  {
    Statement s = conn_.prepare(
        (std::string("SELECT DISTINCT coalesce(worker, '') FROM tasks WHERE status = 'running'") + in_job).c_str());
    bind_job(s);
    while (s.step()) workers.insert(s.text(0));
  }
  int n = 0;
  for (const auto& w : workers) {
    if (!take(w)) continue;
    Statement u = conn_.prepare((std::string("UPDATE tasks SET status = 'pending', worker = NULL, pid = NULL, error = ?2"
                                             " WHERE status = 'running' AND coalesce(worker, '') = ?3") +
                                 in_job)
                                    .c_str());
    bind_job(u).bind(2, std::string(note)).bind(3, w).run();
    n += conn_.changes();
  }
  return n;
}

int Store::requeue_dead(const std::function<bool(const std::string&)>& alive) {
  return requeue_held(std::nullopt, [&](const std::string& w) { return !alive(w); }, "runner died; re-queued");
}

void Store::beat(const std::string& worker) {
  conn_.prepare("INSERT INTO runners(token, last_seen) VALUES(?, ?)"
                " ON CONFLICT(token) DO UPDATE SET last_seen = excluded.last_seen")
      .bind(1, worker).bind(2, unix_now()).run();
}

std::optional<double> Store::last_seen(const std::string& worker) {
  Statement s = conn_.prepare("SELECT last_seen FROM runners WHERE token = ?");
  s.bind(1, worker);
  if (!s.step()) return std::nullopt;
  return s.real(0);
}

std::vector<std::string> Store::runner_tokens() {
  Statement s = conn_.prepare("SELECT token FROM runners ORDER BY token");
  std::vector<std::string> out;
  while (s.step()) out.push_back(s.text(0));
  return out;
}

std::vector<std::pair<std::string, int>> Store::running_holders(const std::string& job) {
  Statement s = conn_.prepare(
      "SELECT t.worker, count(*) FROM job_tasks jt JOIN jobs j ON j.id = jt.job_id JOIN tasks t ON t.id = jt.task_id"
      " WHERE j.name = ? AND t.status = 'running' GROUP BY t.worker ORDER BY t.worker");
  s.bind(1, job);
  std::vector<std::pair<std::string, int>> out;
  while (s.step()) out.emplace_back(s.text(0), static_cast<int>(s.int64(1)));
  return out;
}

int Store::requeue_running(std::int64_t job_id, const std::function<bool(const std::string&)>& keep) {
  return requeue_held(job_id, [&](const std::string& w) { return !keep(w); }, "re-queued by --requeue-running");
}

int Store::reset_failed(std::int64_t job_id) {
  // A failed run's metrics (what it cost) go with it: a pending task shows none.
  Transaction t(conn_);
  conn_.prepare("DELETE FROM metrics WHERE task_id IN (SELECT id FROM tasks WHERE status = 'failed'"
                " AND id IN (SELECT task_id FROM job_tasks WHERE job_id = ?))")
      .bind(1, job_id).run();
  conn_.prepare("UPDATE tasks SET status = 'pending' WHERE status = 'failed'"
                " AND id IN (SELECT task_id FROM job_tasks WHERE job_id = ?)")
      .bind(1, job_id).run();
  const int n = conn_.changes();
  t.commit();
  return n;
}

StatusCounts Store::counts(const std::string& job) {
  StatusCounts out;
  Statement s = conn_.prepare(
      "SELECT j.name, t.status, count(*) FROM job_tasks jt JOIN jobs j ON j.id = jt.job_id"
      " JOIN tasks t ON t.id = jt.task_id WHERE ? = '' OR j.name = ? GROUP BY j.name, t.status ORDER BY j.name");
  s.bind(1, job).bind(2, job);
  while (s.step()) out[s.text(0)][s.text(1)] = static_cast<int>(s.int64(2));
  if (!job.empty() && out.empty() && find_job(job)) out[job];
  return out;
}

std::vector<std::pair<std::int64_t, std::string>> Store::task_statuses(const std::string& job) {
  std::vector<std::pair<std::int64_t, std::string>> out;
  Statement s = conn_.prepare(
      "SELECT jt.idx, t.status FROM job_tasks jt JOIN jobs j ON j.id = jt.job_id JOIN tasks t ON t.id = jt.task_id "
      "WHERE j.name = ?");
  s.bind(1, job);
  while (s.step()) out.emplace_back(s.int64(0), s.text(1));
  return out;
}

std::vector<std::pair<std::string, double>> Store::metrics(std::int64_t task_id) {
  std::vector<std::pair<std::string, double>> out;
  const Reused s = conn_.reuse("SELECT name, value FROM metrics WHERE task_id = ? ORDER BY rowid");
  s->bind(1, task_id);
  while (s->step()) out.emplace_back(s->text(0), s->real(1));
  return out;
}

std::vector<Store::DoneCost> Store::latest_done_costs(const std::string& scene, int limit) {
  std::vector<DoneCost> out;
  Statement s = conn_.prepare(
      "SELECT t.params_json, c.value, t.wall_s, n.value FROM tasks t "
      "JOIN metrics c ON c.task_id = t.id AND c.name = 'cpu_s' "
      "LEFT JOIN metrics n ON n.task_id = t.id AND n.name = 'threads' "
      "WHERE t.scene = ? AND t.status = 'done' AND c.value IS NOT NULL ORDER BY t.finished_at DESC, t.id DESC LIMIT ?");
  s.bind(1, scene);
  s.bind(2, static_cast<std::int64_t>(limit));
  while (s.step()) {
    DoneCost d;
    d.params_json = s.text(0);
    d.cpu_s = s.real(1);
    d.wall_s = s.real(2);
    d.threads = s.is_null(3) ? 0 : static_cast<int>(std::lround(s.real(3)));
    out.push_back(std::move(d));
  }
  return out;
}

std::vector<std::pair<std::string, std::string>> Store::artifacts(std::int64_t task_id) {
  std::vector<std::pair<std::string, std::string>> out;
  const Reused s = conn_.reuse("SELECT kind, path FROM artifacts WHERE task_id = ? ORDER BY rowid");
  s->bind(1, task_id);
  while (s->step()) out.emplace_back(s->text(0), s->text(1));
  return out;
}

std::optional<std::string> Store::job_spec(const std::string& name) {
  Statement s = conn_.prepare("SELECT spec_json FROM jobs WHERE name = ?");
  s.bind(1, name);
  if (s.step()) return s.text(0);
  return std::nullopt;
}

std::int64_t Store::add_fit(const std::string& targets_json, const std::string& method, const std::string& result_json) {
  conn_.prepare("INSERT INTO fits(created_at, targets_json, method, result_json) VALUES(?, ?, ?, ?)")
      .bind(1, unix_now()).bind(2, targets_json).bind(3, method).bind(4, result_json).run();
  return conn_.last_insert_id();
}

std::vector<FitRow> Store::fits() {
  std::vector<FitRow> out;
  Statement s = conn_.prepare("SELECT id, created_at, targets_json, method, result_json FROM fits ORDER BY id");
  while (s.step()) out.push_back(FitRow{s.int64(0), s.real(1), s.text(2), s.text(3), s.text(4)});
  return out;
}

}  // namespace demcal::db
