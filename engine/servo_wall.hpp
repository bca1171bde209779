#pragma once
// Stress-controlled (servo) rigid wall.
//
// The wall moves along its normal so that the compressive force the grains exert
// on it approaches a target. The gain is set each step from the wall's current
// contact stiffness (Wall::stiffness = sum of Kn over its contacts):
//
//   proportional   dx_p = alpha * (F_target - F) / k_contacts        per step
//   integral       v_i += beta * alpha * (F_target - F) / (k_contacts * dt)
//   speed          v = clamp(dx_p / dt + v_i, -v_max, v_max)          (inward positive)
//
// The proportional part alone closes a fraction alpha of the error that the wall's
// own contacts see in one step (stable for alpha < 2, no overshoot for alpha <= 1);
// it cannot lag less than v*dt*k/alpha while the wall must keep moving (a sample
// that dilates or contracts under shear), so a small integral term learns that
// steady speed and removes the lag. With no contact the wall approaches the sample
// at v_max and the integral memory is cleared. Poles of the discrete loop against
// a rigid contact layer: z^2 - (2 - alpha - alpha*beta) z + (1 - alpha) = 0; for
// the triaxial defaults alpha = 0.5, beta = 0.02 they are 0.98 and 0.51 (real,
// inside the unit circle: no oscillation). The speed cap bounds what the wall can
// do while it has few contacts (the gas phase of a preparation).
#include "wall.hpp"

namespace demcal::engine {

struct ServoGains {
  double alpha = 0.5;      // fraction of the contact-stiffness error closed per step, in (0, 1]
  double beta = 0.02;      // integral gain per step, in [0, 0.2]
  double max_speed = 0.0;  // [m/s], > 0

  void validate(const char* field) const;  // throws ConfigError
};

class ServoWall {
 public:
  ServoWall() = default;
  explicit ServoWall(int wall_index) : wall_(wall_index) {}

  int wall() const { return wall_; }
  // Compressive normal force the grains exert on the wall now [N] (>= 0).
  static double normal_force(const Wall& w) { return -w.force.dot(w.normal); }

  // Sets w.velocity for the next step so that the normal force approaches
  // `force_target` [N]; returns the inward speed chosen [m/s].
  double update(Wall& w, double force_target, double dt, const ServoGains& g);
  void reset() { v_int_ = 0.0; }
  double integral_speed() const { return v_int_; }

 private:
  int wall_ = -1;
  double v_int_ = 0.0;
};

}  // namespace demcal::engine
