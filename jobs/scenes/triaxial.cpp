// The drained triaxial scene (seed Sec. 2.2.3, Tables 2.2, 2.3): phi_peak, phi_cv.
#include "../job_error.hpp"
#include "../material_params.hpp"
#include "../scene_registry.hpp"
#include "../scene_resolve.hpp"

#include "engine/errors.hpp"
#include "engine/format.hpp"
#include "engine/scenes/triaxial.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace demcal::jobs {
namespace {

const char* const kSection = "triaxial";

std::vector<ParamSpec> triaxial_params() {
  std::vector<ParamSpec> p = material_params();
  const engine::TriaxialConfig d;
  // particles and strain_rate have no fixed default: resolve() takes them from the fidelity.
  p.push_back(int_param(kSection, "particles", "particles", nullptr).at_least(50).at_most(5e6));
  p.push_back(choice_param(kSection, "packing", "packing", {"dense", "loose"}, "dense"));
  p.push_back(real_param(kSection, "confining_kpa", "confining_kpa", d.confining_pressure / 1e3).above(0).at_most(1e6));
  p.push_back(real_param(kSection, "strain_rate", "strain_rate", nullptr).above(0).at_most(10));
  p.push_back(real_param(kSection, "axial_strain", "axial_strain", d.axial_strain).above(0).below(0.6));
  p.push_back(real_param(kSection, "shear_ramp_strain", "shear_ramp_strain", d.shear_ramp_strain).at_least(0).below(0.3));
  // Grain density: density_scale multiplies material.density; scaled_density sets it
  // outright. Neither given: the seed's 2.65e12 kg/m^3 (scaled_density).
  p.push_back(real_param(kSection, "density_scale", "density_scale", nullptr).above(0).at_most(1e15));
  p.push_back(real_param(kSection, "scaled_density", "scaled_density", nullptr).above(0).at_most(1e20));
  p.push_back(real_param(kSection, "aspect_ratio", "aspect_ratio", d.aspect_ratio).at_least(0.5).at_most(4));
  p.push_back(real_param(kSection, "initial_solid_fraction", "initial_solid_fraction", d.initial_solid_fraction)
                  .above(0.05).at_most(0.4));
  // Preparation
  p.push_back(real_param(kSection, "prep_damping", "prep_damping", d.prep_damping).at_least(0).below(1));
  // Diagnostic, absent unless given: a default here would enter every task's
  // parameters and so change the key of every triaxial task already stored.
  p.push_back(real_param(kSection, "shear_damping", "shear_damping", nullptr).at_least(0).below(1));
  p.push_back(real_param(kSection, "prep_pressure_factor", "prep_pressure_factor", d.prep_pressure_factor)
                  .at_least(1).at_most(1000));
  p.push_back(int_param(kSection, "unloading_steps", "unloading_steps", static_cast<std::int64_t>(d.unloading_steps))
                  .at_least(0).at_most(1e9));
  p.push_back(real_param(kSection, "prep_strain_rate", "prep_strain_rate", d.prep_strain_rate).above(0).at_most(100));
  p.push_back(real_param(kSection, "stress_tolerance", "stress_tolerance", d.stress_tolerance).above(0).below(1));
  p.push_back(real_param(kSection, "ufr_tolerance", "ufr_tolerance", d.ufr_tolerance).above(0).at_most(1));
  p.push_back(int_param(kSection, "prep_step_budget", "prep_step_budget", static_cast<std::int64_t>(d.prep_step_budget))
                  .at_least(1).at_most(1e10));
  p.push_back(int_param(kSection, "stabilise_min_steps", "stabilise_min_steps",
                        static_cast<std::int64_t>(d.stabilise_min_steps)).at_least(0).at_most(1e9));
  p.push_back(int_param(kSection, "check_interval", "check_interval", static_cast<std::int64_t>(d.check_interval))
                  .at_least(1).at_most(1e7));
  // Servo walls
  p.push_back(real_param(kSection, "servo_alpha", "servo_alpha", d.servo_alpha).above(0).at_most(1));
  p.push_back(real_param(kSection, "servo_beta", "servo_beta", d.servo_beta).at_least(0).at_most(0.2));
  p.push_back(real_param(kSection, "shear_servo_strain_rate", "shear_servo_strain_rate", d.shear_servo_strain_rate)
                  .at_least(0).at_most(100));
  // Numerics: dt or dt_factor (resolve() rejects both).
  p.push_back(real_param(kSection, "dt", "dt", nullptr).above(0).below(1));
  p.push_back(real_param(kSection, "dt_factor", "dt_factor", nullptr).above(0).at_most(10));
  // Absent unless given (the engine's 0: the same margin to the critical step).
  p.push_back(real_param(kSection, "frictionless_dt_scale", "frictionless_dt_scale", nullptr).above(0).at_most(10));
  p.push_back(real_param(kSection, "max_overlap_fraction", "max_overlap_fraction", d.max_overlap_fraction)
                  .above(0).at_most(1));
  // Output; the critical-state window defaults to the last third of the shear.
  p.push_back(real_param(kSection, "sample_strain", "sample_strain", d.sample_strain).above(0).below(0.6));
  // No default: a job that does not sample by steps keeps the keys it had.
  p.push_back(int_param(kSection, "sample_steps", "sample_steps", nullptr).at_least(1).at_most(1e12));
  p.push_back(real_param(kSection, "cv_from", "cv_from", nullptr).at_least(0).below(0.6));
  p.push_back(real_param(kSection, "cv_to", "cv_to", nullptr).above(0).below(0.6));
  p.push_back(real_param(kSection, "quasi_static_inertial", "quasi_static_inertial", d.quasi_static_inertial)
                  .above(0).at_most(1));
  p.push_back(real_param(kSection, "dilatancy_window", "dilatancy_window", d.dilatancy_window).above(0).below(0.6));
  return p;
}

engine::TriaxialConfig config_from(const nlohmann::json& p) {
  engine::TriaxialConfig c;
  c.material = material_from(p);
  c.particles = p.at("particles").get<std::size_t>();
  c.packing = p.at("packing").get<std::string>() == "loose" ? engine::Packing::loose : engine::Packing::dense;
  c.confining_pressure = p.at("confining_kpa").get<double>() * 1e3;  // kPa at the edge, Pa inside
  c.strain_rate = p.at("strain_rate").get<double>();
  c.axial_strain = p.at("axial_strain").get<double>();
  c.shear_ramp_strain = p.at("shear_ramp_strain").get<double>();
  c.density_scale = p.value("density_scale", 0.0);
  if (p.contains("scaled_density")) c.scaled_density = p.at("scaled_density").get<double>();
  c.aspect_ratio = p.at("aspect_ratio").get<double>();
  c.initial_solid_fraction = p.at("initial_solid_fraction").get<double>();
  c.prep_damping = p.at("prep_damping").get<double>();
  c.shear_damping = p.value("shear_damping", 0.0);
  c.prep_pressure_factor = p.at("prep_pressure_factor").get<double>();
  c.unloading_steps = p.at("unloading_steps").get<long>();
  c.prep_strain_rate = p.at("prep_strain_rate").get<double>();
  c.stress_tolerance = p.at("stress_tolerance").get<double>();
  c.ufr_tolerance = p.at("ufr_tolerance").get<double>();
  c.prep_step_budget = p.at("prep_step_budget").get<long>();
  c.stabilise_min_steps = p.at("stabilise_min_steps").get<long>();
  c.check_interval = p.at("check_interval").get<long>();
  c.servo_alpha = p.at("servo_alpha").get<double>();
  c.servo_beta = p.at("servo_beta").get<double>();
  c.shear_servo_strain_rate = p.at("shear_servo_strain_rate").get<double>();
  c.dt = p.value("dt", 0.0);
  if (p.contains("dt_factor")) c.dt_factor = p.at("dt_factor").get<double>();
  c.frictionless_dt_scale = p.value("frictionless_dt_scale", 0.0);
  c.max_overlap_fraction = p.at("max_overlap_fraction").get<double>();
  c.sample_strain = p.at("sample_strain").get<double>();
  c.sample_steps = p.value("sample_steps", std::int64_t(0));
  c.cv_from = p.at("cv_from").get<double>();
  c.cv_to = p.at("cv_to").get<double>();
  c.quasi_static_inertial = p.at("quasi_static_inertial").get<double>();
  c.dilatancy_window = p.at("dilatancy_window").get<double>();
  c.seed = p.at("seed").get<std::uint64_t>();
  return c;
}

// Sample size and shear rate per fidelity, when the job gives none, set from the
// fidelity study (docs/studies.md): quick: a smoke test (7-22 s a task on one core,
// inertial number ~4e-3: not quasi-static, good to ~2-3 deg); standard: 2,000
// grains at 1e-4 /s, the reference of the particle and rate knobs (1,000 grains
// are within 0.5 deg of it); reference: more grains, slower shear.
struct Preset {
  std::int64_t particles;
  double strain_rate;
};
Preset preset(const std::string& fidelity) {
  if (fidelity == "quick") return {400, 5e-4};
  if (fidelity == "reference") return {5000, 5e-5};
  return {2000, 1e-4};
}

// Engine field names the job file spells differently.
std::string job_path(const std::string& field) {
  if (field == "triaxial.confining_pressure") return "triaxial.confining_kpa";
  if (field == "triaxial.servo.alpha") return "triaxial.servo_alpha";
  if (field == "triaxial.servo.beta") return "triaxial.servo_beta";
  if (field.rfind("triaxial.servo.", 0) == 0) return "triaxial.servo_alpha";
  if (field == "triaxial.cv_window") return "triaxial.cv_to";
  return job_path_of(field, kSection);
}

std::string num(const nlohmann::json& v) { return v.dump(); }

void resolve(nlohmann::json& p, const std::string& fidelity) {
  resolve_time_step(p, kSection, engine::TriaxialConfig{}.dt_factor);
  if (p.contains("density_scale") && p.contains("scaled_density"))
    throw JobError("triaxial.density_scale", "give density_scale or scaled_density, not both");
  if (!p.contains("density_scale") && !p.contains("scaled_density"))
    p["scaled_density"] = engine::TriaxialConfig{}.scaled_density;
  const Preset pre = preset(fidelity);
  if (!p.contains("particles")) p["particles"] = pre.particles;
  if (!p.contains("strain_rate")) p["strain_rate"] = pre.strain_rate;
  resolve_diameters(p);

  // Critical-state window: the last third of the shear unless given.
  const double eps1 = p["axial_strain"].get<double>();
  if (!p.contains("cv_to")) p["cv_to"] = eps1;
  if (!p.contains("cv_from")) p["cv_from"] = std::round(p["cv_to"].get<double>() * 2.0 / 3.0 * 1e9) / 1e9;
  if (p["cv_to"].get<double>() > eps1 + 1e-12)
    throw JobError("triaxial.cv_to", "must not exceed triaxial.axial_strain (" + num(p["axial_strain"]) + "), got " +
                                         num(p["cv_to"]));
  if (!(p["cv_from"].get<double>() < p["cv_to"].get<double>()))
    throw JobError("triaxial.cv_from", "must be below triaxial.cv_to (" + num(p["cv_to"]) + "), got " + num(p["cv_from"]));
  if (p["sample_strain"].get<double>() > eps1)
    throw JobError("triaxial.sample_strain", "must not exceed triaxial.axial_strain (" + num(p["axial_strain"]) + ")");
  // Named by both keys: a job that never wrote shear_ramp_strain hits this through a
  // short axial_strain, against the default ramp.
  if (p["shear_ramp_strain"].get<double>() >= 0.5 * eps1)
    throw JobError("triaxial.shear_ramp_strain", num(p["shear_ramp_strain"]) +
                                                     (p["shear_ramp_strain"] == engine::TriaxialConfig{}.shear_ramp_strain
                                                          ? " (the default)"
                                                          : "") +
                                                     " must be below half of triaxial.axial_strain (" +
                                                     num(p["axial_strain"]) +
                                                     "): the shear ramps its rate up over that much strain; give a "
                                                     "longer axial_strain or a shorter shear_ramp_strain");
  try {
    config_from(p).validate();
  } catch (const engine::ConfigError& e) {
    throw_as_job_error(e, job_path(e.field()));
  }
}

// One grain density, however it was written: a factor on material.density is keyed
// as the density it gives, so that the same work has one key and is reused. The task
// keeps the spelling its job used (a grid axis, --where).
// (shear_damping written as its default, 0, is dropped through SceneDef::implied.)
nlohmann::json key_params(const nlohmann::json& p) {
  nlohmann::json k = p;
  if (!k.contains("density_scale")) return k;
  k["scaled_density"] = k.value("density", engine::Material{}.density) * k["density_scale"].get<double>();
  k.erase("density_scale");
  return k;
}

// Coordination numbers at the start and end of shear, from the series.
void add_coordination(const engine::Series& s, bool interior_measured, engine::Metrics& m) {
  if (s.rows.empty()) return;
  const auto col = [&](const char* name) -> long {
    const auto it = std::find(s.columns.begin(), s.columns.end(), name);
    return it == s.columns.end() ? -1 : static_cast<long>(it - s.columns.begin());
  };
  const long z_all = col("z_all"), z_mech = col("z_mech");
  if (z_all >= 0) {
    m.emplace_back("coordination_initial", s.rows.front().at(static_cast<std::size_t>(z_all)));
    m.emplace_back("coordination_final", s.rows.back().at(static_cast<std::size_t>(z_all)));
  }
  if (z_mech >= 0) {
    m.emplace_back("coordination_mech_initial", s.rows.front().at(static_cast<std::size_t>(z_mech)));
    m.emplace_back("coordination_mech_final", s.rows.back().at(static_cast<std::size_t>(z_mech)));
  }
  // Over the Love-Weber volume, free of the walls' deficit: the values to compare
  // with the seed's Eq. 2.8.
  // NaN where the interior held too few grains to measure (the run warns).
  const long z_in = col("z_interior"), z_mech_in = col("z_mech_interior");
  auto interior = [&](std::size_t row, long c) {
    return interior_measured ? s.rows.at(row).at(static_cast<std::size_t>(c)) : NAN;
  };
  if (z_in >= 0) {
    m.emplace_back("coordination_interior_initial", interior(0, z_in));
    m.emplace_back("coordination_interior_final", interior(s.rows.size() - 1, z_in));
  }
  if (z_mech_in >= 0) {
    m.emplace_back("coordination_mech_interior_initial", interior(0, z_mech_in));
    m.emplace_back("coordination_mech_interior_final", interior(s.rows.size() - 1, z_mech_in));
  }
}

SceneOutput run(const nlohmann::json& p, const RunContext& ctx) {
  engine::TriaxialConfig c = config_from(p);
  c.threads = ctx.threads;
  engine::TriaxialResult r = engine::run_triaxial(c, ctx.observer);
  SceneOutput out;
  out.outcome = r.outcome;
  if (r.outcome.ok()) {
    out.metrics = r.metrics();
    out.metrics.emplace_back("phi_diff_deg", r.phi_peak_deg - r.phi_cv_deg);
    add_coordination(r.series, r.interior_measured(), out.metrics);
    // No critical-state sample (window too narrow): phi_cv and phi_diff are NaN; leave them out.
    out.metrics.erase(std::remove_if(out.metrics.begin(), out.metrics.end(),
                                     [](const auto& kv) { return std::isnan(kv.second); }),
                      out.metrics.end());
  } else {
    out.metrics = timing_metrics(r.metrics());
  }
  out.series.push_back(std::move(r.series));
  return out;
}

// The shear's rate against quasi-static, the stiffness against the preparation's
// stress, and the step against the critical one.
void advise_rates_and_step(const engine::TriaxialConfig& c, const engine::StepForecast& f, std::ostringstream& os) {
  // The quasi-static check, forecast: at the start of shear the mean stress is p0, so
  // a nominal inertial number above the limit is a warning every such task will carry.
  const double i0 = c.nominal_inertial_number();
  if (i0 > c.quasi_static_inertial)
    next_note(os, 2) << "inertial number " << i0 << " at p0 (strain rate * d_mean * sqrt(rho/p0)) exceeds the quasi-static limit "
       << c.quasi_static_inertial << ": the run will warn not quasi-static";
  // The highest mean stress of the preparation against the stiffness (a 10 MPa test's
  // dense preparation at 1 GPa stops on an overlap past the limit whatever the step).
  const double p_max = c.confining_pressure * (c.packing == engine::Packing::dense ? c.prep_pressure_factor : 1.0);
  const double kappa = c.stiffness_number(p_max);
  if (kappa < engine::TriaxialConfig::kLowStiffnessNumber)
    next_note(os, 3) << "kn / (p d_min) is " << kappa << " at "
       << p_max << " Pa, the preparation's highest mean stress"
       << (c.packing == engine::Packing::dense ? " (triaxial.prep_pressure_factor x p0)" : "")
       << ": grains will press deep into each other, and the run may stop on an overlap past the limit whatever "
          "the step (the seed's material: 3000 in its dense preparation); "
       << engine::TriaxialConfig::low_stiffness_remedy(c.packing == engine::Packing::dense && c.prep_pressure_factor > 1.0);
  // The critical step is an isolated pair's; a packed grain's several contacts lower
  // the limit, and the dense preparation's frictionless stages step at the same
  // margin to theirs: 200 grains at 0.97 and 0.995 of it blew up in preparation, at
  // 0.83 did not settle, and 400 grains at 0.55 and 0.62 jittered without settling.
  if (!f.exceeds() && f.dt > engine::TriaxialConfig::kJitterStepFraction * f.dt_critical) {
    // A concrete step (a wider grading or a stiffer rolling spring puts the default
    // itself past the fraction noted here).
    const double suggest = engine::TriaxialConfig::kSuggestedStepFraction * f.dt_critical;
    next_note(os, 3) << "dt is " << f.dt / f.dt_critical
       << " of the critical step of an isolated pair (" << f.mode << "): a packed grain's several contacts lower "
          "that limit, and above about " << engine::TriaxialConfig::kJitterStepFraction
       << " of it the preparation may not settle, or blow up; "
       << (c.dt > 0.0 ? "a triaxial.dt of about " + engine::fmt(suggest, 3) + " s"
                      : "a triaxial.dt_factor of about " + engine::fmt(c.dt_factor * suggest / f.dt, 2))
       << " keeps it at " << engine::TriaxialConfig::kSuggestedStepFraction << " of that limit";
  }
}

// A shear too short for the servo, a preparation longer than its step budget.
void advise_stage_lengths(const engine::TriaxialConfig& c, const engine::StepForecast& f, std::ostringstream& os) {
  // A shear of a few hundred steps outruns the lateral servo (at 1 /s, 24 steps: sigma3
  // strayed by 3,981%); the run would end invalid. The quick fidelity study's fastest
  // valid setting takes about 5,000.
  const double shear_steps = c.shear_steps();
  if (f.dt > 0.0 && shear_steps < 1000.0)
    next_note(os, 3) << "the shear is only " << shear_steps
       << " steps (triaxial.strain_rate " << c.strain_rate << " /s at a step of " << f.dt
       << " s): the lateral walls' servo cannot follow so fast a shear, and the run will likely end invalid; a "
          "lower triaxial.strain_rate";
  // Random insertion leaves the box at solid fraction initial_solid_fraction (0.3);
  // packed it is about twice that, about 21% of strain on each axis, which the walls
  // close at prep_strain_rate at most. A budget shorter than that stops the first
  // stage with the grains barely touching (grains of 0.01 mm step 1000x finer).
  // The dense preparation's frictionless step is up to about twice dt.
  const double close = 1.0 - std::cbrt(c.initial_solid_fraction / 0.6);
  const double step = f.dt * (c.packing == engine::Packing::dense ? 2.0 : 1.0);
  const double steps_to_close = close / (c.prep_strain_rate * step);
  if (step > 0.0 && steps_to_close > static_cast<double>(c.prep_step_budget))
    next_note(os, 3) << "the preparation's walls, at triaxial.prep_strain_rate "
       << c.prep_strain_rate << " /s and a step of " << step << " s, need about " << steps_to_close
       << " steps to pack the sample, more than triaxial.prep_step_budget (" << c.prep_step_budget
       << "): the run will stop in isotropic_compression; raise prep_strain_rate or prep_step_budget";
  // Soft grains (a low kn) take long steps, and walls closing at the rate that suits
  // the seed's stiffness ram them into each other before their contacts push back.
  if (c.prep_walls_too_fast())
    next_note(os, 3) << c.prep_wall_impact_words();
}

// Frictionless grains, and settings the task does not use (its key changes, its work
// does not).
void advise_unused_settings(const engine::TriaxialConfig& c, const nlohmann::json& p, std::ostringstream& os) {
  // theta_deg defaults to 0, so a job that forgets it tests frictionless grains, and
  // nothing else says so (a triaxial test of them is legal: it runs, to other angles).
  if (c.material.friction_angle == 0.0)
    next_note(os, 2) << "material.theta_deg is 0 (also its default when a job leaves it out): the grains are frictionless, "
          "and the test measures a frictionless packing's angles, not a sand's";
  // Without friction no tangential force turns a grain, spins stay zero, and the
  // rolling resistance never acts: tasks that differ only in eta run the same
  // trajectory (bit for bit, at one step) under different keys.
  if (c.material.friction_angle == 0.0 && c.material.rolling_eta != 0.0)
    next_note(os, 2) << "material.eta exerts no moment at theta_deg 0: without friction no tangential force turns a grain, so "
          "the rolling resistance never acts (it only shortens the critical step through the rolling mode)";
  // Given, it changes the task's key and nothing a loose sample computes.
  if (c.packing == engine::Packing::loose && p.contains("frictionless_dt_scale"))
    next_note(os, 2) << "triaxial.frictionless_dt_scale is not used: a loose sample has no frictionless stage";
  // The grains then weigh scaled_density whatever the sand's density; tasks that
  // differ only in it run the same work under different keys.
  if (c.density_scale <= 0.0 && c.material.density != engine::Material{}.density)
    next_note(os, 6) << "material.density (" << c.material.density
       << " kg/m^3) is not used: the grains' density is triaxial.scaled_density (" << c.scaled_density
       << " kg/m^3); triaxial.density_scale scales material.density instead";
  if (const std::string cut = grading_cut_note(c.material.grading()); !cut.empty()) next_note(os, 3) << cut;
}

// Preparation tolerances loose enough to end a stage far from equilibrium.
void advise_tolerances(const engine::TriaxialConfig& c, std::ostringstream& os) {
  // Loose enough, a stage "reaches equilibrium" at once: 0.99 both stopped the dense
  // compression after 2,000 steps at box porosity 0.494, and the sample went on as dense.
  const engine::TriaxialConfig d;
  std::string loose;
  if (c.ufr_tolerance > 10.0 * d.ufr_tolerance)
    loose += "triaxial.ufr_tolerance " + engine::fmt(c.ufr_tolerance) + " (the forces that far out of balance)";
  if (c.stress_tolerance > 10.0 * d.stress_tolerance)
    loose += (loose.empty() ? "" : " and ") + std::string("triaxial.stress_tolerance ") +
             engine::fmt(c.stress_tolerance) + " (the walls' stress that far from its target)";
  if (!loose.empty())
    next_note(os, 3) << loose << " let a preparation stage end that far from equilibrium: the sample is not the "
       << "packing asked for (the defaults: " << d.ufr_tolerance << " and " << d.stress_tolerance << ")";
}

// A series too coarse, or a shear too short, for what the run judges from it.
void advise_sampling(const engine::TriaxialConfig& c, const engine::StepForecast& f, std::ostringstream& os) {
  // Rows every sample_steps steps replace rows every sample_strain of strain: tasks
  // that differ only in sample_strain then store the same series under different keys.
  if (c.sample_steps > 0 && c.sample_strain != engine::TriaxialConfig{}.sample_strain)
    next_note(os, 6) << "triaxial.sample_strain (" << c.sample_strain << ") is not used: a row is taken every "
       << "triaxial.sample_steps (" << c.sample_steps << ") steps of shear instead";
  if (c.axial_strain < c.dilatancy_window)
    next_note(os, 6) << "triaxial.axial_strain (" << c.axial_strain << ") is shorter than triaxial.dilatancy_window ("
       << c.dilatancy_window << "): max_dilatancy_deg will not be measured (the run will warn)";
  // A series too coarse for what the run judges from it: the peak needs 5 rows (its
  // running mean takes 5), the critical-state window 3 (one row has a standard error
  // of 0 and no trend). Counted as the shear records them: a row at eps1 = 0, one
  // every row_strain, and one at the end; a row on a window's edge is in it.
  const double row_strain =
      c.sample_steps > 0 && f.dt > 0.0 ? static_cast<double>(c.sample_steps) * c.strain_rate * f.dt : c.sample_strain;
  if (row_strain > 0.0) {
    const auto rows_to = [&](double e) { return std::floor(e / row_strain + 1e-9); };     // rows in (0, e]
    const auto rows_below = [&](double e) { return std::ceil(e / row_strain - 1e-9); };  // rows in [0, e)
    const bool end_row = c.axial_strain / row_strain - rows_to(c.axial_strain) > 1e-9;
    const double shear_rows = rows_to(c.axial_strain) + 1.0 + (end_row ? 1.0 : 0.0);
    const double window_rows = rows_to(std::min(c.cv_to, c.axial_strain)) - rows_below(c.cv_from) + 1.0 +
                               (end_row && c.cv_to >= c.axial_strain ? 1.0 : 0.0);
    const std::string every = "the series takes a row every " + engine::fmt(row_strain) + " of strain (" +
                              (c.sample_steps > 0 ? "triaxial.sample_steps" : "triaxial.sample_strain") + ")";
    if (window_rows < engine::TriaxialResult::kMinWindowRows)
      next_note(os, 3) << every << ": about " << window_rows << " in the critical-state window (eps1 " << c.cv_from
         << "-" << c.cv_to << "), fewer than " << engine::TriaxialResult::kMinWindowRows
         << ", which cannot judge it (the run will warn, and phi_cv_se_deg will not be measured); sample more finely "
            "or widen the window";
    if (shear_rows < engine::TriaxialResult::kPeakSmoothingRows)
      next_note(os, 3) << every << ": about " << shear_rows << " over the shear, fewer than "
         << engine::TriaxialResult::kPeakSmoothingRows << ", which cannot locate the peak (the run will warn); sample "
            "more finely";
  }
}

std::string advice(const nlohmann::json& p) {
  const engine::TriaxialConfig c = config_from(p);
  const engine::StepForecast f = c.step_forecast();
  std::ostringstream os;
  advise_rates_and_step(c, f, os);
  advise_stage_lengths(c, f, os);
  advise_unused_settings(c, p, os);
  advise_tolerances(c, os);
  advise_sampling(c, f, os);
  return os.str();
}

// Whole runs on one thread of the 2-core machine docs/performance.md describes
// (2026-11-27, physics version 3; wall time over steps and grains): 62 ns per
// grain-step at 500 grains, 73 at 2,000, 99 at 10,000 (larger samples leave the
// caches), interpolated in log N. A yardstick, not a promise for another machine.
double ns_per_grain_step(double grains) {
  return ns_per_grain_step_at({{500.0, 62.0}, {2000.0, 73.0}, {10000.0, 99.0}}, grains);
}

}  // namespace

SceneDef scene_triaxial() {
  return SceneDef{kSection, triaxial_params(), resolve, run,
                  /*headline=*/{"phi_peak_deg", "phi_cv_deg", "phi_cv_se_deg", "porosity_interior_initial", "eps_v_final",
                                "max_inertial_number", "particles", "wall_s"},
                  /*forecast=*/[](const nlohmann::json& p) { return config_from(p).step_forecast(); },
                  /*advice=*/advice,
                  /*work=*/
                  [](const nlohmann::json& p) {
                    const engine::TriaxialConfig c = config_from(p);
                    return Work{c.shear_steps(), static_cast<double>(c.particles),
                                ns_per_grain_step(static_cast<double>(c.particles))};
                  },
                  /*work_of=*/"the shear",
                  /*work_left_out=*/"the preparation adds about 44,000 steps at 2,000 grains, 74,000 at 10,000 and "
                                   "117,000 at 50,000 (dense, default settings): 3-32% of the shear's steps at the default "
                                   "strain (2,000 grains at 1e-4 /s to 50,000 at 5e-4 /s), and more than a short shear's",
                  /*key_params=*/key_params,
                  /*implied=*/{kImpliedUniformSizes, {"shear_damping", 0.0}}};
}

}  // namespace demcal::jobs
