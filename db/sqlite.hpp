#pragma once
// A thin RAII layer over the SQLite C API. Every value reaches SQL through a bound
// parameter; SQL text is only ever a literal in this layer.
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>

struct sqlite3;
struct sqlite3_stmt;

namespace demcal::db {

// bad_input: the file is not one we may use (not SQLite, not ours, too new,
// corrupt); the CLI maps it to exit code 2. Otherwise a runtime failure (exit 1).
class DbError : public std::runtime_error {
 public:
  DbError(const std::string& what, bool bad_input = false) : std::runtime_error(what), bad_input_(bad_input) {}
  bool bad_input() const { return bad_input_; }

 private:
  bool bad_input_;
};

class Statement;
class Reused;

// Why SQLite would not read `path` as the file of that name (empty when it would):
// "" and ":memory:" are databases in memory (every result lost at exit), and a name
// starting with "file:" is a URI (this SQLite is built to read them), whose file is
// not the one the checks looked at. Connection refuses such names.
std::string sqlite_name_refusal(const std::string& path);

// Throws DbError(bad input) when the database at `path` could not be written or
// created: its folder missing, or write_refusal. Creates nothing.
void check_writable(const std::string& path);

// Why demcal may not write the database at `path` (the file, or its folder, which
// must take SQLite's -wal and -shm files); empty when it may.
std::string write_refusal(const std::string& path);

class Connection {
 public:
  Connection(const std::string& path, bool read_only);
  ~Connection();
  Connection(const Connection&) = delete;
  Connection& operator=(const Connection&) = delete;

  void exec(const char* sql);  // statements without parameters (DDL, PRAGMA, BEGIN)
  Statement prepare(const char* sql);
  // The statement for `sql`, prepared on first use and kept: for reads run once per
  // task (a query over 100,000 tasks spent a third of its time preparing them).
  // One lease per statement at a time.
  Reused reuse(const char* sql);
  std::int64_t last_insert_id() const;
  int changes() const;
  sqlite3* handle() const { return db_; }
  const std::string& path() const { return path_; }

 private:
  bool open_read_only(const std::string& path);
  sqlite3* db_ = nullptr;
  std::string path_;
  std::map<std::string, std::unique_ptr<Statement>> kept_;
};

class Statement {
 public:
  Statement(Connection& c, const char* sql);
  ~Statement();
  Statement(Statement&& o) noexcept : conn_(o.conn_), st_(o.st_) { o.st_ = nullptr; }
  Statement(const Statement&) = delete;
  Statement& operator=(const Statement&) = delete;

  Statement& bind(int i, std::int64_t v);
  Statement& bind(int i, int v) { return bind(i, static_cast<std::int64_t>(v)); }
  Statement& bind(int i, double v);
  Statement& bind(int i, const std::string& v);
  Statement& bind_null(int i);
  Statement& bind(int i, const std::optional<std::string>& v) { return v ? bind(i, *v) : bind_null(i); }

  bool step();  // true while a row is available
  void run() {
    while (step()) {
    }
  }
  void reset();

  std::int64_t int64(int col) const;
  double real(int col) const;  // NULL reads as NaN; text that is not a number throws DbError
  std::string text(int col) const;  // NULL reads as ""
  bool is_null(int col) const;

 private:
  double real_from_text(int col) const;
  Connection* conn_;
  sqlite3_stmt* st_ = nullptr;
};

// A lease on a kept statement: reset when the lease ends, even on an early return,
// so that it holds no read transaction open (a WAL the writers cannot checkpoint)
// and no bindings.
class Reused {
 public:
  explicit Reused(Statement& s);
  ~Reused();
  Reused(const Reused&) = delete;
  Reused& operator=(const Reused&) = delete;
  Statement& operator*() const { return s_; }
  Statement* operator->() const { return &s_; }

 private:
  Statement& s_;
};

// BEGIN ... COMMIT around a series of reads: they all see one snapshot (a runner's
// commit between two of them shows in neither or both), and the WAL's read lock is
// taken once instead of once per statement (a query over 100,000 tasks spent a fifth
// of its time in fcntl). No writes inside.
class ReadSnapshot {
 public:
  explicit ReadSnapshot(Connection& c);
  ~ReadSnapshot();
  ReadSnapshot(const ReadSnapshot&) = delete;
  ReadSnapshot& operator=(const ReadSnapshot&) = delete;

 private:
  Connection& c_;
};

// BEGIN IMMEDIATE ... COMMIT; rolls back when left by an exception. IMMEDIATE takes
// the write lock up front, so two runners never deadlock upgrading a read lock.
class Transaction {
 public:
  explicit Transaction(Connection& c);
  ~Transaction();
  void commit();

 private:
  Connection& c_;
  bool done_ = false;
};

}  // namespace demcal::db
