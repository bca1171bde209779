#pragma once
// Angle of repose by granular column collapse (seed Sec. 2.2.4, Figs. 2.14, 2.15).
//
// A quasi-2D slab: x is the spreading direction, z is up, y is periodic with a
// depth of a few mean diameters (the slab replaces side walls), or bounded by two
// side walls (smooth, or frictional with the grains' theta and eta) when the
// question is what a narrow laboratory channel does to the deposit.
// A column of grains (column_width x column_height) is generated against a smooth
// back wall (x = 0) behind a smooth gate (x = column_width), settled under gravity
// with temporary local damping, levelled to column_height and settled again; the
// damping is switched off and the gate removed (wall.active = false). The grains
// collapse undamped (energy leaves by friction and plastic rolling only) and
// spread over a rough floor of fixed grains of the same size distribution, until
// the kinetic energy per mobile grain stays below a threshold or a time limit is
// reached; then the heap is at rest only if its angle and front held still over a
// last window (rest_by_profile, warned), else the run is not_settled and gives no
// angle. A smooth end
// wall at x = domain_length keeps stray grains in the box.
//
// Real density, real gravity: this scene is dynamic. The stiffness can be scaled
// (stiffness_scale < 1: Kn and Ks both scaled, the time step grows with
// 1/sqrt(scale)); every knob is recorded in the result.
#include "../material.hpp"
#include "../observer.hpp"
#include "../particles.hpp"
#include "../repose_profile.hpp"
#include "../timestep.hpp"
#include "scene_status.hpp"

#include <cstdint>
#include <string>
#include <vector>

namespace demcal::engine {

// The seed's material for this scene: Table 2.1 with theta = 30 deg, eta = 0.1.
Material repose_seed_material();

// How the slab is closed in depth (y).
enum class SideWalls {
  periodic,   // no walls: periodic images (the default; a slab of an unbounded heap)
  smooth,     // two frictionless walls at y = 0 and y = depth
  frictional  // two walls with the grains' friction angle and rolling resistance
};
// Every value, in declaration order: what parse_side_walls and the job layer's
// choice list are built from.
inline constexpr SideWalls kSideWalls[] = {SideWalls::periodic, SideWalls::smooth, SideWalls::frictional};
const char* to_string(SideWalls s);
// The inverse of to_string: false (s untouched) for an unknown name.
bool parse_side_walls(const std::string& name, SideWalls& s);

// The most grains (column and floor) a repose task may have: as the other scenes'
// particle caps, a bound on typos, far above any column one machine settles.
constexpr double kMaxReposeGrains = 5e6;

// How far a grain's interactions reach: the largest diameter plus the default skin.
// A periodic slab thinner than twice it lets a grain meet its own image.
inline double interaction_reach(const Material& m) { return m.d_max + 0.1 * m.d_min; }
// The thinnest periodic slab, in mean diameters, rounded up to a tenth.
double least_periodic_depth_diameters(const Material& m);

struct ReposeConfig {
  Material material = repose_seed_material();

  // Geometry [m]
  double column_width = 0.05;        // L0: gate position
  double column_height = 0.05;       // H0: fill height after levelling (above the floor level)
  double slab_depth_diameters = 4.0; // depth in units of d_mean (periodic: >= 2 (d_max + skin) / d_mean)
  SideWalls side_walls = SideWalls::periodic;
  double domain_length = 0.0;        // x of the end wall; 0: column_width + 4 * column_height + 0.02 m
  double floor_spacing = 0.0;        // centre spacing of the fixed floor grains' square grid; 0: d_max

  // Preparation
  double fill_solid_fraction = 0.33;   // solid fraction of the random insertion region
  double target_solid_fraction = 0.60; // expected settled solid fraction, sizes the grain count
  double overfill = 1.08;              // extra grains generated, trimmed by levelling
  double prep_damping = 0.7;           // local damping during preparation only (off for the collapse)
  double settle_ke_ratio = 5e-5;       // preparation rest: flow KE per grain / (m_mean g d_mean), trimmed
  double settle_time_limit = 1.5;      // [s] per preparation settle

