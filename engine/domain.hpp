#pragma once
// The simulation box: bounds and, per axis, whether it is periodic. Non-periodic
// axes are open (walls, if any, confine the grains); their bounds are informative.
#include "types.hpp"

#include <array>
#include <cmath>

namespace demcal::engine {

struct Domain {
  Vec3 lo = Vec3::Zero();
  Vec3 hi = Vec3::Ones();
  std::array<bool, 3> periodic{false, false, false};

  bool any_periodic() const { return periodic[0] || periodic[1] || periodic[2]; }
  double length(int axis) const { return hi[axis] - lo[axis]; }

  // Shortest image of a separation vector across periodic axes.
  void min_image(Vec3& d) const {
    for (int a = 0; a < 3; ++a) {
      if (!periodic[a]) continue;
      const double len = hi[a] - lo[a];
      d[a] -= len * std::nearbyint(d[a] / len);
    }
  }
  // Folds a position back into [lo, hi) on periodic axes.
  void wrap(Vec3& x) const {
    for (int a = 0; a < 3; ++a) {
      if (!periodic[a]) continue;
      const double len = hi[a] - lo[a];
      x[a] -= len * std::floor((x[a] - lo[a]) / len);
    }
  }
};

}  // namespace demcal::engine
