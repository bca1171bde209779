#include "size_distribution.hpp"

#include "packing.hpp"

#include <algorithm>
#include <cmath>

namespace demcal::engine {

const char* to_string(SizeDistribution s) {
  switch (s) {
    case SizeDistribution::uniform: return "uniform";
    case SizeDistribution::uniform_mass: return "uniform_mass";
    case SizeDistribution::log_uniform_mass: return "log_uniform_mass";
  }
  return "?";
}

bool parse_size_distribution(const std::string& name, SizeDistribution& out) {
  for (SizeDistribution s : kSizeDistributions)
    if (name == to_string(s)) {
      out = s;
      return true;
    }
  return false;
}

namespace {
// The number density of the mass-based gradings is d^-k on [a, b] (k = 3: mass
// uniform in d; k = 4: mass uniform in log d). I(p) = integral of d^(p-k).
double integral_of_power(double a, double b, double q) {  // integral of d^q over [a, b]
  return q == -1.0 ? std::log(b / a) : (std::pow(b, q + 1) - std::pow(a, q + 1)) / (q + 1);
}
double exponent(SizeDistribution s) { return s == SizeDistribution::uniform_mass ? 3.0 : 4.0; }
}  // namespace

double Grading::draw(std::mt19937_64& rng) const {
  // The default consumes one draw exactly as before (stored samples stay the same).
  if (kind == SizeDistribution::uniform || d_max <= d_min) return uniform(rng, d_min, d_max);
  const double k1 = exponent(kind) - 1.0;  // inverse CDF of d^-k: d^-(k-1) linear in u
  const double lo = std::pow(d_min, -k1), hi = std::pow(d_max, -k1);
  // Rounding can step an ulp past the range at u near 0 or 1.
  return std::clamp(std::pow(lo - uniform01(rng) * (lo - hi), -1.0 / k1), d_min, d_max);
}

// Closed forms of the ratios of integrals, written without the cancellation the
// ratios have when d_max is close to d_min.
double Grading::mean() const {
  const double a = d_min, b = d_max;
  if (kind == SizeDistribution::uniform || b <= a) return 0.5 * (a + b);
  if (kind == SizeDistribution::uniform_mass) return 2.0 * a * b / (a + b);
  return 1.5 * a * b * (a + b) / (a * a + a * b + b * b);
}

double Grading::mean_cube() const {
  const double a = d_min, b = d_max;
  if (b - a < 1e-15) return a * a * a;
  if (kind == SizeDistribution::uniform)  // the difference form kept where it is exact enough: stored runs used it
    return b - a < 1e-6 * b ? 0.25 * (a + b) * (a * a + b * b) : (std::pow(b, 4) - std::pow(a, 4)) / (4.0 * (b - a));
  if (kind == SizeDistribution::uniform_mass) return 2.0 * a * a * b * b / (a + b);
  return 3.0 * a * a * a * b * b * b * std::log1p((b - a) / a) / ((b - a) * (a * a + a * b + b * b));
}

double Grading::finer_by_mass(double d) const {
  if (d <= d_min) return 0.0;
  if (d >= d_max) return 1.0;
  const double k = kind == SizeDistribution::uniform ? 0.0 : exponent(kind);  // mass density d^(3-k)
  return integral_of_power(d_min, d, 3.0 - k) / integral_of_power(d_min, d_max, 3.0 - k);
}

std::vector<double> sample_radii(std::size_t n, const Grading& g, std::mt19937_64& rng) {
  std::vector<double> r(n);
  for (auto& x : r) x = 0.5 * g.draw(rng);
  return r;
}

}  // namespace demcal::engine
