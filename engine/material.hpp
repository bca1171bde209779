#pragma once
// Material of the grains and the contact parameters derived from it (seed Table 2.1).
#include "size_distribution.hpp"
#include "types.hpp"

#include <cmath>

namespace demcal::engine {

struct Material {
  double kn = 3.0e7;            // normal stiffness [N/m]
  double ks = 2.7e7;            // tangential stiffness [N/m]
  double density = 2650.0;      // grain density [kg/m^3] (before any density scaling)
  double friction_angle = 0.0;  // inter-particle friction angle theta [rad]
  double rolling_b = 1.0;       // rolling stiffness coefficient b: Kr = b*Ks*r^2
  double rolling_eta = 0.0;     // plastic moment coefficient eta: Mp = eta*r*|Fn|
  // Whether the rolling spring also resists twisting (relative rotation about the
  // normal). The seed's "relative rotational angle" (Eq. 2.5) does not say which;
  // off = rolling only (the tangential part), the common reading.
  bool rolling_twist = false;
  double d_min = 1.0e-3;        // smallest diameter [m]
  double d_max = 2.0e-3;        // largest diameter [m]
  SizeDistribution size_distribution = SizeDistribution::uniform;  // how diameters fill [d_min, d_max]
  // A measured grading curve; [d_min, d_max] cuts it (Grading::curve). Empty: none.
  SieveCurve grading_curve;

  Grading grading() const { return {size_distribution, d_min, d_max, grading_curve}; }

  void validate() const;  // throws ConfigError naming the field
};

// Parameters the force kernel reads, fixed for a run stage.
struct ContactParams {
  double kn = 0, ks = 0, tan_theta = 0, b = 0, eta = 0;
  bool twist = false;  // the rolling spring also resists relative twist
  bool tangential() const { return ks > 0.0; }
  bool rolling() const { return eta > 0.0 && b > 0.0 && ks > 0.0; }
};

inline ContactParams contact_params(const Material& m) {
  return ContactParams{m.kn, m.ks, std::tan(m.friction_angle), m.rolling_b, m.rolling_eta, m.rolling_twist};
}

}  // namespace demcal::engine
