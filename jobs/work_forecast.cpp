#include "work_forecast.hpp"

#include "liveness.hpp"

#include <algorithm>
#include <map>
#include <cmath>
#include <iomanip>
#include <queue>
#include <set>
#include <sstream>

namespace demcal::jobs {

namespace {
double yardstick_seconds(const Work& w) { return w.steps * w.grains * w.ns_per_grain_step * 1e-9; }

// The median of (value, weight) pairs weighted by weight: a task slowed by a busy
// machine moves it little, and small tasks, whose set-up the forecast does not count,
// weigh as little as they cost.
double weighted_median(std::vector<std::pair<double, double>> value_weight) {
  std::sort(value_weight.begin(), value_weight.end());
  double total = 0, below = 0;
  for (const auto& vw : value_weight) total += vw.second;
  for (const auto& [value, weight] : value_weight)
    if ((below += weight) >= 0.5 * total) return value;
  return value_weight.back().first;
}
}  // namespace

MeasuredSpeed measure_speed(const SceneDef& scene, const std::vector<DoneTask>& done, int threads) {
  MeasuredSpeed m;
  m.wanted_threads = threads;
  if (!scene.work) return m;
  struct Usable {
    double cpu, wall, yardstick;  // CPU and wall time over the yardstick; the yardstick
    int threads;
  };
  std::vector<Usable> usable;
  for (const DoneTask& d : done) {
    double forecast = NAN;
    try {
      forecast = yardstick_seconds(scene.work(d.params));
    } catch (const std::exception&) {
      continue;  // parameters this build cannot read (an older or damaged row)
    }
    if (!(std::isfinite(d.cpu_s) && d.cpu_s > 0 && std::isfinite(forecast) && forecast > 0)) continue;
    usable.push_back({d.cpu_s / forecast, d.wall_s / forecast, forecast, d.threads});
  }
  const bool any_matched = std::any_of(usable.begin(), usable.end(), [&](const Usable& u) { return u.threads == threads; });
  std::vector<std::pair<double, double>> cpu, wall;  // over the yardstick, the yardstick
  std::set<int> ran_with;
  for (const Usable& u : usable) {
    if (any_matched && u.threads != threads) continue;
    cpu.emplace_back(u.cpu, u.yardstick);
    if (std::isfinite(u.wall) && u.wall > 0) wall.emplace_back(u.wall, u.yardstick);
    ran_with.insert(u.threads);
  }
  if (cpu.empty()) return m;
  m.tasks = static_cast<int>(cpu.size());
  m.factor = weighted_median(cpu);
  // Wall times only when every measured task has one: a mixed set would weigh the rest.
  if (wall.size() == cpu.size()) m.wall_factor = weighted_median(wall);
  m.threads = ran_with.size() == 1 ? *ran_with.begin() : MeasuredSpeed::kMixedThreads;
  return m;
}

MeasuredSpeed measure_speed(db::Store& store, const SceneDef& scene, int threads) {
  if (!scene.work) return {};
  constexpr int kLatest = 50;
  std::vector<DoneTask> done;
  for (const auto& c : store.latest_done_costs(scene.name, kLatest)) {
    try {
      done.push_back(DoneTask{nlohmann::json::parse(c.params_json), c.cpu_s, c.wall_s, c.threads});
    } catch (const std::exception&) {
    }
  }
  return measure_speed(scene, done, threads);
}

WorkForecast forecast_work(const SceneDef& scene, const std::vector<nlohmann::json>& task_params,
                           const MeasuredSpeed& speed) {
  WorkForecast f;
  if (!scene.work || task_params.empty()) return f;
  f.known = true;
  f.scene = scene.name;
  f.of = scene.work_of;
  f.speed = speed;
  // Measured CPU time holds the preparation as the done tasks had it.
  if (speed.tasks == 0) f.left_out = scene.work_left_out;
  f.lo = INFINITY;
  for (const auto& p : task_params) {
    const Work w = scene.work(p);
    f.bounded_scene = f.bounded_scene || w.upper_bound;
    const double gs = w.steps * w.grains;
    f.lo = std::min(f.lo, gs), f.hi = std::max(f.hi, gs), f.grain_steps += gs;
    f.task_core_seconds.push_back(yardstick_seconds(w) * f.factor());
    f.core_seconds += f.task_core_seconds.back();
  }
  return f;
}

namespace {
std::string sig2(double v) {
  std::ostringstream os;
  os << std::setprecision(2) << v;
  return os.str();
}
constexpr double kYear = 365.25 * 86400.0;
// 0.5 minutes, 12 minutes, 3.4 hours, 7.3 days, 12 years: fixed point; an exponent
// only past a million years (an absurd but valid setting, whose fixed point had
// hundreds of digits).
std::string duration(double seconds) {
  std::ostringstream os;
  const double minutes = seconds / 60.0, hours = minutes / 60.0, years = seconds / kYear;
  if (minutes < 10.0) os << std::fixed << std::setprecision(1) << minutes << " minutes";
  else if (minutes < 120.0) os << std::fixed << std::setprecision(0) << minutes << " minutes";
  else if (hours < 48.0) os << std::fixed << std::setprecision(hours < 10.0 ? 1 : 0) << hours << " hours";
  else if (years < 2.0) os << std::fixed << std::setprecision(hours < 240.0 ? 1 : 0) << hours / 24.0 << " days";
  else if (years < 1e6) os << std::fixed << std::setprecision(0) << years << " years";
  else os << std::setprecision(2) << years << " years";
  return os.str();
}
std::string approx(double seconds, bool upper_bound = false) {
  if (upper_bound) return seconds < 60.0 ? "at most a minute" : "at most " + duration(seconds);
  return seconds < 60.0 ? "under a minute" : "about " + duration(seconds);
}
std::string speed_source(const WorkForecast& w) {
  const MeasuredSpeed& m = w.speed;
  if (m.tasks == 0) return "the speed docs/performance.md measures on this project's machine";
  std::ostringstream os;
  os << std::fixed << std::setprecision(2) << m.factor;
  std::string ran;  // nothing for tasks from before the thread count was stored (0)
  if (m.threads == MeasuredSpeed::kMixedThreads)
    ran = ", run with differing thread counts";
  else if (m.threads > 0 && m.threads != m.wanted_threads)
    ran = ", run with " + std::to_string(m.threads) + " thread(s)";
  return "the speed of the last " + std::to_string(m.tasks) + " done " + w.scene + " task(s) in this database" +
         ran + " (their CPU time, preparation included: " + os.str() + "x the yardstick of docs/performance.md)";
}
}  // namespace

std::string describe(const WorkForecast& w, int workers) {
  std::string s = w.of + " is " + sig2(w.lo) + (w.hi > w.lo * 1.005 ? " to " + sig2(w.hi) : std::string()) +
                  " grain-steps a task, " + sig2(w.grain_steps) + " in all: " + approx(w.core_seconds, w.upper_bound()) +
                  " of one core (" +
                  (workers > 0 ? approx(makespan(w.task_core_seconds, {}, workers), w.upper_bound()) + " on " +
                                     std::to_string(workers) + " worker(s)"
                               : std::string("divide by --workers")) +
                  ") at " + speed_source(w);
  if (!w.left_out.empty()) s += "; " + w.left_out;
  const double longest = w.task_core_seconds.empty()
                              ? 0.0
                              : *std::max_element(w.task_core_seconds.begin(), w.task_core_seconds.end());
  if (longest > kYear)
    s += "; a task would run for " + approx(longest, w.upper_bound()) +
         " of one core: check the settings that set its steps (strain rate, time step, particle count, duration)";
  return s;
}

double cpu_seconds_left(const std::vector<double>& queued, const std::vector<std::pair<double, double>>& running,
                        int threads) {
  double left = 0;
  for (const double c : queued) left += c;
  for (const auto& [c, wall] : running) left += std::max(0.0, c - std::max(0.0, wall) * threads);
  return left;
}

double makespan(const std::vector<double>& queued, const std::vector<double>& running_left, int workers) {
  std::priority_queue<double, std::vector<double>, std::greater<>> free_at(running_left.begin(), running_left.end());
  for (int k = static_cast<int>(running_left.size()); k < workers; ++k) free_at.push(0.0);
  double end = 0;
  for (const double t : queued) {
    const double start = free_at.top();
    free_at.pop();
    free_at.push(start + t);
  }
  while (!free_at.empty()) {
    end = std::max(end, free_at.top());
    free_at.pop();
  }
  return end;
}

TimeLeft time_left(db::Store& store, const std::string& job, double now_unix_s) {
  TimeLeft t;
  std::vector<db::TaskRow> rows;
  for (auto& r : store.tasks(job))
    if (r.status == "pending" || r.status == "running") rows.push_back(std::move(r));
  if (rows.empty()) return t;
  const SceneDef* scene = find_scene(rows.front().scene);
  if (!scene || !scene->work) return t;
  const MeasuredSpeed speed = measure_speed(store, *scene);
  const double cpu_per_wall = speed.wall_factor > 0 ? std::min(1.0, speed.factor / speed.wall_factor) : 1.0;
  try {
    std::vector<nlohmann::json> all;
    for (const auto& r : rows) all.push_back(nlohmann::json::parse(r.params_json));
    t.forecast = forecast_work(*scene, all, speed);
  } catch (const std::exception&) {
    return TimeLeft{};  // a stored task this build cannot read: no estimate rather than a wrong one
  }
  std::vector<double> pending;
  std::vector<std::pair<double, double>> running;
  std::map<std::string, bool> alive;  // per holder token: judged once
  for (std::size_t k = 0; k < rows.size(); ++k) {
    const double c = t.forecast.task_core_seconds[k];
    // A task whose runner is gone (killed with -9, its host silent) is not being
    // worked on: it is counted whole, as the pending task the next run makes it.
    if (rows[k].status == "running") {
      const auto [it, first] = alive.try_emplace(rows[k].worker, false);
      if (first) it->second = holder_alive(store, rows[k].worker);
      if (!it->second) rows[k].status = "pending";
    }
    // A running task has used its wall time so far, at the CPU-to-wall ratio of the
    // done tasks (a busy machine gives a task less than its wall time); one thread's
    // worth, a guess for a task that runs several (the database does not say how many).
    if (rows[k].status == "running")
      running.emplace_back(c, (std::isfinite(rows[k].started_at) ? now_unix_s - rows[k].started_at : 0.0) * cpu_per_wall);
    else
      pending.push_back(c);
  }
  t.pending = static_cast<int>(pending.size());
  t.running = static_cast<int>(running.size());
  t.core_seconds = cpu_seconds_left(pending, running, 1);
  t.known = true;
  return t;
}

std::string describe(const TimeLeft& t) {
  const bool bound = t.forecast.upper_bound();
  std::string s = std::to_string(t.pending + t.running) + " task(s) to go: ";
  if (t.pending == 0 && t.core_seconds == 0)
    s += t.running == 1 ? "the running one has taken longer than forecast" : "the running ones have taken longer than forecast";
  else
    s += approx(t.core_seconds, bound) + " of one core";
  if (t.running > 0 && t.core_seconds > 0)
    s += ", " + approx(t.core_seconds / t.running, bound) + " at the " + std::to_string(t.running) + " running now";
  s += "; at " + speed_source(t.forecast);
  if (!t.forecast.left_out.empty()) s += "; " + t.forecast.left_out;
  return s;
}

}  // namespace demcal::jobs
