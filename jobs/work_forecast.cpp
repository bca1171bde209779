#include "work_forecast.hpp"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <sstream>

namespace demcal::jobs {

WorkForecast forecast_work(const SceneDef& scene, const std::vector<nlohmann::json>& task_params) {
  WorkForecast f;
  if (!scene.work || task_params.empty()) return f;
  f.known = true;
  f.of = scene.work_of;
  f.left_out = scene.work_left_out;
  f.lo = INFINITY;
  for (const auto& p : task_params) {
    const Work w = scene.work(p);
    const double gs = w.steps * w.grains;
    f.lo = std::min(f.lo, gs), f.hi = std::max(f.hi, gs), f.grain_steps += gs;
    f.core_seconds += gs * w.ns_per_grain_step * 1e-9;
  }
  return f;
}

namespace {
std::string sig2(double v) {
  std::ostringstream os;
  os << std::setprecision(2) << v;
  return os.str();
}
// 0.5 minutes, 12 minutes, 3.4 hours: fixed point, never an exponent.
std::string duration(double seconds) {
  std::ostringstream os;
  const double minutes = seconds / 60.0, hours = minutes / 60.0;
  if (minutes < 10.0) os << std::fixed << std::setprecision(1) << minutes << " minutes";
  else if (minutes < 120.0) os << std::fixed << std::setprecision(0) << minutes << " minutes";
  else os << std::fixed << std::setprecision(hours < 10.0 ? 1 : 0) << hours << " hours";
  return os.str();
}
std::string approx(double seconds) { return seconds < 60.0 ? "under a minute" : "about " + duration(seconds); }
}  // namespace

std::string describe(const WorkForecast& w, int workers) {
  std::string s = w.of + " is " + sig2(w.lo) + (w.hi > w.lo * 1.005 ? " to " + sig2(w.hi) : std::string()) +
                  " grain-steps a task, " + sig2(w.grain_steps) + " in all: " + approx(w.core_seconds) +
                  " of one core (" +
                  (workers > 0 ? approx(w.core_seconds / workers) + " on " + std::to_string(workers) + " worker(s)"
                               : std::string("divide by --workers")) +
                  ") at the speed docs/performance.md measures on this project's machine";
  if (!w.left_out.empty()) s += "; " + w.left_out;
  return s;
}

}  // namespace demcal::jobs
