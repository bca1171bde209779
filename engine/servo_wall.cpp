#include "servo_wall.hpp"

#include "errors.hpp"

#include <algorithm>
#include <cmath>
#include <string>

namespace demcal::engine {

void ServoGains::validate(const char* field) const {
  const std::string f(field);
  if (!(alpha > 0.0 && alpha <= 1.0)) throw ConfigError(f + ".alpha", "must lie in (0, 1]");
  if (!(beta >= 0.0 && beta <= 0.2)) throw ConfigError(f + ".beta", "must lie in [0, 0.2]");
  if (!std::isfinite(max_speed) || max_speed <= 0.0) throw ConfigError(f + ".max_speed", "must be a finite number > 0");
}

double ServoWall::update(Wall& w, double force_target, double dt, const ServoGains& g) {
  double v;
  if (w.contacts == 0 || w.stiffness <= 0.0) {
    v_int_ = 0.0;
    v = force_target > 0.0 ? g.max_speed : 0.0;
  } else {
    const double err = force_target - normal_force(w);  // > 0: push harder, move inwards
    const double dx = g.alpha * err / w.stiffness;
    v_int_ = std::clamp(v_int_ + g.beta * dx / dt, -g.max_speed, g.max_speed);
    v = std::clamp(dx / dt + v_int_, -g.max_speed, g.max_speed);
  }
  w.velocity = v * w.normal;
  return v;
}

}  // namespace demcal::engine
