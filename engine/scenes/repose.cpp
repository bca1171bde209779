#include "repose.hpp"

#include "../enum_names.hpp"
#include "../format.hpp"
#include "../errors.hpp"
#include "../measure.hpp"
#include "../packing.hpp"
#include "../run_clock.hpp"
#include "../timestep.hpp"
#include "../world.hpp"

#include <algorithm>
#include <set>
#include <cmath>
#include <sstream>

namespace demcal::engine {

Material repose_seed_material() {
  Material m;  // Table 2.1: Kn 3e7, Ks 2.7e7, rho 2650, b 1, d in [1, 2] mm
  m.friction_angle = deg_to_rad(30.0);
  m.rolling_eta = 0.1;
  return m;
}

namespace {

void positive(double v, const char* field) {
  if (!std::isfinite(v) || v <= 0.0) throw ConfigError(field, "must be a finite number > 0");
}
void non_negative(double v, const char* field) {
  if (!std::isfinite(v) || v < 0.0) throw ConfigError(field, "must be a finite number >= 0");
}

// Kinetic energy (translation + rotation) of the mobile grains.
double kinetic_energy(const Particles& p) {
  double e = 0.0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    if (p.fixed[i]) continue;
    e += 0.5 * p.m[i] * p.v[i].squaredNorm() + 0.2 * p.m[i] * p.r[i] * p.r[i] * p.w[i].squaredNorm();
  }
  return e;
}

// Mean "flow" kinetic energy per mobile grain from displacements over `span`,
// leaving out the fastest `trim` fraction of grains (at least one when trim > 0):
// with an undamped contact law (restitution 1) a caged rattler or a grain
// bouncing in a pocket of the floor never stops, and one of them must not hold
// up the verdict on thousands. `prev` is updated to the current positions.
double flow_ke_per_grain(const Particles& p, const Domain& dom, std::vector<Vec3>& prev, double span, double trim,
                         std::vector<double>& scratch) {
  scratch.clear();
  for (std::size_t i = 0; i < p.size(); ++i) {
    if (p.fixed[i]) continue;
    Vec3 d = p.x[i] - prev[i];
    dom.min_image(d);
    scratch.push_back(0.5 * p.m[i] * d.squaredNorm() / (span * span));
    prev[i] = p.x[i];
  }
  if (scratch.empty()) return 0.0;
  std::size_t keep = scratch.size();
  if (trim > 0.0) {
    const std::size_t drop = std::max<std::size_t>(1, static_cast<std::size_t>(trim * scratch.size()));
    keep = scratch.size() > drop ? scratch.size() - drop : 1;
    std::nth_element(scratch.begin(), scratch.begin() + (keep - 1), scratch.end());
  }
  double sum = 0.0;
  for (std::size_t i = 0; i < keep; ++i) sum += scratch[i];
  return sum / static_cast<double>(keep);
}

// Why a deposit is not at rest, when a handful of grains carry the motion: in a
// small heap without damping a few caged rattlers or grains hopping on the rough floor
// can keep moving long after the heap has stopped. Empty when the motion is spread.
std::string few_grains_moving(const Particles& p, const std::vector<std::uint8_t>& mobile, double floor_level,
                              double front_x, double d_mean) {
  const MotionCarriers c = motion_carriers(p.v, p.m, mobile);
  if (c.carriers == 0 || c.carriers > std::max<std::size_t>(3, c.grains / 20)) return "";
  const auto f = static_cast<std::size_t>(c.fastest);
  std::ostringstream os;
  os.precision(3);
  os << "; " << c.carriers << " of " << c.grains << " grains carry 90% of it (the fastest, " << p.v[f].norm()
     << " m/s, " << (p.x[f].x() > front_x ? "beyond the deposit front" : "within the deposit") << ", ";
  const double height = (p.x[f].z() - floor_level) / d_mean;
  if (height < 0.5) os << "in the rough floor's hollows";
  else os << height << " d above the floor";
  os << "): rattlers or grains hopping on the floor, which nothing damps; a larger column (fidelity standard) "
     << "buries them in the rest criterion's average";
  return os.str();
}

// The largest flow kinetic energy of the last `n` samples: the rest test needs all
// of them below the threshold, so the last one alone may read quiet.
double recent_flow_ke(const Series& energy, int n) {
  const std::size_t k = energy.column("ke_flow_per_grain");
  double e = 0.0;
  for (std::size_t i = energy.rows.size(); i-- > 0 && n-- > 0;) e = std::max(e, energy.rows[i][k]);
  return e;
}

Wall make_wall(const std::string& name, const Vec3& point, const Vec3& normal, bool rough) {
  Wall w;
  w.name = name;
  w.point = point;
  w.normal = normal;
  w.frictional = rough;
  w.rolling = rough;
  return w;
}

std::vector<std::uint8_t> mobile_mask(const Particles& p) {
  std::vector<std::uint8_t> m(p.size());
  for (std::size_t i = 0; i < p.size(); ++i) m[i] = p.fixed[i] ? 0 : 1;
  return m;
}

}  // namespace

const char* to_string(SideWalls s) {
  switch (s) {
    case SideWalls::smooth: return "smooth";
    case SideWalls::frictional: return "frictional";
    default: return "periodic";
  }
}

bool parse_side_walls(const std::string& name, SideWalls& s) { return parse_by_name(name, kSideWalls, s); }

StepForecast ReposeConfig::step_forecast() const {
  Material scaled = material;
  scaled.kn *= stiffness_scale;
  scaled.ks *= stiffness_scale;
  LimitInputs in;
  in.law = contact_params(scaled);
  in.has_walls = true;
  in.wall_frictional = in.wall_rolling = side_walls == SideWalls::frictional;
  return forecast_step(in, material.d_min, material.d_max, material.density, dt, dt_factor);
}

