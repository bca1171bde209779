#pragma once
// What tasks will cost before they run: the grain-steps of the part of each task a
// scene can count beforehand (a collision's run, a triaxial's shear), and the
// core-seconds they take: at the speed the database's done tasks of the scene ran
// at where it holds any, else at the scene's speed on this project's machine.
#include "scene_registry.hpp"

#include "db/store.hpp"

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace demcal::jobs {

// Done tasks' cost against the yardstick: the median over them, weighted by their
// forecast work, of CPU seconds (metric cpu_s, all threads, preparation included)
// over the forecast's core-seconds, and the same of their wall time.
struct MeasuredSpeed {
  int tasks = 0;
  double factor = 1;       // CPU time over the yardstick
  double wall_factor = 0;  // wall time over the yardstick (0: no wall times)
  static constexpr int kMixedThreads = -1;
  int threads = 0;         // the thread count the measured tasks ran with (0: not recorded; kMixedThreads)
  int wanted_threads = 1;  // the thread count asked for
};

struct WorkForecast {
  bool known = false;      // false: the scene cannot count its work beforehand (repose)
  std::string of;          // what is counted ("the shear")
  std::string left_out;    // what is not ("the preparation adds ...")
  double lo = 0, hi = 0;   // grain-steps of the cheapest and dearest task
  double grain_steps = 0;  // all tasks
  double core_seconds = 0;
  std::vector<double> task_core_seconds;  // each task's, in the order given
  bool bounded_scene = false;  // the scene's work is every stage to its limit (measured or not)
  MeasuredSpeed speed;         // what it was forecast at (tasks 0: the project's yardstick)
  std::string scene;

  double factor() const { return speed.tasks > 0 ? speed.factor : 1.0; }
  // A bound, not an estimate: every stage to its limit at the yardstick (measured CPU
  // time already holds how soon such tasks end).
  bool upper_bound() const { return bounded_scene && speed.tasks == 0; }
};

struct DoneTask {
  nlohmann::json params;
  double cpu_s = 0, wall_s = 0;
  int threads = 0;  // 0: not recorded
};
// Tasks run with `threads` threads are measured when there are any (a task on two
// threads spends CPU time waiting for the other, and more on a busy machine), else
// all. Tasks whose parameters this build cannot read are passed over.
MeasuredSpeed measure_speed(const SceneDef& scene, const std::vector<DoneTask>& done, int threads = 1);
// The same over the last 50 done tasks of the scene in a database: the latest tell
// what the machine does now.
MeasuredSpeed measure_speed(db::Store& store, const SceneDef& scene, int threads = 1);

WorkForecast forecast_work(const SceneDef& scene, const std::vector<nlohmann::json>& task_params,
                           const MeasuredSpeed& speed = {});

// "the shear is 2.5e+08 grain-steps a task, 4.4e+09 in all: about 4.6 core-minutes
// (divide by --workers) at ..."; `workers` > 0 gives the wall time on that many instead.
std::string describe(const WorkForecast& w, int workers = 0);

// CPU seconds left: the queued tasks' forecast, plus what each running task's forecast
// (first) has not used in `threads` times its wall time so far (second).
double cpu_seconds_left(const std::vector<double>& queued, const std::vector<std::pair<double, double>>& running,
                        int threads);

// Wall seconds until `workers` finish the queued tasks (wall seconds each, taken in
// order by the first worker free) after the running ones (wall seconds each has left).
double makespan(const std::vector<double>& queued, const std::vector<double>& running_left, int workers);

// What is left of a job in a database: its pending tasks' forecast, and the part of
// each running task's forecast its time since it started has not used.
struct TimeLeft {
  bool known = false;  // false: nothing left, or a scene that cannot count its work
  int pending = 0, running = 0;
  double core_seconds = 0;
  WorkForecast forecast;  // of the pending and running tasks (speed and its source)
};
TimeLeft time_left(db::Store& store, const std::string& job, double now_unix_s);
// "12 task(s) to go: about 14 minutes of one core, about 7.0 minutes at the 2
// running now; at the speed of ..."
std::string describe(const TimeLeft& t);

}  // namespace demcal::jobs
