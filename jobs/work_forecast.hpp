#pragma once
// What tasks will cost before they run: the grain-steps of the part of each task a
// scene can count beforehand (a collision's run, a triaxial's shear), and the
// core-seconds they take at the speeds measured on this project's machine.
#include "scene_registry.hpp"

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace demcal::jobs {

struct WorkForecast {
  bool known = false;      // false: the scene cannot count its work beforehand (repose)
  std::string of;          // what is counted ("the shear")
  double lo = 0, hi = 0;   // grain-steps of the cheapest and dearest task
  double grain_steps = 0;  // all tasks
  double core_seconds = 0;
};

// One core's nanoseconds per grain-step on the triaxial scene at this many grains.
double ns_per_grain_step(double grains);

WorkForecast forecast_work(const SceneDef& scene, const std::vector<nlohmann::json>& task_params);

// "the shear is 2.5e+08 grain-steps a task, 4.4e+09 in all: about 4.6 core-minutes
// (...)"; `workers` > 0 adds the wall time on that many.
std::string describe(const WorkForecast& w, const std::string& scene, int workers = 0);

}  // namespace demcal::jobs