namespace {
double domain_length_of(const ReposeConfig& c) {
  return c.domain_length > 0.0 ? c.domain_length : c.column_width + 4.0 * c.column_height + 0.02;
}

// The rough floor's square grid: cells aligned with x = 0 and x = column_width, so
// that no floor grain straddles the gate plane.
struct FloorGrid {
  int nx = 1, ny = 1;
  double sx = 0, sy = 0;
};
FloorGrid floor_grid(const ReposeConfig& c) {
  const double s0 = c.floor_spacing > 0.0 ? c.floor_spacing : c.material.d_max;
  const double depth = c.slab_depth_diameters * c.material.grading().mean();
  FloorGrid f;
  const int nx_col = std::max(1, static_cast<int>(std::floor(c.column_width / s0)));
  f.sx = c.column_width / nx_col;
  f.nx = static_cast<int>(std::floor(domain_length_of(c) / f.sx));
  f.ny = std::max(1, static_cast<int>(std::floor(depth / s0)));
  f.sy = depth / f.ny;
  return f;
}
}  // namespace

double ReposeConfig::profile_bin() const { return bin_width > 0.0 ? bin_width : material.grading().mean(); }

double ReposeConfig::column_bins() const { return column_width / profile_bin(); }

double ReposeConfig::weight_overlap() const {
  const double d = material.grading().mean();
  const double force = target_solid_fraction * material.density * gravity * column_height * d * d;
  return force / (material.kn * stiffness_scale) / (0.5 * material.d_min);
}

ReposeConfig::GrainEstimate ReposeConfig::grain_estimate() const {
  const double depth = slab_depth_diameters * material.grading().mean();
  GrainEstimate g;
  g.column = std::ceil(overfill * target_solid_fraction * column_width * column_height * depth /
                       (kPi / 6.0 * material.grading().mean_cube()));
  // In floating point: a typo's grid (a 100 km domain) must not overflow an int here.
  const double s0 = floor_spacing > 0.0 ? floor_spacing : material.d_max;
  g.floor = std::ceil(domain_length_of(*this) / s0) * std::max(1.0, std::floor(depth / s0));
  if (g.floor < 1e7) {
    const FloorGrid f = floor_grid(*this);
    g.floor = static_cast<double>(f.nx) * f.ny;
  }
  return g;
}

double ReposeConfig::max_steps() const {
  // Each stage is judged once a sample interval, so it may run one interval past its limit.
  return std::ceil((2.0 * settle_time_limit + time_limit + 3.0 * sample_interval) / step_forecast().dt);
}

double least_periodic_depth_diameters(const Material& m) {
  return std::ceil(20.0 * interaction_reach(m) / m.grading().mean()) / 10.0;
}

void ReposeConfig::validate() const {
  material.validate();
  validate_protocol();
  validate_profile();
  validate_geometry();
}

// The column, the floor and the stages' thresholds and limits, field by field.
void ReposeConfig::validate_protocol() const {
  positive(column_width, "repose.column_width");
  positive(column_height, "repose.column_height");
  positive(slab_depth_diameters, "repose.slab_depth_diameters");
  non_negative(domain_length, "repose.domain_length");
  if (domain_length > 0.0 && domain_length < column_width + material.d_max)
    throw ConfigError("repose.domain_length", "must exceed column_width by at least one grain diameter (or be 0)");
  non_negative(floor_spacing, "repose.floor_spacing");
  if (floor_spacing > 0.0 && floor_spacing < material.d_max)
    throw ConfigError("repose.floor_spacing", "must be at least d_max (grains of the floor may not overlap)");
  if (!(fill_solid_fraction > 0.0 && fill_solid_fraction <= 0.38))
    throw ConfigError("repose.fill_solid_fraction", "must lie in (0, 0.38] for random insertion");
  if (!(target_solid_fraction > 0.3 && target_solid_fraction < 0.74))
    throw ConfigError("repose.target_solid_fraction", "must lie in (0.3, 0.74)");
  if (!(overfill >= 1.0 && overfill <= 2.0)) throw ConfigError("repose.overfill", "must lie in [1, 2]");
  if (!std::isfinite(prep_damping) || prep_damping < 0.0 || prep_damping >= 1.0)
    throw ConfigError("repose.prep_damping", "must lie in [0, 1)");
  positive(settle_ke_ratio, "repose.settle_ke_ratio");
  positive(settle_time_limit, "repose.settle_time_limit");
  positive(rest_ke_ratio, "repose.rest_ke_ratio");
  non_negative(collapse_drag, "repose.collapse_drag");
  if (!(rest_trim >= 0.0 && rest_trim <= 0.1)) throw ConfigError("repose.rest_trim", "must lie in [0, 0.1]");
  if (rest_samples < 1) throw ConfigError("repose.rest_samples", "must be at least 1");
  non_negative(rest_profile_window, "repose.rest_profile_window");
  // A heap whose fitted angle moves by degrees within the window is still flowing.
  if (!(rest_profile_tol_deg > 0.0 && rest_profile_tol_deg <= 2.0))
    throw ConfigError("repose.rest_profile_tol_deg", "must lie in (0, 2] deg: a heap whose angle moves more is not at rest");
  non_negative(min_collapse_time, "repose.min_collapse_time");
  positive(time_limit, "repose.time_limit");
  positive(sample_interval, "repose.sample_interval");
  if (!(stiffness_scale > 0.0 && stiffness_scale <= 1.0))
    throw ConfigError("numerics.stiffness_scale", "must lie in (0, 1]");
  non_negative(dt, "numerics.dt");
  if (dt == 0.0) positive(dt_factor, "numerics.dt_factor");
  positive(gravity, "repose.gravity");
  if (!std::isfinite(energy_guard)) throw ConfigError("numerics.energy_guard", "must be finite");
  if (threads < 1) throw ConfigError("threads", "must be at least 1");
}

