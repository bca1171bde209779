#include "collision.hpp"
#include "../format.hpp"

#include "../errors.hpp"
#include "../measure.hpp"
#include "../packing.hpp"
#include "../run_clock.hpp"
#include "../timestep.hpp"
#include "../world.hpp"

#include <algorithm>
#include <cmath>

namespace demcal::engine {
namespace {


// Slope of y against x by least squares.
double slope(const std::vector<double>& x, const std::vector<double>& y) {
  const double n = static_cast<double>(x.size());
  if (n < 2) return 0.0;
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (std::size_t i = 0; i < x.size(); ++i) {
    sx += x[i];
    sy += y[i];
    sxx += x[i] * x[i];
    sxy += x[i] * y[i];
  }
  const double den = n * sxx - sx * sx;
  return den != 0.0 ? (n * sxy - sx * sy) / den : 0.0;
}

}  // namespace

StepForecast CollisionConfig::step_forecast() const {
  LimitInputs in;
  in.law = contact_params(material);
  if (!keep_friction) in.law.ks = 0.0;
  in.has_walls = true;  // a smooth box
  StepForecast f = forecast_step(in, material.d_min, material.d_max, material.density, dt, dt_factor);
  f.refused = !allow_unstable_dt;
  return f;
}

void CollisionConfig::validate() const {
  material.validate();
  if (particles < 2) throw ConfigError("collision.particles", "must be at least 2");
  if (!(solid_fraction > 0.0 && solid_fraction <= 0.4))
    throw ConfigError("collision.solid_fraction", "must lie in (0, 0.4] for random insertion");
  if (!std::isfinite(velocity_max) || velocity_max <= 0.0)
    throw ConfigError("collision.velocity_max", "must be a finite number > 0");
  if (!std::isfinite(dt) || dt < 0.0) throw ConfigError("numerics.dt", "must be finite and >= 0");
  if (dt == 0.0 && (!std::isfinite(dt_factor) || dt_factor <= 0.0))
    throw ConfigError("numerics.dt_factor", "must be a finite number > 0");
  if (steps < 1) throw ConfigError("collision.steps", "must be at least 1");
  if (!std::isfinite(duration) || duration < 0.0) throw ConfigError("collision.duration", "must be finite and >= 0");
  if (sample_every < 1) throw ConfigError("collision.sample_every", "must be at least 1");
  if (threads < 1) throw ConfigError("threads", "must be at least 1");
  if (!std::isfinite(energy_guard)) throw ConfigError("collision.energy_guard", "must be finite (< 0: off)");
}

Metrics CollisionResult::metrics() const {
  return {{"dt", dt},
          {"dt_critical", dt_critical},
          {"dt_over_critical", dt_critical > 0 ? dt / dt_critical : 0.0},
          {"steps", static_cast<double>(steps_done)},
          {"energy_initial", energy_initial},
          {"energy_final", energy_final},
          {"drift_per_million_steps", drift_per_million_steps},
          {"max_relative_error", max_relative_error},
          {"wall_s", wall_seconds},
          {"cpu_s", cpu_seconds},
          {"threads", static_cast<double>(threads)},
          {"particle_steps_per_s", particle_steps_per_second},
          {"simulated_s", simulated_seconds},
          {"drift_per_simulated_s", drift_per_simulated_second},
          {"wall_s_per_simulated_s", simulated_seconds > 0 ? wall_seconds / simulated_seconds : 0.0}};
}

namespace {

// With the energy check off (allow_unstable_dt, or energy_guard < 0: a stability
// study) a run past the critical step ends "done" whatever its energy did: say how
// much energy it created, which nothing in an elastic, frictionless collision can.
void warn_unchecked_growth(const CollisionConfig& cfg, CollisionResult& res) {
  if (!res.outcome.ok() || cfg.energy_guard >= 0.0 || !(res.energy_initial > 0.0)) return;
  const double growth = res.energy_final / res.energy_initial - 1.0;
  const double limit = CollisionConfig{}.energy_guard;
  if (!(growth > limit)) return;
  res.outcome.warnings.push_back("total energy grew by " + fmt(100.0 * growth, 3) + "% over the run with no source of "
                                 "energy (the " + fmt(100.0 * limit) + "% check of collision.energy_guard was off): the "
                                 "integration created it at dt = " + fmt(res.dt / res.dt_critical, 3) +
                                 " x the critical step (" + res.critical_mode + ")");
}

// A step past the critical one (allowed by allow_unstable_dt) that showed no
// instability within the run is still no stable step: friction's dissipation, or a
// dilute gas's brief contacts, can hide the growth for a while (the timestep study's
// "ran*").
void warn_past_critical(CollisionResult& res) {
  if (!res.outcome.ok() || !(res.dt_critical > 0.0) || res.dt <= res.dt_critical) return;
  res.outcome.warnings.push_back("dt = " + fmt(res.dt / res.dt_critical, 3) + " x the critical step (" +
                                 res.critical_mode + "), allowed by collision.allow_unstable_dt: no instability showed "
                                 "within these " + std::to_string(res.steps_done) + " steps, but this is no stable "
                                 "step (friction's dissipation or brief contacts can hide the growth, which a denser "
                                 "or longer run would show)");
}

// The gas: grains of the material's grading inserted at random, without overlap, in
// a cube sized for collision.solid_fraction, with velocity components uniform in
// [-velocity_max, velocity_max]. `hi` receives the cube's far corner.
Particles make_gas(const CollisionConfig& cfg, const Material& mat, std::mt19937_64& rng, Vec3& hi) {
  std::vector<double> radii = sample_radii(cfg.particles, mat.grading(), rng);
  double vs = 0.0;
  for (double r : radii) vs += sphere_volume(r);
  const double edge = std::cbrt(vs / cfg.solid_fraction);
  hi = Vec3::Constant(edge);
  Particles p;
  try {
    insert_random(p, radii, Vec3::Zero(), hi, mat.density, rng);
  } catch (const ConfigError& e) {  // the insertion's own words name no key of this scene
    throw ConfigError("collision.solid_fraction", e.reason() +
                                                      " (random insertion at collision.solid_fraction " +
                                                      fmt(cfg.solid_fraction) + "): a lower solid_fraction");
  }
  for (auto& v : p.v)
    for (int a = 0; a < 3; ++a) v[a] = uniform(rng, -cfg.velocity_max, cfg.velocity_max);
  return p;
}

// The run's figures from its clock, its step count and its energy drift (the slope of
// the relative energy error over the steps; infinite for a run that failed).
void summarise_run(const CollisionConfig& cfg, const RunClock& clock, long steps_done, double dt,
                   const std::vector<double>& steps_x, const std::vector<double>& rel_e, CollisionResult& res) {
  const double secs = clock.wall_seconds();
  res.steps_done = steps_done;
  res.wall_seconds = secs;
  res.cpu_seconds = clock.cpu_seconds();
  res.threads = cfg.threads;
  res.particle_steps_per_second = secs > 0 ? static_cast<double>(cfg.particles) * res.steps_done / secs : 0.0;
  res.simulated_seconds = static_cast<double>(res.steps_done) * dt;
  res.drift_per_million_steps = slope(steps_x, rel_e) * 1e6;
  res.drift_per_simulated_second = res.drift_per_million_steps / (1e6 * dt);
  if (!res.outcome.ok()) res.drift_per_million_steps = res.drift_per_simulated_second = INFINITY;
}

}  // namespace

CollisionResult run_collision(const CollisionConfig& cfg, Observer* obs) {
  cfg.validate();
  CollisionResult res;
  res.energy.name = "energy";
  res.energy.columns = {"step", "time", "kinetic", "elastic", "total"};
  res.energy.units = {"1", "s", "J", "J", "J"};

  Material mat = cfg.material;
  if (!cfg.keep_friction) {
    mat.friction_angle = 0.0;
    mat.rolling_eta = 0.0;
  }
  std::mt19937_64 rng(cfg.seed);
  const Vec3 lo = Vec3::Zero();
  Vec3 hi;
  Particles p = make_gas(cfg, mat, rng, hi);

  double m_min = 1e300;
  for (double m : p.m) m_min = std::min(m_min, m);
  WorldOptions opt;
  opt.dt = cfg.dt > 0.0 ? cfg.dt : timestep_from_factor(cfg.dt_factor, m_min, mat.kn);
  long total_steps = cfg.steps, sample_every = cfg.sample_every;
  if (cfg.duration > 0.0) {
    total_steps = std::max(1L, static_cast<long>(std::ceil(cfg.duration / opt.dt - 1e-9)));
    sample_every = std::max(1L, (total_steps + 199) / 200);  // at most 200 samples after the first
  }
  opt.threads = cfg.threads;
  opt.allow_unstable_dt = cfg.allow_unstable_dt;
  opt.max_overlap_fraction = cfg.max_overlap_fraction;
  Domain dom;
  dom.lo = lo;
  dom.hi = hi;
  ContactParams law = contact_params(mat);
  if (!cfg.keep_friction) law.ks = 0.0;  // frictionless: the tangential spring carries nothing
  World world(std::move(p), box_walls(lo, hi), dom, law, opt);
  const StabilityLimits lim = stability_limits(world);
  res.dt = opt.dt;
  res.dt_critical = lim.governing().dt_critical;
  res.critical_mode = lim.governing().mode;

  if (obs) obs->on_stage("collision");
  std::vector<double> steps_x, rel_e;
  auto sample = [&]() {
    const Energies e = energies(world);
    const double total = e.kinetic() + e.elastic();
    if (world.step_count() == 0) res.energy_initial = total;
    res.energy_final = total;
    const double rel = total / res.energy_initial - 1.0;
    res.max_relative_error = std::max(res.max_relative_error, std::abs(rel));
    steps_x.push_back(static_cast<double>(world.step_count()));
    rel_e.push_back(rel);
    res.energy.add({static_cast<double>(world.step_count()), world.time(), e.kinetic(), e.elastic(), total}, obs);
  };

  const RunClock clock;
  try {
    world.refresh();
    if (cfg.energy_guard >= 0.0) world.enable_energy_guard(cfg.energy_guard, std::min(1000L, std::max(1L, total_steps / 20)));
    sample();
    if (obs) obs->on_snapshot("initial", world.time(), world.particles());
    while (world.step_count() < total_steps) {
      const long chunk = std::min(sample_every, total_steps - world.step_count());
      world.run(chunk);
      sample();
      if (obs) obs->on_progress(static_cast<double>(world.step_count()) / static_cast<double>(total_steps));
    }
    if (obs) obs->on_snapshot("final", world.time(), world.particles());
  } catch (const InstabilityError& e) {
    res.outcome.status = SceneStatus::unstable;
    res.outcome.failed_stage = "collision";
    res.outcome.message = e.what();
    if (res.dt_critical > 0.0)
      res.outcome.message += "; the step is " + fmt(res.dt / res.dt_critical, 3) + " x the critical step (" +
                             res.critical_mode + "): a smaller collision.dt_factor" +
                             (e.quantity() == "energy" ? std::string(" (collision.energy_guard sets the check's limit)")
                                                       : std::string());
  }
  summarise_run(cfg, clock, world.step_count(), opt.dt, steps_x, rel_e, res);
  warn_unchecked_growth(cfg, res);
  warn_past_critical(res);
  res.outcome.join_warnings();
  return res;
}

TimestepSweep sweep_timestep(const CollisionConfig& base, const std::vector<double>& factors, double tolerance,
                             Observer* obs) {
  TimestepSweep sw;
  sw.factors = factors;
  std::sort(sw.factors.begin(), sw.factors.end());
  bool all_passed = true;  // a pass beyond a failure is luck, not a recommendation
  for (double k : sw.factors) {
    CollisionConfig c = base;
    c.dt = 0.0;
    c.dt_factor = k;
    c.allow_unstable_dt = true;
    c.energy_guard = -1.0;  // the drift is the measurement
    CollisionResult r = run_collision(c, obs);
    all_passed = all_passed && r.outcome.ok() && std::abs(r.drift_per_million_steps) <= tolerance;
    if (all_passed) {
      sw.recommended_factor = k;
      sw.recommended_dt = r.dt;
    }
    sw.runs.push_back(std::move(r));
  }
  return sw;
}

}  // namespace demcal::engine
