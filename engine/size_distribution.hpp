#pragma once
// Grain diameters between d_min and d_max as a grading says. Laboratories give a
// grading as percent finer by mass; a DEM sample is drawn grain by grain, so the
// mass-based gradings are sampled through their number density (mass / d^3).
#include <cstddef>
#include <random>
#include <string>
#include <utility>
#include <vector>

namespace demcal::engine {

enum class SizeDistribution {
  uniform,           // diameters uniform by number (the default; the seed study's reading)
  uniform_mass,      // percent finer by mass a straight line in d
  log_uniform_mass,  // percent finer by mass a straight line in log d, as on a sieve chart
};
inline constexpr SizeDistribution kSizeDistributions[] = {SizeDistribution::uniform, SizeDistribution::uniform_mass,
                                                          SizeDistribution::log_uniform_mass};
const char* to_string(SizeDistribution s);
bool parse_size_distribution(const std::string& name, SizeDistribution& out);

// A measured grading curve, as a sieve analysis reports it: sizes [m], strictly
// increasing, and the fraction of the mass finer than each (non-decreasing, 0 at the
// first size and 1 at the last).
struct SieveCurve {
  std::vector<double> d, finer;
  bool empty() const { return d.empty() && finer.empty(); }
  std::string problem() const;  // why the curve cannot be a grading, or ""
};

struct Grading {
  Grading() = default;
  Grading(SizeDistribution k, double lo, double hi, SieveCurve c = {})
      : kind(k), d_min(lo), d_max(hi), curve(std::move(c)) {}

  SizeDistribution kind = SizeDistribution::uniform;
  double d_min = 0, d_max = 0;
  // Empty: the grading is `kind` across [d_min, d_max]. Otherwise the part of this
  // curve between d_min and d_max, renormalised (a measured curve cut to the range a
  // simulation can afford), interpolated as `kind` says between its points: straight
  // in d (uniform_mass) or in log d (log_uniform_mass, the sieve chart's axis).
  SieveCurve curve;

  double draw(std::mt19937_64& rng) const;  // one diameter (a Sampler for many)
  double mean() const;                      // number mean of d
  double mean_cube() const;                 // number mean of d^3 (mean grain volume = pi/6 of it)
  double finer_by_mass(double d) const;     // fraction of the mass in grains smaller than d
  // Of a curve's mass, the fractions below d_min and above d_max that the cut leaves
  // out of the sample (0, 0 without a curve).
  std::pair<double, double> mass_cut() const;

  // Between two neighbouring sizes of the curve (or the range's ends) the grading is
  // `kind` over that interval: `mass` is its share of the mass, `number` its share of
  // the grains (both of the whole range).
  struct Piece {
    double d_lo, d_hi, mass, number;
  };
  std::vector<Piece> pieces() const;  // one piece [d_min, d_max] without a curve
  std::string problem() const;         // why the curve cannot give this grading, or ""

  // Draws diameters with the curve's pieces worked out once, not per grain. Holds a
  // pointer to the grading, which must outlive it.
  class Sampler {
   public:
    explicit Sampler(const Grading& g);
    double operator()(std::mt19937_64& rng) const;

   private:
    const Grading* g_;
    std::vector<Piece> pieces_;
    std::vector<double> cumulative_;  // share of the grains up to and including each piece
  };

 private:
  double curve_finer(double d) const;  // the curve interpolated at d, not renormalised
};

// n radii drawn from the grading.
std::vector<double> sample_radii(std::size_t n, const Grading& g, std::mt19937_64& rng);

}  // namespace demcal::engine
