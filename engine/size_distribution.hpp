#pragma once
// Grain diameters between d_min and d_max as a grading says. Laboratories give a
// grading as percent finer by mass; a DEM sample is drawn grain by grain, so the
// mass-based gradings are sampled through their number density (mass / d^3).
#include <cstddef>
#include <random>
#include <string>
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

struct Grading {
  SizeDistribution kind = SizeDistribution::uniform;
  double d_min = 0, d_max = 0;

  double draw(std::mt19937_64& rng) const;  // one diameter
  double mean() const;                      // number mean of d
  double mean_cube() const;                 // number mean of d^3 (mean grain volume = pi/6 of it)
  double finer_by_mass(double d) const;     // fraction of the mass in grains smaller than d
};

// n radii drawn from the grading.
std::vector<double> sample_radii(std::size_t n, const Grading& g, std::mt19937_64& rng);

}  // namespace demcal::engine