// How the heap's profile is binned and fitted.
void ReposeConfig::validate_profile() const {
  non_negative(bin_width, "repose.bin_width");
  // The profile bins grains by their centres: a bin narrower than the smallest grain
  // is often empty, and the fit's walk down the slope stops at the first empty bin
  // (1e-4 m bins on 1-2 mm grains fitted 4 bins of the crest's face: 85 deg).
  if (bin_width > 0.0 && bin_width < material.d_min)
    throw ConfigError("repose.bin_width", fmt(bin_width) + " m is narrower than the smallest grain (material.d_min " +
                                              fmt(material.d_min) + " m): the profile bins grains by their centres, so "
                                              "such bins are left empty and cut the fitted slope short; give at least "
                                              "d_min, or 0 for the mean diameter");
  if (!(fit_lo >= 0.0 && fit_lo < fit_hi && fit_hi <= 1.0))
    throw ConfigError("repose.fit_fractions", "need 0 <= fit_lo < fit_hi <= 1");
  non_negative(steep_window, "repose.steep_window");
  positive(front_min_height, "repose.front_min_height");
  non_negative(front_max_gap, "repose.front_max_gap");
}

// Whether the slab, the column and the grain count fit the grains' sizes.
void ReposeConfig::validate_geometry() const {
  const double d_mean = material.grading().mean();
  const double depth = slab_depth_diameters * d_mean;
  const double reach = interaction_reach(material);
  if (side_walls != SideWalls::periodic && depth < material.d_max) {
    std::ostringstream os;
    os << "slab depth " << depth << " m between side walls cannot hold the largest grain (" << material.d_max
       << " m); use at least " << std::ceil(10.0 * material.d_max / d_mean) / 10.0;
    throw ConfigError("repose.slab_depth_diameters", os.str());
  }
  if (side_walls == SideWalls::periodic && depth < 2.0 * reach) {
    std::ostringstream os;
    os << "slab depth " << depth << " m is below twice the interaction reach, 2 x " << reach
       << " m (the largest diameter plus the neighbour skin): periodic images would interact; use at least "
       << least_periodic_depth_diameters(material) << " (mean diameters of " << d_mean << " m)";
    throw ConfigError("repose.slab_depth_diameters", os.str());
  }
  if (column_width < 2.0 * material.d_max)
    throw ConfigError("repose.column_width", "must hold at least two of the largest grains");
  if (column_height < 2.0 * material.d_max)
    throw ConfigError("repose.column_height", "must hold at least two of the largest grains");
  // The grain count follows from the sizes: checked here, where a typo (a 10 m
  // column, a slab 1000 diameters deep) would otherwise run out of memory mid-task.
  const GrainEstimate grains = grain_estimate();
  if (!(grains.column + grains.floor <= kMaxReposeGrains)) {
    std::ostringstream os;
    os << "column " << column_width << " m x " << column_height << " m, slab " << depth << " m deep: about "
       << static_cast<double>(static_cast<long long>((grains.column + grains.floor) / 1e5)) / 10.0
       << " million grains, more than this scene takes (" << kMaxReposeGrains / 1e6
       << " million); check repose.column_width, repose.column_height and repose.depth_diameters";
    throw ConfigError("repose.column_width", os.str());
  }
}

Metrics ReposeResult::metrics() const {
  Metrics m = {{"particles", static_cast<double>(particles)},
               {"floor_particles", static_cast<double>(floor_particles)},
               {"column_width_m", column_width},
               {"column_height_m", column_height},
               {"aspect_ratio", aspect_ratio},
               {"column_solid_fraction", column_solid_fraction},
               {"slab_depth_m", slab_depth_m},
               {"domain_length_m", domain_length},
               {"dt", dt},
               {"dt_critical", dt_critical},
               {"stiffness_scale", stiffness_scale},
               {"kn", kn},
               {"ks", ks},
               {"prep_damping", prep_damping},
               {"prep_time_s", prep_time_s},
               {"collapse_drag_per_s", collapse_drag},
               {"rest_ke_J", rest_ke_J},
               {"bin_width_m", bin_width},
               {"steps", static_cast<double>(steps)},
               {"wall_s", wall_seconds},
               {"cpu_s", cpu_seconds},
               {"threads", static_cast<double>(threads)}};
  if (outcome.ok()) {
    Metrics r = {{"repose_deg", repose_deg},
                 {"repose_fit_err_deg", repose_fit_err_deg},
                 {"steepest_deg", steepest_deg},
                 {"fit_points", static_cast<double>(fit_points)},
                 {"repose_upper_deg", repose_upper_deg},
                 {"repose_lower_deg", repose_lower_deg},
                 {"runout_m", runout_m},
                 {"runout_ratio", runout_ratio},
                 {"grains_beyond_front", static_cast<double>(grains_beyond_front)},
                 {"front_m", front_m},
                 {"final_height_m", final_height_m},
                 {"time_to_rest_s", time_to_rest_s},
                 {"rest_by_profile", rest_by_profile ? 1.0 : 0.0},
                 {"reached_end_wall", reached_end_wall ? 1.0 : 0.0}};
    if (!std::isfinite(repose_deg)) {  // no fit: no angle, no error, no halves, no steepest
      static const std::set<std::string> of_the_fit = {"repose_deg",       "repose_fit_err_deg", "steepest_deg",
                                                       "fit_points",       "repose_upper_deg",   "repose_lower_deg"};
      r.erase(std::remove_if(r.begin(), r.end(), [](const auto& kv) { return of_the_fit.count(kv.first) > 0; }), r.end());
    }
    m.insert(m.begin(), r.begin(), r.end());
  }
  return m;
}

