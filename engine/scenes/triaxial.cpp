#include "triaxial.hpp"
#include "../format.hpp"

#include "../errors.hpp"
#include "../measure.hpp"
#include "../packing.hpp"
#include "../run_clock.hpp"
#include "../series_stats.hpp"
#include "../servo_wall.hpp"
#include "../timestep.hpp"
#include "../world.hpp"

#include <algorithm>
#include <array>
#include <cstdio>
#include <cmath>
#include <sstream>

namespace demcal::engine {

Material triaxial_seed_material() {
  Material m;  // Kn, Ks, density, diameters: Table 2.1 defaults
  m.friction_angle = deg_to_rad(30.0);
  m.rolling_b = 1.0;
  m.rolling_eta = 0.1;
  return m;
}

const char* to_string(Packing p) { return p == Packing::dense ? "dense" : "loose"; }

namespace {
// The dense preparation's first law: theta = eta = 0, no tangential spring.
ContactParams frictionless(ContactParams law) {
  law.ks = 0.0;
  law.tan_theta = 0.0;
  law.eta = 0.0;
  return law;
}

// The frictionless stages' step over dt: the frictionless law's critical step over
// that of the material's full law, its tangential and rolling springs both counted
// whatever theta and eta are, so that every task of a (theta, eta) grid prepares the
// same packing from the same seed (eta = 0 has no rolling mode, and a ratio to its
// own law's limit would prepare its column differently). Where dt is beyond the full
// law's limit (possible only without rolling), the ratio to the target law's keeps
// the frictionless step within its own.
double frictionless_step_ratio(const World& frictionless_world, const ContactParams& target, double dt) {
  const double dtc = stability_limits(frictionless_world).governing().dt_critical;
  const double dtc_target = stability_limits(frictionless_world, target).governing().dt_critical;
  ContactParams full = target;
  full.tan_theta = std::max(full.tan_theta, 1.0);  // any value > 0 counts the springs
  full.eta = std::max(full.eta, 1.0);
  const double dtc_full = stability_limits(frictionless_world, full).governing().dt_critical;
  return dtc / (dt <= dtc_full ? dtc_full : dtc_target);
}

// The step the settings give and the limit of `law`'s isolated contacts in the box of
// six smooth walls, from the extremes of the diameter range.
StepForecast forecast_for(const TriaxialConfig& c, const ContactParams& law) {
  LimitInputs in;
  in.law = law;
  in.has_walls = true;  // six smooth walls
  return forecast_step(in, c.material.d_min, c.material.d_max, c.grain_density(), c.dt, c.dt_factor);
}

}  // namespace

StepForecast TriaxialConfig::step_forecast() const {
  return forecast_for(*this, contact_params(material));  // the target law, the stiffest one the run uses
}

double TriaxialConfig::shear_steps() const {
  return std::ceil((axial_strain + shear_ramp_strain) / (strain_rate * step_forecast().dt));
}

double TriaxialConfig::prep_wall_impact_depth() const {
  const Grading g = material.grading();
  const double solid = static_cast<double>(particles) * M_PI / 6.0 * g.mean_cube();
  const double side = std::cbrt(solid / (initial_solid_fraction * aspect_ratio));
  const double speed = 0.5 * prep_strain_rate * side;
  const double m_max = grain_density() * M_PI / 6.0 * g.d_max * g.d_max * g.d_max;
  return speed * std::sqrt(m_max / material.kn) / (0.5 * g.d_max);
}

std::string TriaxialConfig::prep_wall_impact_words() const {
  const double depth = prep_wall_impact_depth();
  return "the preparation's walls close in fast enough (triaxial.prep_strain_rate " + fmt(prep_strain_rate) +
         " /s) to press the largest grain " + fmt(100.0 * depth, 2) +
         "% of its radius into a wall before its contact pushes back (speed x sqrt(m / kn); the overlap limit is " +
         fmt(100.0 * max_overlap_fraction, 2) + "%): a triaxial.prep_strain_rate of about " +
         fmt(prep_strain_rate_for_impact(kWallImpactSuggested), 2) + " /s keeps that to " +
         fmt(100.0 * kWallImpactSuggested * max_overlap_fraction, 2) +
         "% (500 grains of kn = 1.1e4 N/m blew up at 7.4% and held at 3.7%)";
}

namespace {
// The inertial number of a shear at `rate` on grains of mean diameter d and density
// rho under mean stress p (GDR MiDi 2004): quasi-static well below 1e-3.
double inertial_number(double rate, double d, double rho, double p) {
  return p > 0 ? rate * d * std::sqrt(rho / p) : INFINITY;
}
}  // namespace

double TriaxialConfig::nominal_inertial_number() const {
  return inertial_number(strain_rate, material.grading().mean(), grain_density(), confining_pressure);
}

void TriaxialConfig::validate() const {
  material.validate();
  auto positive = [](double v, const char* f) {
    if (!std::isfinite(v) || v <= 0.0) throw ConfigError(f, "must be a finite number > 0");
  };
  if (particles < 50) throw ConfigError("triaxial.particles", "must be at least 50");
  positive(confining_pressure, "triaxial.confining_pressure");
  positive(strain_rate, "triaxial.strain_rate");
  if (!(axial_strain > 0.0 && axial_strain < 0.6)) throw ConfigError("triaxial.axial_strain", "must lie in (0, 0.6)");
  if (density_scale < 0.0 || !std::isfinite(density_scale))
    throw ConfigError("triaxial.density_scale", "must be finite and >= 0 (0: use scaled_density)");
  if (density_scale == 0.0) positive(scaled_density, "triaxial.scaled_density");
  if (!(aspect_ratio >= 0.5 && aspect_ratio <= 4.0)) throw ConfigError("triaxial.aspect_ratio", "must lie in [0.5, 4]");
  if (!(initial_solid_fraction > 0.05 && initial_solid_fraction <= 0.4))
    throw ConfigError("triaxial.initial_solid_fraction", "must lie in (0.05, 0.4] for random insertion");
  if (!(prep_damping >= 0.0 && prep_damping < 1.0)) throw ConfigError("triaxial.prep_damping", "must lie in [0, 1)");
  if (!(shear_damping >= 0.0 && shear_damping < 1.0))
    throw ConfigError("triaxial.shear_damping", "must lie in [0, 1) (0: none, the seed's protocol)");
  positive(prep_strain_rate, "triaxial.prep_strain_rate");
  if (!std::isfinite(prep_pressure_factor) || prep_pressure_factor < 1.0 || prep_pressure_factor > 1000.0)
    throw ConfigError("triaxial.prep_pressure_factor", "must lie in [1, 1000]");
  if (!(stress_tolerance > 0.0 && stress_tolerance < 1.0))
    throw ConfigError("triaxial.stress_tolerance", "must lie in (0, 1)");
  positive(ufr_tolerance, "triaxial.ufr_tolerance");
  if (prep_step_budget < 1) throw ConfigError("triaxial.prep_step_budget", "must be at least 1");
  if (stabilise_min_steps < 0) throw ConfigError("triaxial.stabilise_min_steps", "must be >= 0");
  if (unloading_steps < 0) throw ConfigError("triaxial.unloading_steps", "must be >= 0");
  if (check_interval < 1) throw ConfigError("triaxial.check_interval", "must be at least 1");
  ServoGains g{servo_alpha, servo_beta, 1.0};
  g.validate("triaxial.servo");
  if (!std::isfinite(shear_servo_strain_rate) || shear_servo_strain_rate < 0.0)
    throw ConfigError("triaxial.shear_servo_strain_rate", "must be finite and >= 0 (0: 20 * strain_rate)");
  if (!std::isfinite(dt) || dt < 0.0) throw ConfigError("numerics.dt", "must be finite and >= 0");
  if (dt == 0.0) positive(dt_factor, "numerics.dt_factor");
  if (!std::isfinite(frictionless_dt_scale) || frictionless_dt_scale < 0.0)
    throw ConfigError("numerics.frictionless_dt_scale", "must be finite and >= 0 (0: the same margin to the critical step)");
  // A dt past its own limit is refused for itself (step_forecast), not blamed on the scale.
  if (packing == Packing::dense && frictionless_dt_scale > 0.0 && !step_forecast().exceeds()) {
    const StepForecast f = forecast_for(*this, frictionless(contact_params(material)));
    if (f.dt * frictionless_dt_scale > f.dt_critical)
      throw ConfigError("numerics.frictionless_dt_scale",
                        "gives a frictionless step of " + fmt(f.dt * frictionless_dt_scale) +
                            " s, above that law's critical step " + fmt(f.dt_critical) + " s (" + f.mode + "); at most " +
                            fmt(f.dt_critical / f.dt));
  }
  positive(max_overlap_fraction, "numerics.max_overlap_fraction");
  if (!(sample_strain > 0.0 && sample_strain <= axial_strain))
    throw ConfigError("triaxial.sample_strain", "must lie in (0, axial_strain]");
  // A row holds 27 numbers: more than a few million rows is memory, not resolution.
  if (sample_steps < 0) throw ConfigError("triaxial.sample_steps", "must be >= 0 (0: sample by strain)");
  if (sample_steps > 0 && !step_forecast().exceeds()) {
    const double steps = shear_steps();
    if (steps / static_cast<double>(sample_steps) > 2e6)
      throw ConfigError("triaxial.sample_steps", "gives " + fmt(steps / static_cast<double>(sample_steps)) +
                                                     " series rows over the shear (" + fmt(steps) + " steps); at least " +
                                                     fmt(std::ceil(steps / 2e6)));
  }
  if (!(shear_ramp_strain >= 0.0 && shear_ramp_strain < 0.5 * axial_strain))
    throw ConfigError("triaxial.shear_ramp_strain", "must lie in [0, axial_strain / 2)");
  if (!(cv_from >= 0.0 && cv_to > cv_from)) throw ConfigError("triaxial.cv_window", "needs 0 <= from < to");
  if (cv_to > axial_strain + 1e-12)
    throw ConfigError("triaxial.cv_window", "ends beyond the target axial strain");
  positive(quasi_static_inertial, "triaxial.quasi_static_inertial");
  positive(dilatancy_window, "triaxial.dilatancy_window");
  if (threads < 1) throw ConfigError("threads", "must be at least 1");
}

Metrics TriaxialResult::metrics() const {
  // A failed run reports no mechanics: only how far it got.
  Metrics m{{"ok", outcome.ok() ? 1.0 : 0.0},
            {"particles", static_cast<double>(particles)},
            {"steps", static_cast<double>(steps)},
            {"wall_s", wall_seconds},
            {"cpu_s", cpu_seconds},
            {"threads", static_cast<double>(threads)},
            {"local_damping_used", local_damping_used ? 1.0 : 0.0},
            {"prep_damping", prep_damping},
            {"shear_damping", shear_damping},
            {"walls_frictionless", walls_frictionless ? 1.0 : 0.0}};
  if (!outcome.ok()) return m;
  const Metrics mech{{"phi_peak_deg", phi_peak_deg},
                     {"phi_peak_smoothed_deg", phi_peak_smoothed_deg},
                     {"eps1_at_peak", eps1_at_peak},
                     {"phi_cv_deg", phi_cv_deg},
                     {"phi_cv_se_deg", phi_cv_se_deg},
                     {"cv_effective_samples", cv_effective_samples},
                     {"cv_dilatancy_deg", cv_dilatancy_deg},
                     {"cv_drift_deg", cv_drift_deg},
                     {"cv_drift_se_deg", cv_drift_se_deg},
                     {"cv_coordination", cv_coordination},
                     {"cv_rows_in_extension", static_cast<double>(cv_rows_in_extension)},
                     {"cv_rows_unloaded", static_cast<double>(cv_rows_unloaded)},
                     {"phi_peak_interior_deg", phi_peak_interior_deg},
                     {"phi_cv_interior_deg", phi_cv_interior_deg},
                     {"q_peak_pa", q_peak},
                     {"phi_peak_rows_to_end", static_cast<double>(peak_rows_to_end)},
                     {"porosity_initial", porosity_initial},
                     {"porosity_final", porosity_final},
                     {"porosity_interior_initial", porosity_interior_initial},
                     {"porosity_interior_final", porosity_interior_final},
                     {"eps_v_final", eps_v_final},
                     {"max_dilatancy_deg", max_dilatancy_deg},
                     {"max_inertial_number", max_inertial_number},
                     {"lw_wall_mismatch", lw_wall_mismatch},
                     {"lw_wall_ratio_cv", lw_wall_ratio_cv},
                     {"interior_grains", static_cast<double>(interior_grains)},
                     {"shear_stress_error_mean", shear_stress_error_mean},
                     {"shear_stress_error_max", shear_stress_error_max},
                     {"dt", dt},
                     {"dt_over_critical", dt_critical > 0 ? dt / dt_critical : 0.0},
                     {"dt_frictionless", dt_frictionless},
                     {"grain_density", grain_density}};
  m.insert(m.end(), mech.begin(), mech.end());
  for (const auto& s : stages) {
    m.push_back({s.name + ".steps", static_cast<double>(s.steps)});
    m.push_back({s.name + ".stress_error", s.stress_error});
    m.push_back({s.name + ".ufr", s.ufr});
    m.push_back({s.name + ".porosity", s.porosity});
  }
  return m;
}

namespace {


class StageFailed : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// The running test: world, servos and the measurements the stages share.
struct Rig {
  World& world;
  const TriaxialConfig& cfg;
  Observer* obs;
  double vs;  // solid volume
  std::array<ServoWall, 6> servo{};
  std::string stage;
  double target_p = 0.0;  // what the servo-held walls are asked for now [Pa]

