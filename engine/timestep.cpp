#include "timestep.hpp"
#include "format.hpp"

#include "errors.hpp"
#include "world.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <sstream>

namespace demcal::engine {
namespace {

struct Body {
  double m, r;
  double inertia() const { return 0.4 * m * r * r; }
};

// Keeps the fastest frequency of each (mode, contact) pair.
void keep_worst(std::vector<ModeLimit>& modes, const std::string& mode, const std::string& contact, double omega2) {
  if (!(omega2 > 0.0)) return;
  const double omega = std::sqrt(omega2);
  for (auto& m : modes) {
    if (m.mode == mode && m.contact == contact) {
      if (omega > m.omega) m = ModeLimit{mode, contact, omega, 2.0 / omega};
      return;
    }
  }
  modes.push_back(ModeLimit{mode, contact, omega, 2.0 / omega});
}

// In-plane vibration of an isolated contact: generalized eigenproblem K q = w^2 M q.
// Each eigenmode is labelled by the spring that stores most of its energy.
void inplane_modes(std::vector<ModeLimit>& modes, const std::string& contact, const Eigen::MatrixXd& M,
                   const Eigen::VectorXd& g_t, double ks, const Eigen::VectorXd& g_r, double kr) {
  Eigen::MatrixXd K = ks * g_t * g_t.transpose() + kr * g_r * g_r.transpose();
  Eigen::GeneralizedSelfAdjointEigenSolver<Eigen::MatrixXd> es(K, M);
  for (int k = 0; k < K.rows(); ++k) {
    const double w2 = es.eigenvalues()[k];
    if (w2 <= 1e-12 * es.eigenvalues().cwiseAbs().maxCoeff()) continue;
    const Eigen::VectorXd q = es.eigenvectors().col(k);
    const double et = ks * std::pow(g_t.dot(q), 2), er = kr * std::pow(g_r.dot(q), 2);
    keep_worst(modes, et >= er ? "tangential" : "rolling", contact, w2);
  }
}

void pair_limits(std::vector<ModeLimit>& modes, const ContactParams& law, Body a, Body b, const std::string& name) {
  keep_worst(modes, "normal", name, law.kn * (1.0 / a.m + 1.0 / b.m));
  if (!law.tangential()) return;
  // Generalized coordinates (x_a, x_b, theta_a, theta_b); tangential slip at the
  // contact u = x_a - x_b + R_a theta_a + R_b theta_b, relative rolling theta_a - theta_b.
  Eigen::MatrixXd M = Eigen::Vector4d(a.m, b.m, a.inertia(), b.inertia()).asDiagonal();
  const double r = 0.5 * (a.r + b.r);
  const double kr = law.rolling() ? law.b * law.ks * r * r : 0.0;
  inplane_modes(modes, name, M, Eigen::Vector4d(1.0, -1.0, a.r, b.r), law.ks, Eigen::Vector4d(0, 0, 1, -1), kr);
}

void wall_limits(std::vector<ModeLimit>& modes, const ContactParams& law, Body a, bool frictional, bool rolling,
                 const std::string& name) {
  keep_worst(modes, "normal", name, law.kn / a.m);
  if (!frictional || !law.tangential()) return;
  Eigen::MatrixXd M = Eigen::Vector2d(a.m, a.inertia()).asDiagonal();
  const double kr = (rolling && law.rolling()) ? law.b * law.ks * a.r * a.r : 0.0;
  inplane_modes(modes, name, M, Eigen::Vector2d(1.0, a.r), law.ks, Eigen::Vector2d(0.0, 1.0), kr);
}


}  // namespace

const ModeLimit& StabilityLimits::governing() const {
  return *std::min_element(modes.begin(), modes.end(),
                           [](const ModeLimit& a, const ModeLimit& b) { return a.dt_critical < b.dt_critical; });
}

StabilityLimits stability_limits(const LimitInputs& in) {
  StabilityLimits out;
  const Body small{in.m_min, in.r_min}, large{in.m_max, in.r_max};
  pair_limits(out.modes, in.law, small, small, "pair d_min-d_min");
  pair_limits(out.modes, in.law, small, large, "pair d_min-d_max");
  if (in.has_walls) wall_limits(out.modes, in.law, small, in.wall_frictional, in.wall_rolling, "wall d_min");
  out.base_step = std::sqrt(in.m_min / in.law.kn);
  return out;
}

StabilityLimits stability_limits(const World& world, double /*dt*/) { return stability_limits(world, world.law()); }

StabilityLimits stability_limits(const World& world, const ContactParams& law_in) {
  const Particles& p = world.particles();
  LimitInputs in;
  in.law = law_in;
  in.m_min = 1e300;
  in.m_max = 0.0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    if (p.fixed[i]) continue;
    if (p.m[i] < in.m_min) {
      in.m_min = p.m[i];
      in.r_min = p.r[i];
    }
    if (p.m[i] > in.m_max) {
      in.m_max = p.m[i];
      in.r_max = p.r[i];
    }
  }
  if (in.m_max == 0.0) {  // nothing moves: nothing can go unstable
    StabilityLimits none;
    none.modes.push_back(ModeLimit{"normal", "no mobile grains", 0.0, 1e300});
    return none;
  }
  for (const auto& w : world.walls()) {
    in.has_walls = true;
    in.wall_frictional |= w.frictional;
    in.wall_rolling |= w.rolling;
  }
  StabilityLimits out = stability_limits(in);

