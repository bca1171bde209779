#pragma once
// Who holds a running task: a runner token "host:pid:start-ticks". The process
// start time (from /proc) guards against a recycled pid making a dead runner look
// alive; a zombie counts as dead.
#include <chrono>
#include <string>

namespace demcal::db {
class Store;
}

namespace demcal::jobs {

// Runners beat every kRunnerBeatS into the database; one on another host that has
// been silent for kRunnerLeaseS is taken for dead and its running tasks re-queued.
constexpr double kRunnerBeatS = 10.0;
constexpr double kRunnerLeaseS = 120.0;

std::string runner_token();  // this process
// Alive as far as this process can tell: a runner on this host by its process (gone,
// a zombie, or a recycled pid: dead); one on another host by its heartbeat in `store`
// (silent for kRunnerLeaseS: dead; a runner that never beat, from a demcal before
// heartbeats: assumed alive). A string that is no token of ours: dead.
bool holder_alive(db::Store& store, const std::string& token);
// Running tasks of runners holder_alive finds dead go back to pending; returns how many.
int requeue_dead_runners(db::Store& store);
// "node01:30457:... (another host, last seen 42 s ago)": for a run waiting on a holder.
std::string describe_holder(db::Store& store, const std::string& token);

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