  double length(int a) const { return world.walls()[2 * a + 1].point[a] - world.walls()[2 * a].point[a]; }
  Vec3 lengths() const { return {length(0), length(1), length(2)}; }
  double area(int a) const { return length((a + 1) % 3) * length((a + 2) % 3); }
  double face_stress(int f) const { return ServoWall::normal_force(world.walls()[f]) / area(f / 2); }
  double axis_stress(int a) const { return 0.5 * (face_stress(2 * a) + face_stress(2 * a + 1)); }
  double porosity() const { return 1.0 - vs / lengths().prod(); }
  double mean_stress() const { return (axis_stress(0) + axis_stress(1) + axis_stress(2)) / 3.0; }
  double stress_error(int first_face, int last_face) const {
    double e = 0.0;
    for (int f = first_face; f <= last_face; ++f)
      e = std::max(e, std::abs(face_stress(f) - target_p) / target_p);
    return e;
  }
  void servo_faces(int first_face, int last_face, const ServoGains& g) {
    for (int f = first_face; f <= last_face; ++f)
      servo[f].update(world.walls()[f], target_p * area(f / 2), world.dt(), g);
  }
  void stop_walls() {
    for (auto& w : world.walls()) w.velocity.setZero();
    for (auto& s : servo) s.reset();
  }
  // Interior measurement volume: the box shrunk by d_max from every wall.
  Region interior() const {
    Region r;
    const double m = cfg.material.d_max;
    for (int a = 0; a < 3; ++a) {
      r.lo[a] = world.walls()[2 * a].point[a] + m;
      r.hi[a] = world.walls()[2 * a + 1].point[a] - m;
    }
    return r;
  }
  StageReport report(const std::string& name, long steps0, bool converged, double err) const {
    StageReport s;
    s.name = name;
    s.converged = converged;
    s.steps = world.step_count() - steps0;
    s.time_s = s.steps * world.dt();
    s.stress_error = err;
    s.ufr = unbalanced_force_ratio(world);
    s.porosity = porosity();
    s.mean_stress = mean_stress();
    return s;
  }
};

// Love-Weber stress in the seed's form (Eq. 2.7): (1 - n) / sum V_p * sum_p sum_c,
// with n the porosity of the measurement volume itself and the sum over grains
// whose centres lie in it. Counting grains by their centres is biased where the
// region's faces cut the layering near the walls; the (1 - n) / sum V_p weight
// removes that bias. Also returns the porosity of the region.
Mat3 interior_stress(const World& w, const Region& reg, double& porosity_in) {
  const RegionVolumes vol = volumes_in(w.particles(), reg);
  const double solid_in = vol.solid, vp_in = vol.centres_inside;
  porosity_in = 1.0 - solid_in / reg.volume();
  const Mat3 plain = love_weber_stress(w, reg);  // sum / V
  return vp_in > 0.0 ? Mat3(plain * (solid_in / vp_in)) : plain;
}

// sin(phi_mob) of an axial and two lateral principal stresses (compression
// positive): (s1 - s3) / (s1 + s3) with s3 the lateral mean; 0 if the sum is not > 0.
double mobilised_sine(double axial, double lateral_a, double lateral_b) {
  const double s3 = 0.5 * (lateral_a + lateral_b);
  return (axial + s3) > 0.0 ? (axial - s3) / (axial + s3) : 0.0;
}
double sine_to_deg(double x) { return rad_to_deg(std::asin(std::clamp(x, -1.0, 1.0))); }

// Largest mean of `width` consecutive values; NaN when there are fewer.
double peak_of_running_mean(const std::vector<double>& x, std::size_t width) {
  const std::size_t n = x.size();
  if (n < width) return NAN;
  double best = -1.0;
  for (std::size_t i = 0; i + width <= n; ++i) {
    double sum = 0.0;
    for (std::size_t k = 0; k < width; ++k) sum += x[i + k];
    best = std::max(best, sum / static_cast<double>(width));
  }
  return best;
}

// sin(psi) = -d eps_v / (2 d eps1 - d eps_v), compression positive. A contraction faster
// than 2 d eps1 (a collapse) leaves the formula's domain: it is the most contractive
// angle, -90 deg, not +90.
double dilatancy_sine(double d_eps_v, double d_eps1) {
  const double denom = 2.0 * d_eps1 - d_eps_v;
  return denom > 0.0 ? -d_eps_v / denom : -1.0;
}

double kinetic_energy(const Particles& p) {
  double e = 0.0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    if (p.fixed[i]) continue;
    e += 0.5 * p.m[i] * p.v[i].squaredNorm() + 0.5 * (0.4 * p.m[i] * p.r[i] * p.r[i]) * p.w[i].squaredNorm();
  }
  return e;
}

// Servo all six walls to p0 until equilibrium (two consecutive passing checks).
// With ramp_steps > 0 the target goes geometrically from the present target to
// target_p over that many steps first. With check_ufr false only the walls' stresses
// are judged (see the unloading stage).
StageReport servo_to_equilibrium(Rig& rig, const std::string& name, double target_p, const ServoGains& g,
                                 double prog0, double prog1, long ramp_steps = 0, bool check_ufr = true) {
  const TriaxialConfig& cfg = rig.cfg;
  World& w = rig.world;
  rig.stage = name;
  const double p_from = rig.target_p;
  rig.target_p = target_p;
  if (rig.obs) rig.obs->on_stage(name);
  const long s0 = w.step_count();
  w.refresh();
  int passes = 0;
  double err = 0.0, ufr = 0.0;
  while (w.step_count() - s0 < cfg.prep_step_budget) {
    const long done = w.step_count() - s0;
    if (done < ramp_steps)
      rig.target_p = p_from * std::pow(target_p / p_from, static_cast<double>(done) / static_cast<double>(ramp_steps));
    else
      rig.target_p = target_p;
    rig.servo_faces(0, 5, g);
    w.step();
    if ((w.step_count() - s0) % cfg.check_interval != 0 || w.step_count() - s0 <= ramp_steps) continue;
    err = rig.stress_error(0, 5);
    ufr = unbalanced_force_ratio(w);
    passes = (err < cfg.stress_tolerance && (!check_ufr || ufr < cfg.ufr_tolerance)) ? passes + 1 : 0;
    if (rig.obs)
      rig.obs->on_progress(prog0 + (prog1 - prog0) * static_cast<double>(w.step_count() - s0) /
                                       static_cast<double>(cfg.prep_step_budget));
    if (passes >= 2) {
      rig.stop_walls();
      return rig.report(name, s0, true, err);
    }
  }
  rig.stop_walls();
  StageReport r = rig.report(name, s0, false, rig.stress_error(0, 5));
  // Far below the target: the walls were still closing in on the grains (their speed
  // is capped), not failing to settle them.
  const std::string closing =
      r.mean_stress < 0.1 * target_p
          ? "; the walls, at most at triaxial.prep_strain_rate " + fmt(cfg.prep_strain_rate) +
                " /s, were still closing in on the grains: raise prep_strain_rate or triaxial.prep_step_budget"
          : "";
  throw StageFailed("stage " + name + " did not reach equilibrium within its budget of " +
                    std::to_string(cfg.prep_step_budget) + " steps: wall stress error " + fmt(r.stress_error) +
                    " (tolerance " + fmt(cfg.stress_tolerance) + "), unbalanced-force ratio " + fmt(r.ufr) +
                    (check_ufr ? " (tolerance " + fmt(cfg.ufr_tolerance) + ")" : " (not judged in this stage)") +
                    ", mean stress " + fmt(r.mean_stress) +
                    " Pa for a target of " + fmt(target_p) + " Pa, porosity " + fmt(r.porosity) + closing);
}

// Walls held still; run until the unbalanced-force ratio passes (dense step ii).
StageReport stabilise(Rig& rig, const std::string& name) {
  const TriaxialConfig& cfg = rig.cfg;
  World& w = rig.world;
  rig.stage = name;
  if (rig.obs) rig.obs->on_stage(name);
  rig.stop_walls();
  const long s0 = w.step_count();
  w.refresh();
  int passes = 0;
  while (w.step_count() - s0 < cfg.prep_step_budget) {
    w.step();
    const long done = w.step_count() - s0;
    if (done % cfg.check_interval != 0 || done < cfg.stabilise_min_steps) continue;
    passes = unbalanced_force_ratio(w) < cfg.ufr_tolerance ? passes + 1 : 0;
    if (passes >= 2) return rig.report(name, s0, true, rig.stress_error(0, 5));
  }
  StageReport r = rig.report(name, s0, false, rig.stress_error(0, 5));
  throw StageFailed("stage " + name + " did not stabilise within its budget of " +
                    std::to_string(cfg.prep_step_budget) + " steps: unbalanced-force ratio " + fmt(r.ufr) +
                    " (tolerance " + fmt(cfg.ufr_tolerance) + ")");
}

// The axial strain of one shear step: how far a series row may lie from its nominal
// strain, either side (rows are taken within half of it).
double shear_step_strain(const TriaxialConfig& cfg, const TriaxialResult& res) { return cfg.strain_rate * res.dt; }

}  // namespace