namespace {

// Sizes every stage uses, worked out once from the config.
struct ReposeSizes {
  double d_mean, v_mean, m_mean;  // mean diameter, grain volume and mass
  double W, H, Ly, L;             // column width and height, slab depth, domain length [m]
  double g, bin;                  // gravity [m/s^2], profile bin [m]
};

ReposeSizes sizes_of(const ReposeConfig& cfg) {
  const Material& mat = cfg.material;
  ReposeSizes z;
  z.d_mean = mat.grading().mean();
  z.v_mean = kPi / 6.0 * mat.grading().mean_cube();
  z.m_mean = mat.density * z.v_mean;
  z.W = cfg.column_width;
  z.H = cfg.column_height;
  z.Ly = cfg.slab_depth_diameters * z.d_mean;
  z.L = domain_length_of(cfg);
  z.g = cfg.gravity;
  z.bin = cfg.profile_bin();
  return z;
}

void name_series(ReposeResult& res) {
  res.energy.name = "energy";
  res.energy.columns = {"time", "kinetic", "ke_per_grain", "ke_flow_per_grain", "front_x", "repose_deg"};
  res.energy.units = {"s", "J", "J", "J", "m", "deg"};
  res.prep.name = "prep";
  res.prep.columns = {"time", "ke_per_grain", "ke_flow_per_grain"};
  res.prep.units = {"s", "J", "J"};
  res.profile.name = "profile";
  res.profile.columns = {"x", "h", "count"};
  res.profile.units = {"m", "m", "1"};
}

std::string describe_boundaries(const ReposeConfig& cfg, const ReposeSizes& z) {
  std::ostringstream os;
  if (cfg.side_walls == SideWalls::periodic)
    os << "slab periodic in y (depth " << z.Ly << " m, no side walls)";
  else
    os << "slab of depth " << z.Ly << " m between " << to_string(cfg.side_walls) << " side walls y = 0 and y = "
       << z.Ly << (cfg.side_walls == SideWalls::frictional ? " (the grains' theta and eta)" : "");
  os << "; smooth back wall x = 0; smooth gate x = " << z.W
     << " (removed at collapse); smooth end wall x = " << z.L << "; floor: fixed grains (same size distribution) on a"
     << " rough plane z = 0";
  return os.str();
}

// One layer of fixed grains on a jittered square grid resting on z = 0; each grain
// stays inside its cell.
struct Floor {
  Particles grains;
  double level = 0.0;  // mean grain diameter: the height profiles are measured from
  double top = 0.0;    // the largest
};

Floor lay_floor(const ReposeConfig& cfg, std::mt19937_64& rng) {
  const Material& mat = cfg.material;
  const FloorGrid grid = floor_grid(cfg);
  const int nx = grid.nx, ny = grid.ny;
  const double sx = grid.sx, sy = grid.sy;
  Floor fl;
  auto lay = [&](auto draw_diameter) {
    for (int ix = 0; ix < nx; ++ix)
      for (int iy = 0; iy < ny; ++iy) {
        const double r = 0.5 * draw_diameter();
        const double jx = (0.5 * sx - r) * uniform(rng, -1.0, 1.0);
        const double jy = (0.5 * sy - r) * uniform(rng, -1.0, 1.0);
        fl.grains.add(Vec3((ix + 0.5) * sx + jx, (iy + 0.5) * sy + jy, r), r, mat.density, true);
      }
  };
  // The default inlines its draw into the jitter's arithmetic, where GCC contracts
  // the two into FMAs: the floors of stored results were laid that way, and a draw
  // through Grading (or a branch between the two) rounds differently.
  if (mat.size_distribution == SizeDistribution::uniform)
    lay([&] { return uniform(rng, mat.d_min, mat.d_max); });
  else {
    const Grading grading = mat.grading();
    const Grading::Sampler draw(grading);
    lay([&] { return draw(rng); });
  }
  for (std::size_t i = 0; i < fl.grains.size(); ++i) {
    fl.level += 2.0 * fl.grains.r[i];
    fl.top = std::max(fl.top, 2.0 * fl.grains.r[i]);
  }
  fl.level /= static_cast<double>(fl.grains.size());
  return fl;
}

// The column's grains inserted at random in a tall region behind the gate, above
// the floor's grains there (which come first, fixed).
struct Fill {
  Particles grains;
  std::size_t n_floor = 0;
  double z0 = 0.0, height = 0.0;  // the region's bottom and height [m]
};

Fill fill_column(const ReposeConfig& cfg, const ReposeSizes& z, const Floor& floor, std::mt19937_64& rng) {
  const Material& mat = cfg.material;
  const double target_vs = cfg.target_solid_fraction * z.W * z.H * z.Ly;
  const std::size_t n_grains = static_cast<std::size_t>(std::ceil(cfg.overfill * target_vs / z.v_mean));
  std::vector<double> radii = sample_radii(n_grains, mat.grading(), rng);
  double vs = 0.0;
  for (double r : radii) vs += sphere_volume(r);
  Fill f;
  f.z0 = floor.top + 0.05 * mat.d_min;
  f.height = vs / (cfg.fill_solid_fraction * z.W * z.Ly);
  for (std::size_t i = 0; i < floor.grains.size(); ++i)
    if (floor.grains.x[i][0] < z.W) f.grains.add(floor.grains.x[i], floor.grains.r[i], mat.density, true);
  f.n_floor = f.grains.size();
  const bool periodic_y = cfg.side_walls == SideWalls::periodic;
  try {
    insert_random(f.grains, radii, Vec3(0.0, 0.0, f.z0), Vec3(z.W, z.Ly, f.z0 + f.height), mat.density, rng,
                  {false, periodic_y, false});
  } catch (const ConfigError& e) {  // the insertion's own words name no key of this scene
    throw ConfigError("repose.fill_solid_fraction",
                      e.reason() +
                          " (the column's grains are inserted at random at repose.fill_solid_fraction " +
                          fmt(cfg.fill_solid_fraction) + " in a slab of repose.depth_diameters " +
                          fmt(cfg.slab_depth_diameters) + " mean diameters" +
                          (periodic_y ? std::string() : std::string(" between side walls, which leave less room")) +
                          "): a lower fill_solid_fraction or a deeper slab");
  }
  return f;
}

WorldOptions world_options(const ReposeConfig& cfg, const ContactParams& law, const Fill& fill) {
  double m_min = 1e300;
  for (std::size_t i = fill.n_floor; i < fill.grains.size(); ++i) m_min = std::min(m_min, fill.grains.m[i]);
  WorldOptions opt;
  opt.dt = cfg.dt > 0.0 ? cfg.dt : timestep_from_factor(cfg.dt_factor, m_min, law.kn);
  opt.gravity = Vec3(0.0, 0.0, -cfg.gravity);
  opt.threads = cfg.threads;
  opt.local_damping = cfg.prep_damping;
  return opt;
}

struct ReposeWalls {
  Wall floor, back, gate, end;
  std::vector<Wall> side;  // none for a periodic slab
  std::vector<Wall> with_sides(std::vector<Wall> w) const {
    w.insert(w.end(), side.begin(), side.end());
    return w;
  }
};

ReposeWalls repose_walls(const ReposeConfig& cfg, const ReposeSizes& z) {
  ReposeWalls rw{make_wall("floor", Vec3::Zero(), Vec3::UnitZ(), true),
                 make_wall("back", Vec3::Zero(), Vec3::UnitX(), false),
                 make_wall("gate", Vec3(z.W, 0.0, 0.0), -Vec3::UnitX(), false),
                 make_wall("end", Vec3(z.L, 0.0, 0.0), -Vec3::UnitX(), false),
                 {}};
  if (cfg.side_walls != SideWalls::periodic) {
    const bool rough = cfg.side_walls == SideWalls::frictional;
    rw.side.push_back(make_wall("side_y0", Vec3::Zero(), Vec3::UnitY(), rough));
    rw.side.push_back(make_wall("side_y1", Vec3(0.0, z.Ly, 0.0), -Vec3::UnitY(), rough));
  }
  return rw;
}

// What the stages share: the stage under way (named in a failure), the steps and
// the preparation's clock.
struct ReposeRun {
  const ReposeConfig& cfg;
  Observer* obs;
  ReposeResult& res;
  std::size_t n_floor_prep;  // fixed floor grains behind the gate, first in the preparation's worlds
  double ke_unit;            // m_mean * g * d_mean [J]
  std::string stage = "fill";
  long steps_total = 0;
  double prep_clock = 0.0;

