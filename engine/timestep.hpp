#pragma once
// Stability limits of the explicit integrator for every mode of the contact law.
// See docs/timestep.md for the derivation.
#include "material.hpp"

#include <string>
#include <vector>

namespace demcal::engine {

class World;

struct ModeLimit {
  std::string mode;     // "normal", "tangential" (spring coupled with rotation), "rolling"
  std::string contact;  // which isolated contact sets it, e.g. "pair d_min-d_min", "wall d_min"
  double omega;         // highest angular frequency of the mode [rad/s]
  double dt_critical;   // 2 / omega: the velocity-Verlet stability limit
};

struct StabilityLimits {
  std::vector<ModeLimit> modes;  // one entry per (mode, contact) present
  double base_step = 0.0;        // sqrt(m_min / Kn), the seed's Eq. 2.9 with k = 1
  // Upper bound on the highest frequency with the contacts the packing has now
  // (Gershgorin); 0 when no contacts exist. Always at least the isolated limit.
  double omega_with_contacts = 0.0;
  const ModeLimit& governing() const;  // the mode with the smallest critical step
};

struct LimitInputs {
  ContactParams law;
  double m_min = 0, r_min = 0;  // smallest mobile sphere
  double m_max = 0, r_max = 0;  // largest mobile sphere
  bool wall_frictional = false;
  bool wall_rolling = false;
  bool has_walls = false;
};

StabilityLimits stability_limits(const LimitInputs& in);
// Limits for a world's grains, walls and current contact parameters; `dt` (if > 0)
// only changes nothing but is accepted for symmetry with set_dt.
StabilityLimits stability_limits(const World& world, double dt = 0.0);
// The same grains and walls under another law (one a stage is about to switch to).
StabilityLimits stability_limits(const World& world, const ContactParams& law);

// Throws TimestepError naming the governing mode when dt exceeds its limit.
void check_timestep(double dt, const StabilityLimits& limits);

// dt = factor * sqrt(m_min / Kn) (seed Eq. 2.9).
double timestep_from_factor(double factor, double m_min, double kn);

// A scene's step and the limit of its isolated contacts, known before any grain
// exists: from the extremes of the diameter range. The world's own check, with the
// contacts it then has, can only be stricter. For job validation.
struct StepForecast {
  double dt = 0.0, dt_critical = 0.0;
  double m_min = 0.0, inertia_min = 0.0;  // the smallest grain's mass and moment of inertia
  std::string mode;    // the governing mode and contact
  bool refused = true;  // false where the scene runs past the limit on purpose (a stability study)
  bool exceeds() const { return dt > dt_critical; }
};
// `in` carries the law and the walls; the masses come from d_min, d_max, density.
// dt = explicit_dt if > 0, else dt_factor * sqrt(m_min / Kn).
StepForecast forecast_step(LimitInputs in, double d_min, double d_max, double density, double explicit_dt,
                           double dt_factor);

}  // namespace demcal::engine