// Whether the critical-state window is at critical state: no volume change (the
// dilatancy angle of the fitted eps_v slope) and no drift of phi_mob (a fitted change
// across the window larger than its tolerance and than twice its own standard error,
// which counts the rows' correlation). A window that fails keeps its phi_cv, with a
// warning that says what moved and what would help: the number is not a critical-state
// value, and maps and fits built on it inherit that.
void judge_critical_state(const TriaxialConfig& cfg, const std::vector<double>& e1, const std::vector<double>& ev,
                          const std::vector<double>& phi, TriaxialResult& res) {
  const std::string window = "eps1 " + fmt(cfg.cv_from) + "-" + fmt(cfg.cv_to);
  // No "; " inside: a task's warnings are joined with it.
  const std::string advice =
      " (shear further: triaxial.axial_strain, or move the window: triaxial.cv_from, triaxial.cv_to)";
  // A window where the volume jumps (the dilatancy angle near its +-90 deg bounds) or
  // the stress ratio scatters by tens of degrees about its trend (the drift's standard
  // error, not its size: a steady post-peak fall of 10 deg is what more strain cures)
  // is no slow approach to a critical state: a collapse, a gas, a sample too small for
  // the rate.
  const std::string swing_advice =
      " (phi_mob and the volume swing rather than drift: the shear is too fast or the sample too small for a "
      "steady state, so a lower triaxial.strain_rate or more triaxial.particles, not more strain)";
  if (e1.size() >= static_cast<std::size_t>(TriaxialResult::kMinWindowRows)) {
    const double r = linear_trend(e1, ev).slope;  // compression positive: dilation r < 0
    res.cv_dilatancy_deg = sine_to_deg(dilatancy_sine(r, 1.0));
    const Trend drift = linear_trend(e1, phi);
    const double width = e1.back() - e1.front();
    res.cv_drift_deg = drift.slope * width;
    res.cv_drift_se_deg = drift.se * width;
    std::vector<std::string> why;
    if (std::abs(res.cv_dilatancy_deg) > cfg.cv_dilatancy_tolerance_deg)
      why.push_back(std::string("the sample still ") + (res.cv_dilatancy_deg > 0 ? "dilates" : "contracts") +
                    " (dilatancy angle " + fmt(res.cv_dilatancy_deg, 2) + " deg over the window, |psi| <= " +
                    fmt(cfg.cv_dilatancy_tolerance_deg, 2) + " deg expected), so phi_cv carries dilatancy");
    if (std::abs(res.cv_drift_deg) > cfg.cv_drift_tolerance_deg && std::abs(res.cv_drift_deg) > 2.0 * res.cv_drift_se_deg)
      why.push_back(std::string("phi_mob ") + (res.cv_drift_deg < 0 ? "falls" : "rises") + " by " +
                    fmt(std::abs(res.cv_drift_deg), 2) + " +- " + fmt(res.cv_drift_se_deg, 2) + " deg across the window");
    const bool swings = std::abs(res.cv_dilatancy_deg) >= 45.0 || res.cv_drift_se_deg >= 5.0;
    if (!why.empty())
      res.outcome.warnings.push_back("not at critical state over " + window + ": " + why.front() +
                                     (why.size() > 1 ? " and " + why.back() : std::string()) +
                                     (swings ? swing_advice : advice));
  } else {
    res.phi_cv_se_deg = NAN;
    res.outcome.warnings.push_back(
        "the critical-state window (" + window + ") holds " + std::to_string(e1.size()) + " series row" +
        (e1.size() == 1 ? "" : "s") + ", fewer than " + std::to_string(TriaxialResult::kMinWindowRows) +
        ": too few to judge whether the sample is at critical state there or to give phi_cv a standard error "
        "(phi_cv_se_deg not measured: sample the series more finely, triaxial.sample_strain or "
        "triaxial.sample_steps, or widen the window, triaxial.cv_from and triaxial.cv_to)");
    return;
  }
  if (res.cv_effective_samples < 4.0)
    res.outcome.warnings.push_back("the critical-state window (" + window + ") holds about " +
                                   fmt(res.cv_effective_samples, 2) +
                                   " independent samples of phi_mob, so phi_cv_se_deg is itself uncertain (a wider "
                                   "window or replicas pin phi_cv down)");
}