  // Damped settling until the flow's kinetic energy per grain falls below its
  // threshold (after min_time); the time it took.
  double settle(World& w, double min_time, const char* name) {
    stage = name;
    if (obs) obs->on_stage(name);
    const long chunk = std::max(1L, static_cast<long>(std::llround(cfg.sample_interval / w.dt())));
    const long n_mobile = static_cast<long>(w.particles().size() - n_floor_prep);
    const double t0 = w.time();
    std::vector<Vec3> prev = w.particles().x;
    std::vector<double> scratch;
    while (true) {
      w.run(chunk);
      steps_total += chunk;
      const double t = w.time() - t0;
      const double ke_all = kinetic_energy(w.particles()) / static_cast<double>(std::max(1L, n_mobile));
      const double ke = flow_ke_per_grain(w.particles(), w.domain(), prev, chunk * w.dt(), cfg.rest_trim, scratch);
      res.prep.add({prep_clock + t, ke_all, ke}, nullptr);
      if (t >= min_time && ke < cfg.settle_ke_ratio * ke_unit) break;
      if (t > cfg.settle_time_limit) throw std::runtime_error(not_settled(w, name, t, ke));
    }
    prep_clock += w.time() - t0;
    return w.time() - t0;
  }

  std::string not_settled(const World& w, const char* name, double t, double ke) const {
    std::ostringstream os;
    const Particles& pp = w.particles();
    std::size_t fast = 0;
    for (std::size_t i = 0; i < pp.size(); ++i)
      if (pp.v[i].squaredNorm() > pp.v[fast].squaredNorm()) fast = i;
    os << "column preparation (" << name << ") not at rest after " << t << " s (repose.settle_time_limit "
       << cfg.settle_time_limit << " s): kinetic energy per grain " << ke << " J, threshold "
       << cfg.settle_ke_ratio * ke_unit << " J; fastest grain at (" << pp.x[fast].transpose() << ") m moves at "
       << pp.v[fast].norm() << " m/s; a longer repose.settle_time_limit gives the column more time";
    return os.str();
  }
};

// The settled column with every grain whose top is above the target height
// removed, at rest; `kept` counts the mobile grains left.
Particles level_column(const World& settled, double top_limit, long& kept) {
  Particles lev = settled.particles();
  std::vector<std::uint8_t> drop(lev.size(), 0);
  kept = 0;
  for (std::size_t i = 0; i < lev.size(); ++i) {
    lev.v[i].setZero();
    lev.w[i].setZero();
    if (lev.fixed[i]) continue;
    drop[i] = lev.x[i][2] + lev.r[i] > top_limit ? 1 : 0;
    kept += drop[i] ? 0 : 1;
  }
  lev.remove_if(drop);
  return lev;
}

// The column as prepared: its height, aspect ratio and solid fraction.
void record_column(const Particles& pc, double floor_level, const ReposeSizes& z, ReposeResult& res) {
  double top = 0.0, vcol = 0.0;
  for (std::size_t i = 0; i < pc.size(); ++i) {
    if (pc.fixed[i]) continue;
    top = std::max(top, pc.x[i][2] + pc.r[i]);
    vcol += sphere_volume(pc.r[i]);
  }
  res.column_height = top - floor_level;
  res.aspect_ratio = res.column_height / z.W;
  res.column_solid_fraction = vcol / (z.W * z.Ly * res.column_height);
  if (res.column_height < 0.97 * z.H) {
    std::ostringstream os;
    os << "column settled to " << res.column_height << " m, below the target " << z.H
       << " m: raise overfill or lower target_solid_fraction";
    res.outcome.warnings.push_back(os.str());
  }
}

// The whole floor (fixed) and the column's grains (free), for the collapse.
Particles collapse_grains(const Floor& floor, const Particles& column, double density) {
  Particles all;
  for (std::size_t i = 0; i < floor.grains.size(); ++i) all.add(floor.grains.x[i], floor.grains.r[i], density, true);
  for (std::size_t i = 0; i < column.size(); ++i)
    if (!column.fixed[i]) all.add(column.x[i], column.r[i], density, false);
  return all;
}

// Where the deposit ends and the heap's slope as the final measurement would read them.
struct HeapReader {
  const ReposeConfig& cfg;
  const ReposeSizes& z;
  const std::vector<std::uint8_t>& mobile;
  double floor_level;
  int gap_bins;

