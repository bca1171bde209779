#pragma once
// Helpers for the distribution tests (shards, merge, SLURM script, MPI): running
// other programs than demcal, raw SQL on a database, comparing results bit for bit.
#include "cli_util.hpp"
#include "db/merge.hpp"

#include <sqlite3.h>

#include <cstring>

namespace demcal::test {

// Runs argv[0] (a path) with args; stdout/stderr to files in dir, as spawn() does.
inline Result run_program(const std::vector<std::string>& argv, const std::string& dir,
                          const std::map<std::string, std::string>& env = {}, const std::string& tag = "out") {
  return finish(spawn_program(argv, dir, env, tag), dir, tag);
}

inline Result run_bash(const std::string& script, const std::string& dir, const std::map<std::string, std::string>& env = {}) {
  return run_program({"/bin/bash", "-c", script}, dir, env);
}

inline void sql(const std::string& path, const std::string& text) {
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  char* err = nullptr;
  const int rc = sqlite3_exec(db, text.c_str(), nullptr, nullptr, &err);
  EXPECT_EQ(rc, SQLITE_OK) << (err ? err : "");
  sqlite3_free(err);
  sqlite3_close(db);
}

// Every row of every table (timestamps included), as text: equal dumps mean equal databases.
inline std::string dump(const std::string& path) {
  sqlite3* db = nullptr;
  if (sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READONLY, nullptr) != SQLITE_OK) return "<cannot open>";
  std::string out;
  for (const char* q : {"SELECT * FROM jobs ORDER BY id", "SELECT * FROM tasks ORDER BY id",
                        "SELECT * FROM job_tasks ORDER BY job_id, idx", "SELECT * FROM metrics ORDER BY task_id, name",
                        "SELECT * FROM artifacts ORDER BY task_id, kind, path", "SELECT * FROM fits ORDER BY id"}) {
    sqlite3_stmt* st = nullptr;
    sqlite3_prepare_v2(db, q, -1, &st, nullptr);
    out += std::string(q) + "\n";
    while (sqlite3_step(st) == SQLITE_ROW) {
      for (int c = 0; c < sqlite3_column_count(st); ++c) {
        if (sqlite3_column_type(st, c) == SQLITE_FLOAT) {
          const double v = sqlite3_column_double(st, c);
          std::uint64_t bits;
          std::memcpy(&bits, &v, sizeof bits);
          out += std::to_string(bits);
        } else {
          const auto* t = sqlite3_column_text(st, c);
          out += t ? reinterpret_cast<const char*>(t) : "NULL";
        }
        out += "|";
      }
      out += "\n";
    }
    sqlite3_finalize(st);
  }
  sqlite3_close(db);
  return out;
}

inline bool same_bits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

// The job's tasks in expansion order in both databases: same keys, all done, and
// the same metrics bit for bit, timing metrics (wall clock, throughput) aside.
// Returns the number of metrics compared.
inline int expect_same_results(const std::string& db_a, const std::string& db_b, const std::string& job) {
  db::Store a(db_a, true), b(db_b, true);
  const auto ta = a.tasks(job), tb = b.tasks(job);
  EXPECT_EQ(ta.size(), tb.size());
  int compared = 0;
  for (std::size_t i = 0; i < std::min(ta.size(), tb.size()); ++i) {
    EXPECT_EQ(ta[i].index, tb[i].index);
    EXPECT_EQ(ta[i].key, tb[i].key) << "index " << i;
    EXPECT_EQ(ta[i].status, "done") << db_a << " index " << i << ": " << ta[i].error;
    EXPECT_EQ(tb[i].status, "done") << db_b << " index " << i << ": " << tb[i].error;
    const auto ma = a.metrics(ta[i].id), mb = b.metrics(tb[i].id);
    EXPECT_EQ(ma.size(), mb.size()) << "index " << i;
    EXPECT_FALSE(ma.empty()) << "index " << i;
    for (std::size_t k = 0; k < std::min(ma.size(), mb.size()); ++k) {
      EXPECT_EQ(ma[k].first, mb[k].first);
      if (demcal::db::is_timing_metric(ma[k].first)) continue;
      EXPECT_TRUE(same_bits(ma[k].second, mb[k].second) || (std::isnan(ma[k].second) && std::isnan(mb[k].second)))
          << "index " << i << " metric " << ma[k].first << ": " << ma[k].second << " vs " << mb[k].second;
      ++compared;
    }
  }
  return compared;
}

}  // namespace demcal::test