// A stress spike shorter than the running mean (seen: the axial walls' stress up 80%
// for two rows of 0.001 strain at eps1 = 0.10, the interior's not at all, then the
// kinetic energy up sevenfold as the chain gave way) sets the maximum of the rows
// without being the material's peak strength.
void judge_peak(const TriaxialConfig& cfg, TriaxialResult& res) {
  const bool at_end = res.peak_rows_to_end >= 0 && res.peak_rows_to_end < TriaxialResult::kPeakSmoothingRows / 2;
  // A loose sample hardens into its critical state: its largest row is one of the
  // window's (34.0 deg at eps1 0.288, 4.6 deg above phi_cv, read as a peak).
  if (cfg.in_cv_window(res.eps1_at_peak, shear_step_strain(cfg, res)))
    res.outcome.warnings.push_back("phi_peak " + fmt(res.phi_peak_deg) + " deg lies at eps1 " +
                                   fmt(res.eps1_at_peak, 3) + ", inside the critical-state window (eps1 " +
                                   fmt(cfg.cv_from) + "-" + fmt(cfg.cv_to) +
                                   "): either the sample shows no peak before its critical state (as a loose sample "
                                   "does), and phi_peak is the highest of the window's scatter, or the window starts "
                                   "before the peak (a later triaxial.cv_from)");
  else if (at_end)
    // The centred running mean cannot reach the last rows, so it cannot tell a curve
    // still rising from a spike there (one row of 20 at the end was called a spike).
    res.outcome.warnings.push_back("phi_mob is largest " +
                                   std::string(res.peak_rows_to_end == 0 ? "in the series' last row"
                                                                         : "next to the series' end") +
                                   " (phi_peak " + fmt(res.phi_peak_deg) + " deg at eps1 " +
                                   fmt(res.eps1_at_peak, 3) + "), which the " +
                                   std::to_string(TriaxialResult::kPeakSmoothingRows) +
                                   "-row running mean does not reach: the curve was still rising there, or a spike of "
                                   "the walls' stress ended the series (a larger triaxial.axial_strain tells them apart)");
  // A NaN smoothed peak (too few rows) tells nothing.
  if (!TriaxialResult::peak_on_a_spike(res.phi_peak_deg, res.phi_peak_smoothed_deg, res.peak_rows_to_end)) return;
  const std::string span = cfg.sample_steps > 0 ? std::to_string(TriaxialResult::kPeakSmoothingRows) + " rows"
                                                : fmt(TriaxialResult::kPeakSmoothingRows * cfg.sample_strain) +
                                                      " of strain";
  std::string interior;
  if (res.interior_measured() && std::isfinite(res.phi_peak_interior_deg))
    interior = ", the interior's Love-Weber stress peaks at " + fmt(res.phi_peak_interior_deg) + " deg";
  res.outcome.warnings.push_back("phi_peak " + fmt(res.phi_peak_deg) + " deg (at eps1 " + fmt(res.eps1_at_peak, 3) +
                                 ") rests on a spike of the walls' stress ratio: the running mean over " + span +
                                 " peaks at " + fmt(res.phi_peak_smoothed_deg) + " deg" + interior +
                                 " (phi_peak_smoothed_deg is the steadier figure, replicas show how often spikes occur)");
}

