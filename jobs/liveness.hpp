#pragma once
// Who holds a running task: a runner token "host:pid:start-ticks". The process
// start time (from /proc) guards against a recycled pid making a dead runner look
// alive; a zombie counts as dead.
#include <chrono>
#include <cstdint>
#include <iosfwd>
#include <optional>
#include <string>
#include <unordered_map>

namespace demcal::db {
class Store;
}

namespace demcal::jobs {

// Runners beat every kRunnerBeatS into the database; one on another host that has
// been silent for kRunnerLeaseS is taken for dead and its running tasks re-queued.
constexpr double kRunnerBeatS = 10.0;
constexpr double kRunnerLeaseS = 120.0;
// A watcher holds a beat that looks stale for this long (three beats) before it
// believes it: a runner whose clock runs behind this host's writes beats that look
// old but keep changing.
constexpr double kRunnerConfirmS = 3 * kRunnerBeatS;

// What a long-lived runner has watched of other hosts' heartbeats, on its own clock.
// The beats' stamps are the other host's clock; whether they still change is not.
class BeatWatch {
 public:
  // `last_seen`: the stored beat (nullopt: never beat); `unix_now`: this host's clock;
  // `watch_s`: this process's steady clock. Dead when the beat has not changed for
  // kRunnerLeaseS of watching (whatever its stamp says: a clock ahead of ours), or
  // when its stamp is older than the lease and it has not changed for
  // kRunnerConfirmS of watching. A runner that never beat is assumed alive.
  bool alive(const std::string& token, std::optional<double> last_seen, double unix_now, double watch_s);
  // How far the runner's clock seems behind this host's, from the stamp of a beat
  // seen to arrive (nullopt until one arrives while watched, or when under two beats).
  std::optional<double> clock_behind(const std::string& token) const;

 private:
  struct Seen {
    double stamp = 0, since = 0;  // the beat's stamp; when this process first saw it
    std::optional<double> behind;  // unix_now - stamp when a new beat was seen arriving
  };
  std::unordered_map<std::string, Seen> seen_;
};

std::string runner_token();  // this process
bool process_alive_here(long pid);  // a process of this host's pid namespace, not a zombie
// This hostname and pid namespace as part of a file name ("vm-pidns4026531836"): the
// processes whose pids process_alive_here can judge.
std::string process_host_tag();
std::string hostname();      // this machine's name, for tokens, part files and lock files
// Alive as far as this process can tell: a runner on this host by its process (gone,
// a zombie, or a recycled pid: dead); one on another host by its heartbeat in `store`
// (silent for kRunnerLeaseS: dead; a runner that never beat, from a demcal before
// heartbeats: assumed alive), judged by `watch` when the caller keeps one (a runner
// that polls), else by the beat's stamp against this host's clock. A string that is
// no token of ours: dead.
bool holder_alive(db::Store& store, const std::string& token, BeatWatch* watch = nullptr);
// Running tasks of runners holder_alive finds dead go back to pending; returns how many.
int requeue_dead_runners(db::Store& store, BeatWatch* watch = nullptr);
// --requeue-running: the job's running tasks back to pending, whatever their holder's
// heartbeat says (the user knows a runner elsewhere is gone), except those of a runner
// alive on this host, which would go on running them: those are named in `log`.
int requeue_running_tasks(db::Store& store, std::int64_t job_id, std::ostream& log);
// "node01:30457:... (another host, last seen 42 s ago)": for a run waiting on a holder.
std::string describe_holder(db::Store& store, const std::string& token, const BeatWatch* watch = nullptr);

// A runner's heartbeat: beats when made, then on tick() once kRunnerBeatS has passed.
class Heartbeat {
 public:
  Heartbeat(db::Store& store, std::string token);
  void tick();

 private:
  db::Store& store_;
  std::string token_;
  std::chrono::steady_clock::time_point last_;
};

}  // namespace demcal::jobs
