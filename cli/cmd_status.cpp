#include "common.hpp"

#include "db/store.hpp"

#include <iomanip>
#include <iostream>

namespace demcal::cli {
namespace {

// Why tasks failed, a few per job (their first line): the counts alone send the
// user to `query` for the reason.
// The query command that shows a job's tasks, naming the database unless it is the default.
std::string query_hint(const std::string& db, const std::string& job) {
  return "demcal query" + (db == "demcal.db" ? std::string() : " --db " + db) + " --job " + job;
}

void print_failures(db::Store& store, const db::StatusCounts& counts, const std::string& db) {
  constexpr int kShown = 3;
  for (const auto& [name, by] : counts) {
    const auto it = by.find("failed");
    if (it == by.end() || it->second == 0) continue;
    int shown = 0;
    for (const auto& t : store.tasks(name)) {
      if (t.status != "failed") continue;
      std::string why = t.error.substr(0, t.error.find('\n'));
      if (why.size() > 200) why = why.substr(0, 197) + "...";
      std::cout << name << ": task " << t.id << " failed: " << why << "\n";
      if (++shown == kShown) break;
    }
    if (it->second > kShown)
      std::cout << name << ": " << it->second - kShown << " more failed (" << query_hint(db, name) << ")\n";
  }
}

// Finished tasks whose metrics carry a warning (not quasi-static, a diagnostic on):
// how many, and the first one's words.
void print_warnings(db::Store& store, const db::StatusCounts& counts, const std::string& db) {
  for (const auto& [name, by] : counts) {
    const auto it = by.find("done");
    if (it == by.end() || it->second == 0) continue;
    int n = 0;
    std::string first;
    std::int64_t first_id = 0;
    for (const auto& t : store.tasks(name)) {
      if (t.status != "done" || t.error.empty()) continue;
      if (n++ == 0) {
        first = t.error.substr(0, t.error.find('\n'));
        first_id = t.id;
      }
    }
    if (n == 0) continue;
    if (first.size() > 200) first = first.substr(0, 197) + "...";
    std::cout << name << ": " << n << " done task(s) with warnings, e.g. task " << first_id << ": " << first
              << " (" << query_hint(db, name) << " shows each)\n";
  }
}

}  // namespace

void add_status(CLI::App& app, int& exit_code) {
  auto* cmd = app.add_subcommand("status", "Task counts per status, per job, the reason of up to three failed tasks per job, and how many finished tasks carry warnings");
  auto db = std::make_shared<std::string>("demcal.db");
  auto job = std::make_shared<std::string>();
  cmd->add_option("--db", *db, "SQLite database")->capture_default_str();
  cmd->add_option("--job", *job, "only this job");
  cmd->callback([db, job, &exit_code] {
    exit_code = guarded("", [&] {
      require_db(*db);
      db::Store store(*db, /*read_only=*/true);
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
      print_failures(store, counts, *db);
      print_warnings(store, counts, *db);
      return kOk;
    });
  });
}

}  // namespace demcal::cli
