#include "common.hpp"

#include "db/store.hpp"
#include "jobs/liveness.hpp"
#include "jobs/query.hpp"
#include "jobs/job_spec.hpp"
#include "jobs/work_forecast.hpp"

#include <iomanip>
#include <map>
#include <iostream>

namespace demcal::cli {
namespace {

std::string first_line(const std::string& text, std::size_t max) {
  std::string s = text.substr(0, text.find('\n'));
  return s.size() > max ? s.substr(0, max - 3) + "..." : s;
}

// Why tasks failed, a few per job (their first line): the counts alone send the
// user to `query` for the reason. Then finished tasks whose metrics carry a warning
// (not quasi-static, a diagnostic on): how many, and the first one's words. Each
// job's tasks are read once, for both.
void print_messages(db::Store& store, const db::StatusCounts& counts, const std::string& db) {
  constexpr int kShown = 3;
  struct Warned {
    std::string job, first;
    std::int64_t first_id = 0;
    int n = 0;
  };
  std::vector<Warned> warned;
  for (const auto& [name, by] : counts) {
    const auto failed = by.find("failed"), done = by.find("done");
    const bool any_failed = failed != by.end() && failed->second > 0;
    if (!any_failed && (done == by.end() || done->second == 0)) continue;
    int shown = 0;
    Warned w{name, "", 0, 0};
    for (const auto& t : store.tasks(name)) {
      if (t.status == "failed" && shown < kShown) {
        std::cout << name << ": task " << t.id << " failed: " << first_line(t.error, 200) << "\n";
        ++shown;
      } else if (t.status == "done" && !t.error.empty() && w.n++ == 0) {
        w.first = first_line(t.error, 200);
        w.first_id = t.id;
      }
    }
    if (any_failed && failed->second > kShown)
      std::cout << name << ": " << failed->second - kShown << " more failed (" << jobs::query_hint(db, name) << ")\n";
    if (w.n > 0) warned.push_back(w);
  }
  for (const auto& w : warned)
    std::cout << w.job << ": " << w.n << " done task(s) with warnings, e.g. task " << w.first_id << ": " << w.first
              << " (" << jobs::query_hint(db, w.job) << " shows each)\n";
}

// A database holding only part of a job (a shard's part, a merge of some shards)
// looks complete by its own counts: compare with what the job file expands to.
void print_missing(db::Store& store, const db::StatusCounts& counts) {
  for (const auto& [name, by] : counts) {
    int total = 0;
    for (const auto& [status, n] : by) total += n;
    const auto spec = store.job_spec(name);
    if (!spec) continue;
    std::uint64_t expected = 0;
    try {
      expected = jobs::count_tasks(*spec, "job " + name);
    } catch (const std::exception&) {
      continue;  // a spec whose grid this demcal cannot read (older keys): nothing to compare
    }
    if (expected > static_cast<std::uint64_t>(total))
      std::cout << name << ": " << expected - static_cast<std::uint64_t>(total) << " of the job file's " << expected
                << " task(s) are not in this database (a shard's part, or a merge of some shards): fit and map "
                   "use only what is here\n";
  }
}

// How long the unfinished tasks of each job will take, at the speed the database's
// done tasks of the scene ran at (or the project's yardstick without any).
void print_time_left(db::Store& store, const db::StatusCounts& counts) {
  const double now = db::unix_now();
  for (const auto& [name, by] : counts) {
    const auto pending = by.find("pending"), running = by.find("running");
    if ((pending == by.end() || pending->second == 0) && (running == by.end() || running->second == 0)) continue;
    try {
      const jobs::TimeLeft t = jobs::time_left(store, name, now);
      if (t.known) std::cout << name << ": " << jobs::describe(t) << "\n";
    } catch (const std::exception& e) {  // a forecast only: the counts and failures still print
      std::cout << name << ": no forecast of the time left (" << e.what() << ")\n";
    }
  }
}

// Tasks left 'running' by a runner that is gone (killed with -9, its host lost):
// counted as running, they would be forecast as finishing any minute.
void print_orphans(db::Store& store, const db::StatusCounts& counts) {
  for (const auto& [name, by] : counts) {
    const auto running = by.find("running");
    if (running == by.end() || running->second == 0) continue;
    std::map<std::string, int> gone;  // holder token -> tasks
    for (const auto& t : store.tasks(name))
      if (t.status == "running" && !jobs::holder_alive(store, t.worker)) ++gone[t.worker];
    for (const auto& [token, n] : gone)
      std::cout << name << ": " << n << " of the running task(s) are held by a runner that is gone (" << token
                << "): no one is at work on them; any `demcal run` of the job puts them back in the queue\n";
  }
}

}  // namespace

void add_status(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand("status", "Task counts per status, per job, the time the unfinished tasks will take, the reason of up to three failed tasks per job, and how many finished tasks carry warnings");
  auto db = std::make_shared<std::string>("demcal.db");
  auto job = std::make_shared<std::string>();
  cmd->add_option("--db", *db, "SQLite database")->check(kDbPath)->capture_default_str();
  cmd->add_option("--job", *job, "only this job")->check(kNonEmpty);
  cmd->callback([db, job, &exit_code] {
    exit_code = guarded("", [&] {
      require_db(*db);
      db::Store store(*db, /*read_only=*/true);
      const db::ReadSnapshot snapshot = store.snapshot();  // counts, forecast and failures of one moment
      const db::StatusCounts counts = store.counts(*job);
      if (!job->empty() && counts.empty()) {
        std::cerr << "demcal: error: --job: no job named \"" << *job << "\"\n";
        return kBadInput;
      }
      const char* statuses[] = {"pending", "running", "done", "failed"};
      std::size_t w = 3;
      for (const auto& [name, by] : counts) w = std::max(w, name.size());
      std::cout << std::left << std::setw(static_cast<int>(w) + 2) << "job" << std::right;
      for (const char* s : statuses) std::cout << std::setw(9) << s;
      std::cout << std::setw(9) << "total" << "\n";
      for (const auto& [name, by] : counts) {
        int total = 0;
        std::cout << std::left << std::setw(static_cast<int>(w) + 2) << name << std::right;
        for (const char* s : statuses) {
          const auto it = by.find(s);
          const int n = it == by.end() ? 0 : it->second;
          total += n;
          std::cout << std::setw(9) << n;
        }
        std::cout << std::setw(9) << total << "\n";
      }
      print_orphans(store, counts);
      print_time_left(store, counts);
      print_messages(store, counts, *db);
      print_missing(store, counts);
      return kOk;
    });
  });
}

}  // namespace demcal::cli
