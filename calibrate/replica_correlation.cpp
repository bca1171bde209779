#include "replica_correlation.hpp"

#include <algorithm>
#include <cmath>
#include <unordered_map>
#include <utility>
#include <vector>

namespace demcal::calibrate {

ReplicaCorrelation replica_correlation(const ResponseSurface& a, const ResponseSurface& b) {
  ReplicaCorrelation c;
  if (a.job != b.job) {
    c.reason = "different jobs (different packings)";
    return c;
  }
  std::unordered_map<std::int64_t, double> of_b;
  for (const auto& p : b.points)
    for (std::size_t r = 0; r < p.tasks.size() && r < p.values.size(); ++r) of_b.emplace(p.tasks[r], p.values[r]);
  double sab = 0, saa = 0, sbb = 0;
  for (const auto& p : a.points) {
    std::vector<std::pair<double, double>> pairs;
    for (std::size_t r = 0; r < p.tasks.size() && r < p.values.size(); ++r)
      if (auto it = of_b.find(p.tasks[r]); it != of_b.end()) pairs.emplace_back(p.values[r], it->second);
    if (pairs.size() < 2) continue;
    double ma = 0, mb = 0;
    for (const auto& [va, vb] : pairs) ma += va, mb += vb;
    ma /= static_cast<double>(pairs.size());
    mb /= static_cast<double>(pairs.size());
    for (const auto& [va, vb] : pairs) {
      sab += (va - ma) * (vb - mb);
      saa += (va - ma) * (va - ma);
      sbb += (vb - mb) * (vb - mb);
    }
    c.dof += static_cast<int>(pairs.size()) - 1;
    ++c.points;
  }
  if (c.dof < kMinCorrelationDof) {
    c.reason = std::to_string(c.dof) + " dof from paired replicas, fewer than " + std::to_string(kMinCorrelationDof);
    return c;
  }
  if (!(saa > 0) || !(sbb > 0)) {
    c.reason = "no spread between replicas";
    return c;
  }
  c.rho = std::clamp(sab / std::sqrt(saa * sbb), -kMaxCorrelation, kMaxCorrelation);
  c.estimated = true;
  return c;
}

}  // namespace demcal::calibrate
