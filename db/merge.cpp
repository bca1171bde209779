#include "merge.hpp"

#include "schema.hpp"
#include "sqlite.hpp"

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fcntl.h>
#include <functional>
#include <unistd.h>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <sstream>
#include <sys/stat.h>

namespace demcal::db {
namespace {

namespace fs = std::filesystem;

// Two job specs (the job files as recorded) that run the same tasks: equal but for
// the free-text description, which `demcal run` lets a later run of the job rewrite.
bool same_job(const std::string& a, const std::string& b) {
  if (a == b) return true;
  auto ja = nlohmann::json::parse(a, nullptr, false), jb = nlohmann::json::parse(b, nullptr, false);
  if (!ja.is_object() || !jb.is_object()) return false;
  ja.erase("description");
  jb.erase("description");
  return ja == jb;
}

int pragma_int(Connection& c, const char* sql) {
  Statement s = c.prepare(sql);
  return s.step() ? static_cast<int>(s.int64(0)) : 0;
}

// A part must be an existing demcal database of a schema version whose merged tables
// are this one's: versions 1 and 2 differ only in the runners' heartbeats, which a
// merge does not carry (a part's running tasks arrive as pending).
constexpr int kOldestMergeable = 1;
void check_part(const std::string& part, const std::string& into) {
  struct stat st {};
  if (::stat(part.c_str(), &st) != 0) throw DbError(part + ": no such file; nothing merged", true);
  if (!S_ISREG(st.st_mode)) throw DbError(part + ": not a regular file; nothing merged", true);
  if (st.st_size == 0) throw DbError(part + ": empty file, not a demcal database; nothing merged", true);
  std::error_code ec;
  if (fs::exists(into) && fs::equivalent(part, into, ec))
    throw DbError(part + ": is the destination itself; nothing merged", true);
  try {
    check_file(part);  // not SQLite, corrupt, someone else's, newer
  } catch (const DbError& e) {
    throw DbError(std::string(e.what()) + "; nothing merged", true);
  }
  Connection c(part, /*read_only=*/true);
  const int app = pragma_int(c, "PRAGMA application_id");
  const int version = pragma_int(c, "PRAGMA user_version");
  if (app != kApplicationId) throw DbError(part + ": not a demcal database (no demcal schema); nothing merged", true);
  if (version < kOldestMergeable || version > kSchemaVersion)
    throw DbError(part + ": schema version " + std::to_string(version) + ", but this demcal merges versions " +
                      std::to_string(kOldestMergeable) + " to " + std::to_string(kSchemaVersion) +
                      " (an older one is migrated by any `demcal run --db " + part + "` of this demcal); nothing merged",
                  true);
}

// A metric value as stored: NULL (a NaN went in) or a double, compared bit for bit.
struct Value {
  bool null = true;
  double v = 0;
  bool operator==(const Value& o) const { return null == o.null && (null || std::memcmp(&v, &o.v, sizeof v) == 0); }
};
Value value_at(const Statement& s, int col) { return s.is_null(col) ? Value{} : Value{false, s.real(col)}; }
void bind_value(Statement& s, int i, const Value& v) {
  if (v.null)
    s.bind_null(i);
  else
    s.bind(i, v.v);
}
std::string show(const Value& v) {
  if (v.null) return "NULL";
  std::ostringstream o;
  o.precision(17);
  o << v.v;
  return o.str();
}

using Metrics = std::map<std::string, Value>;
Metrics metrics_of(Connection& c, std::int64_t task_id) {
  Metrics m;
  Statement s = c.prepare("SELECT name, value FROM metrics WHERE task_id = ?");
  s.bind(1, task_id);
  while (s.step()) m[s.text(0)] = value_at(s, 1);
  return m;
}

// What differs between two metric sets, for the conflict report ("" when equal);
// timing metrics do not count.
std::string metrics_diff(Metrics here, Metrics there) {
  for (auto* m : {&here, &there})
    for (auto it = m->begin(); it != m->end();) it = is_timing_metric(it->first) ? m->erase(it) : std::next(it);
  std::string out;
  int n = 0;
  auto add = [&](const std::string& text) {
    if (n++ < 3) out += (out.empty() ? "" : "; ") + text;
  };
  for (const auto& [name, v] : here) {
    auto it = there.find(name);
    if (it == there.end())
      add(name + " only in the destination");
    else if (!(it->second == v))
      add(name + " " + show(v) + " (destination) vs " + show(it->second) + " (part)");
  }
  for (const auto& [name, v] : there)
    if (!here.count(name)) add(name + " only in the part");
  if (n > 3) out += "; and " + std::to_string(n - 3) + " more";
  return out;
}

// The columns of tasks that make up a result.
struct TaskResult {
  std::string status, worker, error;
  std::int64_t attempts = 0;
  std::optional<std::int64_t> pid;
  Value started_at, finished_at, wall_s;
  bool error_null = true, worker_null = true;
};

void write_result(Connection& out, std::int64_t task_id, const TaskResult& r, Connection& part,
                  std::int64_t part_task_id) {
  Statement u = out.prepare(
      "UPDATE tasks SET status = ?, attempts = ?, worker = ?, pid = ?, started_at = ?, finished_at = ?, wall_s = ?,"
      " error = ? WHERE id = ?");
  u.bind(1, r.status).bind(2, r.attempts);
  if (r.worker_null) u.bind_null(3); else u.bind(3, r.worker);
  if (r.pid) u.bind(4, *r.pid); else u.bind_null(4);
  bind_value(u, 5, r.started_at);
  bind_value(u, 6, r.finished_at);
  bind_value(u, 7, r.wall_s);
  if (r.error_null) u.bind_null(8); else u.bind(8, r.error);
  u.bind(9, task_id).run();
  out.prepare("DELETE FROM metrics WHERE task_id = ?").bind(1, task_id).run();
  out.prepare("DELETE FROM artifacts WHERE task_id = ?").bind(1, task_id).run();
  {
    Statement m = part.prepare("SELECT name, value FROM metrics WHERE task_id = ? ORDER BY rowid");
    m.bind(1, part_task_id);
    Statement ins = out.prepare("INSERT INTO metrics(task_id, name, value) VALUES(?, ?, ?)");
    while (m.step()) {
      ins.reset();
      ins.bind(1, task_id).bind(2, m.text(0));
      bind_value(ins, 3, value_at(m, 1));
      ins.run();
    }
  }
  Statement a = part.prepare("SELECT kind, path FROM artifacts WHERE task_id = ? ORDER BY rowid");
  a.bind(1, part_task_id);
  Statement ins = out.prepare("INSERT OR IGNORE INTO artifacts(task_id, kind, path) VALUES(?, ?, ?)");
  while (a.step()) {
    ins.reset();
    ins.bind(1, task_id).bind(2, a.text(0)).bind(3, a.text(1)).run();
  }
}

bool finished(const std::string& status) { return status == "done" || status == "failed"; }

class Merger {
 public:
  Merger(Connection& out, const std::string& into, MergeReport& report, const std::function<bool()>& stop)
      : out_(out), into_(into), r_(report), stop_(stop) {}

