// The angle-of-repose scene (seed Sec. 2.2.4): column collapse on a rough floor.
#include "../job_error.hpp"
#include "../material_params.hpp"
#include "../scene_registry.hpp"
#include "../scene_resolve.hpp"

#include "engine/errors.hpp"
#include "engine/scenes/repose.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace demcal::jobs {
namespace {

const char* const kSection = "repose";
// Whole runs on one thread of the 2-core machine docs/performance.md describes
// (2026-11-27; CPU time over steps and the grains grain_estimate() counts): 95 ns per
// grain-step for the quick preset's ~420 grains, 132 for the standard preset's
// ~5,400, interpolated in log N. A yardstick, not a promise for another machine.
double ns_per_grain_step(double grains) { return ns_per_grain_step_at({{420.0, 95.0}, {5400.0, 132.0}}, grains); }

std::vector<ParamSpec> repose_params() {
  std::vector<ParamSpec> p = material_params();
  const engine::ReposeConfig d;
  // The grain count follows from the column (width x height x depth); the column,
  // slab depth, stiffness scale and time limit default by fidelity in resolve().
  p.push_back(real_param(kSection, "column_width", "column_width", nullptr).above(0).at_most(10));
  p.push_back(real_param(kSection, "column_height", "column_height", nullptr).above(0).at_most(10));
  p.push_back(real_param(kSection, "depth_diameters", "depth_diameters", nullptr).above(0).at_most(1000));
  // No fallback: a job that leaves side_walls out is periodic and keeps the task
  // key it had before this field existed (stored results stay reusable).
  std::vector<std::string> side_walls;
  for (engine::SideWalls s : engine::kSideWalls) side_walls.emplace_back(engine::to_string(s));
  p.push_back(choice_param(kSection, "side_walls", "side_walls", side_walls, nullptr));
  p.push_back(real_param(kSection, "domain_length", "domain_length", d.domain_length).at_least(0).at_most(100));
  p.push_back(real_param(kSection, "floor_spacing", "floor_spacing", d.floor_spacing).at_least(0).at_most(1));
  // Preparation
  p.push_back(real_param(kSection, "fill_solid_fraction", "fill_solid_fraction", d.fill_solid_fraction)
                  .above(0).at_most(0.38));
  p.push_back(real_param(kSection, "target_solid_fraction", "target_solid_fraction", d.target_solid_fraction)
                  .above(0.3).below(0.74));
  p.push_back(real_param(kSection, "overfill", "overfill", d.overfill).at_least(1).at_most(2));
  p.push_back(real_param(kSection, "prep_damping", "prep_damping", d.prep_damping).at_least(0).below(1));
  p.push_back(real_param(kSection, "settle_ke_ratio", "settle_ke_ratio", d.settle_ke_ratio).above(0).at_most(1));
  p.push_back(real_param(kSection, "settle_time_limit", "settle_time_limit", d.settle_time_limit).above(0).at_most(1000));
  // Collapse
  p.push_back(real_param(kSection, "rest_ke_ratio", "rest_ke_ratio", d.rest_ke_ratio).above(0).at_most(1));
  p.push_back(real_param(kSection, "rest_trim", "rest_trim", d.rest_trim).at_least(0).at_most(0.1));
  p.push_back(int_param(kSection, "rest_samples", "rest_samples", static_cast<std::int64_t>(d.rest_samples))
                  .at_least(1).at_most(10000));
  p.push_back(real_param(kSection, "collapse_drag", "collapse_drag", d.collapse_drag).at_least(0).at_most(1e4));
  p.push_back(real_param(kSection, "min_collapse_time", "min_collapse_time", d.min_collapse_time).at_least(0).at_most(1000));
  p.push_back(real_param(kSection, "time_limit", "time_limit", nullptr).above(0).at_most(1000));
  // No fallback, as side_walls: tasks of jobs that leave these out keep their keys
  // (the check only turns runs that would end not_settled into results).
  p.push_back(real_param(kSection, "rest_profile_window", "rest_profile_window", nullptr).at_least(0).at_most(1000));
  p.push_back(real_param(kSection, "rest_profile_tol_deg", "rest_profile_tol_deg", nullptr).above(0).at_most(2));
  p.push_back(real_param(kSection, "sample_interval", "sample_interval", d.sample_interval).above(0).at_most(10));
  // Numerics: dt or dt_factor (resolve() rejects both).
  p.push_back(real_param(kSection, "stiffness_scale", "stiffness_scale", nullptr).above(0).at_most(1));
  p.push_back(real_param(kSection, "dt", "dt", nullptr).above(0).below(1));
  p.push_back(real_param(kSection, "dt_factor", "dt_factor", nullptr).above(0).at_most(10));
  p.push_back(real_param(kSection, "gravity", "gravity", d.gravity).above(0).at_most(1e4));
  p.push_back(real_param(kSection, "energy_guard", "energy_guard", d.energy_guard).at_most(1e6));  // < 0: off
  // Measurement
  p.push_back(real_param(kSection, "bin_width", "bin_width", d.bin_width).at_least(0).at_most(1));
  p.push_back(real_param(kSection, "fit_lo", "fit_lo", d.fit_lo).at_least(0).below(1));
  p.push_back(real_param(kSection, "fit_hi", "fit_hi", d.fit_hi).above(0).at_most(1));
  p.push_back(real_param(kSection, "steep_window", "steep_window", d.steep_window).at_least(0).at_most(1));
  p.push_back(real_param(kSection, "front_min_height", "front_min_height", d.front_min_height).above(0).at_most(100));
  p.push_back(real_param(kSection, "front_max_gap", "front_max_gap", d.front_max_gap).at_least(0).at_most(1000));
  return p;
}

engine::ReposeConfig config_from(const nlohmann::json& p) {
  engine::ReposeConfig c;
  c.material = material_from(p);
  c.column_width = p.at("column_width").get<double>();
  c.column_height = p.at("column_height").get<double>();
  c.slab_depth_diameters = p.at("depth_diameters").get<double>();
  // The choice is checked against the parameter's list before this runs.
  // Absent: the engine's default (periodic).
  if (p.contains("side_walls")) engine::parse_side_walls(p.at("side_walls").get<std::string>(), c.side_walls);
  c.domain_length = p.at("domain_length").get<double>();
  c.floor_spacing = p.at("floor_spacing").get<double>();
  c.fill_solid_fraction = p.at("fill_solid_fraction").get<double>();
  c.target_solid_fraction = p.at("target_solid_fraction").get<double>();
  c.overfill = p.at("overfill").get<double>();
  c.prep_damping = p.at("prep_damping").get<double>();
  c.settle_ke_ratio = p.at("settle_ke_ratio").get<double>();
  c.settle_time_limit = p.at("settle_time_limit").get<double>();
  c.rest_ke_ratio = p.at("rest_ke_ratio").get<double>();
  c.rest_trim = p.at("rest_trim").get<double>();
  c.rest_samples = p.at("rest_samples").get<int>();
  c.collapse_drag = p.at("collapse_drag").get<double>();
  c.min_collapse_time = p.at("min_collapse_time").get<double>();
  c.time_limit = p.at("time_limit").get<double>();
  if (p.contains("rest_profile_window")) c.rest_profile_window = p.at("rest_profile_window").get<double>();
  if (p.contains("rest_profile_tol_deg")) c.rest_profile_tol_deg = p.at("rest_profile_tol_deg").get<double>();
  c.sample_interval = p.at("sample_interval").get<double>();
  c.stiffness_scale = p.at("stiffness_scale").get<double>();
  c.dt = p.value("dt", 0.0);
  if (p.contains("dt_factor")) c.dt_factor = p.at("dt_factor").get<double>();
  c.gravity = p.at("gravity").get<double>();
  c.energy_guard = p.at("energy_guard").get<double>();
  c.bin_width = p.at("bin_width").get<double>();
  c.fit_lo = p.at("fit_lo").get<double>();
  c.fit_hi = p.at("fit_hi").get<double>();
  c.steep_window = p.at("steep_window").get<double>();
  c.front_min_height = p.at("front_min_height").get<double>();
  c.front_max_gap = p.at("front_max_gap").get<double>();
  c.seed = p.at("seed").get<std::uint64_t>();
  return c;
}

// Column, slab depth, stiffness scale and time limit per fidelity, when the job
// gives none. quick: a 15 mm column of ~300 grains at 1e-3 stiffness (under a
// minute on one core); standard: the seed's 50 mm column at 1e-3 stiffness (277 s
// on one thread); reference: the seed's column at 1e-2 stiffness (1,008 s), which
// the standard preset matches within 0.3 deg (repose-fidelity study, docs/studies.md).
struct Preset {
  double column_width, column_height, depth_diameters, stiffness_scale, time_limit;
};
Preset preset(const std::string& fidelity) {
  if (fidelity == "quick") return {0.015, 0.015, 3.0, 1e-3, 1.5};
  if (fidelity == "reference") return {0.05, 0.05, 4.0, 1e-2, 3.0};
  return {0.05, 0.05, 4.0, 1e-3, 2.0};
}

// Engine field names the job file spells differently.
std::string job_path(const std::string& field) {
  if (field == "repose.slab_depth_diameters") return "repose.depth_diameters";
  if (field == "repose.fit_fractions") return "repose.fit_hi";
  return job_path_of(field, kSection);
}

std::string num(const nlohmann::json& v) { return v.dump(); }

void resolve(nlohmann::json& p, const std::string& fidelity) {
  resolve_time_step(p, kSection, engine::ReposeConfig{}.dt_factor);
  resolve_diameters(p);
  const Preset pre = preset(fidelity);
  if (!p.contains("column_width")) p["column_width"] = pre.column_width;
  if (!p.contains("column_height")) p["column_height"] = pre.column_height;
  if (!p.contains("depth_diameters")) {
    // The preset's slab depth in metres, whatever the grading: in units of a smaller
    // mean diameter it would be thinner than the periodic images allow.
    const engine::Material m = material_from(p);
    const double d_mean = m.grading().mean();
    double depth = pre.depth_diameters;
    if (p.contains("size_distribution")) depth *= 0.5 * (m.d_min + m.d_max) / d_mean;
    // A wide grading's largest grain may reach past the preset depth: the default is
    // then the least a periodic slab allows (the engine's check, ReposeConfig::validate).
    if (depth * d_mean < 2.0 * engine::interaction_reach(m)) depth = engine::least_periodic_depth_diameters(m);
    p["depth_diameters"] = depth;
  }
  if (!p.contains("stiffness_scale")) p["stiffness_scale"] = pre.stiffness_scale;
  if (!p.contains("time_limit")) p["time_limit"] = pre.time_limit;
  if (!(p["fit_lo"].get<double>() < p["fit_hi"].get<double>())) {
    // Blame the one the user moved, as for min_collapse_time below.
    if (p["fit_hi"].get<double>() == engine::ReposeConfig{}.fit_hi)
      throw JobError("repose.fit_lo", "must be below repose.fit_hi (" + num(p["fit_hi"]) + ", its default), got " +
                                          num(p["fit_lo"]));
    throw JobError("repose.fit_hi", "must exceed repose.fit_lo (" + num(p["fit_lo"]) + "), got " + num(p["fit_hi"]));
  }
  if (p["min_collapse_time"].get<double>() >= p["time_limit"].get<double>()) {
    // Blame the one the user moved: a min_collapse_time left at its default is not theirs.
    if (p["min_collapse_time"].get<double>() == engine::ReposeConfig{}.min_collapse_time)
      throw JobError("repose.time_limit", "must exceed repose.min_collapse_time (" + num(p["min_collapse_time"]) +
                                              " s, its default), got " + num(p["time_limit"]));
    throw JobError("repose.min_collapse_time", "must be below repose.time_limit (" + num(p["time_limit"]) + ")");
  }
  // A window the job sets must fit the collapse, or the check it asks for never runs.
  if (p.contains("rest_profile_window") && p["rest_profile_window"].get<double>() > 0.0) {
    const double w = p["rest_profile_window"].get<double>(), dt = p["sample_interval"].get<double>();
    const double room = p["time_limit"].get<double>() - p["min_collapse_time"].get<double>();
    if (w < 2.0 * dt)
      throw JobError("repose.rest_profile_window", "must span at least two samples (2 x repose.sample_interval = " +
                                                       num(2.0 * dt) + " s) or be 0 (off), got " + num(p["rest_profile_window"]));
    if (w > room)
      throw JobError("repose.rest_profile_window", "must fit between repose.min_collapse_time and repose.time_limit (" +
                                                       num(room) + " s here), got " + num(p["rest_profile_window"]));
  }
  try {
    config_from(p).validate();
  } catch (const engine::ConfigError& e) {
    throw_as_job_error(e, job_path(e.field()));
  }
}

// The settings that leave a check no room, said before the run (the job may mean it).
std::string advice(const nlohmann::json& p) {
  const engine::ReposeConfig c = config_from(p);
  std::ostringstream os;
  if (c.profile_check_has_no_room())
    next_note(os, 6) << "repose.time_limit " << c.time_limit << " s leaves the rest-by-profile check no room (its "
       << c.rest_profile_window << " s window after repose.min_collapse_time " << c.min_collapse_time
       << " s): a heap whose rattlers keep the kinetic energy above the threshold will fail not_settled; raise "
          "repose.time_limit above "
       << c.profile_check_time() << " s, or set repose.rest_profile_window to 0 to do without the check";
  if (const std::string cut = grading_cut_note(c.material.grading()); !cut.empty()) next_note(os, 6) << cut;
  // The run warns of a slope over fewer than 6 bins, or gives no angle: say so first.
  if (c.column_bins() < engine::ReposeResult::kMinSlopeBins)
    next_note(os, 3) << "repose.column_width " << c.column_width << " m is " << c.column_bins()
       << " profile bins wide (repose.bin_width, by default the mean diameter): its heap's slope will span about as "
          "few, under the "
       << engine::ReposeResult::kMinSlopeBins
       << " the angle needs, and the run will warn that it is no measurement or find no slope (a wider column)";
  if (c.weight_overlap() > engine::ReposeConfig::kWeightOverlapNote)
    next_note(os, 3) << "at repose.stiffness_scale " << c.stiffness_scale << " the column's weight alone presses a grain at "
       << "its foot about " << c.weight_overlap() << " of the smallest radius into its neighbours, and the collapse's "
          "impacts add to it: the run may stop on an overlap past the limit; a larger "
          "repose.stiffness_scale";
  // Near the limit the collapse's energy guard may stop the run (an isolated pair's
  // critical step; a grain with several contacts has a lower one).
  const engine::StepForecast f = c.step_forecast();
  if (!f.exceeds() && f.dt > 0.8 * f.dt_critical)
    next_note(os, 3) << "dt is " << f.dt / f.dt_critical << " of the critical step of an isolated pair (" << f.mode
       << "): a grain with several contacts has a lower limit, and the collapse may gain energy and stop on the "
          "energy guard (repose.dt_factor; the default " << engine::ReposeConfig{}.dt_factor << ")";
  // theta_deg defaults to 0, so a job that forgets it asks for frictionless grains:
  // they spread instead of heaping (a repose column at eta 0.1 was still flowing at
  // its 1.5 s limit), and with no tangential force nothing turns a grain for eta to resist.
  if (c.material.friction_angle == 0.0)
    next_note(os, 6) << "material.theta_deg is 0 (also its default when a job leaves it out): "
       << (c.collapse_drag > 0.0 ? "frictionless grains build no heap, they spread until repose.collapse_drag stops "
                                   "them, and the low deposit's angle is the drag's, not the material's"
                                 : "frictionless grains build no heap, they spread and may still be moving at "
                                   "repose.time_limit (not_settled)")
       << (c.material.rolling_eta != 0.0 ? ", and material.eta exerts no moment without friction" : "");
  return os.str();
}

SceneOutput run(const nlohmann::json& p, const RunContext& ctx) {
  engine::ReposeConfig c = config_from(p);
  c.threads = ctx.threads;
  engine::ReposeResult r = engine::run_repose(c, ctx.observer);
  SceneOutput out;
  out.outcome = r.outcome;
  out.metrics = r.outcome.ok() ? r.metrics() : timing_metrics(r.metrics());
  for (engine::Series* s : {&r.profile, &r.energy, &r.prep})
    if (!s->name.empty()) out.series.push_back(std::move(*s));
  return out;
}

}  // namespace

