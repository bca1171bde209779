#pragma once
// Cell-grid neighbour search with a Verlet skin, producing a half list (each pair
// once, j > i) in compressed rows, with the contact history stored alongside and
// carried over from the previous list at every rebuild.
#include "domain.hpp"
#include "particles.hpp"
#include "types.hpp"

#include <algorithm>
#include <cstdint>
#include <vector>

namespace demcal::engine {

class NeighborList {
 public:
  // Rows: the candidates of particle i are entries [start[i], start[i+1]).
  std::vector<int> start;
  std::vector<int> j;
  // Contact history per entry: tangential spring force and rolling moment acting
  // on i; `touching` flags entries whose history is live.
  std::vector<Vec3> fs;
  std::vector<Vec3> mr;
  std::vector<std::uint8_t> touching;

  // Rebuilds the list for the current positions; history of pairs present in both
  // the old and the new list is kept. Pairs of two fixed grains are left out.
  void build(const Particles& p, const Domain& dom, double skin, int threads);

  // True when some particle has moved, or grown, by more than half the skin since
  // the last build.
  bool needs_rebuild(const Particles& p, const Domain& dom, double skin, int threads = 1) const;
  // The same test for one grain: d is its displacement since the build (minimum
  // image), r and rb its radius now and at the build. For a caller that folds the
  // test into a pass of its own over build_positions() and build_radii().
  static bool moved_too_far(const Vec3& d, double r, double rb, double skin) {
    const double left = 0.5 * skin - std::max(0.0, r - rb);
    return left <= 0.0 || d.squaredNorm() > left * left;
  }
  const Vec3* build_positions() const { return x_build_.data(); }
  const double* build_radii() const { return r_build_.data(); }
  bool built_for(std::size_t n) const { return x_build_.size() == n; }

  std::size_t size() const { return j.size(); }
  long builds() const { return builds_; }

 private:
  void carry_history(const std::vector<int>& new_start, const std::vector<int>& new_j, int threads);

  std::vector<Vec3> x_build_;
  std::vector<double> r_build_;
  long builds_ = 0;
};

}  // namespace demcal::engine