  void merge(const std::string& path) {
    Connection part(path, /*read_only=*/true);
    path_ = path;
    check_stop();
    merge_jobs(part);
    merge_tasks(part);
    merge_links(part);
    merge_fits(part);
    ++r_.parts;
  }

 private:
  void merge_jobs(Connection& part) {
    jobs_.clear();
    Statement s = part.prepare("SELECT id, name, spec_json, created_at, updated_at FROM jobs ORDER BY id");
    while (s.step()) {
      const std::int64_t part_id = s.int64(0);
      const std::string name = s.text(1), spec = s.text(2);
      const double created = s.real(3), updated = s.real(4);
      Statement f = out_.prepare("SELECT id, spec_json FROM jobs WHERE name = ?");
      f.bind(1, name);
      if (f.step()) {
        if (!same_job(f.text(1), spec)) {
          const auto from = job_from_.find(name);
          throw DbError(path_ + ": job \"" + name + "\" was run from a different job file (spec) than the job of that name " +
                            (from != job_from_.end() ? "in " + from->second + ", merged before it" : "in " + into_) +
                            "; nothing merged",
                        true);
        }
        jobs_[part_id] = {f.int64(0), name};  // the destination's row stays as it is
      } else {
        out_.prepare("INSERT INTO jobs(name, spec_json, created_at, updated_at) VALUES(?, ?, ?, ?)")
            .bind(1, name).bind(2, spec).bind(3, created).bind(4, updated).run();
        jobs_[part_id] = {out_.last_insert_id(), name};
        job_from_[name] = path_;
        ++r_.jobs_added;
      }
    }
  }

