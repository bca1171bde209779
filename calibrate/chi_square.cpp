#include "chi_square.hpp"

#include <cmath>
#include <stdexcept>

namespace demcal::calibrate {
namespace {

// Series for x < a + 1, continued fraction (modified Lentz) above: each converges
// fast on its side (Numerical Recipes, section 6.2).
double gamma_p_series(double a, double x) {
  double term = 1.0 / a, sum = term;
  for (int n = 1; n < 1000 && std::abs(term) > 1e-16 * std::abs(sum); ++n) {
    term *= x / (a + n);
    sum += term;
  }
  return sum * std::exp(-x + a * std::log(x) - std::lgamma(a));
}

double gamma_q_fraction(double a, double x) {
  constexpr double tiny = 1e-300;
  double b = x + 1 - a, c = 1 / tiny, d = 1 / b, h = d;
  for (int n = 1; n < 1000; ++n) {
    const double an = -n * (n - a);
    b += 2;
    d = an * d + b;
    if (std::abs(d) < tiny) d = tiny;
    c = b + an / c;
    if (std::abs(c) < tiny) c = tiny;
    d = 1 / d;
    const double step = d * c;
    h *= step;
    if (std::abs(step - 1) < 1e-16) break;
  }
  return std::exp(-x + a * std::log(x) - std::lgamma(a)) * h;
}

}  // namespace

double regularized_gamma_p(double a, double x) {
  if (!(a > 0) || !(x >= 0)) throw std::invalid_argument("regularized_gamma_p: needs a > 0 and x >= 0");
  if (x == 0) return 0;
  return x < a + 1 ? gamma_p_series(a, x) : 1 - gamma_q_fraction(a, x);
}

double chi2_upper_quantile(int dof, double tail) {
  if (dof < 1 || !(tail > 0 && tail < 1)) throw std::invalid_argument("chi2_upper_quantile: needs dof >= 1, 0 < tail < 1");
  const double a = 0.5 * dof;
  auto upper = [&](double x) { return 1 - regularized_gamma_p(a, 0.5 * x); };
  // The upper tail falls with x: bracket, then bisect to the last bit that matters.
  double lo = 0, hi = dof + 10.0;
  while (upper(hi) > tail) hi *= 2;
  for (int k = 0; k < 200 && hi - lo > 1e-12 * hi; ++k) {
    const double mid = 0.5 * (lo + hi);
    (upper(mid) > tail ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

}  // namespace demcal::calibrate
