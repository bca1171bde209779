#include "size_distribution.hpp"

#include "enum_names.hpp"
#include "packing.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

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
  return parse_by_name(name, kSizeDistributions, out);
}

namespace {
// The number density of the mass-based gradings is d^-k on [a, b] (k = 3: mass
// uniform in d; k = 4: mass uniform in log d). I(p) = integral of d^(p-k).
double integral_of_power(double a, double b, double q) {  // integral of d^q over [a, b]
  return q == -1.0 ? std::log(b / a) : (std::pow(b, q + 1) - std::pow(a, q + 1)) / (q + 1);
}
double exponent(SizeDistribution s) { return s == SizeDistribution::uniform_mass ? 3.0 : 4.0; }
}  // namespace

namespace {
// One grading across [a, b] as `kind` says: the whole range without a curve, one
// piece of it with one.
double draw_range(SizeDistribution kind, double a, double b, std::mt19937_64& rng) {
  // The default consumes one draw exactly as before (stored samples stay the same).
  if (kind == SizeDistribution::uniform || b <= a) return uniform(rng, a, b);
  const double k1 = exponent(kind) - 1.0;  // inverse CDF of d^-k: d^-(k-1) linear in u
  const double lo = std::pow(a, -k1), hi = std::pow(b, -k1);
  // Rounding can step an ulp past the range at u near 0 or 1.
  return std::clamp(std::pow(lo - uniform01(rng) * (lo - hi), -1.0 / k1), a, b);
}

// Closed forms of the ratios of integrals, written without the cancellation the
// ratios have when b is close to a.
double mean_range(SizeDistribution kind, double a, double b) {
  if (kind == SizeDistribution::uniform || b <= a) return 0.5 * (a + b);
  if (kind == SizeDistribution::uniform_mass) return 2.0 * a * b / (a + b);
  return 1.5 * a * b * (a + b) / (a * a + a * b + b * b);
}

double mean_cube_range(SizeDistribution kind, double a, double b) {
  if (b - a < 1e-15) return a * a * a;
  if (kind == SizeDistribution::uniform)  // the difference form kept where it is exact enough: stored runs used it
    return b - a < 1e-6 * b ? 0.25 * (a + b) * (a * a + b * b) : (std::pow(b, 4) - std::pow(a, 4)) / (4.0 * (b - a));
  if (kind == SizeDistribution::uniform_mass) return 2.0 * a * a * b * b / (a + b);
  return 3.0 * a * a * a * b * b * b * std::log1p((b - a) / a) / ((b - a) * (a * a + a * b + b * b));
}

double finer_range(SizeDistribution kind, double a, double b, double d) {
  if (d <= a) return 0.0;
  if (d >= b) return 1.0;
  const double k = kind == SizeDistribution::uniform ? 0.0 : exponent(kind);  // mass density d^(3-k)
  return integral_of_power(a, d, 3.0 - k) / integral_of_power(a, b, 3.0 - k);
}
}  // namespace

std::string SieveCurve::problem() const {
  if (d.size() != finer.size()) return "sizes and fractions differ in number";
  if (d.size() < 2) return "needs at least two sizes";
  for (std::size_t i = 0; i < d.size(); ++i) {
    std::ostringstream at_os;
    at_os << "point " << i + 1 << " (d = " << d[i] << " m): ";
    const std::string at = at_os.str();
    if (!std::isfinite(d[i]) || d[i] <= 0.0) return at + "the size must be a finite number > 0";
    if (!std::isfinite(finer[i]) || finer[i] < 0.0 || finer[i] > 1.0) return at + "the fraction finer must lie in [0, 1]";
    if (i > 0 && !(d[i] > d[i - 1])) return at + "sizes must increase from one point to the next";
    if (i > 0 && finer[i] < finer[i - 1]) return at + "the mass finer must not decrease as the size grows";
  }
  if (finer.front() != 0.0)
    return "the first size must have nothing finer (0%): it is the smallest grain (a sieve analysis whose finest "
           "sieve passes some mass needs a smaller size at 0% below it)";
  if (finer.back() != 1.0)
    return "the last size must have everything finer (100%): it is the largest grain (add the size that passes "
           "everything at 100%)";
  return "";
}

