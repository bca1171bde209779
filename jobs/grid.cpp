#include "grid.hpp"

namespace demcal::jobs {

std::uint64_t grid_size(const ParamSet& set, int replicas) {
  std::uint64_t n = static_cast<std::uint64_t>(replicas);
  for (const auto& a : set.axes) {
    // Tested before multiplying: eight axes of 256 values make exactly 2^64, which
    // wrapped to 0 and passed the task limit.
    if (!a.values.empty() && n > grid_size_cap / a.values.size()) return grid_size_cap;
    n *= a.values.size();
  }
  return n;
}

std::vector<nlohmann::json> expand(const ParamSet& set, int replicas, std::uint64_t seed) {
  std::vector<nlohmann::json> out;
  out.reserve(grid_size(set, replicas));
  std::vector<std::size_t> at(set.axes.size(), 0);  // odometer over the axes
  while (true) {
    nlohmann::json p = set.base;
    for (std::size_t i = 0; i < at.size(); ++i) p[set.axes[i].name] = set.axes[i].values[at[i]];
    for (int r = 0; r < replicas; ++r) {
      p["seed"] = seed + static_cast<std::uint64_t>(r);
      out.push_back(p);
    }
    std::size_t k = at.size();
    while (k > 0 && ++at[k - 1] == set.axes[k - 1].values.size()) at[--k] = 0;
    if (k == 0) break;
  }
  return out;
}

}  // namespace demcal::jobs
