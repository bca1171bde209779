#pragma once
// Helpers for running the demcal binary from tests.
#include "db/store.hpp"
#include "../temp_dir.hpp"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <chrono>
#include <fcntl.h>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <sys/wait.h>
#include <thread>
#include <unistd.h>
#include <vector>

namespace demcal::test {

namespace fs = std::filesystem;


inline std::string slurp(const std::string& p) {
  std::ifstream f(p, std::ios::binary);
  std::stringstream s;
  s << f.rdbuf();
  return s.str();
}

inline void write(const std::string& p, const std::string& text) { std::ofstream(p, std::ios::trunc) << text; }

// Starts argv[0] (a path, or a name found on PATH) with the rest of argv in dir,
// stdout/stderr to files <tag>.stdout/.stderr there; returns the pid.
inline pid_t spawn_program(const std::vector<std::string>& argv, const std::string& dir,
                           const std::map<std::string, std::string>& env = {}, const std::string& tag = "out") {
  const std::string out = dir + "/" + tag + ".stdout", err = dir + "/" + tag + ".stderr";
  const pid_t pid = fork();
  if (pid == 0) {
    const int o = open(out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    const int e = open(err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    dup2(o, 1);
    dup2(e, 2);
    for (const auto& [k, v] : env) setenv(k.c_str(), v.c_str(), 1);
    if (chdir(dir.c_str()) != 0) _exit(126);
    std::vector<char*> args;
    for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
    args.push_back(nullptr);
    execvp(args[0], args.data());
    _exit(127);
  }
  return pid;
}

// Starts demcal with args (stdout/stderr to files in dir); returns the pid.
inline pid_t spawn(const std::vector<std::string>& args, const std::string& dir,
                   const std::map<std::string, std::string>& env = {}, const std::string& tag = "out") {
  std::vector<std::string> argv{DEMCAL_BIN};
  argv.insert(argv.end(), args.begin(), args.end());
  return spawn_program(argv, dir, env, tag);
}

struct Result {
  int rc = -1;
  std::string out, err;
};

inline Result finish(pid_t pid, const std::string& dir, const std::string& tag = "out") {
  int st = 0;
  waitpid(pid, &st, 0);
  Result r;
  r.rc = WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
  r.out = slurp(dir + "/" + tag + ".stdout");
  r.err = slurp(dir + "/" + tag + ".stderr");
  return r;
}

inline Result run_demcal(const std::vector<std::string>& args, const std::string& dir,
                     const std::map<std::string, std::string>& env = {}) {
  return finish(spawn(args, dir, env), dir);
}

// A small collision job: `n` tasks over dt_factor; `particles` x `steps` sets the cost.
inline std::string collision_job(const std::string& name, const std::vector<double>& factors, int particles = 30,
                                 int steps = 400) {
  nlohmann::json j = {{"name", name},
                      {"scene", "collision"},
                      {"material", {{"kn", 3e7}, {"diameter", {{"min", 0.001}, {"max", 0.002}}}}},
                      {"collision", {{"particles", particles}, {"steps", steps}, {"sample_every", 20}}},
                      {"grid", {{"dt_factor", factors}}},
                      {"seed", 1},
                      {"threads", 1}};  // tests share the machine: no engine threads
  return j.dump(2);
}

inline std::vector<db::TaskRow> tasks_of(const std::string& db, const std::string& job = "") {
  db::Store s(db, true);
  return s.tasks(job);
}

inline int count_status(const std::vector<db::TaskRow>& rows, const std::string& status) {
  int n = 0;
  for (const auto& r : rows) n += r.status == status;
  return n;
}

// Waits (up to 60 s) until a task of `job` in `db` is running; false if none was seen.
inline bool task_seen_running(const std::string& db, const std::string& job) {
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(60);
  while (std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    try {
      if (fs::exists(db) && count_status(tasks_of(db, job), "running") >= 1) return true;
    } catch (const std::exception&) {
      // the runner has made the file but not yet its tables
    }
  }
  return false;
}

}  // namespace demcal::test
