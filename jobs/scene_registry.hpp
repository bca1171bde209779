#pragma once
// Scene dispatch: a scene name maps to its parameter table, the resolution of one
// task's parameters into a checked engine config, and a run. Each scene lives in
// one file, jobs/scenes/<name>.cpp, defining scene_<name>(); CMake lists them.
#include "params.hpp"

#include "engine/observer.hpp"
#include "engine/scenes/scene_status.hpp"
#include "engine/timestep.hpp"

#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace demcal::jobs {

struct RunContext {
  int threads = 1;
  engine::Observer* observer = nullptr;
};

struct SceneOutput {
  engine::SceneOutcome outcome;
  engine::Metrics metrics;  // when the outcome is not ok, only what the run cost (timing_metrics)
  std::vector<engine::Series> series;
};
// Of a failed run's metrics, what it cost (wall and CPU time, threads): a failure's
// cost is the user's too, and no mechanics of a run that did not finish may pass.
engine::Metrics timing_metrics(const engine::Metrics& all);

// A scene's speed at `grains` from speeds measured at a few sample sizes ({grains,
// ns per grain-step}, increasing grains): piecewise linear in log N, held at the ends.
double ns_per_grain_step_at(const std::vector<std::pair<double, double>>& measured, double grains);

struct Work {
  double steps = 0, grains = 0;
  double ns_per_grain_step = 0;  // the scene's speed on one core of the project's machine
  bool upper_bound = false;      // steps to every stage's limit: a run that ends sooner costs less
};

struct SceneDef {
  std::string name;  // also the job-file section holding its protocol
  std::vector<ParamSpec> params;  // material and scene section
  // Fills derived defaults (e.g. from fidelity) into one task's flat parameters and
  // checks what single fields cannot (relations, the engine's own validation).
  // Throws JobError naming the job-file path.
  std::function<void(nlohmann::json& params, const std::string& fidelity)> resolve;
  std::function<SceneOutput(const nlohmann::json& params, const RunContext& ctx)> run;
  // The metrics a reader wants first: what a table shows unless asked for others.
  std::vector<std::string> headline;
  // One task's time step against its isolated contacts' limit, before it runs.
  std::function<engine::StepForecast(const nlohmann::json& params)> forecast;
  // What a task's settings predict the run will warn about (empty: nothing), said by
  // validate and run before it starts.
  std::function<std::string(const nlohmann::json& params)> advice;
  // The part of a task's work known before it runs (its steps and grains), what it
  // counts ("the shear") and what it leaves out; null where a scene cannot say.
  std::function<Work(const nlohmann::json& params)> work;
  std::string work_of, work_left_out;
  // The parameters a task's key hashes, where one setting has several spellings (the
  // same work must have one key to be reused); null: the parameters as they are.
  std::function<nlohmann::json(const nlohmann::json& params)> key_params;
  // Optional keys a task's parameters may lack, and the value a task without one runs
  // at: `--where size_distribution=uniform` must match the tasks that left it out.
  std::vector<std::pair<std::string, nlohmann::json>> implied;
};
// Every scene's resolve() drops size_distribution when it is "uniform".
inline const std::pair<std::string, nlohmann::json> kImpliedUniformSizes{"size_distribution", "uniform"};

const SceneDef* find_scene(const std::string& name);
std::vector<std::string> scene_names();

}  // namespace demcal::jobs
