#pragma once
// Random generation of polydisperse samples without overlaps.
#include "particles.hpp"
#include "types.hpp"

#include <array>
#include <cstdint>
#include <random>
#include <vector>

namespace demcal::engine {

// Portable uniform double in [0, 1) from a 64-bit Mersenne Twister (the standard
// distributions are implementation-defined; this is identical everywhere).
inline double uniform01(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }
inline double uniform(std::mt19937_64& rng, double a, double b) { return a + (b - a) * uniform01(rng); }

// n radii with diameters uniform in [d_min, d_max].
std::vector<double> sample_radii(std::size_t n, double d_min, double d_max, std::mt19937_64& rng);

// Places spheres of the given radii at random, non-overlapping positions with their
// whole volume inside [lo, hi] (periodic axes may wrap). Largest first. Throws
// ConfigError("particles", ...) when the box is too small to hold them.
void insert_random(Particles& p, std::vector<double> radii, const Vec3& lo, const Vec3& hi, double density,
                   std::mt19937_64& rng, const std::array<bool, 3>& periodic = {false, false, false},
                   int max_attempts_per_sphere = 2000);

}  // namespace demcal::engine
