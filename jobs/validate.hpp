#pragma once
// Strict validation of a job's material, scene and grid sections against the
// scene's parameter table: unknown keys, wrong types, non-finite or out-of-range
// values, empty lists and duplicate list values are errors naming the JSON path.
#include "scene_registry.hpp"

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace demcal::jobs {

// A parameter that takes several values: one axis of the grid.
struct Axis {
  std::string name;  // flat parameter name
  std::string path;  // where its list was written
  std::vector<nlohmann::json> values;
};

struct ParamSet {
  nlohmann::json base = nlohmann::json::object();  // flat name -> single value
  std::vector<Axis> axes;                          // in declaration order, then grid keys
  std::vector<std::string> notes;                  // legal but easy to miss, for the user
};

ParamSet read_params(const nlohmann::json& job, const SceneDef& scene);

}  // namespace demcal::jobs