std::string Grading::problem() const {
  if (curve.empty()) return "";
  if (const std::string p = curve.problem(); !p.empty()) return p;
  if (kind == SizeDistribution::uniform)
    return "a curve is interpolated by mass: its distribution must be uniform_mass or log_uniform_mass";
  if (!(d_max > d_min)) return "min and max must differ: a curve grades grains over a range of sizes";
  if (d_min < curve.d.front() || d_max > curve.d.back()) {
    std::ostringstream os;
    os << "the diameter range [" << d_min << ", " << d_max << "] m must lie within the curve's sizes, ["
       << curve.d.front() << ", " << curve.d.back() << "] m (min and max cut a curve, they cannot extend it)";
    return os.str();
  }
  if (!(curve_finer(d_max) > curve_finer(d_min))) return "the curve holds no mass between the smallest and largest diameter";
  return "";
}

double Grading::curve_finer(double d) const {
  const auto& x = curve.d;
  if (d <= x.front()) return curve.finer.front();
  if (d >= x.back()) return curve.finer.back();
  const std::size_t i = static_cast<std::size_t>(std::upper_bound(x.begin(), x.end(), d) - x.begin());
  const double t = kind == SizeDistribution::log_uniform_mass ? std::log(d / x[i - 1]) / std::log(x[i] / x[i - 1])
                                                              : (d - x[i - 1]) / (x[i] - x[i - 1]);
  return curve.finer[i - 1] + t * (curve.finer[i] - curve.finer[i - 1]);
}

std::pair<double, double> Grading::mass_cut() const {
  if (curve.empty()) return {0.0, 0.0};
  return {curve_finer(d_min), 1.0 - curve_finer(d_max)};
}

std::vector<Grading::Piece> Grading::pieces() const {
  if (curve.empty() || d_max <= d_min) return {{d_min, d_max, 1.0, 1.0}};
  std::vector<double> at{d_min};
  for (double x : curve.d)
    if (x > d_min && x < d_max) at.push_back(x);
  at.push_back(d_max);
  const double f0 = curve_finer(d_min), span = curve_finer(d_max) - f0;
  std::vector<Piece> out;
  double grains = 0;
  for (std::size_t i = 0; i + 1 < at.size(); ++i) {
    const double mass = (curve_finer(at[i + 1]) - curve_finer(at[i])) / span;
    // Grains in a piece: its mass over the mean grain mass of its own grading.
    const double n = mass / mean_cube_range(kind, at[i], at[i + 1]);
    out.push_back({at[i], at[i + 1], mass, n});
    grains += n;
  }
  for (auto& p : out) p.number /= grains;
  return out;
}

Grading::Sampler::Sampler(const Grading& g) : g_(&g) {
  if (g.curve.empty()) return;
  pieces_ = g.pieces();
  double sum = 0;
  for (const Piece& p : pieces_) cumulative_.push_back(sum += p.number);
}

double Grading::Sampler::operator()(std::mt19937_64& rng) const {
  if (pieces_.empty()) return draw_range(g_->kind, g_->d_min, g_->d_max, rng);
  const double u = uniform01(rng);
  // The first piece whose cumulative share of the grains exceeds u; never one without
  // grains (u within rounding of 1 past empty last pieces steps back).
  std::size_t k = static_cast<std::size_t>(std::upper_bound(cumulative_.begin(), cumulative_.end(), u) - cumulative_.begin());
  k = std::min(k, pieces_.size() - 1);
  while (pieces_[k].number == 0.0 && k > 0) --k;
  return draw_range(g_->kind, pieces_[k].d_lo, pieces_[k].d_hi, rng);
}

double Grading::draw(std::mt19937_64& rng) const { return Sampler(*this)(rng); }

double Grading::mean() const {
  if (curve.empty()) return mean_range(kind, d_min, d_max);
  double sum = 0;
  for (const Piece& p : pieces()) sum += p.number * mean_range(kind, p.d_lo, p.d_hi);
  return sum;
}

double Grading::mean_cube() const {
  if (curve.empty()) return mean_cube_range(kind, d_min, d_max);
  double sum = 0;
  for (const Piece& p : pieces()) sum += p.number * mean_cube_range(kind, p.d_lo, p.d_hi);
  return sum;
}

double Grading::finer_by_mass(double d) const {
  if (curve.empty()) return finer_range(kind, d_min, d_max, d);
  if (d <= d_min) return 0.0;
  if (d >= d_max) return 1.0;
  const double f0 = curve_finer(d_min);
  return (curve_finer(d) - f0) / (curve_finer(d_max) - f0);
}

std::vector<double> sample_radii(std::size_t n, const Grading& g, std::mt19937_64& rng) {
  const Grading::Sampler draw(g);
  std::vector<double> r(n);
  for (auto& x : r) x = 0.5 * draw(rng);
  return r;
}

}  // namespace demcal::engine