SceneDef scene_repose() {
  const engine::ReposeConfig d;
  return SceneDef{kSection, repose_params(), resolve, run,
                  /*headline=*/{"repose_deg", "repose_fit_err_deg", "repose_upper_deg", "repose_lower_deg", "runout_ratio",
                                "time_to_rest_s", "particles", "wall_s"},
                  /*forecast=*/[](const nlohmann::json& p) { return config_from(p).step_forecast(); },
                  /*advice=*/advice,
                  // How long a heap takes to come to rest is known only once it runs:
                  // the forecast is the bound of every stage's time limit until done
                  // tasks in the database say what the scene costs.
                  /*work=*/
                  [](const nlohmann::json& p) {
                    const engine::ReposeConfig c = config_from(p);
                    const engine::ReposeConfig::GrainEstimate g = c.grain_estimate();
                    return Work{c.max_steps(), g.column + g.floor, ns_per_grain_step(g.column + g.floor), /*upper_bound=*/true};
                  },
                  /*work_of=*/"the run to every stage's time limit",
                  /*work_left_out=*/"a heap that comes to rest sooner costs less (tasks measured here took 12-50% of it); once done "
                                    "repose tasks are in the database, validate --db and run forecast at what they cost",
                  /*key_params=*/nullptr,
                  // The optional keys have no fallback, so a job that leaves them out
                  // keeps the keys its tasks had before they existed; one that writes
                  // their defaults out asks for the same work and gets the same key.
                  /*implied=*/
                  {kImpliedUniformSizes,
                   {"side_walls", engine::to_string(d.side_walls)},
                   {"rest_profile_window", d.rest_profile_window},
                   {"rest_profile_tol_deg", d.rest_profile_tol_deg}}};
}

}  // namespace demcal::jobs
