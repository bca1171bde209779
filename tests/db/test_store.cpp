#include "db/schema.hpp"
#include "db/store.hpp"

#include "../temp_dir.hpp"

#include <gtest/gtest.h>
#include <sqlite3.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <atomic>
#include <thread>
#include <unistd.h>

namespace fs = std::filesystem;
using demcal::test::TempDir;
using demcal::db::DbError;
using demcal::db::Store;

namespace {

std::string slurp(const std::string& p) {
  std::ifstream f(p, std::ios::binary);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

void raw_sql(const std::string& path, const char* sql) {
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(db, sql, nullptr, nullptr, nullptr), SQLITE_OK) << sqlite3_errmsg(db);
  sqlite3_close(db);
}

std::vector<demcal::db::NewTask> tasks(std::initializer_list<const char*> keys) {
  std::vector<demcal::db::NewTask> out;
  for (const char* k : keys) out.push_back({k, "collision", std::string("{\"k\":\"") + k + "\"}"});
  return out;
}

demcal::db::Outcome done_with(double metric) {
  demcal::db::Outcome o;
  o.status = "done";
  o.wall_s = 0.5;
  o.metrics = {{"m", metric}, {"drift", INFINITY}};
  o.artifacts = {{"hdf5", "/x/1.h5"}};
  return o;
}

// `open` must throw a DbError flagged as bad input whose message contains `says`.
template <class F>
void expect_bad_input(F open, const std::string& says) {
  try {
    open();
    ADD_FAILURE() << "no error; expected one saying \"" << says << "\"";
  } catch (const DbError& e) {
    EXPECT_TRUE(e.bad_input()) << e.what();
    EXPECT_NE(std::string(e.what()).find(says), std::string::npos) << e.what();
  }
}

}  // namespace

TEST(Store, CreatesSchemaWithVersionAndWal) {
  TempDir d;
  { Store s(d.file("a.db")); }
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(d.file("a.db").c_str(), &db), SQLITE_OK);
  sqlite3_stmt* st = nullptr;
  sqlite3_prepare_v2(db, "PRAGMA user_version", -1, &st, nullptr);
  ASSERT_EQ(sqlite3_step(st), SQLITE_ROW);
  EXPECT_EQ(sqlite3_column_int(st, 0), demcal::db::kSchemaVersion);
  sqlite3_finalize(st);
  sqlite3_prepare_v2(db, "PRAGMA journal_mode", -1, &st, nullptr);
  ASSERT_EQ(sqlite3_step(st), SQLITE_ROW);
  EXPECT_STREQ(reinterpret_cast<const char*>(sqlite3_column_text(st, 0)), "wal");
  sqlite3_finalize(st);
  sqlite3_close(db);
  Store again(d.file("a.db"));  // reopening migrates nothing and succeeds
}

// A version-1 file that already has version 2's table (its version set back by hand,
// or a migration whose version write was lost) migrates, its rows kept.
TEST(Store, AMigrationFindsItsTableAlreadyThere) {
  TempDir d;
  {
    Store s(d.file("a.db"));
    s.put_job("j", "{}", tasks({"k1"}));
    s.beat("node01:1:1");
  }
  raw_sql(d.file("a.db"), "PRAGMA user_version=1");
  Store s(d.file("a.db"));
  EXPECT_EQ(s.tasks("j").size(), 1u);
  EXPECT_EQ(s.runner_tokens(), std::vector<std::string>{"node01:1:1"});
}

TEST(Store, ReadersLeaveNoWalFilesBehindAndCannotWrite) {
  // query and status open the store read-only: closing must leave the database one
  // file (a copy of demcal.db alone is then the whole record), and writes are refused.
  TempDir d;
  const std::string path = d.file("demcal.db");
  {
    Store s(path);
    s.put_job("j", "{}", {{"k1", "collision", "{}"}});
  }
  ASSERT_FALSE(fs::exists(path + "-wal"));
  {
    Store r(path, /*read_only=*/true);
    EXPECT_EQ(r.tasks("j").size(), 1u);
    EXPECT_THROW(r.put_job("k", "{}", {{"k2", "collision", "{}"}}), DbError);
  }
  EXPECT_FALSE(fs::exists(path + "-wal"));
  EXPECT_FALSE(fs::exists(path + "-shm"));
  Store again(path, true);
  EXPECT_EQ(again.tasks().size(), 1u) << "the refused write left nothing";
}

