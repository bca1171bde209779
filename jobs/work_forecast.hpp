#pragma once
// What tasks will cost before they run: the grain-steps of the part of each task a
// scene can count beforehand (a collision's run, a triaxial's shear), and the
// core-seconds they take at the scene's speed measured on this project's machine.
#include "scene_registry.hpp"

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace demcal::jobs {

struct WorkForecast {
  bool known = false;      // false: the scene cannot count its work beforehand (repose)
  std::string of;          // what is counted ("the shear")
  std::string left_out;    // what is not ("the preparation adds ...")
  double lo = 0, hi = 0;   // grain-steps of the cheapest and dearest task
  double grain_steps = 0;  // all tasks
  double core_seconds = 0;
};

WorkForecast forecast_work(const SceneDef& scene, const std::vector<nlohmann::json>& task_params);

// "the shear is 2.5e+08 grain-steps a task, 4.4e+09 in all: about 4.6 core-minutes
// (divide by --workers) at ..."; `workers` > 0 gives the wall time on that many instead.
std::string describe(const WorkForecast& w, int workers = 0);

}  // namespace demcal::jobs
