#pragma once
// The content key of a task: equal keys mean identical work, so a finished task is
// reused by a re-run or by any overlapping job.
#include <nlohmann/json.hpp>
#include <string>

namespace demcal::jobs {

// Hash of the scene, the canonical dump of the resolved parameters (keys sorted,
// reals as doubles) and kPhysicsVersion; 32 hex digits.
std::string task_key(const std::string& scene, const nlohmann::json& params);

}  // namespace demcal::jobs