TEST(Store, AFileBeingCreatedIsNeverTakenForAForeignOne) {
  // A second runner checks the file while the first creates its schema: every check
  // must see the file as new or as a whole demcal database, never half of each (the
  // tables committed but read apart from the application id). Before the check read
  // one snapshot, this failed within a few dozen files on this 2-core machine.
  TempDir d;
  int checks = 0;
  for (int i = 0; i < 150; ++i) {
    const std::string path = d.file("race" + std::to_string(i) + ".db");
    std::atomic<bool> created{false};
    std::string refused;
    std::thread checker([&] {
      while (!created.load() && refused.empty()) {
        try {
          demcal::db::check_file(path);
          ++checks;
        } catch (const DbError& e) {
          refused = e.what();
        }
      }
    });
    try {
      Store s(path);
    } catch (...) {
      created = true;
      checker.join();
      throw;
    }
    created = true;
    checker.join();
    ASSERT_EQ(refused, "") << "file " << i << " after " << checks << " checks";
  }
  EXPECT_GT(checks, 150);
}

TEST(Store, RejectsNonSqliteFileUntouched) {
  TempDir d;
  const std::string p = d.file("notes.db");
  std::ofstream(p) << "these are my notes, not a database\n";
  const std::string before = slurp(p);
  try {
    Store s(p);
    FAIL() << "expected DbError";
  } catch (const DbError& e) {
    EXPECT_TRUE(e.bad_input());
    EXPECT_NE(std::string(e.what()).find("not a SQLite database"), std::string::npos) << e.what();
  }
  EXPECT_EQ(slurp(p), before);
}

TEST(Store, RejectsForeignSqliteUntouched) {
  TempDir d;
  const std::string p = d.file("other.db");
  raw_sql(p, "CREATE TABLE customers(id INTEGER, name TEXT)");
  const std::string before = slurp(p);
  try {
    Store s(p);
    FAIL() << "expected DbError";
  } catch (const DbError& e) {
    EXPECT_TRUE(e.bad_input());
    EXPECT_NE(std::string(e.what()).find("not a demcal"), std::string::npos) << e.what();
  }
  EXPECT_EQ(slurp(p), before);
}

TEST(Store, RejectsNewerSchemaUntouched) {
  TempDir d;
  const std::string p = d.file("new.db");
  { Store s(p); }
  raw_sql(p, "PRAGMA journal_mode=DELETE; PRAGMA user_version=99");
  const std::string before = slurp(p);
  try {
    Store s(p);
    FAIL() << "expected DbError";
  } catch (const DbError& e) {
    EXPECT_TRUE(e.bad_input());
    EXPECT_NE(std::string(e.what()).find("newer"), std::string::npos) << e.what();
  }
  EXPECT_EQ(slurp(p), before);
}

TEST(Store, RejectsCorruptFile) {
  TempDir d;
  const std::string p = d.file("bad.db");
  { Store s(p); s.put_job("j", "{}", tasks({"a", "b"})); }
  raw_sql(p, "PRAGMA journal_mode=DELETE");
  std::string bytes = slurp(p);
  for (std::size_t i = 100; i < bytes.size(); i += 7) bytes[i] = static_cast<char>(bytes[i] ^ 0x5a);
  std::ofstream(p, std::ios::binary | std::ios::trunc) << bytes;
  EXPECT_THROW({ Store s(p); }, DbError);
  EXPECT_EQ(slurp(p), bytes);
}

TEST(Store, ClaimIsExclusiveAndFinishStoresResults) {
  TempDir d;
  Store s(d.file("a.db"));
  s.put_job("j", "{}", tasks({"k1", "k2"}));
  auto rows = s.tasks("j");
  ASSERT_EQ(rows.size(), 2u);
  EXPECT_EQ(rows[0].status, "pending");
  EXPECT_TRUE(s.claim(rows[0].id, "w1"));
  EXPECT_FALSE(s.claim(rows[0].id, "w2"));
  EXPECT_FALSE(s.finish(rows[0].id, "w2", done_with(1.0)));  // not the holder
  EXPECT_TRUE(s.finish(rows[0].id, "w1", done_with(2.0)));
  const auto t = s.task(rows[0].id);
  EXPECT_EQ(t->status, "done");
  EXPECT_EQ(t->attempts, 1);
  const auto m = s.metrics(rows[0].id);
  ASSERT_EQ(m.size(), 2u);
  EXPECT_EQ(m[0].second, 2.0);
  EXPECT_TRUE(std::isinf(m[1].second));
  EXPECT_EQ(s.artifacts(rows[0].id).size(), 1u);
  EXPECT_EQ(s.counts("j")["j"]["done"], 1);
  EXPECT_EQ(s.counts("j")["j"]["pending"], 1);
}

