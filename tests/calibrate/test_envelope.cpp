#include "calibrate/envelope.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace demcal::test {
namespace {

TEST(Envelope, MohrCoulombRecoversKnownFrictionAngleAndCohesion) {
  const double phi = 35.0, c = 12.0;  // deg, kPa
  const double N = std::pow(std::tan((45 + phi / 2) * M_PI / 180), 2);
  std::mt19937_64 rng(11);
  std::normal_distribution<double> noise(0.0, 2.0);
  std::vector<double> s3, s1;
  for (double p : {50.0, 100.0, 200.0, 400.0})
    for (int r = 0; r < 3; ++r) {
      s3.push_back(p);
      s1.push_back(N * p + 2 * c * std::sqrt(N) + noise(rng));
    }
  const auto e = calibrate::fit_envelope(s3, s1);
  std::printf("phi %.3f +- %.3f deg, c %.3f +- %.3f kPa; phi (c = 0) %.3f\n", e.phi_deg, e.phi_se, e.c, e.c_se, e.phi0_deg);
  EXPECT_GT(e.phi_se, 0);
  EXPECT_GT(e.c_se, 0);
  // The regression's own errors for 2 kPa noise over these pressures (Sxx = 215,625 kPa^2,
  // n = 12): se(N) = 0.0043, so phi_se ~ 0.027 deg and c_se ~ 0.26 kPa; an
  // over-estimate would widen the checks below into meaninglessness.
  EXPECT_LT(e.phi_se, 0.06);
  EXPECT_LT(e.c_se, 0.6);
  EXPECT_NEAR(e.phi_deg, phi, std::max(3 * e.phi_se, 0.05));
  EXPECT_NEAR(e.c, c, std::max(3 * e.c_se, 0.5));
  EXPECT_EQ(e.pressures, 4);
  // Without noise and without cohesion, both lines agree exactly.
  std::vector<double> t1;
  for (double p : s3) t1.push_back(N * p);
  const auto z = calibrate::fit_envelope(s3, t1);
  EXPECT_NEAR(z.phi_deg, phi, 1e-9);
  EXPECT_NEAR(z.c, 0, 1e-9);
  EXPECT_NEAR(z.phi0_deg, phi, 1e-9);
  // One pressure: the secant angle only, from the mean ratio (sigma1 = 3.05 sigma3: 30.6 deg).
  const auto one = calibrate::fit_envelope({100, 100}, {300, 310});
  EXPECT_EQ(one.pressures, 1);
  EXPECT_TRUE(std::isnan(one.phi_deg));
  EXPECT_TRUE(std::isnan(one.c));
  EXPECT_NEAR(one.phi0_deg, std::asin(2.05 / 4.05) * 180 / M_PI, 1e-9);
  EXPECT_GT(one.phi0_se, 0.0);
  EXPECT_TRUE(std::isnan(calibrate::fit_envelope({100}, {300}).phi0_se));
  EXPECT_THROW(calibrate::fit_envelope({}, {}), std::invalid_argument);
  // sigma1 rising slower than sigma3 is no friction angle (it printed phi = -28 deg).
  EXPECT_THROW(calibrate::fit_envelope({50, 100, 200}, {100, 120, 160}), std::invalid_argument);
  EXPECT_EQ(z.dof, 10);
}

TEST(Envelope, CohesionErrorMatchesTheSpreadOfRepeatedFits) {
  // Low pressures and a large cohesion, where the slope's and the intercept's errors
  // are strongly correlated and the covariance term of c's error carries the weight:
  // c = b / (2 sqrt N) moves one way with b and the other with N. Over 2,000 noisy
  // repeats of the same nine tests, the standard deviation of the fitted c must be
  // what each fit's c_se says (0.905 and 0.853 kPa here; with the covariance's sign
  // flipped c_se would read 0.17, without the covariance 0.61).
  const double phi = 35.0, c = 100.0;
  const double N = std::pow(std::tan((45 + phi / 2) * M_PI / 180), 2);
  std::mt19937_64 rng(5);
  std::normal_distribution<double> noise(0.0, 2.0);
  double sum = 0, sum2 = 0, se_sum = 0;
  const int repeats = 2000;
  for (int k = 0; k < repeats; ++k) {
    std::vector<double> s3, s1;
    for (double p : {25.0, 50.0, 75.0})
      for (int r = 0; r < 3; ++r) {
        s3.push_back(p);
        s1.push_back(N * p + 2 * c * std::sqrt(N) + noise(rng));
      }
    const auto e = calibrate::fit_envelope(s3, s1);
    sum += e.c;
    sum2 += e.c * e.c;
    se_sum += e.c_se;
  }
  const double mean = sum / repeats, sd = std::sqrt((sum2 - repeats * mean * mean) / (repeats - 1));
  // The mean of c_se is biased low by about 1/(4 dof) (a sample sd's bias); 10% covers it.
  EXPECT_NEAR(se_sum / repeats / sd, 1.0, 0.1) << "sd of c " << sd << ", mean c_se " << se_sum / repeats;
  EXPECT_NEAR(mean, c, 3 * sd / std::sqrt(repeats));
}

TEST(Envelope, StudentQuantilesForFewDegreesOfFreedom) {
  EXPECT_NEAR(calibrate::t95(1), 12.706, 1e-3);
  EXPECT_NEAR(calibrate::t95(2), 4.303, 1e-3);
  EXPECT_NEAR(calibrate::t95(10), 2.228, 1e-3);
  EXPECT_NEAR(calibrate::t95(1000), 1.96, 1e-3);
  EXPECT_TRUE(std::isnan(calibrate::t95(0)));
  // Each state reads its own stored angle.
  EXPECT_STREQ(calibrate::state_metric(calibrate::EnvelopeState::peak), "phi_peak_deg");
  EXPECT_STREQ(calibrate::state_metric(calibrate::EnvelopeState::smoothed), "phi_peak_smoothed_deg");
  EXPECT_STREQ(calibrate::state_metric(calibrate::EnvelopeState::cv), "phi_cv_deg");
}

}  // namespace
}  // namespace demcal::test
