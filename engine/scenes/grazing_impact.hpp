#pragma once
// Oblique (grazing) impact of one sphere on a wall or on another sphere, with the
// full contact law (friction, rolling resistance) and no damping. Nothing in the
// law can create energy: sliding and plastic rolling only dissipate, the springs
// only store. So the total energy (translational + rotational kinetic + elastic
// spring energy) after separation may never exceed the energy before impact, up
// to the integrator's error, which vanishes as O(dt^2). A known failure of peer
// codes' wall contacts (a tangential spring not carried into the tangent plane, a
// torque arm inconsistent with the slip velocity) shows as a gain that does not
// vanish with dt.
//
// Geometry: the incidence angle alpha is measured from the contact normal
// (0 = head-on, 90 = grazing). The impact starts with the spheres exactly touching,
// so contact begins on a step boundary.
#include "../material.hpp"
#include "scene_status.hpp"

#include <string>
#include <vector>

namespace demcal::engine {

enum class ImpactTarget { wall, fixed_sphere, free_sphere };
const char* to_string(ImpactTarget t);
// "wall", "fixed_sphere" (or "sphere"), "free_sphere"; throws ConfigError("grazing.target").
ImpactTarget impact_target_from(const std::string& name);

struct GrazingConfig {
  Material material;                // theta, eta, b used as given (defaults below: 30 deg, 0.1, 1)
  ImpactTarget target = ImpactTarget::wall;
  double incidence_deg = 45.0;      // from the contact normal, in [0, 90)
  double speed = 1.0;               // impact speed [m/s]
  double spin = 0.0;                // initial angular velocity about the axis normal to the plane of incidence [rad/s]
  double radius = 0.5e-3;           // projectile radius [m]
  double target_radius = 0.0;       // sphere targets; 0: same as the projectile
  double dt_fraction = 0.01;        // dt = dt_fraction * t_c, t_c = pi sqrt(m*/Kn) (normal contact duration)
  long max_steps = 10000000;

  GrazingConfig();
  void validate() const;  // throws ConfigError naming the field
};

struct GrazingResult {
  SceneOutcome outcome;
  ImpactTarget target = ImpactTarget::wall;
  double incidence_deg = 0;
  double dt = 0, t_contact = 0;     // time step and the normal contact duration pi sqrt(m*/Kn)
  long contact_steps = 0;
  double energy_initial = 0;        // [J]
  double energy_final = 0;          // after separation (all kinetic)
  double energy_ratio = 0;          // energy_final / energy_initial
  double max_energy_ratio = 0;      // largest (kinetic + elastic) / initial seen at any step
  double rebound_deg = 0;           // outgoing relative velocity from the separation normal (0 = straight back)
  double normal_restitution = 0;    // -v_n(out) / v_n(in) of the relative contact velocity
  double spin_final = 0;            // projectile's angular velocity about the plane normal [rad/s]
  bool slid = false;                // the Coulomb cap was reached at some step
  bool rolled_plastic = false;      // the plastic rolling moment was reached at some step
};

GrazingResult run_grazing_impact(const GrazingConfig& config);

// One run per incidence angle.
std::vector<GrazingResult> sweep_grazing(const GrazingConfig& base, const std::vector<double>& incidence_deg);

}  // namespace demcal::engine