// A value edited by hand into a REAL column stays text when SQLite cannot read it as a
// number; sqlite3_column_double would read it as 0, a silently wrong metric.
TEST(Store, AMetricHeldAsTextReadsAsItsNumberOrNamesTheText) {
  TempDir d;
  const std::string path = d.file("a.db");
  std::int64_t id = 0;
  {
    Store s(path);
    s.put_job("j", "{}", tasks({"k1"}));
    id = s.tasks("j")[0].id;
    ASSERT_TRUE(s.claim(id, "w1"));
    ASSERT_TRUE(s.finish(id, "w1", done_with(2.0)));
  }
  raw_sql(path, "UPDATE metrics SET value = 'nan' WHERE name = 'm'; UPDATE metrics SET value = '-Inf' WHERE name = 'drift'");
  {
    Store s(path);
    const auto m = s.metrics(id);
    ASSERT_EQ(m.size(), 2u);
    EXPECT_TRUE(std::isnan(m[0].second)) << m[0].second;
    EXPECT_TRUE(std::isinf(m[1].second) && m[1].second < 0) << m[1].second;
  }
  raw_sql(path, "UPDATE metrics SET value = '1,5' WHERE name = 'm'");
  Store s(path);
  expect_bad_input([&] { s.metrics(id); }, "column value holds the text \"1,5\" where a number belongs");
  // Blank text converts nothing (strtod reads 0 from it); a control byte is shown, not
  // left to cut the message.
  raw_sql(path, "UPDATE metrics SET value = ' ' WHERE name = 'm'");
  expect_bad_input([&] { s.metrics(id); }, "holds the text \" \"");
  raw_sql(path, "UPDATE metrics SET value = '2.5' || char(9) || 'x' WHERE name = 'm'");
  expect_bad_input([&] { s.metrics(id); }, "holds the text \"2.5\\x09x\"");
}

// Per-task reads reuse their prepared statement; a kept statement must not hold its
// read transaction open after the read (the WAL could never be checkpointed while a
// query or status runs), and a snapshot must show one state of the file throughout.
TEST(Store, KeptStatementsHoldNothingOpenAndASnapshotSeesOneState) {
  TempDir d;
  const std::string path = d.file("a.db");
  Store s(path);
  s.put_job("j", "{}", tasks({"k1"}));
  const std::int64_t id = s.tasks("j")[0].id;
  ASSERT_TRUE(s.claim(id, "w1"));
  ASSERT_TRUE(s.finish(id, "w1", done_with(2.0)));
  ASSERT_EQ(s.metrics(id)[0].second, 2.0);
  ASSERT_EQ(s.artifacts(id).size(), 1u);
  raw_sql(path, "UPDATE metrics SET value = 3 WHERE name = 'm'");
  // TRUNCATE must wait for every reader: it reports busy (1) while one holds a snapshot.
  const auto checkpoint_busy = [&] {
    sqlite3* db = nullptr;
    EXPECT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
    int busy = -1;
    sqlite3_exec(db, "PRAGMA wal_checkpoint(TRUNCATE)",
                 [](void* b, int, char** v, char**) { *static_cast<int*>(b) = std::atoi(v[0]); return 0; }, &busy,
                 nullptr);
    sqlite3_close(db);
    return busy;
  };
  EXPECT_EQ(checkpoint_busy(), 0);
  EXPECT_EQ(s.metrics(id)[0].second, 3.0);
  {
    const auto snapshot = s.snapshot();
    EXPECT_EQ(s.metrics(id)[0].second, 3.0);
    raw_sql(path, "UPDATE metrics SET value = 4 WHERE name = 'm'");
    EXPECT_EQ(s.metrics(id)[0].second, 3.0);  // the snapshot's state, not the new commit
    EXPECT_EQ(checkpoint_busy(), 1);
  }
  EXPECT_EQ(s.metrics(id)[0].second, 4.0);
  EXPECT_EQ(checkpoint_busy(), 0);
  // A read left by an exception, rows unread, holds nothing either.
  raw_sql(path, "UPDATE metrics SET value = 'x' WHERE name = 'm'");
  EXPECT_THROW(s.metrics(id), DbError);
  EXPECT_EQ(checkpoint_busy(), 0);
}