  SurfaceProfile profile(const Particles& p) const {
    return surface_profile(p.x, p.r, &mobile, 0.0, z.L, z.bin, floor_level);
  }
  Front front(const SurfaceProfile& prof, const Particles& p) const {
    return deposit_front(prof, 0, cfg.front_min_height * z.d_mean, gap_bins, &p.x, &p.r, &mobile);
  }
  // Front x and angle now (NaN angle: no fit yet).
  std::pair<double, double> now(const Particles& p) const {
    const SurfaceProfile prof = profile(p);
    const Front fr = front(prof, p);
    const SlopeFit fit = fit_heap(prof, fr, cfg.fit_lo, cfg.fit_hi);
    return {fr.x, fit.ok ? fit.angle_deg : NAN};
  }
};

// Runs the collapse until the flow's kinetic energy stays below the rest threshold
// for rest_samples samples (true) or the time limit (false).
bool collapse_to_rest(ReposeRun& run, World& w, const HeapReader& heap, long chunk) {
  const ReposeConfig& cfg = run.cfg;
  ReposeResult& res = run.res;
  const double n_mobile = static_cast<double>(res.particles);
  std::vector<Vec3> x_prev = w.particles().x;
  std::vector<double> scratch;
  auto sample = [&]() {
    const Particles& p = w.particles();
    const double ke = kinetic_energy(p);
    const double ke_flow = flow_ke_per_grain(p, w.domain(), x_prev, chunk * w.dt(), cfg.rest_trim, scratch);
    const auto [front_x, angle] = heap.now(p);
    res.energy.add({w.time(), ke, ke / n_mobile, ke_flow, front_x, angle}, run.obs);
    return ke_flow;
  };
  w.refresh();
  sample();
  if (run.obs) run.obs->on_snapshot("column", w.time(), w.particles());
  int quiet = 0;
  const long drag_every = 100;
  const double drag_factor = std::exp(-cfg.collapse_drag * drag_every * w.dt());
  while (true) {
    if (cfg.collapse_drag > 0.0) {
      for (long done = 0; done < chunk;) {
        const long k = std::min(drag_every, chunk - done);
        w.run(k);
        done += k;
        Particles& pm = w.particles();
        const double f = k == drag_every ? drag_factor : std::exp(-cfg.collapse_drag * k * w.dt());
        for (std::size_t i = 0; i < pm.size(); ++i)
          if (!pm.fixed[i]) {
            pm.v[i] *= f;
            pm.w[i] *= f;
          }
      }
    } else {
      w.run(chunk);
    }
    run.steps_total += chunk;
    const double ke = sample();
    const double t = w.time();
    quiet = ke < res.rest_ke_J ? quiet + 1 : 0;
    if (run.obs) run.obs->on_progress(0.25 + 0.75 * std::min(1.0, t / cfg.time_limit));
    if (t >= cfg.min_collapse_time && quiet >= cfg.rest_samples) return true;
    if (t >= cfg.time_limit) return false;
  }
}

// A heap whose kinetic energy never fell below the threshold may still be at rest
// by its profile (rattlers keep the energy up): judged over the last
// rest_profile_window of the energy series. The note says what was seen.
std::string judge_by_profile(const ReposeConfig& cfg, double time_now, double bin, HeapStillness& still,
                             ReposeResult& res) {
  const auto col = [&](const char* name) {
    const std::size_t c = res.energy.column(name);
    std::vector<double> v;
    for (const auto& row : res.energy.rows) v.push_back(row[c]);
    return v;
  };
  const std::vector<double> time = col("time"), front = col("front_x"), angle = col("repose_deg");
  still = heap_stillness(time, front, angle, time_now - cfg.rest_profile_window, cfg.min_collapse_time);
  std::ostringstream note;
  if (still.judged) {
    res.profile_angle_change_deg = still.angle_change_deg;
    res.profile_front_change_m = still.front_change_m;
    res.rest_by_profile = still.angle_change_deg <= cfg.rest_profile_tol_deg && still.front_change_m <= bin;
    if (res.rest_by_profile) {
      const double since = still_since(time, front, angle, cfg.rest_profile_window, cfg.min_collapse_time,
                                       cfg.rest_profile_tol_deg, bin);
      if (since < still.since) still.since = since;  // NaN (the blocks judged otherwise): the window's start
    }
    note << "over the last " << cfg.rest_profile_window << " s the heap's angle moved by " << still.angle_change_deg
         << " deg (tolerance " << cfg.rest_profile_tol_deg << ") and its front by " << still.front_change_m
         << " m (the spread of its lowest value in each sixth of the window; tolerance one bin, " << bin << " m)";
    if (still.front_excursion_m > still.front_change_m + 1e-12)
      note << ", with excursions of up to " << still.front_excursion_m << " m (grains hopping at the toe)";
  } else {
    note << "the heap's profile was not judged: " << still.why;
    if (cfg.profile_check_has_no_room())
      note << " (repose.time_limit " << cfg.time_limit << " s leaves no room for the " << cfg.rest_profile_window
           << " s window after repose.min_collapse_time " << cfg.min_collapse_time << " s: raise it above "
           << cfg.profile_check_time() << " s for the check to run)";
  }
  return note.str();
}

// The deposit's front, runout, slope fit (whole, upper and lower half) and steepest
// local angle from the final profile.
void measure_deposit(const ReposeConfig& cfg, const ReposeSizes& z, const HeapReader& heap, const Particles& p,
                     const SurfaceProfile& prof, ReposeResult& res) {
  const Front front = heap.front(prof, p);
  const SlopeFit fit = fit_heap(prof, front, cfg.fit_lo, cfg.fit_hi);
  if (front.bin >= 0)  // no front, no deposit to be beyond
    for (std::size_t i = 0; i < p.size(); ++i)
      if (heap.mobile[i] && p.x[i][0] - p.r[i] > front.x) ++res.grains_beyond_front;
  res.final_height_m = fit.h_max;
  res.front_m = front.x;
  res.runout_m = front.x - z.W;
  res.runout_ratio = res.runout_m / z.W;
  for (std::size_t i = 0; i < p.size(); ++i)
    if (heap.mobile[i] && p.x[i][0] + p.r[i] > z.L - 0.5 * cfg.material.d_min) res.reached_end_wall = true;
  if (res.reached_end_wall) res.outcome.warnings.push_back("grains reached the end wall: runout is bounded by domain_length");
  if (!fit.ok) {
    // A heap at rest with no slope to fit (a profile of one or two bins) has no angle:
    // no result, as a triaxial that was no test has none.
    res.repose_deg = NAN;
    res.outcome.status = SceneStatus::invalid;
    res.outcome.failed_stage = "measure";
    res.outcome.message = "no angle of repose: " + fit.why +
                          (res.reached_end_wall                 ? " (the grains reached the end wall: a longer repose.domain_length)"
                           : z.bin > cfg.material.d_min * (1.0 + 1e-9) ? " (a larger column, or a narrower repose.bin_width)"
                                                                     : " (a larger column)");
    return;
  }
  res.repose_deg = fit.angle_deg;
  res.repose_fit_err_deg = fit.angle_err_deg;
  res.fit_points = fit.points;
  for (std::string& doubt : slope_doubts(fit, z.d_mean, z.bin, z.L, res.reached_end_wall))
    res.outcome.warnings.push_back(std::move(doubt));
  // A heap a few grains across has a line through it, not a slope: a 6 mm column of
  // 34 grains read 12.3 +- 9.3 deg over 4 bins, with nothing said.
  if (fit.points < ReposeResult::kMinSlopeBins) {
    std::ostringstream os;
    os << "the slope is fitted over " << fit.points << " profile bins, fewer than " << ReposeResult::kMinSlopeBins
       << " (angle error " << fit.angle_err_deg << " deg): the heap is too small for its angle to be a measurement "
       << "(a larger repose.column_width and column_height give it more)";
    res.outcome.warnings.push_back(os.str());
  } else if (fit.angle_err_deg > ReposeResult::kMaxFitErrDeg) {
    // Enough bins, but no straight slope through them (a staircase of grain layers,
    // a concave heap): 30.25 +- 7.8 deg over 6 bins was stored with nothing said.
    std::ostringstream os;
    os << "the slope fit's standard error is " << fit.angle_err_deg << " deg (above " << ReposeResult::kMaxFitErrDeg
       << "): the profile over its " << fit.points << " bins is no straight slope, and the angle is a line through "
       << "it (a larger column, or the profile in the HDF5 file, shows its shape)";
    res.outcome.warnings.push_back(os.str());
  }
  res.repose_upper_deg = fit.upper_angle_deg;
  res.repose_lower_deg = fit.lower_angle_deg;
  res.fit_slope = fit.slope;
  res.fit_intercept = fit.intercept;
  res.fit_x_upper = fit.x_upper;
  res.fit_x_lower = fit.x_lower;
  const double win = cfg.steep_window > 0.0 ? cfg.steep_window : 5.0 * z.d_mean;
  const int wbins = std::max(2, static_cast<int>(std::lround(win / z.bin)));
  res.steepest_deg = steepest_angle_deg(prof.x, prof.h, fit.x_upper, fit.x_lower, wbins);
}

// The final state: profile, whether the heap is at rest (by energy, else by its
// profile), and if so its measurements; else the run is not_settled, saying why.
void finish_collapse(const ReposeConfig& cfg, const ReposeSizes& z, const World& w, const HeapReader& heap, bool at_rest,
                     long chunk, ReposeResult& res) {
  const Particles& p = w.particles();
  // Reported even when not settled, for inspection.
  const SurfaceProfile prof = heap.profile(p);
  for (std::size_t b = 0; b < prof.x.size(); ++b)
    res.profile.add({prof.x[b], prof.h[b], static_cast<double>(prof.count[b])}, nullptr);

  std::string not_at_rest, profile_note;
  HeapStillness still;
  if (!at_rest) {
    std::ostringstream os;
    os << "flow kinetic energy per grain up to " << recent_flow_ke(res.energy, cfg.rest_samples) << " J over the last "
       << cfg.rest_samples << " samples, threshold " << res.rest_ke_J << " J"
       << few_grains_moving(p, heap.mobile, heap.floor_level, res.energy.rows.back()[res.energy.column("front_x")],
                            z.d_mean);
    not_at_rest = os.str();
    if (cfg.rest_profile_window > 0.0) profile_note = judge_by_profile(cfg, w.time(), z.bin, still, res);
  }
  if (!at_rest && !res.rest_by_profile) {
    std::ostringstream os;
    os << "deposit not at rest after " << w.time() << " s (time limit " << cfg.time_limit << " s): " << not_at_rest;
    if (!profile_note.empty()) os << "; " << profile_note;
    res.outcome.status = SceneStatus::not_settled;
    res.outcome.failed_stage = "collapse";
    res.outcome.message = os.str();
    return;
  }
  if (res.rest_by_profile) {
    res.time_to_rest_s = still.since;
    std::ostringstream os;
    os << "at rest by its profile, not by kinetic energy: at the time limit (" << cfg.time_limit << " s) the "
       << not_at_rest << "; but " << profile_note << ": the angle is the final state's, time_to_rest_s the earliest time from which its angle and front held within "
       << "those tolerances (" << still.since << " s), "
       << "and the runout where the front stood at the end (a grain at the toe may still move it by a bin or two)";
    res.outcome.warnings.push_back(os.str());
  } else {
    res.time_to_rest_s = w.time() - (cfg.rest_samples - 1) * chunk * w.dt();  // first quiet sample
  }
  measure_deposit(cfg, z, heap, p, prof, res);
}

// The set-up the result records before anything runs: sizes, closures, the law.
void record_setup(const ReposeConfig& cfg, const ReposeSizes& z, const ContactParams& law, ReposeResult& res) {
  res.threads = cfg.threads;
  res.column_width = z.W;
  res.slab_depth_m = z.Ly;
  res.domain_length = z.L;
  res.bin_width = z.bin;
  res.stiffness_scale = cfg.stiffness_scale;
  res.prep_damping = cfg.prep_damping;
  res.collapse_drag = cfg.collapse_drag;
  res.rest_ke_J = cfg.rest_ke_ratio * z.m_mean * z.g * z.d_mean;
  res.boundaries = describe_boundaries(cfg, z);
  res.kn = law.kn;
  res.ks = law.ks;
}

// Preparation: damped settling behind the gate, levelling to the column's height,
// settling again. Returns the levelled column (with the floor behind the gate).
Particles prepare_column(ReposeRun& run, const ReposeSizes& z, const Floor& floor, Fill& fill, const ReposeWalls& rw,
                         const Domain& dom, const ContactParams& law, const WorldOptions& opt) {
  ReposeResult& res = run.res;
  World w1(std::move(fill.grains), rw.with_sides({rw.floor, rw.back, rw.gate}), dom, law, opt);
  res.prep_time_s += run.settle(w1, std::sqrt(2.0 * fill.height / z.g), "settle");
  if (run.obs) run.obs->on_progress(0.15);

  run.stage = "level";
  long kept = 0;
  Particles lev = level_column(w1, floor.level + z.H, kept);
  World w2(std::move(lev), rw.with_sides({rw.floor, rw.back, rw.gate}), dom, law, opt);
  res.prep_time_s += run.settle(w2, 0.02, "settle_levelled");
  if (run.obs) run.obs->on_progress(0.25);
  res.particles = kept;
  record_column(w2.particles(), floor.level, z, res);
  return w2.particles();
}

// Collapse: full floor, no gate, no damping, until the heap is at rest or the time
// limit; then the deposit measured. The contact history of the column is rebuilt
// within the first steps (the world is reassembled with the floor beyond the gate,
// which the gate plane would otherwise have touched).
void collapse(ReposeRun& run, const ReposeSizes& z, const Floor& floor, const Particles& column, const ReposeWalls& rw,
              const Domain& dom, const ContactParams& law, const WorldOptions& opt) {
  const ReposeConfig& cfg = run.cfg;
  ReposeResult& res = run.res;
  run.stage = "collapse";
  if (run.obs) run.obs->on_stage("collapse");
  WorldOptions copt = opt;
  copt.local_damping = 0.0;
  Wall gate_off = rw.gate;
  gate_off.active = false;
  World w(collapse_grains(floor, column, cfg.material.density), rw.with_sides({rw.floor, rw.back, gate_off, rw.end}),
          dom, law, copt);
  const StabilityLimits lim = stability_limits(w);
  res.dt_critical = lim.governing().dt_critical;
  res.critical_mode = lim.governing().mode + " (" + lim.governing().contact + ")";
  if (cfg.energy_guard >= 0.0) w.enable_energy_guard(cfg.energy_guard, 1000);

  const std::vector<std::uint8_t> mobile = mobile_mask(w.particles());
  const HeapReader heap{cfg, z, mobile, floor.level, static_cast<int>(std::ceil(cfg.front_max_gap * z.d_mean / z.bin))};
  const long chunk = std::max(1L, static_cast<long>(std::llround(cfg.sample_interval / w.dt())));
  const bool at_rest = collapse_to_rest(run, w, heap, chunk);
  res.steps = run.steps_total;
  if (run.obs) run.obs->on_snapshot("heap", w.time(), w.particles());
  res.final_particles = w.particles();
  res.final_particles.f.clear();  // forces and torques are not part of the record
  res.final_particles.t.clear();
  finish_collapse(cfg, z, w, heap, at_rest, chunk, res);
}

}  // namespace

