#include "packing.hpp"

#include "errors.hpp"
#include "size_distribution.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <unordered_map>

namespace demcal::engine {

std::vector<double> sample_radii(std::size_t n, double d_min, double d_max, std::mt19937_64& rng) {
  return sample_radii(n, Grading{SizeDistribution::uniform, d_min, d_max}, rng);
}

void insert_random(Particles& p, std::vector<double> radii, const Vec3& lo, const Vec3& hi, double density,
                   std::mt19937_64& rng, const std::array<bool, 3>& periodic, int max_attempts_per_sphere) {
  if (radii.empty()) return;
  std::sort(radii.begin(), radii.end(), std::greater<double>());
  const double rmax = radii.front();
  const double cell = 2.0 * rmax;
  const Vec3 len = hi - lo;
  std::array<long, 3> n{};
  for (int a = 0; a < 3; ++a) n[a] = std::max(1L, static_cast<long>(std::floor(len[a] / cell)));
  auto key = [&](long cx, long cy, long cz) { return (cz * n[1] + cy) * n[0] + cx; };
  auto cell_of = [&](const Vec3& x, int a) {
    return std::clamp(static_cast<long>(std::floor((x[a] - lo[a]) / len[a] * n[a])), 0L, n[a] - 1);
  };
  std::unordered_map<long, std::vector<std::size_t>> grid;
  std::vector<Vec3> placed;
  std::vector<double> placed_r;
  placed.reserve(radii.size());

  for (double r : radii) {
    bool ok = false;
    for (int attempt = 0; attempt < max_attempts_per_sphere && !ok; ++attempt) {
      Vec3 x;
      for (int a = 0; a < 3; ++a) {
        const double margin = periodic[a] ? 0.0 : r;
        if (len[a] < 2.0 * margin) {
          std::ostringstream os;
          os << "box edge " << len[a] << " m on axis " << a << " is smaller than a grain diameter " << 2 * r << " m";
          throw ConfigError("particles", os.str());
        }
        x[a] = uniform(rng, lo[a] + margin, hi[a] - margin);
      }
      ok = true;
      const long c[3] = {cell_of(x, 0), cell_of(x, 1), cell_of(x, 2)};
      for (long dz = -1; dz <= 1 && ok; ++dz)
        for (long dy = -1; dy <= 1 && ok; ++dy)
          for (long dx = -1; dx <= 1 && ok; ++dx) {
            long cc[3] = {c[0] + dx, c[1] + dy, c[2] + dz};
            bool skip = false;
            for (int a = 0; a < 3; ++a) {
              if (cc[a] < 0 || cc[a] >= n[a]) {
                if (!periodic[a]) skip = true;
                cc[a] = (cc[a] % n[a] + n[a]) % n[a];
              }
            }
            if (skip) continue;
            auto it = grid.find(key(cc[0], cc[1], cc[2]));
            if (it == grid.end()) continue;
            for (std::size_t k : it->second) {
              Vec3 d = placed[k] - x;
              for (int a = 0; a < 3; ++a)
                if (periodic[a]) d[a] -= len[a] * std::nearbyint(d[a] / len[a]);
              const double s = placed_r[k] + r;
              if (d.squaredNorm() < s * s) {
                ok = false;
                break;
              }
            }
          }
      if (ok) {
        grid[key(c[0], c[1], c[2])].push_back(placed.size());
        placed.push_back(x);
        placed_r.push_back(r);
      }
    }
    if (!ok) {
      std::ostringstream os;
      os << "could not place " << radii.size() << " grains without overlap in a box of " << len.transpose()
         << " m (placed " << placed.size() << "); enlarge the box or lower the solid fraction";
      throw ConfigError("particles", os.str());
    }
  }
  // Spatial order (by cell) keeps neighbours close in memory.
  std::vector<std::size_t> order(placed.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::vector<long> cell_key(placed.size());
  for (std::size_t i = 0; i < placed.size(); ++i)
    cell_key[i] = key(cell_of(placed[i], 0), cell_of(placed[i], 1), cell_of(placed[i], 2));
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return cell_key[a] < cell_key[b]; });
  for (std::size_t k : order) p.add(placed[k], placed_r[k], density);
}

}  // namespace demcal::engine