  void merge_tasks(Connection& part) {
    tasks_.clear();
    Statement s = part.prepare(
        "SELECT id, job_id, scene, params_json, key, status, attempts, worker, pid, started_at, finished_at, wall_s,"
        " error FROM tasks ORDER BY id");
    Statement find = out_.prepare("SELECT id, status FROM tasks WHERE key = ?");
    while (s.step()) {
      check_stop();
      const std::int64_t part_id = s.int64(0);
      const std::string key = s.text(4);
      TaskResult res;
      res.status = s.text(5);
      res.attempts = s.int64(6);
      res.worker_null = s.is_null(7);
      res.worker = s.text(7);
      if (!s.is_null(8)) res.pid = s.int64(8);
      res.started_at = value_at(s, 9);
      res.finished_at = value_at(s, 10);
      res.wall_s = value_at(s, 11);
      res.error_null = s.is_null(12);
      res.error = s.text(12);
      find.reset();
      find.bind(1, key);
      if (!find.step()) {
        find.reset();
        const auto job = jobs_.find(s.int64(1));
        if (job == jobs_.end()) throw DbError(path_ + ": task " + key + " names a job that is not there (damaged file)", true);
        out_.prepare("INSERT INTO tasks(job_id, scene, params_json, key) VALUES(?, ?, ?, ?)")
            .bind(1, job->second.first).bind(2, s.text(2)).bind(3, s.text(3)).bind(4, key).run();
        const std::int64_t id = out_.last_insert_id();
        tasks_[part_id] = id;
        ++r_.tasks_added;
        if (finished(res.status)) {
          write_result(out_, id, res, part, part_id);
          ++r_.results_taken;
        }
        continue;
      }
      const std::int64_t id = find.int64(0);
      const std::string here = find.text(1);
      find.reset();
      tasks_[part_id] = id;
      if (!finished(res.status)) {
        if (finished(here)) ++r_.kept;
        continue;  // nothing to bring; the destination has the task already
      }
      if (!finished(here) || (here == "failed" && res.status == "done")) {
        write_result(out_, id, res, part, part_id);
        ++r_.results_taken;
      } else if (here == "done" && res.status == "failed") {
        ++r_.kept;
      } else if (here == "failed") {
        ++r_.identical;  // failed in both: the destination's failure stays
      } else {
        const std::string diff = metrics_diff(metrics_of(out_, id), metrics_of(part, part_id));
        if (diff.empty()) {
          ++r_.identical;
        } else {
          r_.conflicts.push_back(path_ + ": task key " + key + " (" + where(part, part_id) + "): " + diff +
                                 "; the destination's result is kept");
        }
      }
    }
  }

  // "job NAME index I" for the first job listing the task in the part.
  std::string where(Connection& part, std::int64_t part_task_id) {
    Statement s = part.prepare(
        "SELECT j.name, jt.idx FROM job_tasks jt JOIN jobs j ON j.id = jt.job_id WHERE jt.task_id = ? ORDER BY jt.job_id, jt.idx LIMIT 1");
    s.bind(1, part_task_id);
    if (!s.step()) return "no job";
    return "job " + s.text(0) + " index " + std::to_string(s.int64(1));
  }

  void merge_links(Connection& part) {
    Statement s = part.prepare("SELECT job_id, idx, task_id FROM job_tasks ORDER BY job_id, idx");
    Statement f = out_.prepare("SELECT t.key FROM job_tasks jt JOIN tasks t ON t.id = jt.task_id WHERE jt.job_id = ? AND jt.idx = ?");
    Statement ins = out_.prepare("INSERT INTO job_tasks(job_id, idx, task_id) VALUES(?, ?, ?)");
    while (s.step()) {
      const auto job = jobs_.find(s.int64(0));
      const auto task = tasks_.find(s.int64(2));
      if (job == jobs_.end() || task == tasks_.end())
        throw DbError(path_ + ": a job_tasks row names a missing job or task (damaged file)", true);
      const std::int64_t idx = s.int64(1);
      f.reset();
      f.bind(1, job->second.first).bind(2, idx);
      if (f.step()) {
        const std::string key_here = f.text(0);
        f.reset();
        Statement k = out_.prepare("SELECT key FROM tasks WHERE id = ?");
        k.bind(1, task->second);
        const std::string key_there = k.step() ? k.text(0) : "";
        if (key_here != key_there)
          r_.conflicts.push_back(path_ + ": job " + job->second.second + " index " + std::to_string(idx) + " is task key " +
                                 key_there + " in the part but " + key_here + " in the destination; kept");
        continue;
      }
      f.reset();
      ins.reset();
      ins.bind(1, job->second.first).bind(2, idx).bind(3, task->second).run();
      ++r_.links_added;
    }
  }

  void merge_fits(Connection& part) {
    Statement s = part.prepare("SELECT created_at, targets_json, method, result_json FROM fits ORDER BY id");
    Statement f = out_.prepare(
        "SELECT 1 FROM fits WHERE created_at IS ? AND targets_json = ? AND method = ? AND result_json = ?");
    Statement ins = out_.prepare("INSERT INTO fits(created_at, targets_json, method, result_json) VALUES(?, ?, ?, ?)");
    while (s.step()) {
      const Value created = value_at(s, 0);
      f.reset();
      bind_value(f, 1, created);
      f.bind(2, s.text(1)).bind(3, s.text(2)).bind(4, s.text(3));
      const bool there = f.step();
      f.reset();
      if (there) continue;
      ins.reset();
      bind_value(ins, 1, created);
      ins.bind(2, s.text(1)).bind(3, s.text(2)).bind(4, s.text(3)).run();
      ++r_.fits_added;
    }
  }

