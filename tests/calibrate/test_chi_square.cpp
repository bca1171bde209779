#include "calibrate/chi_square.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

using demcal::calibrate::chi2_upper_quantile;
using demcal::calibrate::regularized_gamma_p;

// Closed forms: P(1, x) = 1 - e^-x, and P(1/2, x) = erf(sqrt x), on both sides of the
// series / continued-fraction switch at x = a + 1.
TEST(ChiSquare, RegularizedGammaMatchesClosedForms) {
  for (double x : {0.01, 0.5, 1.9, 2.1, 7.0, 30.0}) {
    EXPECT_NEAR(regularized_gamma_p(1.0, x), 1 - std::exp(-x), 1e-13) << x;
    EXPECT_NEAR(regularized_gamma_p(0.5, x), std::erf(std::sqrt(x)), 1e-13) << x;
  }
  EXPECT_EQ(regularized_gamma_p(3.0, 0.0), 0.0);
  EXPECT_THROW(regularized_gamma_p(0.0, 1.0), std::invalid_argument);
}

// Table values (Abramowitz & Stegun 26.4; NIST e-Handbook 1.3.6.7.4). Wilson-Hilferty,
// used before, gave 6.58 for one degree of freedom at 1%.
TEST(ChiSquare, UpperQuantilesMatchTables) {
  struct Row {
    int dof;
    double tail, x;
  };
  for (const Row& r : {Row{1, 0.01, 6.634897}, Row{2, 0.01, 9.210340}, Row{3, 0.01, 11.344867},
                       Row{5, 0.05, 11.070498}, Row{10, 0.01, 23.209251}, Row{30, 0.01, 50.892181},
                       Row{100, 0.01, 135.806723}, Row{1, 0.5, 0.454936}})
    EXPECT_NEAR(chi2_upper_quantile(r.dof, r.tail), r.x, 2e-6 * r.x) << r.dof << " " << r.tail;
  EXPECT_NEAR(chi2_upper_quantile(2, 0.01), -2 * std::log(0.01), 1e-9);  // exact for 2 dof
  EXPECT_THROW(chi2_upper_quantile(0, 0.01), std::invalid_argument);
  EXPECT_THROW(chi2_upper_quantile(3, 1.0), std::invalid_argument);
}
