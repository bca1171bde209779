#include "schema.hpp"

#include <sqlite3.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <sys/stat.h>
#include <vector>

namespace demcal::db {
namespace {

const char* const kMigrations[] = {
    // 0 -> 1
    R"sql(
CREATE TABLE jobs(
  id INTEGER PRIMARY KEY,
  name TEXT NOT NULL UNIQUE,
  spec_json TEXT NOT NULL,
  created_at REAL NOT NULL,
  updated_at REAL NOT NULL);
-- A task is one unit of work, identified by its content key; several jobs may
-- share it through job_tasks, so identical work is never run twice.
CREATE TABLE tasks(
  id INTEGER PRIMARY KEY,
  job_id INTEGER NOT NULL REFERENCES jobs(id),
  scene TEXT NOT NULL,
  params_json TEXT NOT NULL,
  key TEXT NOT NULL UNIQUE,
  status TEXT NOT NULL DEFAULT 'pending'
    CHECK(status IN ('pending', 'running', 'done', 'failed')),
  attempts INTEGER NOT NULL DEFAULT 0,
  worker TEXT,
  pid INTEGER,
  started_at REAL,
  finished_at REAL,
  wall_s REAL,
  error TEXT);  -- failed: why; done: its warnings ("warning: ...") or NULL
CREATE INDEX tasks_status ON tasks(status);
CREATE TABLE job_tasks(
  job_id INTEGER NOT NULL REFERENCES jobs(id),
  idx INTEGER NOT NULL,
  task_id INTEGER NOT NULL REFERENCES tasks(id),
  PRIMARY KEY(job_id, idx));
CREATE INDEX job_tasks_task ON job_tasks(task_id);
CREATE TABLE metrics(
  task_id INTEGER NOT NULL REFERENCES tasks(id),
  name TEXT NOT NULL,
  value REAL,
  PRIMARY KEY(task_id, name));
CREATE TABLE artifacts(
  task_id INTEGER NOT NULL REFERENCES tasks(id),
  kind TEXT NOT NULL,
  path TEXT NOT NULL,
  PRIMARY KEY(task_id, kind, path));
CREATE TABLE fits(
  id INTEGER PRIMARY KEY,
  created_at REAL NOT NULL,
  targets_json TEXT NOT NULL,
  method TEXT NOT NULL,
  result_json TEXT NOT NULL);
)sql",
    // 1 -> 2: runners' heartbeats, so that a run on another host can tell a runner
    // that died there (its tasks left 'running') from one still at work. IF NOT
    // EXISTS: a version-1 file that has the table (a version number set back by
    // hand, or a migration whose version write was lost) migrates all the same.
    R"sql(
CREATE TABLE IF NOT EXISTS runners(
  token TEXT PRIMARY KEY,
  last_seen REAL NOT NULL);
)sql",
};
static_assert(sizeof(kMigrations) / sizeof(kMigrations[0]) == kSchemaVersion, "one migration per version");

int pragma_int(Connection& c, const char* sql) {
  Statement s = c.prepare(sql);
  return s.step() ? static_cast<int>(s.int64(0)) : 0;
}

bool file_is_empty_or_missing(const std::string& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return true;
  return st.st_size == 0;
}

void check_header(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw DbError("cannot read database " + path + ": " + std::strerror(errno), true);
  char head[16] = {};
  in.read(head, sizeof head);
  if (in.gcount() != 16 || std::string(head, 16) != std::string("SQLite format 3\0", 16))
    throw DbError(path + " is not a SQLite database (and was left untouched)", true);
}

// The tables and columns a file of schema `version` has, in the order the migrations
// make them: built in memory from kMigrations, so that the check below follows the
// schema without a list of its own to keep in step.
struct TableColumns {
  std::string table;
  std::vector<std::string> columns;
};
std::vector<TableColumns> schema_tables(int version) {
  sqlite3* db = nullptr;
  std::vector<TableColumns> out;
  const auto texts = [&](const char* sql, const std::string& bind) {
    std::vector<std::string> v;
    sqlite3_stmt* st = nullptr;
    if (sqlite3_prepare_v2(db, sql, -1, &st, nullptr) != SQLITE_OK) throw std::logic_error(sqlite3_errmsg(db));
    if (!bind.empty()) sqlite3_bind_text(st, 1, bind.c_str(), -1, SQLITE_TRANSIENT);
    while (sqlite3_step(st) == SQLITE_ROW) v.emplace_back(reinterpret_cast<const char*>(sqlite3_column_text(st, 0)));
    sqlite3_finalize(st);
    return v;
  };
  try {
    if (sqlite3_open(":memory:", &db) != SQLITE_OK) throw std::logic_error("cannot open an in-memory database");
    for (int v = 0; v < version; ++v)
      if (sqlite3_exec(db, kMigrations[v], nullptr, nullptr, nullptr) != SQLITE_OK) throw std::logic_error(sqlite3_errmsg(db));
    for (const auto& t : texts("SELECT name FROM sqlite_master WHERE type = 'table' ORDER BY rowid", ""))
      out.push_back({t, texts("SELECT name FROM pragma_table_info(?) ORDER BY cid", t)});
  } catch (...) {
    sqlite3_close(db);
    throw;
  }
  sqlite3_close(db);
  return out;
}