// A shard's runner counts its part from (index, status) pairs alone.
TEST(Store, TaskStatusesGiveEachTaskItsIndexInTheJob) {
  TempDir d;
  Store s(d.file("a.db"));
  s.put_job("j", "{}", tasks({"k1", "k2", "k3"}));
  s.put_job("other", "{}", tasks({"k3"}));
  const auto rows = s.tasks("j");
  ASSERT_TRUE(s.claim(rows[1].id, "w1"));
  ASSERT_TRUE(s.finish(rows[1].id, "w1", done_with(1.0)));
  auto st = s.task_statuses("j");
  std::sort(st.begin(), st.end());
  ASSERT_EQ(st.size(), 3u);
  EXPECT_EQ(st[0], (std::pair<std::int64_t, std::string>{0, "pending"}));
  EXPECT_EQ(st[1], (std::pair<std::int64_t, std::string>{1, "done"}));
  EXPECT_EQ(st[2], (std::pair<std::int64_t, std::string>{2, "pending"}));
  const auto other = s.task_statuses("other");
  ASSERT_EQ(other.size(), 1u);
  EXPECT_EQ(other[0].first, 0);  // its own index in its own job
  EXPECT_TRUE(s.task_statuses("nope").empty());
}

TEST(Store, OverlappingJobsShareTasksByKey) {
  TempDir d;
  Store s(d.file("a.db"));
  s.put_job("a", "{}", tasks({"k1", "k2"}));
  s.put_job("b", "{}", tasks({"k2", "k3"}));
  const auto a = s.tasks("a"), b = s.tasks("b");
  EXPECT_EQ(a[1].id, b[0].id);
  EXPECT_EQ(s.tasks().size(), 3u);
  // Re-submitting a job is idempotent.
  s.put_job("a", "{}", tasks({"k1", "k2"}));
  EXPECT_EQ(s.tasks().size(), 3u);
  EXPECT_EQ(s.tasks("a").size(), 2u);
}

TEST(Store, AnEditedJobSaysWhichTasksLeftIt) {
  TempDir d;
  Store s(d.file("a.db"));
  std::vector<std::int64_t> dropped{99};
  s.put_job("a", R"({"grid":[1,2]})", tasks({"k1", "k2"}), false, &dropped);
  EXPECT_TRUE(dropped.empty());
  const std::int64_t k2 = s.tasks("a")[1].id;
  s.put_job("a", R"({"grid":[1,2]})", tasks({"k1", "k2"}), false, &dropped);
  EXPECT_TRUE(dropped.empty()) << "the same spec again drops nothing";
  s.put_job("a", R"({"grid":[1,3]})", tasks({"k1", "k3"}), false, &dropped);
  ASSERT_EQ(dropped.size(), 1u);
  EXPECT_EQ(dropped[0], k2);
  EXPECT_EQ(s.tasks("a").size(), 2u);
  EXPECT_EQ(s.tasks().size(), 3u) << "the dropped task stays in the database";
}

TEST(Store, RequeuesTasksOfDeadWorkersAndReleases) {
  TempDir d;
  Store s(d.file("a.db"));
  s.put_job("j", "{}", tasks({"k1", "k2", "k3"}));
  const auto rows = s.tasks("j");
  ASSERT_TRUE(s.claim(rows[0].id, "dead"));
  ASSERT_TRUE(s.claim(rows[1].id, "alive"));
  ASSERT_TRUE(s.claim(rows[2].id, "alive"));
  EXPECT_EQ(s.requeue_dead([](const std::string& w) { return w == "alive"; }), 1);
  EXPECT_EQ(s.task(rows[0].id)->status, "pending");
  EXPECT_EQ(s.task(rows[0].id)->attempts, 1);
  s.release(rows[1].id, "alive", "interrupted");
  EXPECT_EQ(s.task(rows[1].id)->status, "pending");
  EXPECT_EQ(s.task(rows[2].id)->status, "running");
}

TEST(Store, ReadOnlyOpenDoesNotCreate) {
  TempDir d;
  EXPECT_THROW({ Store s(d.file("missing.db"), true); }, DbError);
  EXPECT_FALSE(fs::exists(d.file("missing.db")));
}

TEST(Store, AFolderIsBadInputNamedAsAFolder) {
  TempDir d;
  fs::create_directory(d.file("runs.db"));
  expect_bad_input([&] { Store s(d.file("runs.db")); }, "is a folder, not a database file");
  expect_bad_input([&] { Store s(d.file("runs.db"), true); }, "is a folder");
}

TEST(Store, EmptyFileReadOnlyIsBadInputNotAMissingTable) {
  // A 0-byte file is a valid empty SQLite database: reading it must say that it
  // holds no results (bad input), not fail later on "no such table".
  TempDir d;
  { std::ofstream(d.file("empty.db")); }
  expect_bad_input([&] { Store s(d.file("empty.db"), true); }, "holds no demcal results");
  EXPECT_EQ(fs::file_size(d.file("empty.db")), 0u);
}

TEST(Store, DatabaseInAMissingDirectoryIsBadInputNamingIt) {
  TempDir d;
  expect_bad_input([&] { Store s(d.file("nope/x.db"), false); }, "does not exist");
  EXPECT_FALSE(fs::exists(d.file("nope")));
}
