#include "grazing_impact.hpp"

#include "../errors.hpp"
#include "../measure.hpp"
#include "../world.hpp"

#include <algorithm>
#include <cmath>

namespace demcal::engine {

const char* to_string(ImpactTarget t) {
  switch (t) {
    case ImpactTarget::wall: return "wall";
    case ImpactTarget::fixed_sphere: return "fixed_sphere";
    case ImpactTarget::free_sphere: return "free_sphere";
  }
  return "unknown";
}

ImpactTarget impact_target_from(const std::string& name) {
  if (name == "wall") return ImpactTarget::wall;
  if (name == "fixed_sphere" || name == "sphere") return ImpactTarget::fixed_sphere;
  if (name == "free_sphere") return ImpactTarget::free_sphere;
  throw ConfigError("grazing.target", "expected \"wall\", \"fixed_sphere\" or \"free_sphere\", got \"" + name + "\"");
}

GrazingConfig::GrazingConfig() {
  material.friction_angle = deg_to_rad(30.0);
  material.rolling_eta = 0.1;
  material.rolling_b = 1.0;
}

void GrazingConfig::validate() const {
  material.validate();
  if (!(incidence_deg >= 0.0 && incidence_deg < 90.0))
    throw ConfigError("grazing.incidence_deg", "must lie in [0, 90) degrees from the contact normal");
  if (!(std::isfinite(speed) && speed > 0.0)) throw ConfigError("grazing.speed", "must be a finite number > 0");
  if (!std::isfinite(spin)) throw ConfigError("grazing.spin", "must be finite");
  if (!(std::isfinite(radius) && radius > 0.0)) throw ConfigError("grazing.radius", "must be a finite number > 0");
  if (!(std::isfinite(target_radius) && target_radius >= 0.0))
    throw ConfigError("grazing.target_radius", "must be finite and >= 0");
  if (!(dt_fraction > 0.0 && dt_fraction <= 0.25))
    throw ConfigError("grazing.dt_fraction", "must lie in (0, 0.25] of the contact duration");
  if (max_steps < 1) throw ConfigError("grazing.max_steps", "must be at least 1");
}

namespace {

double total_energy(const World& world) {
  const Energies e = energies(world);
  return e.kinetic() + e.elastic();
}

// The projectile (grain 0) in contact with its target, moving at cfg.speed at
// cfg.incidence_deg from the contact normal and spinning at cfg.spin. Plane of
// incidence x-z, spin about y. Returns the unit normal from the target towards the
// projectile, which approaches along minus it.
Vec3 place_impact(const GrazingConfig& cfg, Particles& p, std::vector<Wall>& walls) {
  const double a = deg_to_rad(cfg.incidence_deg);
  const double r1 = cfg.radius;
  const double r2 = cfg.target_radius > 0.0 ? cfg.target_radius : cfg.radius;
  const Vec3 m(std::sin(a), 0.0, std::cos(a));
  if (cfg.target == ImpactTarget::wall) {
    p.add(Vec3(0.0, 0.0, r1), r1, cfg.material.density);
    p.v[0] = cfg.speed * Vec3(std::sin(a), 0.0, -std::cos(a));
    Wall w;
    w.name = "floor";
    w.point = Vec3::Zero();
    w.normal = Vec3::UnitZ();
    w.frictional = true;
    w.rolling = true;
    walls.push_back(w);
  } else {
    p.add((r1 + r2) * m, r1, cfg.material.density);
    p.v[0] = cfg.speed * Vec3(0.0, 0.0, -1.0);
    p.add(Vec3::Zero(), r2, cfg.material.density, cfg.target == ImpactTarget::fixed_sphere);
  }
  p.w[0] = cfg.spin * Vec3::UnitY();
  return cfg.target == ImpactTarget::wall ? Vec3(Vec3::UnitZ()) : m;
}

// Steps until the pair has touched and separated again (or the step limit): whether it
// separated. Records the largest energy ratio, the steps in contact, whether the spring
// slid or rolled plastically; n_last is the last contact normal, target to projectile.
bool follow_impact(World& world, const GrazingConfig& cfg, GrazingResult& res, Vec3& n_last) {
  const double tan_theta = std::tan(cfg.material.friction_angle);
  // Contact lasts about t_c (longer for a grazing slide); allow ample margin.
  const long limit = std::min(cfg.max_steps, static_cast<long>(std::ceil(20.0 / cfg.dt_fraction)) + 100);
  bool touched = false;
  while (world.step_count() < limit) {
    world.step();
    int live = 0;
    world.for_each_contact([&](const ContactView& c) {
      ++live;
      n_last = -c.n;  // c.n points from the projectile towards the target
      const double fn = world.law().kn * c.delta;
      if (tan_theta > 0.0 && fn > 0.0 && c.fs.norm() >= fn * tan_theta * (1.0 - 1e-9)) res.slid = true;
      const double mp = world.law().eta * c.r_roll * fn;
      if (world.law().rolling() && c.mr.norm() >= mp * (1.0 - 1e-9) && mp > 0.0) res.rolled_plastic = true;
    });
    if (live > 0) {
      touched = true;
      ++res.contact_steps;
    }
    res.max_energy_ratio = std::max(res.max_energy_ratio, total_energy(world) / res.energy_initial);
    if (touched && live == 0) return true;
  }
  res.outcome.status = SceneStatus::not_converged;
  res.outcome.failed_stage = "impact";
  res.outcome.message = touched ? "the spheres did not separate within the step limit" : "no contact was made";
  return false;
}

}  // namespace

GrazingResult run_grazing_impact(const GrazingConfig& cfg) {
  cfg.validate();
  GrazingResult res;
  res.target = cfg.target;
  res.incidence_deg = cfg.incidence_deg;
  const double r1 = cfg.radius;
  const double r2 = cfg.target_radius > 0.0 ? cfg.target_radius : cfg.radius;
  const bool wall_target = cfg.target == ImpactTarget::wall;
  Particles p;
  std::vector<Wall> walls;
  const Vec3 n_in = place_impact(cfg, p, walls);
  const double vn_in = p.v[0].dot(n_in);  // < 0: approaching

  const double m1 = p.m[0];
  const double m_eff = cfg.target == ImpactTarget::free_sphere ? m1 * p.m[1] / (m1 + p.m[1]) : m1;
  res.t_contact = kPi * std::sqrt(m_eff / cfg.material.kn);
  res.dt = cfg.dt_fraction * res.t_contact;

  Domain dom;
  dom.lo = Vec3::Constant(-10.0 * (r1 + r2));
  dom.hi = Vec3::Constant(10.0 * (r1 + r2));
  WorldOptions opt;
  opt.dt = res.dt;
  World world(std::move(p), std::move(walls), dom, contact_params(cfg.material), opt);
  world.refresh();
  res.energy_initial = total_energy(world);
  res.max_energy_ratio = 1.0;
  Vec3 n_last = n_in;
  try {
    if (!follow_impact(world, cfg, res, n_last)) return res;
  } catch (const InstabilityError& e) {
    res.outcome.status = SceneStatus::unstable;
    res.outcome.failed_stage = "impact";
    res.outcome.message = e.what();
    return res;
  }
  res.energy_final = total_energy(world);
  res.energy_ratio = res.energy_final / res.energy_initial;
  const Particles& q = world.particles();
  const Vec3 v_rel = wall_target ? q.v[0] : Vec3(q.v[0] - q.v[1]);
  const double vn = v_rel.dot(n_last);
  const double vt = (v_rel - vn * n_last).norm();
  res.rebound_deg = rad_to_deg(std::atan2(vt, vn));
  res.normal_restitution = vn_in != 0.0 ? -vn / vn_in : 0.0;
  res.spin_final = q.w[0].dot(Vec3::UnitY());
  return res;
}

std::vector<GrazingResult> sweep_grazing(const GrazingConfig& base, const std::vector<double>& incidence_deg) {
  std::vector<GrazingResult> out;
  for (double a : incidence_deg) {
    GrazingConfig c = base;
    c.incidence_deg = a;
    out.push_back(run_grazing_impact(c));
  }
  return out;
}

}  // namespace demcal::engine