  // Collapse
  // Rest is judged on the "flow" kinetic energy: KE of each grain's mean velocity
  // over one sample interval (displacement / interval). Undamped contacts keep
  // ringing elastically with displacements of nanometres; the instantaneous KE
  // (also recorded) then never decays, although no grain moves.
  double rest_ke_ratio = 1e-5;     // rest: flow KE per mobile grain / (m_mean g d_mean)
  double rest_trim = 0.01;         // fastest fraction of grains left out of the rest check (rattlers)
  int rest_samples = 4;            // ... for this many consecutive samples
  // Background viscous drag in the collapse [1/s]: every 100 steps the mobile
  // grains' velocities are scaled by exp(-rate * 100 dt). 0 as the seed. The seed's
  // law has no dissipation without friction, so theta = eta = 0 never comes to rest
  // unless this is > 0. (Local damping would be the wrong tool here: it resists
  // motion by a fraction of the force, like friction, and holds a frictionless heap
  // at ~20 deg.)
  double collapse_drag = 0.0;
  double min_collapse_time = 0.05; // [s] rest is not judged earlier (the column starts at rest)
  double time_limit = 2.0;         // [s] after the gate opens; beyond it: not_settled, unless ...
  // ... the heap itself has held still: its fitted angle within rest_profile_tol_deg
  // and its front within one profile bin over the last rest_profile_window seconds.
  // Undamped, a few grains bouncing in the rough floor's hollows (or the heap rocking
  // on its rolling springs) can keep the kinetic energy above the threshold for good
  // while the angle, the answer, no longer changes. Judged only at the time limit, so
  // a run that rests by kinetic energy is the same run with or without it; the
  // result then carries a warning. 0: off.
  double rest_profile_window = 0.5;   // [s]
  double rest_profile_tol_deg = 0.2;  // [deg]
  double sample_interval = 0.005;  // [s] between series rows and rest checks

  // Numerics
  double stiffness_scale = 1.0;  // Kn, Ks multiplied by this (1: the seed's values)
  double dt = 0.0;               // explicit step [s]; 0: dt_factor * sqrt(m_min / Kn_scaled)
  double dt_factor = 0.465;      // 0.465 * sqrt(m_min/Kn) = 1.0e-7 s for the seed's material (its dt)
  double gravity = 9.81;         // [m/s^2], along -z
  double energy_guard = 0.02;    // relative energy-growth tolerance during the collapse; < 0: off

  // Measurement
  double bin_width = 0.0;         // profile bin [m]; 0: d_mean
  double fit_lo = 0.2, fit_hi = 0.8;  // fit between these fractions of the deposit height
  double steep_window = 0.0;      // steepest-angle window [m]; 0: 5 * d_mean
  double front_min_height = 0.25; // a bin belongs to the deposit above this height [d_mean]
  double front_max_gap = 2.0;     // gap that detaches bouncers from the deposit [d_mean]

  std::uint64_t seed = 1;
  int threads = 1;

  void validate() const;  // throws ConfigError naming the field
  StepForecast step_forecast() const;  // for job validation (timestep.hpp)