ReposeResult run_repose(const ReposeConfig& cfg, Observer* obs) {
  cfg.validate();
  const RunClock clock;
  ReposeResult res;
  name_series(res);
  const ReposeSizes z = sizes_of(cfg);
  Material law_mat = cfg.material;
  law_mat.kn *= cfg.stiffness_scale;
  law_mat.ks *= cfg.stiffness_scale;
  const ContactParams law = contact_params(law_mat);
  record_setup(cfg, z, law, res);

  std::mt19937_64 rng(cfg.seed);
  const Floor floor = lay_floor(cfg, rng);
  res.floor_level = floor.level;
  res.floor_particles = static_cast<long>(floor.grains.size());
  Fill fill = fill_column(cfg, z, floor, rng);
  const WorldOptions opt = world_options(cfg, law, fill);
  res.dt = opt.dt;

  Domain dom;
  dom.lo = Vec3(0.0, 0.0, 0.0);
  dom.hi = Vec3(z.L, z.Ly, fill.z0 + fill.height + z.H);
  dom.periodic = {false, cfg.side_walls == SideWalls::periodic, false};
  const ReposeWalls rw = repose_walls(cfg, z);

  ReposeRun run{cfg, obs, res, fill.n_floor, z.m_mean * z.g * z.d_mean};
  try {
    const Particles column = prepare_column(run, z, floor, fill, rw, dom, law, opt);
    collapse(run, z, floor, column, rw, dom, law, opt);
  } catch (const InstabilityError& e) {
    res.outcome.status = SceneStatus::unstable;
    res.outcome.failed_stage = run.stage;
    res.outcome.message = e.what();
    // What the engine's message cannot know: a scaled-down stiffness lets the column's
    // own weight press grains deep into each other whatever the step.
    if (e.quantity() == "overlap" && cfg.weight_overlap() > ReposeConfig::kWeightOverlapNote)
      res.outcome.message += "; at repose.stiffness_scale " + fmt(cfg.stiffness_scale) +
                             " the column's weight alone presses a grain at its foot " + fmt(cfg.weight_overlap(), 2) +
                             " of the smallest radius into its neighbours, and the collapse's impacts add to it: a "
                             "larger repose.stiffness_scale";
  } catch (const std::runtime_error& e) {
    res.outcome.status = SceneStatus::not_settled;
    res.outcome.failed_stage = run.stage;
    res.outcome.message = e.what();
  }
  res.steps = run.steps_total;
  res.outcome.join_warnings();
  res.wall_seconds = clock.wall_seconds();
  res.cpu_seconds = clock.cpu_seconds();
  if (obs) obs->on_progress(1.0);
  return res;
}

}  // namespace demcal::engine
