#include "sqlite.hpp"

#include <sqlite3.h>

#include <strings.h>
#include <unistd.h>

#include <cctype>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <vector>

namespace demcal::db {
namespace {
[[noreturn]] void fail(sqlite3* db, const std::string& what, int rc) {
  const bool bad = rc == SQLITE_NOTADB || rc == SQLITE_CORRUPT;
  throw DbError(what + ": " + (db ? sqlite3_errmsg(db) : sqlite3_errstr(rc)), bad);
}

// A file: URI for `path` (absolute; '%', '?' and '#' escaped) with a query string.
std::string uri_of(const std::string& path, const char* query) {
  std::string u = "file:";
  for (char c : std::filesystem::absolute(path).string()) {
    if (c == '%') u += "%25";
    else if (c == '?') u += "%3f";
    else if (c == '#') u += "%23";
    else u += c;
  }
  return u + "?" + query;
}
}  // namespace

std::string sqlite_name_refusal(const std::string& path) {
  if (path.empty()) return "empty database path";
  if (path == ":memory:") return "\":memory:\" is a database in memory: every result would be lost; give a file";
  if (path.size() >= 5 && ::strncasecmp(path.c_str(), "file:", 5) == 0)
    return "\"" + path + "\" would be read by SQLite as a URI, not as a file name (write ./" + path +
           " for a file of that name)";
  return "";
}

// Why demcal may not write `path` (empty when it may): the file, or the folder that
// must take SQLite's -wal and -shm files beside it.
std::string write_refusal(const std::string& path) {
  const auto dir = std::filesystem::absolute(path).parent_path();
  if (std::filesystem::exists(path) && ::access(path.c_str(), W_OK) != 0) return "the file is read-only";
  if (std::filesystem::is_directory(dir) && ::access(dir.c_str(), W_OK) != 0)
    return "its folder " + dir.string() + " is not writable (SQLite keeps its journal beside the file)";
  return "";
}

void check_writable(const std::string& path) {
  const auto dir = std::filesystem::absolute(path).parent_path();
  if (!std::filesystem::is_directory(dir))
    throw DbError("cannot open database " + path + ": directory " + dir.string() + " does not exist", true);
  if (const std::string why = write_refusal(path); !why.empty())
    throw DbError("cannot write database " + path + ": " + why, true);
}

Connection::Connection(const std::string& path, bool read_only) : path_(path) {
  if (const std::string why = sqlite_name_refusal(path); !why.empty()) throw DbError("database " + why, true);
  bool open = false;
  if (read_only) {
    // Readers open the file read-write (never creating it) with writes refused
    // (query_only): a connection opened SQLITE_OPEN_READONLY leaves the WAL's -wal and
    // -shm files behind when it closes, since it may not checkpoint and remove them.
    // SQLite opens a file it may not write read-only without a word: that case, and
    // a folder that cannot take the -shm file, take the read-only paths below.
    open = write_refusal(path).empty() &&
           sqlite3_open_v2(path.c_str(), &db_, SQLITE_OPEN_READWRITE | SQLITE_OPEN_NOMUTEX, nullptr) == SQLITE_OK &&
           sqlite3_exec(db_, "PRAGMA query_only = ON", nullptr, nullptr, nullptr) == SQLITE_OK;
    if (!open) {
      sqlite3_close(db_);
      db_ = nullptr;
    }
    if (!open && std::filesystem::is_regular_file(path)) open = open_read_only(path);
  } else {
    check_writable(path);
  }
  if (!open) {
    const int flags = read_only ? SQLITE_OPEN_READONLY : (SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE);
    const int rc = sqlite3_open_v2(path.c_str(), &db_, flags | SQLITE_OPEN_NOMUTEX, nullptr);
    if (rc != SQLITE_OK) {
      std::string msg = db_ ? sqlite3_errmsg(db_) : sqlite3_errstr(rc);
      sqlite3_close(db_);
      db_ = nullptr;
      const auto dir = std::filesystem::absolute(path).parent_path();
      if (rc == SQLITE_CANTOPEN && !std::filesystem::is_directory(dir))
        msg = "directory " + dir.string() + " does not exist";
      // The path is the user's input: a file SQLite cannot open is bad input (exit 2).
      throw DbError("cannot open database " + path + ": " + msg,
                    rc == SQLITE_NOTADB || rc == SQLITE_CORRUPT || rc == SQLITE_CANTOPEN);
    }
  }
  // Two runners share one file: wait for the other's write lock instead of failing.
  sqlite3_busy_timeout(db_, 30000);
  sqlite3_extended_result_codes(db_, 0);
}

// A database demcal may read but not write. A WAL database needs its -shm file, which
// SQLite creates beside it: where the folder refuses that, the file is read as
// immutable (no locks, no WAL: what the last checkpoint left). That is everything
// only when no -wal file holds newer pages (its writer closed cleanly), so immutable
// is tried only then: a -wal with content (a writer alive, or killed before its
// checkpoint) would be ignored without a word. Returns false when nothing works
// (the caller reports SQLite's error).
bool Connection::open_read_only(const std::string& path) {
  std::error_code ec;
  const std::string wal = path + "-wal";
  const bool wal_empty = !std::filesystem::exists(wal, ec) || std::filesystem::file_size(wal, ec) == 0;
  // No -wal and no -shm: no connection has the database open in WAL mode, so the file
  // is the whole database and is read as immutable, which creates nothing. mode=ro
  // would make a -shm and -wal beside it with the file's read-only permissions,
  // left behind at close, and the owner's next write would fail on them.
  const bool no_log = !std::filesystem::exists(wal, ec) && !std::filesystem::exists(path + "-shm", ec);
  const std::vector<const char*> order =
      no_log ? std::vector<const char*>{"immutable=1", "mode=ro"} : std::vector<const char*>{"mode=ro", "immutable=1"};
  for (const char* query : order) {
    if (std::string(query) == "immutable=1" && !wal_empty)
      throw DbError("cannot read database " + path + ": its write-ahead log " + wal +
                        " holds changes not yet in the file, and reading them needs SQLite's -shm file beside it, "
                        "which cannot be made or opened here (open the database once where it may be written, or "
                        "copy it together with its -wal and -shm files)",
                    true);
    const int flags = SQLITE_OPEN_READONLY | SQLITE_OPEN_URI | SQLITE_OPEN_NOMUTEX;
    if (sqlite3_open_v2(uri_of(path, query).c_str(), &db_, flags, nullptr) == SQLITE_OK &&
        sqlite3_exec(db_, "SELECT count(*) FROM sqlite_master", nullptr, nullptr, nullptr) == SQLITE_OK)
      return true;
    sqlite3_close(db_);
    db_ = nullptr;
  }
  return false;
}

Connection::~Connection() {
  kept_.clear();  // finalized before the close, which would otherwise fail as busy
  sqlite3_close(db_);
}

void Connection::exec(const char* sql) {
  char* err = nullptr;
  const int rc = sqlite3_exec(db_, sql, nullptr, nullptr, &err);
  if (rc != SQLITE_OK) {
    std::string msg = err ? err : sqlite3_errstr(rc);
    sqlite3_free(err);
    throw DbError(path_ + ": " + msg, rc == SQLITE_NOTADB || rc == SQLITE_CORRUPT);
  }
}

Statement Connection::prepare(const char* sql) { return Statement(*this, sql); }

Reused Connection::reuse(const char* sql) {
  auto& kept = kept_[sql];
  if (!kept) kept = std::make_unique<Statement>(*this, sql);
  return Reused(*kept);
}

Reused::Reused(Statement& s) : s_(s) {}
Reused::~Reused() { s_.reset(); }
std::int64_t Connection::last_insert_id() const { return sqlite3_last_insert_rowid(db_); }
int Connection::changes() const { return sqlite3_changes(db_); }

Statement::Statement(Connection& c, const char* sql) : conn_(&c) {
  const int rc = sqlite3_prepare_v2(c.handle(), sql, -1, &st_, nullptr);
  if (rc != SQLITE_OK) fail(c.handle(), c.path(), rc);
}

Statement::~Statement() { sqlite3_finalize(st_); }

Statement& Statement::bind(int i, std::int64_t v) {
  sqlite3_bind_int64(st_, i, v);
  return *this;
}
Statement& Statement::bind(int i, double v) {
  sqlite3_bind_double(st_, i, v);
  return *this;
}
Statement& Statement::bind(int i, const std::string& v) {
  sqlite3_bind_text(st_, i, v.data(), static_cast<int>(v.size()), SQLITE_TRANSIENT);
  return *this;
}
Statement& Statement::bind_null(int i) {
  sqlite3_bind_null(st_, i);
  return *this;
}

bool Statement::step() {
  const int rc = sqlite3_step(st_);
  if (rc == SQLITE_ROW) return true;
  if (rc == SQLITE_DONE) return false;
  fail(conn_->handle(), conn_->path(), rc);
}

void Statement::reset() {
  sqlite3_reset(st_);
  sqlite3_clear_bindings(st_);
}

std::int64_t Statement::int64(int col) const { return sqlite3_column_int64(st_, col); }
double Statement::real(int col) const {
  switch (sqlite3_column_type(st_, col)) {
    case SQLITE_NULL:
      return NAN;
    case SQLITE_TEXT:
    case SQLITE_BLOB:
      return real_from_text(col);
    default:
      return sqlite3_column_double(st_, col);
  }
}

// SQLite keeps text that does not read as a number (a value written by hand: "nan",
// "1,5", "-") as text in a REAL column, and sqlite3_column_double reads such text as 0:
// a metric would be silently zero. Text that reads whole as a number (strtod: "nan" and
// "inf" too) is that number; anything else names the column and the text.
double Statement::real_from_text(int col) const {
  const std::string t = text(col);
  const char* begin = t.c_str();
  char* end = nullptr;
  const double v = std::strtod(begin, &end);
  const bool parsed = end != nullptr && end != begin;  // blank text converts nothing, and reads 0
  while (parsed && *end != '\0' && std::isspace(static_cast<unsigned char>(*end))) ++end;
  if (parsed && *end == '\0' && t.size() == std::strlen(begin)) return v;
  const char* name = sqlite3_column_name(st_, col);
  std::string shown;  // control bytes (a NUL would cut the message) written as \xNN
  for (std::size_t i = 0; i < t.size() && i < 40; ++i) {
    const auto c = static_cast<unsigned char>(t[i]);
    if (c < 0x20 || c == 0x7f) {
      char hex[8];
      std::snprintf(hex, sizeof hex, "\\x%02x", c);
      shown += hex;
    } else {
      shown += t[i];
    }
  }
  if (t.size() > 40) shown += "...";
  throw DbError(conn_->path() + ": column " + (name ? name : "?") + " holds the text \"" + shown +
                    "\" where a number belongs (a damaged or hand-edited database)",
                true);
}
std::string Statement::text(int col) const {
  const auto* p = sqlite3_column_text(st_, col);
  return p ? std::string(reinterpret_cast<const char*>(p), static_cast<std::size_t>(sqlite3_column_bytes(st_, col)))
           : std::string();
}
bool Statement::is_null(int col) const { return sqlite3_column_type(st_, col) == SQLITE_NULL; }

ReadSnapshot::ReadSnapshot(Connection& c) : c_(c) { c_.exec("BEGIN DEFERRED"); }
ReadSnapshot::~ReadSnapshot() { sqlite3_exec(c_.handle(), "COMMIT", nullptr, nullptr, nullptr); }

Transaction::Transaction(Connection& c) : c_(c) { c_.exec("BEGIN IMMEDIATE"); }
Transaction::~Transaction() {
  if (!done_) sqlite3_exec(c_.handle(), "ROLLBACK", nullptr, nullptr, nullptr);
}
void Transaction::commit() {
  c_.exec("COMMIT");
  done_ = true;
}

}  // namespace demcal::db
