#pragma once
// Small builders shared by the engine tests.
#include "engine/world.hpp"

#include <cmath>

namespace demcal::engine::testing {

constexpr double kDensity = 2650.0;

inline ContactParams law(double kn = 3e7, double ks = 2.7e7, double theta_deg = 0.0, double b = 1.0,
                         double eta = 0.0) {
  return ContactParams{kn, ks, std::tan(deg_to_rad(theta_deg)), b, eta};
}

inline double mass_of(double r) { return kDensity * sphere_volume(r); }

inline WorldOptions options(double dt, int threads = 1) {
  WorldOptions o;
  o.dt = dt;
  o.threads = threads;
  return o;
}

inline Domain open_domain() {
  Domain d;
  d.lo = Vec3::Constant(-1.0);
  d.hi = Vec3::Constant(1.0);
  return d;
}

inline Wall plane(const std::string& name, const Vec3& point, const Vec3& normal, bool frictional = false,
                  bool rolling = false) {
  Wall w;
  w.name = name;
  w.point = point;
  w.normal = normal;
  w.frictional = frictional;
  w.rolling = rolling;
  return w;
}


}  // namespace demcal::engine::testing
