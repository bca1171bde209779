// The elastic collision scene (seed Sec. 2.2.2): the time-step test.
#include "../job_error.hpp"
#include "../material_params.hpp"
#include "../scene_registry.hpp"
#include "../scene_resolve.hpp"

#include "engine/errors.hpp"
#include "engine/scenes/collision.hpp"

#include <algorithm>
#include <cmath>

namespace demcal::jobs {
namespace {

const char* const kSection = "collision";

std::vector<ParamSpec> collision_params() {
  std::vector<ParamSpec> p = material_params();
  const engine::CollisionConfig d;
  p.push_back(int_param(kSection, "particles", "particles", static_cast<std::int64_t>(d.particles)).at_least(2).at_most(5e6));
  p.push_back(real_param(kSection, "solid_fraction", "solid_fraction", d.solid_fraction).above(0).at_most(0.4));
  p.push_back(real_param(kSection, "velocity_max", "velocity_max", d.velocity_max).above(0).at_most(1e4));
  // steps, sample_every, dt and dt_factor have no fixed default: resolve() picks them.
  p.push_back(int_param(kSection, "steps", "steps", nullptr).at_least(1).at_most(1e12));
  p.push_back(int_param(kSection, "sample_every", "sample_every", nullptr).at_least(1).at_most(1e12));
  // Simulated time instead of steps: tasks over a dt grid then cover the same physics.
  p.push_back(real_param(kSection, "duration", "duration", nullptr).above(0).at_most(1e3));
  p.push_back(real_param(kSection, "dt", "dt", nullptr).above(0).below(1));
  p.push_back(real_param(kSection, "dt_factor", "dt_factor", nullptr).above(0).at_most(10));
  p.push_back(bool_param(kSection, "keep_friction", "keep_friction", d.keep_friction));
  p.push_back(bool_param(kSection, "allow_unstable_dt", "allow_unstable_dt", d.allow_unstable_dt));
  // No fixed default: off where allow_unstable_dt asks to watch the method fail.
  p.push_back(real_param(kSection, "energy_guard", "energy_guard", nullptr).at_most(1e6));
  return p;
}

// A run that may go past the critical step is there to show the energy it gains: no
// guard unless the job gives one.
double energy_guard_of(const nlohmann::json& p) {
  return p.value("energy_guard", p.at("allow_unstable_dt").get<bool>() ? -1.0 : engine::CollisionConfig{}.energy_guard);
}

engine::CollisionConfig config_from(const nlohmann::json& p) {
  engine::CollisionConfig c;
  c.material = material_from(p);
  c.particles = p.at("particles").get<std::size_t>();
  c.solid_fraction = p.at("solid_fraction").get<double>();
  c.velocity_max = p.at("velocity_max").get<double>();
  c.steps = p.value("steps", std::int64_t(1));
  c.sample_every = p.value("sample_every", std::int64_t(1));
  c.duration = p.value("duration", 0.0);
  c.dt = p.value("dt", 0.0);
  if (p.contains("dt_factor")) c.dt_factor = p.at("dt_factor").get<double>();
  c.keep_friction = p.at("keep_friction").get<bool>();
  c.allow_unstable_dt = p.at("allow_unstable_dt").get<bool>();
  c.energy_guard = energy_guard_of(p);
  c.seed = p.at("seed").get<std::uint64_t>();
  return c;
}

// Step counts per fidelity, when the job gives none. The drift is a least-squares
// slope per million steps, so a longer run resolves a smaller drift; the timestep
// study (docs/studies.md) charts the step size, and these lengths were chosen for
// cost (quick: ~1 s, standard: ~10 s on one core for 1,250 grains), not measured.
std::int64_t default_steps(const std::string& fidelity) {
  if (fidelity == "quick") return 20000;
  if (fidelity == "reference") return 1000000;
  return 200000;
}

void resolve(nlohmann::json& p, const std::string& fidelity) {
  resolve_time_step(p, kSection, engine::CollisionConfig{}.dt_factor);
  p["energy_guard"] = energy_guard_of(p);
  if (p.contains("duration")) {
    // The engine derives steps and sampling from the duration and dt.
    for (const char* k : {"steps", "sample_every"})
      if (p.contains(k)) throw JobError(std::string("collision.") + k, "give collision.duration or collision.steps, not both");
  } else {
    if (!p.contains("steps")) p["steps"] = default_steps(fidelity);
    const auto steps = p["steps"].get<std::int64_t>();
    if (!p.contains("sample_every")) p["sample_every"] = std::max<std::int64_t>(1, steps / 200);
    if (p["sample_every"].get<std::int64_t>() > steps)
      throw JobError("collision.sample_every", "must not exceed collision.steps (" + std::to_string(steps) + ")");
  }
  resolve_diameters(p);
  try {
    config_from(p).validate();
  } catch (const engine::ConfigError& e) {
    throw_as_job_error(e, job_path_of(e.field(), kSection));
  }
}

SceneOutput run(const nlohmann::json& p, const RunContext& ctx) {
  engine::CollisionConfig c = config_from(p);
  c.threads = ctx.threads;
  engine::CollisionResult r = engine::run_collision(c, ctx.observer);
  SceneOutput out;
  out.outcome = r.outcome;
  out.metrics = r.outcome.ok() ? r.metrics() : timing_metrics(r.metrics());
  out.series.push_back(std::move(r.energy));
  return out;
}

// The scene is frictionless unless keep_friction: theta and eta given then change the
// task's key and nothing it computes.
std::string advice(const nlohmann::json& p) {
  if (p.at("keep_friction").get<bool>()) return "";
  if (p.at("theta_deg").get<double>() == 0.0 && p.at("eta").get<double>() == 0.0) return "";
  return "material.theta_deg and material.eta are not used: the collision scene runs frictionless unless "
         "collision.keep_friction is true";
}

}  // namespace

SceneDef scene_collision() {
  return SceneDef{kSection, collision_params(), resolve, run,
                  /*headline=*/{"dt_over_critical", "drift_per_million_steps", "max_relative_error", "wall_s"},
                  /*forecast=*/[](const nlohmann::json& p) { return config_from(p).step_forecast(); },
                  /*advice=*/advice,
                  /*work=*/
                  [](const nlohmann::json& p) {
                    const engine::CollisionConfig c = config_from(p);
                    const double steps = c.duration > 0.0 ? std::ceil(c.duration / c.step_forecast().dt)
                                                          : static_cast<double>(c.steps);
                    // A dilute elastic gas, few contacts a grain: examples/collision.json ran at
                    // 37-59 million grain-steps a second on one core (docs/performance.md).
                    return Work{steps, static_cast<double>(c.particles), 20.0};
                  },
                  /*work_of=*/"the collision run",
                  /*work_left_out=*/"",
                  /*key_params=*/nullptr,
                  /*implied=*/{kImpliedUniformSizes}};
}

}  // namespace demcal::jobs