// A demcal file that lacks a table or a column of its schema version (dropped by hand,
// a version reset) would fail half-way through a run, after writing to it: refused
// up front instead. (Columns added by hand are left alone.)
void require_tables(Connection& c, const std::string& path, int version, int tables) {
  if (version == 0) {
    if (tables > 0)
      throw DbError(path + " is a damaged demcal database: schema version 0, yet it holds tables (left untouched)", true);
    return;
  }
  const std::string where = " (schema version " + std::to_string(version) + "; left untouched)";
  Statement q = c.prepare("SELECT count(*) FROM sqlite_master WHERE type = 'table' AND name = ?");
  Statement cols = c.prepare("SELECT count(*) FROM pragma_table_info(?) WHERE name = ?");
  for (const auto& t : schema_tables(version)) {
    q.reset();
    q.bind(1, t.table);
    if (!q.step() || q.int64(0) == 0)
      throw DbError(path + " is a damaged demcal database: table " + t.table + " is missing" + where, true);
    for (const std::string& column : t.columns) {
      cols.reset();
      cols.bind(1, t.table).bind(2, column);
      if (!cols.step() || cols.int64(0) == 0)
        throw DbError(path + " is a damaged demcal database: table " + t.table + " has no column " + column + where,
                      true);
    }
  }
}

}  // namespace

void check_file(const std::string& path) {
  if (const std::string why = sqlite_name_refusal(path); !why.empty()) throw DbError("database " + why, true);
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec))
    throw DbError(path + " is a folder, not a database file (give a file in it, e.g. " +
                  (std::filesystem::path(path) / "demcal.db").string() + ")", true);
  // /dev/null reads as empty, and SQLite cannot keep a database in a device or pipe.
  if (std::filesystem::exists(path, ec) && !std::filesystem::is_regular_file(path, ec))
    throw DbError(path + " is not a regular file (a device, pipe or socket): give a database file", true);
  if (file_is_empty_or_missing(path)) return;
  check_header(path);
  Connection c(path, /*read_only=*/true);
  // One read transaction, so that every read below sees the same snapshot: a runner
  // creating this file commits its tables, version and application id together, and
  // reading them one statement at a time could see the tables without the id (a
  // "foreign" database) while the two runners of Runner.TwoRunnersOfOneJob* raced.
  c.exec("BEGIN");
  try {
    Statement qc = c.prepare("PRAGMA quick_check");
    if (!qc.step() || qc.text(0) != "ok")
      throw DbError(path + " is corrupt (quick_check: " + qc.text(0) + "); left untouched", true);
  } catch (const DbError& e) {
    if (e.bad_input()) throw;
    throw DbError(path + " cannot be read as a database: " + e.what(), true);
  }
  const int version = pragma_int(c, "PRAGMA user_version");
  const int app = pragma_int(c, "PRAGMA application_id");
  const int tables = pragma_int(c, "SELECT count(*) FROM sqlite_master");
  if (app != kApplicationId && (app != 0 || version != 0 || tables > 0))
    throw DbError(path + " is a SQLite database but not a demcal one (left untouched)", true);
  if (version > kSchemaVersion)
    throw DbError(path + " has schema version " + std::to_string(version) + ", newer than this demcal supports (" +
                      std::to_string(kSchemaVersion) + "); upgrade demcal",
                  true);
  require_tables(c, path, version, tables);
  c.exec("COMMIT");
}

void migrate(Connection& c) {
  int version = pragma_int(c, "PRAGMA user_version");
  while (version < kSchemaVersion) {
    Transaction t(c);
    // Re-read inside the write lock: another runner may have migrated meanwhile.
    version = pragma_int(c, "PRAGMA user_version");
    if (version >= kSchemaVersion) break;
    c.exec(kMigrations[version]);
    ++version;
    c.exec(("PRAGMA user_version = " + std::to_string(version)).c_str());
    c.exec(("PRAGMA application_id = " + std::to_string(kApplicationId)).c_str());
    t.commit();
  }
}

}  // namespace demcal::db