namespace {

Series triaxial_series() {
  Series s;
  s.name = "triaxial";
  s.columns = {"eps1",  "eps2",   "eps3",    "eps_v", "porosity", "porosity_interior", "sigma1", "sigma2", "sigma3",
               "p",     "q",      "q_over_p", "phi_mob_deg", "lw_xx", "lw_yy", "lw_zz", "lw_p",
               "lw_q",  "z_all",  "z_mech",  "kinetic", "ufr",    "inertial", "time", "step",
               "z_interior", "z_mech_interior", "lw_xy", "lw_xz", "lw_yz"};
  s.units = {"1",  "1",  "1",  "1",   "1",   "1",  "Pa", "Pa", "Pa", "Pa", "Pa", "1", "deg",
             "Pa", "Pa", "Pa", "Pa", "Pa", "1",  "1",  "J",  "1",  "1",  "s",  "1",
             "1",  "1",  "Pa", "Pa", "Pa"};
  return s;
}

// The grains before any wall moves: diameters from the material's grading, inserted
// at random at a low solid fraction into a box of the configured aspect ratio.
struct Sample {
  Particles particles;
  Vec3 lo, hi;
  double solid_volume = 0.0;
  double width = 0.0;  // lateral side of the box [m]
};

Sample make_sample(const TriaxialConfig& cfg, TriaxialResult& res) {
  std::mt19937_64 rng(cfg.seed);
  std::vector<double> radii = sample_radii(cfg.particles, cfg.material.grading(), rng);
  Sample smp;
  double dsum = 0.0;
  for (double r : radii) {
    smp.solid_volume += sphere_volume(r);
    dsum += 2.0 * r;
  }
  res.d_mean = dsum / static_cast<double>(radii.size());
  res.particles = static_cast<long>(radii.size());
  smp.width = std::cbrt(smp.solid_volume / (cfg.initial_solid_fraction * cfg.aspect_ratio));
  smp.lo = Vec3::Zero();
  smp.hi = Vec3(smp.width, smp.width, smp.width * cfg.aspect_ratio);
  insert_random(smp.particles, radii, smp.lo, smp.hi, cfg.grain_density(), rng);
  return smp;
}

WorldOptions world_options(const TriaxialConfig& cfg, const Particles& p) {
  double m_min = 1e300;
  for (double m : p.m) m_min = std::min(m_min, m);
  WorldOptions opt;
  opt.dt = cfg.dt > 0.0 ? cfg.dt : timestep_from_factor(cfg.dt_factor, m_min, cfg.material.kn);
  opt.threads = cfg.threads;
  opt.max_overlap_fraction = cfg.max_overlap_fraction;
  opt.local_damping = cfg.prep_damping;
  return opt;
}

// The step is checked against the target law (the stiffest one used); a dense
// preparation then starts frictionless, at that law's own larger step.
void choose_steps(World& world, const TriaxialConfig& cfg, const ContactParams& target, double dt,
                  TriaxialResult& res) {
  const StabilityLimits lim = stability_limits(world);
  res.dt = dt;
  res.dt_critical = lim.governing().dt_critical;
  res.critical_mode = lim.governing().mode + " (" + lim.governing().contact + ")";
  if (cfg.packing != Packing::dense) return;
  world.set_contact_params(frictionless(target));  // dense step (i)
  const double scale = cfg.frictionless_dt_scale > 0.0 ? cfg.frictionless_dt_scale
                                                        : frictionless_step_ratio(world, target, dt);
  res.dt_frictionless = dt * scale;
  world.set_dt(res.dt_frictionless);  // refuses a step above the frictionless law's limit
}

// Isotropic preparation to p0. Loose: with the target law. Dense (the seed's): the
// frictionless law to prep_pressure_factor * p0, unloaded to p0, then the target law
// switched on, stabilised and recompressed.
void prepare(Rig& rig, const ContactParams& target, double dt, double width, TriaxialResult& res) {
  const TriaxialConfig& cfg = rig.cfg;
  World& world = rig.world;
  const ServoGains gains{cfg.servo_alpha, cfg.servo_beta, 0.5 * cfg.prep_strain_rate * width};
  if (cfg.packing != Packing::dense) {
    res.stages.push_back(servo_to_equilibrium(rig, "isotropic_compression", cfg.confining_pressure, gains, 0.0, 0.3));
    return;
  }
  const double p0 = cfg.confining_pressure, pf = cfg.prep_pressure_factor;
  res.stages.push_back(servo_to_equilibrium(rig, "isotropic_compression", pf * p0, gains, 0.0, 0.1));
  rig.target_p = pf * p0;
  if (pf != 1.0)
    // The walls' stresses only: a frictionless packing held by servo walls at p0
    // keeps creeping (UFR 0.01-0.045 for 160,000 steps in one 2,000-grain run, a
    // round-off decides whether it dips below 0.01 early), while friction,
    // switched on next, arrests it within the stabilise stage, which judges UFR.
    // unloading_steps counts steps of dt: the ramp lasts as long in simulated time
    // whatever step the frictionless stages take.
    res.stages.push_back(servo_to_equilibrium(rig, "unloading", p0, gains, 0.1, 0.15,
                                              std::lround(static_cast<double>(cfg.unloading_steps) * dt / world.dt()),
                                              false));
  world.set_dt(dt);  // before the stiffer law, which would refuse the larger step
  world.set_contact_params(target);
  res.stages.push_back(stabilise(rig, "stabilise"));
  res.stages.push_back(servo_to_equilibrium(rig, "recompression", cfg.confining_pressure, gains, 0.15, 0.3));
}

// One row of the shear's series a call, strains from the box at the start of shear;
// also keeps the lateral walls' stress error.
struct ShearRecorder {
  Rig& rig;
  TriaxialResult& res;
  Vec3 L0;
  double V0;
  long s0;
  double err_sum = 0.0;
  long err_n = 0;

  ShearRecorder(Rig& r, TriaxialResult& out)
      : rig(r), res(out), L0(r.lengths()), V0(L0.prod()), s0(r.world.step_count()) {}

  double axial_strain() const { return (L0[2] - rig.length(2)) / L0[2]; }

