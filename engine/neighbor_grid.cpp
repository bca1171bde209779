#include "neighbor_grid.hpp"

#include "errors.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <sstream>
#ifdef _OPENMP
#include <omp.h>
#endif

namespace demcal::engine {
namespace {

struct Grid {
  Vec3 origin;
  Vec3 cell;  // cell edge per axis
  std::array<int, 3> n{1, 1, 1};
  std::array<bool, 3> periodic{false, false, false};

  int axis_index(double x, int a) const {
    int c = static_cast<int>(std::floor((x - origin[a]) / cell[a]));
    if (periodic[a]) {
      c %= n[a];
      if (c < 0) c += n[a];
      return c;
    }
    return std::clamp(c, 0, n[a] - 1);
  }
  int index(const Vec3& x) const {
    return (axis_index(x[2], 2) * n[1] + axis_index(x[1], 1)) * n[0] + axis_index(x[0], 0);
  }
};

Grid make_grid(const Particles& p, const Domain& dom, double reach) {
  Grid g;
  Vec3 lo = Vec3::Constant(1e300), hi = Vec3::Constant(-1e300);
  for (const Vec3& x : p.x) {
    lo = lo.cwiseMin(x);
    hi = hi.cwiseMax(x);
  }
  for (int a = 0; a < 3; ++a) {
    g.periodic[a] = dom.periodic[a];
    if (dom.periodic[a]) {
      const double len = dom.length(a);
      if (len < 2.0 * reach) {
        std::ostringstream os;
        os << "periodic length " << len << " m on axis " << a << " is shorter than twice the interaction reach "
           << reach << " m (largest diameter plus skin)";
        throw ConfigError("domain.periodic", os.str());
      }
      g.origin[a] = dom.lo[a];
      g.n[a] = std::max(1, static_cast<int>(std::floor(len / reach)));
      g.cell[a] = len / g.n[a];
    } else {
      g.origin[a] = lo[a];
      const double extent = std::max(hi[a] - lo[a], reach);
      g.n[a] = std::max(1, static_cast<int>(std::floor(extent / reach)));
      g.cell[a] = std::max(extent / g.n[a], reach);
    }
  }
  // A sparse cloud spread far would make the dense grid huge: coarsen it.
  const double max_cells = 8.0 * static_cast<double>(p.size()) + 4096.0;
  while (static_cast<double>(g.n[0]) * g.n[1] * g.n[2] > max_cells) {
    for (int a = 0; a < 3; ++a) {
      if (g.periodic[a] || g.n[a] == 1) continue;
      g.n[a] = std::max(1, g.n[a] / 2);
      g.cell[a] *= 2.0;
    }
  }
  return g;
}

// Offsets of the distinct neighbour cells of cell (cx, cy, cz), itself included.
int neighbour_cells(const Grid& g, int cx, int cy, int cz, int* out) {
  int count = 0;
  int axes[3][3] = {}, na[3] = {};
  const int c[3] = {cx, cy, cz};
  for (int a = 0; a < 3; ++a) {
    na[a] = 0;
    for (int d = -1; d <= 1; ++d) {
      int v = c[a] + d;
      if (g.periodic[a]) {
        v = (v % g.n[a] + g.n[a]) % g.n[a];
      } else if (v < 0 || v >= g.n[a]) {
        continue;
      }
      bool seen = false;
      for (int k = 0; k < na[a]; ++k) seen |= (axes[a][k] == v);
      if (!seen) axes[a][na[a]++] = v;
    }
  }
  for (int z = 0; z < na[2]; ++z)
    for (int y = 0; y < na[1]; ++y)
      for (int x = 0; x < na[0]; ++x) out[count++] = (axes[2][z] * g.n[1] + axes[1][y]) * g.n[0] + axes[0][x];
  return count;
}

}  // namespace

void NeighborList::build(const Particles& p, const Domain& dom, double skin, int threads) {
  const int n = static_cast<int>(p.size());
  const double rmax = n ? *std::max_element(p.r.begin(), p.r.end()) : 0.0;
  const Grid g = make_grid(p, dom, 2.0 * rmax + skin);
  const int ncells = g.n[0] * g.n[1] * g.n[2];

  // Counting sort of particles into cells (stable: deterministic order).
  std::vector<int> cell_of(n), cell_start(ncells + 1, 0), cell_items(n);
  for (int i = 0; i < n; ++i) {
    cell_of[i] = g.index(p.x[i]);
    ++cell_start[cell_of[i] + 1];
  }
  std::partial_sum(cell_start.begin(), cell_start.end(), cell_start.begin());
  {
    std::vector<int> fill(cell_start.begin(), cell_start.end() - 1);
    for (int i = 0; i < n; ++i) cell_items[fill[cell_of[i]]++] = i;
  }

  // New rows, one per particle, sorted by j.
  std::vector<int> counts(n + 1, 0);
  std::vector<std::vector<int>> chunk_j(std::max(1, threads));
#pragma omp parallel num_threads(std::max(1, threads))
  {
    int tid = 0;
#ifdef _OPENMP
    tid = omp_get_thread_num();
#endif
    std::vector<int>& out = chunk_j[tid];
    int cells[27];
#pragma omp for schedule(static)
    for (int i = 0; i < n; ++i) {
      const int c = cell_of[i];
      const int cx = c % g.n[0], cy = (c / g.n[0]) % g.n[1], cz = c / (g.n[0] * g.n[1]);
      const int nc = neighbour_cells(g, cx, cy, cz, cells);
      const std::size_t row_begin = out.size();
      for (int k = 0; k < nc; ++k) {
        for (int s = cell_start[cells[k]]; s < cell_start[cells[k] + 1]; ++s) {
          const int jj = cell_items[s];
          if (jj <= i || (p.fixed[i] && p.fixed[jj])) continue;
          Vec3 d = p.x[jj] - p.x[i];
          dom.min_image(d);
          const double reach = p.r[i] + p.r[jj] + skin;
          if (d.squaredNorm() < reach * reach) out.push_back(jj);
        }
      }
      std::sort(out.begin() + static_cast<long>(row_begin), out.end());
      counts[i + 1] = static_cast<int>(out.size() - row_begin);
    }
  }
  std::vector<int> new_start(n + 1, 0);
  std::partial_sum(counts.begin(), counts.end(), new_start.begin());
  std::vector<int> new_j;
  new_j.reserve(new_start[n]);
  for (auto& c : chunk_j) new_j.insert(new_j.end(), c.begin(), c.end());

  // Carry the history of live contacts over: merge old and new rows by j.
  std::vector<Vec3> new_fs(new_j.size(), Vec3::Zero()), new_mr(new_j.size(), Vec3::Zero());
  std::vector<std::uint8_t> new_touch(new_j.size(), 0);
  const bool have_old = static_cast<int>(start.size()) == n + 1;
  if (have_old) {
#pragma omp parallel for schedule(static) num_threads(std::max(1, threads))
    for (int i = 0; i < n; ++i) {
      int a = start[i], ae = start[i + 1];
      for (int b = new_start[i]; b < new_start[i + 1]; ++b) {
        while (a < ae && j[a] < new_j[b]) ++a;
        if (a < ae && j[a] == new_j[b] && touching[a]) {
          new_fs[b] = fs[a];
          new_mr[b] = mr[a];
          new_touch[b] = 1;
        }
      }
    }
  }
  start.swap(new_start);
  j.swap(new_j);
  fs.swap(new_fs);
  mr.swap(new_mr);
  touching.swap(new_touch);
  x_build_ = p.x;
  r_build_ = p.r;
  ++builds_;
}

bool NeighborList::needs_rebuild(const Particles& p, const Domain& dom, double skin, int threads) const {
  if (!built_for(p.size())) return true;
  // A pair can close by the displacement of each grain plus the growth of each
  // radius since the build: rebuild when either side may have used half the skin.
  const long n = static_cast<long>(p.size());
  bool stale = false;
#pragma omp parallel for schedule(static) num_threads(std::max(1, threads)) reduction(|| : stale)
  for (long i = 0; i < n; ++i) {
    Vec3 d = p.x[i] - x_build_[i];
    dom.min_image(d);
    stale = stale || moved_too_far(d, p.r[i], r_build_[i], skin);
  }
  return stale;
}

}  // namespace demcal::engine
