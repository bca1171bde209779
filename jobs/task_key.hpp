#pragma once
// The content key of a task: equal keys mean identical work, so a finished task is
// reused by a re-run or by any overlapping job.
#include <nlohmann/json.hpp>
#include <string>

namespace demcal::jobs {

// Hash of the scene, the canonical dump of the resolved parameters (keys sorted,
// reals as doubles) and the scene's physics_version; 32 hex digits. A task that writes particle
// snapshots is other work than one that does not (its file holds them): `snapshots`
// adds to the key, so turning them on runs the tasks again instead of reusing files
// without any.
std::string task_key(const std::string& scene, const nlohmann::json& params, bool snapshots = false);

}  // namespace demcal::jobs