  double record() {
    const TriaxialConfig& cfg = rig.cfg;
    const World& world = rig.world;
    const Vec3 L = rig.lengths();
    const double e1 = (L0[2] - L[2]) / L0[2], e2 = (L0[0] - L[0]) / L0[0], e3 = (L0[1] - L[1]) / L0[1];
    const double ev = (V0 - L.prod()) / V0;
    const double s1 = rig.axis_stress(2), s2 = rig.axis_stress(0), s3 = rig.axis_stress(1);
    const double s3m = 0.5 * (s2 + s3);
    const double pm = (s1 + s2 + s3) / 3.0, q = s1 - s3m;
    double n_in = 0.0;
    const Mat3 lw = interior_stress(world, rig.interior(), n_in);
    const double lwp = lw.trace() / 3.0, lwq = lw(2, 2) - 0.5 * (lw(0, 0) + lw(1, 1));
    const Coordination z = coordination(world);
    const Coordination z_in = coordination(world, rig.interior());
    const double ufr = unbalanced_force_ratio(world);
    const double inertial = inertial_number(cfg.strain_rate, res.d_mean, cfg.grain_density(), pm);
    for (int f = 0; f < 4; ++f) {
      const double e = std::abs(rig.face_stress(f) - cfg.confining_pressure) / cfg.confining_pressure;
      if (world.step_count() > s0) {
        err_sum += e;
        ++err_n;
        res.shear_stress_error_max = std::max(res.shear_stress_error_max, e);
      }
    }
    res.series.add({e1, e2, e3, ev, rig.porosity(), n_in, s1, s2, s3, pm, q, pm > 0 ? q / pm : 0.0,
                    sine_to_deg(mobilised_sine(s1, s2, s3)), lw(0, 0), lw(1, 1), lw(2, 2), lwp, lwq,
                    z.all, z.mechanical, kinetic_energy(world.particles()), ufr, inertial, world.time(),
                    static_cast<double>(world.step_count()), z_in.all, z_in.mechanical,
                    // The symmetric shear components (the antisymmetric part is the rolling
                    // moments' couple stress): near zero while the principal axes stay the
                    // box's (frictionless walls), so they show when a shear band tilts them.
                    0.5 * (lw(0, 1) + lw(1, 0)), 0.5 * (lw(0, 2) + lw(2, 0)), 0.5 * (lw(1, 2) + lw(2, 1))},
                   rig.obs);
    return e1;
  }
};

// Grains whose centres lie in the interior now.
long interior_count(const Rig& rig) {
  const Region in = rig.interior();
  long n = 0;
  for (const Vec3& x : rig.world.particles().x) n += in.contains(x) ? 1 : 0;
  return n;
}

// The deviatoric stage: top and bottom walls at a constant axial strain rate,
// lateral walls servo-held at p0, to the target axial strain.
void shear(Rig& rig, TriaxialResult& res) {
  const TriaxialConfig& cfg = rig.cfg;
  World& world = rig.world;
  Observer* obs = rig.obs;
  rig.stage = "shear";
  rig.target_p = cfg.confining_pressure;
  if (obs) obs->on_stage("shear");
  const double t_shear0 = world.time();
  ShearRecorder rec(rig, res);
  const Vec3& L0 = rec.L0;
  for (int a = 0; a < 3; ++a) res.sample_size[a] = L0[a];
  res.porosity_initial = rig.porosity();
  {
    double n_in = 0.0;
    const Mat3 lw = interior_stress(world, rig.interior(), n_in);
    res.porosity_interior_initial = n_in;
    res.interior_grains = interior_count(rig);
    const double p_walls = rig.mean_stress();
    res.lw_wall_mismatch = std::abs(lw.trace() / 3.0 - p_walls) / p_walls;
  }
  // Top and bottom walls: constant speed 0.5 * rate * L0 each, reached by a
  // linear ramp in time over the first shear_ramp_strain (a sudden start hits
  // the heavy, stiff grains like an impact and shows up as a false peak).
  const double v_axial = 0.5 * cfg.strain_rate * L0[2];
  const double t_ramp = 2.0 * cfg.shear_ramp_strain / cfg.strain_rate;
  auto set_axial_speed = [&]() {
    const double t = world.time() - t_shear0;
    const double v = t_ramp > 0.0 ? v_axial * std::min(1.0, (t + world.dt()) / t_ramp) : v_axial;
    world.walls()[4].velocity = v * world.walls()[4].normal;
    world.walls()[5].velocity = v * world.walls()[5].normal;
  };
  const double lat_rate = cfg.shear_servo_strain_rate > 0 ? cfg.shear_servo_strain_rate : 20.0 * cfg.strain_rate;
  const ServoGains gains{cfg.servo_alpha, cfg.servo_beta, 0.5 * lat_rate * std::max(L0[0], L0[1])};

  world.refresh();
  rec.record();
  if (obs) obs->on_snapshot("prepared", world.time(), world.particles());
  const double snapshot_strain = 0.05;  // ParaView frames: enough to see a shear band form
  double next_snapshot = snapshot_strain;
  double next = cfg.sample_strain;
  const double dstrain = cfg.strain_rate * world.dt();  // per step
  const long est_steps = static_cast<long>(std::ceil(cfg.axial_strain / dstrain));
  const long budget = est_steps + est_steps / 10 + static_cast<long>(t_ramp / world.dt()) + 100;
  double e1 = 0.0;
  // The end is judged with the sampling's tolerance: otherwise a sample landing half
  // a step short of the target was followed by one more step and a near-duplicate
  // last row and frame, in some replicas and not others.
  const double end = cfg.axial_strain - 0.5 * dstrain;
  while (e1 < end) {
    if (world.step_count() - rec.s0 > budget)
      throw StageFailed("shear did not reach the target axial strain within " + std::to_string(budget) + " steps");
    rig.servo_faces(0, 3, gains);
    set_axial_speed();
    world.step();
    e1 = rec.axial_strain();
    const bool due = cfg.sample_steps > 0 ? (world.step_count() - rec.s0) % cfg.sample_steps == 0
                                           : e1 >= next - 0.5 * dstrain;
    if (due || e1 >= end) {
      rec.record();
      next += cfg.sample_strain;
      if (obs) obs->on_progress(0.3 + 0.7 * std::min(1.0, e1 / cfg.axial_strain));
    }
    // Frames at their strain whatever the rows' spacing (rows every N steps may
    // span more than a frame's 0.05).
    if (obs && e1 >= next_snapshot - 0.5 * dstrain && e1 < end) {
      char label[32];
      std::snprintf(label, sizeof label, "eps1=%.2f", next_snapshot);
      obs->on_snapshot(label, world.time(), world.particles());
      next_snapshot += snapshot_strain;
    }
  }
  if (obs) obs->on_snapshot("final", world.time(), world.particles());
  // The interior shrinks with the sample: the critical state is measured on fewer.
  res.interior_grains = std::min(res.interior_grains, interior_count(rig));
  rig.stop_walls();
  res.shear_stress_error_mean = rec.err_n ? rec.err_sum / static_cast<double>(rec.err_n) : 0.0;
  res.stages.push_back(rig.report("shear", rec.s0, true, rig.stress_error(0, 3)));
}

// The peak and critical-state angles from the walls and from the interior
// Love-Weber stress, with the critical-state window judged.
void angles_from_series(const TriaxialConfig& cfg, TriaxialResult& res) {
  const Series& s = res.series;
  const std::size_t c_e1 = s.column("eps1"), c_ev = s.column("eps_v"), c_s1 = s.column("sigma1"),
                    c_s2 = s.column("sigma2"), c_s3 = s.column("sigma3"), c_q = s.column("q"),
                    c_in = s.column("inertial");
  const std::size_t c_xx = s.column("lw_xx"), c_yy = s.column("lw_yy"), c_zz = s.column("lw_zz"),
                    c_lwp = s.column("lw_p"), c_p = s.column("p");
  double best = -1.0, best_in = -1.0, cv_in = 0.0, lw_ratio = 0.0;
  int lw_rows = 0;
  std::vector<double> sines, cv, cv_e1, cv_ev, cv_phi;
  for (const auto& r : s.rows) {
    const double x = mobilised_sine(r[c_s1], r[c_s2], r[c_s3]);
    sines.push_back(x);
    const double x_in = mobilised_sine(r[c_zz], r[c_xx], r[c_yy]);
    if (x > best) {
      best = x;
      res.eps1_at_peak = r[c_e1];
      res.q_peak = r[c_q];
      res.peak_rows_to_end = static_cast<int>(s.rows.size() - sines.size());
    }
    best_in = std::max(best_in, x_in);
    if (cfg.in_cv_window(r[c_e1], shear_step_strain(cfg, res))) {
      cv.push_back(x);
      cv_in += x_in;
      if (r[c_p] > 0.0) {  // a row the walls carried nothing in has no ratio (such rows are warned)
        lw_ratio += r[c_lwp] / r[c_p];
        ++lw_rows;
      }
      cv_e1.push_back(r[c_e1]);
      cv_ev.push_back(r[c_ev]);
      cv_phi.push_back(sine_to_deg(x));
    }
    res.max_inertial_number = std::max(res.max_inertial_number, r[c_in]);
  }
  res.phi_peak_deg = sine_to_deg(best);
  res.phi_peak_smoothed_deg = sine_to_deg(peak_of_running_mean(sines, TriaxialResult::kPeakSmoothingRows));
  res.phi_peak_interior_deg = sine_to_deg(best_in);
  judge_peak(cfg, res);
  if (sines.size() < static_cast<std::size_t>(TriaxialResult::kPeakSmoothingRows))
    res.outcome.warnings.push_back(
        "the shear's series holds " + std::to_string(sines.size()) + " rows, too few to locate the peak: phi_peak " +
        fmt(res.phi_peak_deg) + " deg is the largest of them (at eps1 " + fmt(res.eps1_at_peak, 3) +
        ") and phi_peak_smoothed_deg is not measured (sample the series more finely: triaxial.sample_strain or "
        "triaxial.sample_steps)");
  res.cv_samples = static_cast<int>(cv.size());
  if (cv.empty()) {
    res.outcome.warnings.push_back("critical-state window holds no sample: phi_cv not measured");
    res.phi_cv_deg = NAN;
    res.phi_cv_se_deg = NAN;
    res.phi_cv_interior_deg = NAN;
    return;
  }
  const MeanEstimate est = correlated_mean(cv);
  res.phi_cv_deg = sine_to_deg(est.mean);
  res.phi_cv_interior_deg = sine_to_deg(cv_in / static_cast<double>(cv.size()));
  res.lw_wall_ratio_cv = lw_rows > 0 ? lw_ratio / lw_rows : NAN;
  res.phi_cv_se_deg = rad_to_deg(est.se / std::sqrt(std::max(1e-12, 1.0 - est.mean * est.mean)));
  res.cv_effective_samples = est.effective_samples;
  judge_critical_state(cfg, cv_e1, cv_ev, cv_phi, res);
}

}  // namespace

// The window's mean coordination, its rows in extension (sigma1 below the lateral
// walls' mean) and its rows where the top and bottom walls carried nothing (sigma1 = 0).
void judge_window(const TriaxialConfig& cfg, TriaxialResult& res) {
  const Series& s = res.series;
  const std::size_t c_e1 = s.column("eps1"), c_z = s.column("z_all"), c_s1 = s.column("sigma1"),
                    c_s2 = s.column("sigma2"), c_s3 = s.column("sigma3");
  double z = 0.0;
  int n = 0;
  res.cv_rows_in_extension = res.cv_rows_unloaded = 0;
  for (const auto& r : s.rows) {
    if (!cfg.in_cv_window(r[c_e1], shear_step_strain(cfg, res))) continue;
    z += r[c_z];
    ++n;
    res.cv_rows_unloaded += r[c_s1] <= 0.0;
    res.cv_rows_in_extension += r[c_s1] < 0.5 * (r[c_s2] + r[c_s3]);
  }
  res.cv_coordination = n > 0 ? z / n : NAN;
}

