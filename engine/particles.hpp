#pragma once
// Particle state in structure-of-arrays form: one contiguous array per quantity.
#include "types.hpp"

#include <cstddef>
#include <vector>

namespace demcal::engine {

struct Particles {
  std::vector<Vec3> x;  // position [m]
  std::vector<Vec3> v;  // velocity [m/s]
  std::vector<Vec3> w;  // angular velocity [rad/s]
  std::vector<Vec3> f;  // force [N]
  std::vector<Vec3> t;  // torque [N m]
  std::vector<double> r;      // radius [m]
  std::vector<double> m;      // mass [kg]
  std::vector<double> inv_m;  // 1/m, 0 for fixed grains
  std::vector<double> inv_i;  // 1/I with I = 2/5 m r^2, 0 for fixed grains
  std::vector<std::uint8_t> fixed;  // 1: never integrated (rough floors)

  std::size_t size() const { return x.size(); }

  // Appends a sphere of radius `radius` and density `density` at rest.
  std::size_t add(const Vec3& pos, double radius, double density, bool is_fixed = false) {
    const double mass = density * sphere_volume(radius);
    x.push_back(pos);
    v.push_back(Vec3::Zero());
    w.push_back(Vec3::Zero());
    f.push_back(Vec3::Zero());
    t.push_back(Vec3::Zero());
    r.push_back(radius);
    m.push_back(mass);
    inv_m.push_back(is_fixed ? 0.0 : 1.0 / mass);
    inv_i.push_back(is_fixed ? 0.0 : 1.0 / (0.4 * mass * radius * radius));
    fixed.push_back(is_fixed ? 1 : 0);
    return x.size() - 1;
  }

  // Multiplies every mass (and inertia) by `factor`: density scaling for quasi-static runs.
  void scale_density(double factor) {
    for (std::size_t i = 0; i < size(); ++i) {
      m[i] *= factor;
      inv_m[i] /= factor;
      inv_i[i] /= factor;
    }
  }

  void remove_if(const std::vector<std::uint8_t>& drop);  // compacting erase
  void reorder(const std::vector<std::size_t>& order);     // new[i] = old[order[i]]
};

}  // namespace demcal::engine
