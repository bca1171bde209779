#pragma once
// The chi-square distribution's upper quantile, for the fit's consistency warning
// (a misfit above the 99% level). Exact to ~1e-10 relative: the Wilson-Hilferty
// approximation used before put the 1-dof level at 6.58 instead of 6.635.

namespace demcal::calibrate {

// The regularised lower incomplete gamma function P(a, x), a > 0, x >= 0.
double regularized_gamma_p(double a, double x);

// x with P(chi2_dof > x) = tail, for dof >= 1 and tail in (0, 1).
double chi2_upper_quantile(int dof, double tail);

}  // namespace demcal::calibrate
