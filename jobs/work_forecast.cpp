#include "work_forecast.hpp"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <sstream>

namespace demcal::jobs {

// Whole triaxial runs on one thread of the 2-core machine docs/performance.md
// describes (2026-11-27, physics version 3; wall time over steps and grains): 62 ns
// per grain-step at 500 grains, 73 at 2,000, 99 at 10,000 (larger samples leave the
// caches). A yardstick, not a promise for another machine.
double ns_per_grain_step(double grains) {
  const double x[] = {std::log10(500.0), std::log10(2000.0), std::log10(10000.0)}, y[] = {62.0, 73.0, 99.0};
  const double g = std::clamp(std::log10(std::max(grains, 1.0)), x[0], x[2]);
  const int k = g <= x[1] ? 0 : 1;
  return y[k] + (y[k + 1] - y[k]) * (g - x[k]) / (x[k + 1] - x[k]);
}

WorkForecast forecast_work(const SceneDef& scene, const std::vector<nlohmann::json>& task_params) {
  WorkForecast f;
  if (!scene.work || task_params.empty()) return f;
  f.known = true;
  f.of = scene.work_of;
  f.lo = INFINITY;
  for (const auto& p : task_params) {
    const Work w = scene.work(p);
    const double gs = w.steps * w.grains;
    f.lo = std::min(f.lo, gs), f.hi = std::max(f.hi, gs), f.grain_steps += gs;
    f.core_seconds += gs * ns_per_grain_step(w.grains) * 1e-9;
  }
  return f;
}

namespace {
std::string sig2(double v) {
  std::ostringstream os;
  os << std::setprecision(2) << v;
  return os.str();
}
std::string minutes(double seconds) {
  return seconds < 60.0 ? "1 minute or less" : sig2(seconds / 60.0) + " minutes";
}
}  // namespace

std::string describe(const WorkForecast& w, const std::string& scene, int workers) {
  std::string s = w.of + " is " + sig2(w.lo) + (w.hi > w.lo * 1.005 ? " to " + sig2(w.hi) : std::string()) +
                  " grain-steps a task, " + sig2(w.grain_steps) + " in all: about " +
                  (w.core_seconds < 60.0 ? std::string("1 core-minute or less")
                                         : sig2(w.core_seconds / 60.0) + " core-minutes");
  if (workers > 1) s += " (" + minutes(w.core_seconds / workers) + " on " + std::to_string(workers) + " workers)";
  s += " at the speed docs/performance.md measures for one core of this project's machine";
  if (scene == "triaxial") s += "; the preparation adds 5-15%";
  return s;
}

}  // namespace demcal::jobs