  void check_stop() {
    if (stop_ && stop_()) throw DbError("stopped while merging " + path_ + " into " + into_ + "; nothing merged");
  }

  Connection& out_;
  std::string into_, path_;
  MergeReport& r_;
  const std::function<bool()>& stop_;
  std::map<std::int64_t, std::pair<std::int64_t, std::string>> jobs_;  // part job id -> destination id, name
  std::map<std::int64_t, std::int64_t> tasks_;                          // part task id -> destination id
  std::map<std::string, std::string> job_from_;  // job name -> the part that brought it in (not the destination)
};

}  // namespace

// `file` is where the rows go; `into` is the name the user gave (messages only).
static MergeReport merge_into(const std::string& file, const std::string& into, const std::vector<std::string>& parts,
                              const std::function<bool()>& stop) {
  Connection out(file, /*read_only=*/false);
  out.exec("PRAGMA journal_mode = WAL");
  out.exec("PRAGMA synchronous = NORMAL");
  out.exec("PRAGMA foreign_keys = ON");
  migrate(out);
  MergeReport report;
  Transaction t(out);
  Merger m(out, into, report, stop);
  for (const auto& p : parts) m.merge(p);
  t.commit();
  // A database built under another name is renamed when whole: its WAL is folded
  // into the file first (and removed), so the rename moves every row. Runs set WAL
  // again when they open it.
  if (file != into) out.exec("PRAGMA journal_mode = DELETE");
  return report;
}

bool is_timing_metric(const std::string& name) {
  return name == "wall_s" || name.rfind("wall_s_", 0) == 0 || name == "cpu_s" || name == "particle_steps_per_s" ||
         name == "threads";
}

namespace {

void remove_database_files(const std::string& file) {
  for (const char* suffix : {"", "-wal", "-shm", "-journal"}) {
    std::error_code ec;
    fs::remove(file + suffix, ec);
  }
}

// Renames `from` to `to` unless `to` exists (a file another process made meanwhile
// is not ours to replace). Filesystems without RENAME_NOREPLACE get link + unlink.
void publish(const std::string& from, const std::string& to) {
  if (::renameat2(AT_FDCWD, from.c_str(), AT_FDCWD, to.c_str(), RENAME_NOREPLACE) == 0) return;
  int err = errno;
  if (err == EINVAL || err == ENOSYS || err == ENOTSUP) {
    if (::link(from.c_str(), to.c_str()) == 0) {
      ::unlink(from.c_str());
      return;
    }
    err = errno;
  }
  throw DbError("cannot name the merged database " + to + ": " + std::strerror(err) +
                (err == EEXIST ? " (another process made that file while this merge ran; merge again)" : ""));
}

}  // namespace

MergeReport merge_databases(const std::string& into, const std::vector<std::string>& parts,
                            const std::function<bool()>& stop) {
  // Every part first: a bad one stops the merge before the destination is touched.
  for (const auto& p : parts) check_part(p, into);
  check_file(into);
  struct stat st {};
  if (::lstat(into.c_str(), &st) == 0 || errno != ENOENT) {
    // An existing destination: one transaction, so a merge that fails (two parts ran
    // different job files under one name) or is stopped leaves it as it was.
    return merge_into(into, into, parts, stop);
  }
  // A new destination is built under another name and named when whole: a merge
  // killed part-way leaves no empty database where the merged one should be, only
  // a part file that says what it is. Created exclusively: a file of that name is
  // not ours to remove.
  // The pid alone can repeat (a container's, after a killed merge left its part):
  // the next free number is taken.
  std::string part;
  int fd = -1;
  for (int n = 0; fd < 0 && n < 100; ++n) {
    part = into + ".merging-" + std::to_string(::getpid()) + (n ? "-" + std::to_string(n) : "") + ".part";
    fd = ::open(part.c_str(), O_WRONLY | O_CREAT | O_EXCL, 0644);
    if (fd < 0 && errno != EEXIST) break;
  }
  if (fd < 0) {
    const int err = errno;
    const bool folder = err == ENOENT || err == ENOTDIR || err == EACCES || err == EROFS || err == EPERM;
    throw DbError("cannot create the merged database " + into + " (its part file " + part + "): " + std::strerror(err),
                  /*bad_input=*/folder);
  }
  ::close(fd);
  try {
    MergeReport report = merge_into(part, into, parts, stop);  // closed here: the WAL is folded in
    publish(part, into);
    remove_database_files(part);  // -wal/-shm, should SQLite have left them
    return report;
  } catch (...) {
    remove_database_files(part);
    throw;
  }
}

}  // namespace demcal::db