// What ends a finished run as no triaxial test at all (empty: it was one). Warnings
// grade what a result carries; these are not a result: the lateral walls lost sigma3
// (a shear far too fast for the servo), the top and bottom walls lost the sample
// (sigma1 = 0 on more than a tenth of the window's rows, at least two: the walls'
// stress no longer measures it; one row is warned), the sample lost its contact
// network over the window (a granular gas), or the axial stress fell below the
// confining one there on average beyond its noise (phi_cv + 2 se < 0: no critical
// state does that, frictionless grains included; within the noise, as 50 frictionless
// grains at aspect ratio 4 read -0.6 +- 2.9 deg, it is warned).
std::string why_invalid(const TriaxialConfig& cfg, const TriaxialResult& res) {
  const std::string remedy = " (a lower triaxial.strain_rate or triaxial.scaled_density, more triaxial.particles)";
  if (res.shear_stress_error_mean > cfg.invalid_stress_error)
    return "the lateral walls lost sigma3: it strayed from p0 by " + fmt(100.0 * res.shear_stress_error_mean) +
           "% on average during shear (limit " + fmt(100.0 * cfg.invalid_stress_error) +
           "%), so this was no drained test at p0" + remedy;
  if (res.cv_rows_unloaded > std::max(1.0, 0.1 * res.cv_samples))
    return "the top and bottom walls lost the sample: sigma1 was 0 on " + std::to_string(res.cv_rows_unloaded) +
           " of the " + std::to_string(res.cv_samples) + " rows of the critical-state window (grains no longer pressed "
           "against them), so the walls' stress measures no critical state" + remedy;
  if (res.cv_coordination < cfg.invalid_coordination)
    return "the sample lost its contact network: mean coordination number " + fmt(res.cv_coordination, 3) +
           " over the critical-state window (below " + fmt(cfg.invalid_coordination) +
           ": fewer than one contact for eight grains, a collisional gas, not a solid at critical state)" + remedy;
  if (res.phi_cv_deg + 2.0 * (std::isfinite(res.phi_cv_se_deg) ? res.phi_cv_se_deg : 0.0) < 0.0)
    return "no shear strength: phi_cv is negative (" + fmt(res.phi_cv_deg, 2) +
           (std::isfinite(res.phi_cv_se_deg) ? " +- " + fmt(res.phi_cv_se_deg, 2) +
                                                   " deg, below zero by more than two standard errors"
                                             : std::string(" deg, its standard error not measured")) +
           "), the axial stress fell below the confining one over "
           "the critical-state window, which no critical state does: the sample is too small or sheared too fast to "
           "have one" + remedy;
  return "";
}