  // With many contacts a grain vibrates faster than against one: Gershgorin's bound
  // on M^-1 K, row by row, from the contacts present now.
  std::vector<double> ktrans(p.size(), 0.0), krot(p.size(), 0.0);
  const ContactParams& law = in.law;
  world.for_each_contact([&](const ContactView& c) {
    const double kt = law.tangential() ? law.ks : 0.0;
    const double kr = law.rolling() ? law.b * law.ks * c.r_roll * c.r_roll : 0.0;
    for (int side = 0; side < 2; ++side) {
      const int i = side == 0 ? c.i : c.j;
      if (i < 0) continue;
      const double arm = side == 0 ? c.arm_i : c.arm_j;
      ktrans[i] += std::max(law.kn, kt);
      krot[i] += kt * arm * arm + kr;
    }
  });
  double w2 = 0.0;
  for (std::size_t i = 0; i < p.size(); ++i) {
    if (p.fixed[i]) continue;
    const double inertia = 0.4 * p.m[i] * p.r[i] * p.r[i];
    w2 = std::max(w2, 2.0 * (ktrans[i] / p.m[i] + krot[i] / inertia));
  }
  out.omega_with_contacts = std::sqrt(w2);
  return out;
}

void check_timestep(double dt, const StabilityLimits& limits) {
  const ModeLimit& g = limits.governing();
  if (dt > g.dt_critical) {
    const std::string factor = fmt(g.dt_critical / limits.base_step);
    throw TimestepError(g.mode, dt, g.dt_critical,
                        "time step " + fmt(dt) + " s exceeds the critical step of the " + g.mode + " mode (" +
                            g.contact + "): " + fmt(g.dt_critical) + " s = " + factor +
                            " * sqrt(m_min/Kn); a dt_factor of at most " + factor +
                            ", and well below it (a grain with several contacts has a lower limit)");
  }
}

double timestep_from_factor(double factor, double m_min, double kn) {
  if (!std::isfinite(factor) || factor <= 0.0) throw ConfigError("dt_factor", "must be a finite positive number");
  return factor * std::sqrt(m_min / kn);
}

StepForecast forecast_step(LimitInputs in, double d_min, double d_max, double density, double explicit_dt,
                           double dt_factor) {
  const auto mass = [density](double d) { return density * sphere_volume(0.5 * d); };
  in.r_min = 0.5 * d_min;
  in.r_max = 0.5 * d_max;
  in.m_min = mass(d_min);
  in.m_max = mass(d_max);
  const StabilityLimits lim = stability_limits(in);
  StepForecast f;
  f.dt = explicit_dt > 0.0 ? explicit_dt : timestep_from_factor(dt_factor, in.m_min, in.law.kn);
  f.dt_critical = lim.governing().dt_critical;
  f.m_min = in.m_min;
  f.inertia_min = 0.4 * in.m_min * in.r_min * in.r_min;
  f.mode = lim.governing().mode + " mode (" + lim.governing().contact + ")";
  return f;
}

}  // namespace demcal::engine
