// Grazing impact (issue 9): a sphere on a wall, on a fixed and on a free sphere,
// across incidence angles, with friction (30 deg) and rolling resistance (eta 0.1,
// b 1) and no damping. The law can store and dissipate energy but never create
// it, so after separation the energy may exceed the initial energy only by the
// integrator's own error: that of the same impact head-on without friction at the
// same step (the exit of the normal spring falls between steps; O(dt^3) here).
#include <cmath>
#include "engine/errors.hpp"
#include "engine/scenes/grazing_impact.hpp"

#include <gtest/gtest.h>

#include <cstdio>

using namespace demcal::engine;

namespace {

double frictionless_head_on_gain(ImpactTarget t, double dt_fraction) {
  GrazingConfig c;
  c.target = t;
  c.incidence_deg = 0.0;
  c.dt_fraction = dt_fraction;
  c.material.friction_angle = 0.0;
  c.material.rolling_eta = 0.0;
  const GrazingResult r = run_grazing_impact(c);
  EXPECT_TRUE(r.outcome.ok()) << r.outcome.message;
  return r.energy_ratio - 1.0;
}

void expect_no_gain(ImpactTarget t, double dt_fraction, double spin) {
  const double allowed = std::max(0.0, frictionless_head_on_gain(t, dt_fraction)) + 1e-6;
  double worst = -1.0, worst_angle = 0.0;
  for (double a = 5.0; a <= 85.0; a += 5.0) {
    GrazingConfig c;
    c.target = t;
    c.incidence_deg = a;
    c.dt_fraction = dt_fraction;
    c.spin = spin;
    const GrazingResult r = run_grazing_impact(c);
    ASSERT_TRUE(r.outcome.ok()) << to_string(t) << " at " << a << " deg: " << r.outcome.message;
    EXPECT_LE(r.energy_ratio - 1.0, allowed) << to_string(t) << " gained energy at " << a << " deg, dt = "
                                             << dt_fraction << " t_c, spin " << spin;
    if (r.energy_ratio - 1.0 > worst) {
      worst = r.energy_ratio - 1.0;
      worst_angle = a;
    }
  }
  std::printf("[ report   ] %-12s dt = %.4f t_c, spin %6.0f rad/s: largest E_after/E_before - 1 = %+.3e at %2.0f deg "
              "(allowed %.3e)\n", to_string(t), dt_fraction, spin, worst, worst_angle, allowed);
}

}  // namespace

TEST(GrazingImpact, NoEnergyGainAgainstAWall) {
  for (double f : {0.1, 0.0125})
    for (double spin : {0.0, 2000.0, -2000.0}) expect_no_gain(ImpactTarget::wall, f, spin);
}

TEST(GrazingImpact, NoEnergyGainAgainstAFixedSphere) {
  for (double f : {0.1, 0.0125})
    for (double spin : {0.0, 2000.0, -2000.0}) expect_no_gain(ImpactTarget::fixed_sphere, f, spin);
}

TEST(GrazingImpact, NoEnergyGainAgainstAFreeSphere) {
  for (double f : {0.1, 0.0125})
    for (double spin : {0.0, 2000.0, -2000.0}) expect_no_gain(ImpactTarget::free_sphere, f, spin);
}

TEST(GrazingImpact, IntegratorErrorVanishesWithTheStep) {
  // The only source of gain is the step: it falls at least 8x per halving (O(dt^3)
  // with contact starting on a step boundary) and is below 1e-5 at t_c / 80.
  const double g1 = frictionless_head_on_gain(ImpactTarget::wall, 0.05);
  const double g2 = frictionless_head_on_gain(ImpactTarget::wall, 0.025);
  EXPECT_GT(g1 / g2, 7.0);
  EXPECT_LT(frictionless_head_on_gain(ImpactTarget::wall, 0.0125), 1e-5);
}

TEST(GrazingImpact, FrictionlessGrazingReboundIsSpecular) {
  GrazingConfig c;
  c.material.friction_angle = 0.0;
  c.material.rolling_eta = 0.0;
  c.incidence_deg = 60.0;
  c.dt_fraction = 0.005;
  const GrazingResult r = run_grazing_impact(c);
  ASSERT_TRUE(r.outcome.ok());
  EXPECT_NEAR(r.rebound_deg, 60.0, 0.01);
  EXPECT_NEAR(r.energy_ratio, 1.0, 1e-6);
  EXPECT_FALSE(r.slid);
}

TEST(GrazingImpact, FrictionTurnsTheReboundTowardsTheNormalAndSlidesAtGrazingAngles) {
  GrazingConfig c;
  c.incidence_deg = 75.0;
  c.dt_fraction = 0.01;
  const GrazingResult r = run_grazing_impact(c);
  ASSERT_TRUE(r.outcome.ok());
  EXPECT_TRUE(r.slid);
  EXPECT_LT(r.energy_ratio, 1.0);
  EXPECT_LT(r.rebound_deg, 75.0);
  EXPECT_GT(r.spin_final, 0.0);  // sliding along +x on a floor below spins it about +y
  // Rigid-body impact (Walton) with e = 1: the grain slides throughout, so the
  // tangential impulse is mu * 2 m v_n and tan(rebound) = tan(incidence) - 2 mu; the
  // friction torque less the rolling moment (eta r Fn, plastic nearly at once) spins it
  // to 5 (mu - eta) v_n / r. The tangential spring's compliance is the only difference.
  const double mu = std::tan(c.material.friction_angle), eta = c.material.rolling_eta;
  const double a = c.incidence_deg * M_PI / 180.0, vn = c.speed * std::cos(a), vt = c.speed * std::sin(a);
  const double vt_after = vt - 2.0 * mu * vn, w_after = 5.0 * (mu - eta) * vn / c.radius;
  EXPECT_NEAR(r.rebound_deg, std::atan(vt_after / vn) * 180.0 / M_PI, 0.1);
  EXPECT_NEAR(r.spin_final, w_after, 0.02 * w_after);
  const double ke_after = vn * vn + vt_after * vt_after + 0.4 * std::pow(w_after * c.radius, 2);
  EXPECT_NEAR(r.energy_ratio, ke_after / (c.speed * c.speed), 0.01);
  std::printf("[ report   ] 75 deg, tan theta = 0.577: rebound %.3f deg, energy ratio %.4f, spin %.4g rad/s\n",
              r.rebound_deg, r.energy_ratio, r.spin_final);
}

TEST(GrazingImpact, BadConfigNamesTheField) {
  GrazingConfig c;
  c.incidence_deg = 90.0;
  try {
    run_grazing_impact(c);
    FAIL();
  } catch (const ConfigError& e) {
    EXPECT_EQ(e.field(), "grazing.incidence_deg");
  }
  EXPECT_THROW(impact_target_from("floor"), ConfigError);
  EXPECT_EQ(impact_target_from("sphere"), ImpactTarget::fixed_sphere);
}