namespace {

// Final state and the largest dilatancy angle over any dilatancy_window of strain.
void volume_change_from_series(const TriaxialConfig& cfg, TriaxialResult& res) {
  const Series& s = res.series;
  const std::size_t c_e1 = s.column("eps1"), c_ev = s.column("eps_v");
  res.porosity_final = s.rows.back()[s.column("porosity")];
  res.porosity_interior_final = s.rows.back()[s.column("porosity_interior")];
  res.eps_v_final = s.rows.back()[c_ev];
  // Rows lie up to half a shear step from their strain (TriaxialConfig::in_cv_window).
  const double span = cfg.dilatancy_window - shear_step_strain(cfg, res) - 1e-9;
  res.max_dilatancy_deg = NAN;
  for (std::size_t i = 0; i < s.rows.size(); ++i) {
    for (std::size_t j = i + 1; j < s.rows.size(); ++j) {
      const double de1 = s.rows[j][c_e1] - s.rows[i][c_e1];
      if (de1 < span) continue;
      const double dev = s.rows[j][c_ev] - s.rows[i][c_ev];
      res.max_dilatancy_deg = std::fmax(res.max_dilatancy_deg, sine_to_deg(dilatancy_sine(dev, de1)));  // NaN: none yet
      break;
    }
  }
  // A shear shorter than the window has no pair of rows that far apart: the angle
  // stayed at its starting -90 deg and was stored as measured.
  if (std::isnan(res.max_dilatancy_deg))
    res.outcome.warnings.push_back("the shear, to eps1 " + fmt(cfg.axial_strain) +
                                   ", is shorter than triaxial.dilatancy_window (" + fmt(cfg.dilatancy_window) +
                                   "): max_dilatancy_deg is not measured");
}

// A small sample's interior holds a few grains or none (50 grains: about 2), and its
// porosity, Love-Weber stress and angles would be stored as if measured.
void judge_the_interior(const TriaxialConfig& cfg, TriaxialResult& res) {
  if (res.interior_measured()) return;
  for (double* v : {&res.phi_peak_interior_deg, &res.phi_cv_interior_deg, &res.porosity_interior_initial,
                    &res.porosity_interior_final, &res.lw_wall_mismatch, &res.lw_wall_ratio_cv})
    *v = NAN;
  res.outcome.warnings.push_back("the interior (the box less d_max = " + fmt(cfg.material.d_max) +
                                 " m from each wall) held " + std::to_string(res.interior_grains) +
                                 " grains at the start or the end of shear, fewer than " +
                                 std::to_string(TriaxialResult::kMinInteriorGrains) +
                                 ": its porosity, Love-Weber stress, angles and coordination are not measured "
                                 "(more triaxial.particles give it grains)");
}

void warn_about_the_regime(const TriaxialConfig& cfg, TriaxialResult& res) {
  if (res.max_inertial_number > cfg.quasi_static_inertial)
    res.outcome.warnings.push_back("not quasi-static: largest inertial number (strain rate * d_mean * sqrt(rho/p)) " +
                                   fmt(res.max_inertial_number) +
                                   " exceeds " + fmt(cfg.quasi_static_inertial) +
                                   " (a slower triaxial.strain_rate or a smaller triaxial.scaled_density lowers it)");
  if (cfg.shear_damping > 0.0)
    res.outcome.warnings.push_back("local damping " + fmt(cfg.shear_damping) +
                                   " was on during shear: a diagnostic, not the seed's undamped protocol; its forces "
                                   "carry part of the load, so the walls' angles overstate the contact network's "
                                   "(phi_cv " + fmt(res.phi_cv_deg, 3) + " deg at the walls, " +
                                   (std::isnan(res.phi_cv_interior_deg) ? std::string("not measured")
                                                                        : fmt(res.phi_cv_interior_deg, 3) + " deg") +
                                   " in the interior)");
  const auto window_rows = [&](int n) {
    return std::to_string(n) + " of the " + std::to_string(res.cv_samples) + " rows of the critical-state window";
  };
  if (res.cv_rows_unloaded > 0)
    res.outcome.warnings.push_back("sigma1 was 0 on " + window_rows(res.cv_rows_unloaded) +
                                   ": the top and bottom walls lost the sample for a moment");
  // Within two standard errors of zero: noise about a critical state with almost no strength.
  if (res.phi_cv_deg < 0.0)
    res.outcome.warnings.push_back("phi_cv is negative (" + fmt(res.phi_cv_deg, 2) + " +- " + fmt(res.phi_cv_se_deg, 2) +
                                   " deg), within two standard errors of zero: the sample is too small or sheared too "
                                   "fast to measure a critical state this weak (more triaxial.particles, a lower "
                                   "strain_rate)");
  if (res.cv_coordination < TriaxialResult::kSparseCoordination)
    res.outcome.warnings.push_back("the contact network was sparse over the critical-state window: mean coordination "
                                   "number " + fmt(res.cv_coordination, 3) + ", below " +
                                   fmt(TriaxialResult::kSparseCoordination) +
                                   " (many grains touched no other), so the walls' stress measures a collisional flow "
                                   "more than a critical state (a lower triaxial.strain_rate or "
                                   "triaxial.scaled_density, more triaxial.particles)");
  if (res.cv_rows_in_extension > 0)
    res.outcome.warnings.push_back("sigma1 fell below sigma3 on " + window_rows(res.cv_rows_in_extension) +
                                   " (extension, where the test compresses): the sample is too small or sheared too "
                                   "fast for a steady critical state there");
  if (res.shear_stress_error_mean > 5.0 * cfg.stress_tolerance)
    res.outcome.warnings.push_back("lateral walls held sigma3 only within " +
                                   fmt(100.0 * res.shear_stress_error_mean) + "% on average during shear");
}

// What the engine's instability message cannot know: the step it names may be the
// frictionless stages' own (larger than dt), and an overlap past the limit under a
// stage's load is the load's, not the step's, when the stiffness is low against it
// (the dense preparation's first stage compresses to prep_pressure_factor * p0).
std::string instability_context(const Rig& rig, const InstabilityError& e, const TriaxialResult& res) {
  const TriaxialConfig& cfg = rig.cfg;
  std::string s;
  if (rig.world.dt() != res.dt && res.dt_frictionless > 0.0)
    s += " (that step is the frictionless stages' own, " + fmt(res.dt_frictionless / res.dt, 4) + " x dt, dt = " +
         fmt(res.dt) + " s: the same margin to their own critical step)";
  if (e.quantity() != "overlap") return s;
  const double kappa = cfg.stiffness_number(rig.target_p);
  // The dense preparation's first stage, at its target (not ramping down from it).
  const bool at_prep_load = cfg.prep_pressure_factor != 1.0 &&
                            std::abs(rig.target_p - cfg.prep_pressure_factor * cfg.confining_pressure) <=
                                1e-9 * rig.target_p;
  s += "; the stage loads the grains to " + fmt(rig.target_p) + " Pa" +
       (at_prep_load ? " (triaxial.prep_pressure_factor " + fmt(cfg.prep_pressure_factor) + " x p0)" : std::string()) +
       ", where kn / (p d_min) = " + fmt(kappa, 3);
  if (kappa < TriaxialConfig::kLowStiffnessNumber)
    s += ": a stiffness this low against the load presses grains deep into each other whatever the step (the "
         "seed's material: 3e5 at 100 kPa, 3000 in its dense preparation); " +
         std::string(TriaxialConfig::low_stiffness_remedy(at_prep_load));
  if (rig.stage != "shear" && cfg.prep_walls_too_fast())
    s += "; " + cfg.prep_wall_impact_words();
  // In shear the walls drive the grains: far past the quasi-static limit they ram
  // them into each other faster than the contacts push back (5 /s on 400 grains:
  // an overlap of 0.29 of a radius after 26,000 steps, the shear being 10 steps).
  const double inertial = cfg.nominal_inertial_number();
  if (rig.stage == "shear" && inertial > 10.0 * cfg.quasi_static_inertial)
    s += "; the shear at triaxial.strain_rate " + fmt(cfg.strain_rate) + " /s has an inertial number of " +
         fmt(inertial, 3) + " at p0, " + fmt(inertial / cfg.quasi_static_inertial, 3) +
         " x the quasi-static limit: the walls ram the grains into each other, so a lower triaxial.strain_rate";
  return s;
}

// What a preparation stage that ran out of budget cannot know: at a step close to an
// isolated pair's critical step, a grain with several contacts is past its own limit
// in the rotational modes and the packing jitters without settling or blowing up.
// Measured (400 grains, dense, theta 30, eta 0.1): at 0.55 and 0.62 of the pair's
// critical step the stabilise stage kept an unbalanced-force ratio of 0.02-0.05 for
// 400,000 steps, with the preparation's damping at 0.3 or 0.6; at 0.41 (the default
// dt_factor 0.3) it settles in a few thousand.
std::string not_converged_context(const TriaxialConfig& cfg, const TriaxialResult& res, const std::string& stage,
                                  const std::string& message) {
  if (stage == "shear") return "";  // its budget follows from the strain, not from prep_step_budget
  const bool near_limit = res.dt_critical > 0.0 && res.dt / res.dt_critical > TriaxialConfig::kJitterStepFraction;
  std::string s;
  // The jitter was measured over the default budget; a shorter one may just be short.
  if (message.find("prep_step_budget") == std::string::npos &&
      (!near_limit || cfg.prep_step_budget < TriaxialConfig{}.prep_step_budget))
    s += "; a larger triaxial.prep_step_budget (" + std::to_string(cfg.prep_step_budget) +
         " steps) gives the stage more time";
  if (near_limit) {
    const double suggest = TriaxialConfig::kSuggestedStepFraction * res.dt_critical;
    const std::string key = cfg.dt > 0.0 ? "triaxial.dt " + fmt(cfg.dt) + " s" : "triaxial.dt_factor " + fmt(cfg.dt_factor);
    const std::string fix = cfg.dt > 0.0 ? "a triaxial.dt of about " + fmt(suggest, 3) + " s"
                                         : "a triaxial.dt_factor of about " + fmt(cfg.dt_factor * suggest / res.dt, 2);
    s += "; the time step is " + fmt(res.dt / res.dt_critical, 2) + " of an isolated pair's critical step (" + key +
         "): a grain with several contacts has a lower limit, and a packing stepped this close to it may jitter "
         "without settling whatever the budget or damping; " + fix + " (" +
         fmt(TriaxialConfig::kSuggestedStepFraction) + " of that step)";
  }
  return s;
}

}  // namespace

TriaxialResult run_triaxial(const TriaxialConfig& cfg, Observer* obs) {
  cfg.validate();
  const RunClock clock;
  TriaxialResult res;
  res.packing = to_string(cfg.packing);
  res.threads = cfg.threads;
  res.walls = "six smooth rigid walls (frictionless: normal force only); z axial, x and y lateral; servo-controlled";
  res.walls_frictionless = true;
  res.prep_damping = cfg.prep_damping;
  res.local_damping_used = cfg.prep_damping > 0.0 || cfg.shear_damping > 0.0;
  res.shear_damping = cfg.shear_damping;
  res.grain_density = cfg.grain_density();
  res.series = triaxial_series();

  Sample smp = make_sample(cfg, res);
  const WorldOptions opt = world_options(cfg, smp.particles);
  Domain dom;
  dom.lo = smp.lo;
  dom.hi = smp.hi;
  const ContactParams target = contact_params(cfg.material);
  World world(std::move(smp.particles), box_walls(smp.lo, smp.hi), dom, target, opt);
  choose_steps(world, cfg, target, opt.dt, res);

  Rig rig{world, cfg, obs, smp.solid_volume, {}, "", cfg.confining_pressure};
  auto finish = [&]() {
    res.steps = world.step_count();
    res.wall_seconds = clock.wall_seconds();
    res.cpu_seconds = clock.cpu_seconds();
  };
  try {
    prepare(rig, target, opt.dt, smp.width, res);
    world.set_local_damping(cfg.shear_damping);  // 0 unless the diagnostic asks for it
    shear(rig, res);
  } catch (const InstabilityError& e) {
    res.outcome.status = SceneStatus::unstable;
    res.outcome.failed_stage = rig.stage;
    res.outcome.message = e.what() + instability_context(rig, e, res);  // failed_stage names the stage
    finish();
    return res;
  } catch (const StageFailed& e) {
    res.outcome.status = SceneStatus::not_converged;
    res.outcome.failed_stage = rig.stage;
    res.outcome.message = e.what() + not_converged_context(cfg, res, rig.stage, e.what());
    finish();
    return res;
  }

  angles_from_series(cfg, res);
  volume_change_from_series(cfg, res);
  judge_window(cfg, res);
  // Before the verdict: an invalid run's interior of a few grains is not measured either.
  judge_the_interior(cfg, res);
  if (const std::string why = why_invalid(cfg, res); !why.empty()) {
    res.outcome.status = SceneStatus::invalid;
    res.outcome.failed_stage = "shear";
    res.outcome.message = why;
    finish();
    return res;
  }
  warn_about_the_regime(cfg, res);
  res.outcome.join_warnings();
  finish();
  if (obs) obs->on_progress(1.0);
  return res;
}

}  // namespace demcal::engine