  // Grains the task generates, from the sizes alone: the column before levelling
  // trims it (overfill included) and the rough floor. validate()'s bound on typos,
  // and the cost forecast's grain count.
  struct GrainEstimate {
    double column = 0, floor = 0;
  };
  GrainEstimate grain_estimate() const;
  // The most steps a task can take: both preparation settlings and the collapse, each
  // to its time limit (a heap that comes to rest sooner stops sooner).
  double max_steps() const;
  // The time the rest-by-profile check needs (its window after min_collapse_time),
  // and whether time_limit leaves it none (the check is on but can never run).
  double profile_check_time() const { return min_collapse_time + rest_profile_window; }
  // The overlap, as a fraction of the smallest radius, that the column's own weight
  // presses into a grain at its foot at the scaled stiffness (the column's pressure
  // rho g H at solid fraction target_solid_fraction, carried by one contact a mean
  // grain's cross-section): how far stiffness_scale can go. The collapse's impacts add
  // to it (1e-6 on the seed's material, the quick column: 0.035 here, and an overlap
  // of 0.27 of the radius in the collapse).
  double weight_overlap() const;
  // The profile's bin: bin_width, by default the mean diameter.
  double profile_bin() const;
  // The column's width in profile bins: a column a few bins wide heaps a slope of
  // fewer bins (a 6 mm column of 1-2 mm grains, 4 bins, fitted its heap over 6 bins
  // and a 5 mm one over fewer).
  double column_bins() const;
  static constexpr double kWeightOverlapNote = 0.02;  // validate notes above this
  bool profile_check_has_no_room() const { return rest_profile_window > 0.0 && time_limit < profile_check_time(); }

 private:
  void validate_protocol() const;  // validate()'s parts
  void validate_profile() const;
  void validate_geometry() const;
};

struct ReposeResult {
  SceneOutcome outcome;

  // Measurements (meaningful only when outcome.ok())
  double repose_deg = 0, repose_fit_err_deg = 0, steepest_deg = 0;
  int fit_points = 0;
  static constexpr int kMinSlopeBins = 6;  // fewer: the run warns that the angle is no measurement
  static constexpr double kMaxFitErrDeg = 3.0;  // a larger standard error: no straight slope, warned
  double repose_upper_deg = 0, repose_lower_deg = 0;  // the fit over the upper / lower half of its heights
  double fit_slope = 0, fit_intercept = 0, fit_x_upper = 0, fit_x_lower = 0;  // line h = intercept + slope x
  double runout_m = 0;        // front - gate position
  double runout_ratio = 0;    // (L_inf - L0) / L0
  long grains_beyond_front = 0;  // mobile grains past the deposit's front (left out of the fit)
  double front_m = 0;         // L_inf: front position from the back wall
  double final_height_m = 0;  // deposit height above the floor level
  // After the gate opened: by kinetic energy the first of the quiet samples, by profile
  // the earliest time from which the angle and front held still (still_since; sooner).
  double time_to_rest_s = 0;
  bool rest_by_profile = false;  // kinetic energy never passed; the heap's angle and front held still
  double profile_angle_change_deg = 0, profile_front_change_m = 0;  // over the window, when judged
  bool reached_end_wall = false;

  // Set-up, recorded
  long particles = 0;         // mobile grains after levelling
  long floor_particles = 0;
  double column_width = 0, column_height = 0, aspect_ratio = 0, column_solid_fraction = 0;
  double slab_depth_m = 0, domain_length = 0, floor_level = 0;
  double dt = 0, dt_critical = 0;
  std::string critical_mode;
  double stiffness_scale = 1, kn = 0, ks = 0;
  double prep_damping = 0, prep_time_s = 0, collapse_drag = 0;
  double rest_ke_J = 0;       // the threshold in joules (flow KE per grain, trimmed)
  double bin_width = 0;
  long steps = 0;
  double wall_seconds = 0;
  double cpu_seconds = 0;  // all threads (RunClock)
  int threads = 1;
  std::string boundaries;     // words: which walls, which are periodic

  Series prep;     // preparation: time, ke_per_grain, ke_flow_per_grain (damped settling behind the gate)
  Series energy;   // collapse: time, kinetic, ke_per_grain, ke_flow_per_grain (trimmed), front_x, repose_deg (NaN: no fit)
  Series profile;  // final: x, h, count
  Particles final_particles;  // floor (fixed) grains first, then the mobile ones

  Metrics metrics() const;
};

ReposeResult run_repose(const ReposeConfig& config, Observer* observer = nullptr);

}  // namespace demcal::engine
