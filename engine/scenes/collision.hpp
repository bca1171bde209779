#pragma once
// Elastic collision test of the seed's Sec. 2.2.2 (Fig. 2.6): a gas of grains with
// random velocities in a closed box, no gravity, friction, rolling or damping.
// Nothing can dissipate or create energy, so any drift of the total energy is the
// integrator's error: the test that picks the time step.
#include "../material.hpp"
#include "../observer.hpp"
#include "../timestep.hpp"
#include "scene_status.hpp"

#include <cstdint>
#include <string>
#include <vector>

namespace demcal::engine {

struct CollisionConfig {
  Material material;              // friction, rolling are forced to zero unless keep_friction
  std::size_t particles = 1250;
  double solid_fraction = 0.2;    // sets the cubic box edge
  double velocity_max = 1.0;      // velocity components uniform in [-v, v] [m/s]
  double dt = 0.0;                // explicit step [s]; 0: dt_factor * sqrt(m_min/Kn)
  double dt_factor = 0.3;          // the timestep study's recommendation (docs/studies.md)
  long steps = 200000;
  long sample_every = 1000;
  double duration = 0.0;          // > 0: simulated time [s] instead of steps (steps = ceil(duration/dt),
                                  // 200 samples): runs at different dt then cover the same collisions
  bool keep_friction = false;     // stability studies: run with the material's theta, eta
  bool allow_unstable_dt = false; // stability studies: run past the critical step
  double max_overlap_fraction = 0.25;
  // Nothing here can create energy: a total energy grown by this fraction of its
  // start stops the run as unstable (World::enable_energy_guard). < 0: off, for
  // stability studies that measure the gain.
  double energy_guard = 0.02;
  std::uint64_t seed = 1;
  int threads = 1;

  void validate() const;  // throws ConfigError naming the field
  StepForecast step_forecast() const;  // for job validation (timestep.hpp)
};

struct CollisionResult {
  SceneOutcome outcome;
  double dt = 0;
  double dt_critical = 0;      // governing mode's limit
  std::string critical_mode;
  long steps_done = 0;
  double energy_initial = 0;   // total energy at step 0 [J]
  double energy_final = 0;
  double drift_per_million_steps = 0;  // relative, from a least-squares line through E(t)/E0
  double max_relative_error = 0;       // max |E - E0| / E0 over the samples
  double wall_seconds = 0;
  double cpu_seconds = 0;  // all threads (RunClock)
  int threads = 1;
  double particle_steps_per_second = 0;
  double simulated_seconds = 0;        // steps_done * dt
  double drift_per_simulated_second = 0;  // relative, from the same line: drift_per_million_steps / (1e6 dt)
  Series energy;  // step, time, kinetic, elastic, total

  Metrics metrics() const;
};

CollisionResult run_collision(const CollisionConfig& config, Observer* observer = nullptr);

// Runs the test at each dt factor, smallest first (`factors` comes back sorted); the
// recommended factor is the largest such that at it and at every smaller factor the
// run was stable with |drift| within `tolerance` (relative per million steps).
struct TimestepSweep {
  std::vector<double> factors;
  std::vector<CollisionResult> runs;
  double recommended_factor = 0;  // 0 when none passed
  double recommended_dt = 0;
};
TimestepSweep sweep_timestep(const CollisionConfig& base, const std::vector<double>& factors, double tolerance,
                             Observer* observer = nullptr);

}  // namespace demcal::engine
